"""The bare UDP echo in Rust, the third row of rsi_latency.py and egm_latency.py.

``benchmarks/native_echo`` (a std-only binary crate, not part of plugcell) does what the
Python echo does — ``recv_from`` → ``send_to`` of the part of the datagram that carries
its sequence number (:class:`rsi_latency.EchoPart`), timing each packet in → answer out —
and speaks the same lines with the robot side (``READY <port> <note>``, a line ending the
warm-up, a line asking for the JSON report).  It answers in its main thread, so this
module gives that thread, from outside, the scheduling the other sensors' answering
threads give themselves (:meth:`RealTime.apply`): ``SCHED_FIFO`` at the same priority,
every thread of it on the same CPUs, its memory locked (``--mlock``, by the binary).
Any missed cycle it shows is then neither Python's nor plugcell's.

Built with ``cargo build --release`` when a benchmark runs (cached in
``benchmarks/native_echo/target``: ~2 s the first time, nothing after).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from plugcell.devices.robot.stream.realtime import RealTime, fifo_refused, pin

CRATE = Path(__file__).resolve().with_name("native_echo")
BINARY = CRATE / "target" / "release" / "plugcell_native_echo"
#: The row's name in the table and the JSON.
NAME = "native UDP echo (Rust)"


def build() -> Path | str:
    """Build the crate (cargo, release; up to date: nothing to do) and return the binary,
    or — no cargo on PATH — why the row is left out (a sentence).

    Raises
    ------
    RuntimeError
        cargo is there but the build failed: its messages.
    """
    cargo = shutil.which("cargo")
    if cargo is None:
        return ("native echo left out: no cargo on PATH (a Rust toolchain, e.g. "
                "https://rustup.rs, builds benchmarks/native_echo)")
    done = subprocess.run([cargo, "build", "--release", "--quiet"], cwd=CRATE,
                          capture_output=True, text=True)
    if done.returncode != 0 or not BINARY.is_file():
        raise RuntimeError(f"building {CRATE} failed:\n{done.stderr[-3000:]}")
    return BINARY


def schedule(pid: int, rt: RealTime) -> str:
    """Give the echo's answering thread (its main thread, ``pid``) ``rt``'s priority and
    every thread of it ``rt``'s CPUs; what happened, as :meth:`RealTime.apply` says it."""
    notes = []
    if rt.cpus is not None:
        try:
            tids = [int(t) for t in os.listdir(f"/proc/{pid}/task")]
        except OSError:
            tids = [pid]
        notes = [pin(rt.cpus, tid) for tid in tids][:1]
    if rt.priority is None:
        return ", ".join(["normal priority", *notes])
    try:
        os.sched_setscheduler(pid, os.SCHED_FIFO, os.sched_param(rt.priority))
    except (AttributeError, OSError) as exc:
        return ", ".join([f"{fifo_refused(exc, rt.priority)}; normal priority", *notes])
    return ", ".join([f"SCHED_FIFO priority {rt.priority}", *notes])


def spawn(binary: Path, echo_args: list[str], rt: RealTime) -> tuple[subprocess.Popen, int, str]:
    """Start the echo (``echo_args``: :meth:`EchoPart.args`), scheduled as ``rt`` says;
    the process, its port and a note of its scheduling.

    Raises
    ------
    RuntimeError
        It did not say ``READY``: what it said instead.
    """
    proc = subprocess.Popen([str(binary), *echo_args, *(["--mlock"] if rt.lock_memory else [])],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    if not line.startswith("READY "):
        proc.kill()
        raise RuntimeError(f"the native echo did not start: {line!r}")
    _, port, *note = line.split(maxsplit=2)
    return proc, int(port), ", ".join([schedule(proc.pid, rt), *(n.strip() for n in note)])


if __name__ == "__main__":  # build it: python benchmarks/rust_echo.py
    print(build(), file=sys.stderr)
