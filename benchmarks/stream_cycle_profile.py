"""Where the time of one real-time cycle goes: the RSI and EGM links fed recorded packets.

    python benchmarks/stream_cycle_profile.py [--cycles 20000] [--vendor rsi egm] [--gap-ms 0]
        [--profile]

No socket and no second process: a link (``RsiLink``, absolute joint corrections;
``EgmLink``, joint mode) with the swinging joint offset of ``rsi_latency.py`` and the
shared-memory publisher of the link process (:class:`~plugcell.devices.robot.stream.process
.Publisher`) as its observer is fed the packets ``rsi_latency.py`` and ``egm_latency.py``
send, one after the other, through the code a datagram takes in the link's thread
(``_accept`` → ``_cycle_once``; the answer goes to a socket stand-in that drops it).
Each cycle is timed by stage with ``time.perf_counter_ns``: *parse* (the vendor's
parser), *ask* (the cycle's state, the correction source, the limiter), *encode* (the
answer), and *rest* (sequence, counters, the send call, the publisher, the waiters).
The table gives each stage's median and p99 (µs); the machine's load shows in the p99,
the medians are the per-packet work.  Back to back the cycles find their code and data in
the caches; ``--gap-ms 4`` sleeps a cycle between two, as the link does, and shows the
cost of a cycle that finds them evicted by the machine's other processes.  ``--profile``
adds cProfile's largest functions (the profiler's own cost inflates every call; the
shares are what matter).
"""

from __future__ import annotations

import argparse
import cProfile
import ctypes
import os
import pstats
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from egm_latency import egm_message
from rsi_latency import rob_packet

STAGES = ("parse", "ask", "encode", "rest", "cycle")


class _Drop:
    """The socket stand-in: ``sendto`` drops the answer."""

    def sendto(self, packet: bytes, addr: tuple[str, int]) -> int:
        return len(packet)


def make_link(vendor: str) -> tuple[Any, Callable[[int], bytes]]:
    """A link of ``vendor`` ("rsi", "egm") ready to be fed, and its packet of cycle k."""
    from plugcell.devices.robot.stream.process import SLOTS, TEXT_BYTES, Publisher
    from plugcell.devices.robot.stream.source import SineOffset
    from plugcell.io.units import DEG

    source = SineOffset(axis=5, amplitude=2 * DEG, period=4.0, periods=10**6)
    if vendor == "rsi":
        from plugcell.devices.robot.rsi import RsiConfig, RsiLink

        link = RsiLink(RsiConfig(robot_host="127.0.0.1", listen_port=0, mode="absolute",
                                 cycle="IPO_FAST"), source)

        def packet(k: int) -> bytes:
            return rob_packet(4_000_000_000 + 4 * k, (k % 1000) * 1e-3)
    else:
        from plugcell.devices.robot.egm import EgmConfig, EgmLink

        link = EgmLink(EgmConfig(robot_host="127.0.0.1", listen_port=0, mode="joint",
                                 sample_rate_ms=4), source)

        def packet(k: int) -> bytes:
            return egm_message(k + 1, (k % 1000) * 1e-3)
    link._sock = _Drop()
    link.observer = Publisher((ctypes.c_double * SLOTS)(), ctypes.create_string_buffer(TEXT_BYTES))
    link._warm_up()
    return link, packet


def _timed(link: Any, name: str, into: list[int]) -> None:
    """Wrap the link's method ``name`` so that each call adds its time to ``into[0]``."""
    inner = getattr(link, name)

    def wrapper(*args: Any) -> Any:
        t0 = time.perf_counter_ns()
        try:
            return inner(*args)
        finally:
            into[0] += time.perf_counter_ns() - t0

    setattr(link, name, wrapper)


def measure(vendor: str, cycles: int, gap_s: float = 0.0) -> dict[str, np.ndarray]:
    """Per-stage times (ns) of ``cycles`` cycles, after as many warm-up cycles, with
    ``gap_s`` seconds of sleep between two cycles."""
    link, packet = make_link(vendor)
    packets = [packet(k) for k in range(2 * cycles)]
    addr = ("127.0.0.1", 50000)
    parse, ask, encode = [0], [0], [0]
    for name, into in (("_parse", parse), ("_ask", ask), ("_encode", encode)):
        _timed(link, name, into)
    times = {s: np.zeros(cycles, dtype=np.int64) for s in STAGES}
    for k, data in enumerate(packets):
        if gap_s:
            time.sleep(gap_s)
        parse[0] = ask[0] = encode[0] = 0
        t0 = time.perf_counter_ns()
        state = link._accept(data, addr)
        link._cycle_once(state, addr, time.monotonic_ns())
        total = time.perf_counter_ns() - t0
        if k >= cycles:
            i = k - cycles
            times["parse"][i], times["ask"][i], times["encode"][i] = parse[0], ask[0], encode[0]
            times["rest"][i] = total - parse[0] - ask[0] - encode[0]
            times["cycle"][i] = total
    st = link.stats()
    if st.answered != len(packets) or link.failure is not None:
        raise RuntimeError(f"{vendor}: the link did not answer every packet: {st}")
    return times


def profile(vendor: str, cycles: int, top: int) -> None:
    """cProfile's ``top`` functions by own time over ``cycles`` cycles."""
    link, packet = make_link(vendor)
    packets = [packet(k) for k in range(cycles)]
    addr = ("127.0.0.1", 50000)
    prof = cProfile.Profile()
    prof.enable()
    for data in packets:
        link._cycle_once(link._accept(data, addr), addr, time.monotonic_ns())
    prof.disable()
    pstats.Stats(prof).sort_stats("tottime").print_stats(top)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cycles", type=int, default=20000)
    ap.add_argument("--vendor", nargs="+", choices=("rsi", "egm"), default=["rsi", "egm"])
    ap.add_argument("--profile", action="store_true", help="also cProfile's largest functions")
    ap.add_argument("--top", type=int, default=20)
    ap.add_argument("--gap-ms", type=float, default=0.0,
                    help="sleep between two cycles, as the link waits for the next packet "
                    "(the machine's other processes then evict the caches)")
    args = ap.parse_args(argv)
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}; "
          f"Python {sys.version.split()[0]}; {args.cycles} cycles per link "
          f"(after as many warm-up cycles), {args.gap_ms:g} ms between two")
    print()
    print("| link | " + " | ".join(f"{s} p50 / p99 (µs)" for s in STAGES) + " |")
    print("|---|" + "---:|" * len(STAGES))
    for vendor in args.vendor:
        t = measure(vendor, args.cycles, args.gap_ms / 1000)
        cells = [f"{np.percentile(t[s], 50) / 1e3:.1f} / {np.percentile(t[s], 99) / 1e3:.1f}"
                 for s in STAGES]
        print(f"| {vendor.upper()} | " + " | ".join(cells) + " |")
    if args.profile:
        for vendor in args.vendor:
            print(f"\ncProfile, {vendor.upper()}, {args.cycles} cycles:")
            profile(vendor, args.cycles, args.top)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
