"""What the journal's durability rule and the protocol's messages cost *any* implementation
of the request path.

    .venv/bin/python benchmarks/durability_floor.py [--cycles 4000] [--repeat 3]

The event-loop floor of ``plugcell bench transport`` (raw Zenoh between two OS
processes, each sample handed to an event loop by ``call_soon_threadsafe``, the answer
put from that loop, the requester awaiting a future) with the answering side doing,
before each answer, what the journal's rule asks of every request ("a process row is
committed before its acknowledgement is sent; every update before it is published",
``framework/journal.py``) and nothing else:

* ``nothing`` — the floor itself;
* ``log append`` — the same three rows (a process and its Running and Completed
  updates) encoded with msgspec and appended to a file with one ``os.write``: the
  cheapest write that, like SQLite's WAL with ``synchronous=NORMAL``, survives the
  death of the process (the kernel has the bytes);
* ``SQLite commit`` — the same rows inserted into the journal's tables and committed
  in one SQLite transaction (WAL, ``synchronous=NORMAL``): how plugcell's journal kept
  the rule until 2026-11-26;
* ``Journal`` — the real :class:`~plugcell.framework.journal.Journal`:
  ``record_process``, two ``record_update`` and one ``commit``, as an ``Echo`` costs
  the service (a log append; its rows move into SQLite in the background).

No decoding, admission, scheduling or outbox in these: whatever a native or Python
framework adds comes on top, so they bound from below what the request path can reach
with each way of keeping the rule.  Two more variants add the protocol's own work per
message, done in Python with plugcell's own functions but without its framework (no
scheduler, tasks, timeouts or outbox) — what a lean Python request path could reach:

* ``protocol's bytes`` — the floor with the requests and answers of ``protocol`` (below),
  encoded once beforehand: what their size costs Zenoh;
* ``protocol`` — the requester sends a real ``Echo`` CreateProcess (its input checked
  and typed, :func:`~plugcell.framework.wire.encode`, the identifier attached) and waits
  for the answer's final update, decoded and matched to the request; the answering
  side admits it as a service does (:func:`~plugcell.framework.admission.decode_request`,
  ``check_envelope``, ``check_process``, ``check_input``) and answers with the
  acknowledgement and the ``Completed`` update carrying the data, in one
  :class:`~plugcell.framework.messages.ProcessUpdateBatch` — the same bytes on the wire
  as plugcell's;
* ``protocol + Journal`` — the same, journaled as the service journals an ``Echo``
  (the process row, its Running and Completed updates, one commit) before the answer.

The variants run interleaved, ``--repeat`` rounds; the table gives each one's median
over the rounds of the average one-way latency (round trip ÷ 2) and what it adds to the
floor.  Last, the protocol's work of one round trip (both sides, no journal) is timed in
a tight loop in this process: what the same Python costs with warm caches, beside what it
adds between the two processes, where each side's caches go cold between messages.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import platform
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from importlib import metadata
from pathlib import Path
from typing import Any

import msgspec
import zenoh

VARIANTS = ("nothing", "log append", "SQLite commit", "Journal", "protocol's bytes",
            "protocol", "protocol + Journal")
#: The variants whose messages are plugcell's CreateProcess and its answer.
PROTOCOL = ("protocol", "protocol + Journal")
REQUESTER, SERVICE = "REQUESTER", "SERVICE"


def _echo() -> Any:
    """The ``Echo`` command of the transport benchmark's service (its catalogue entry)."""
    from plugcell.apps.bench.device import BenchService

    return next(c for c in BenchService.commands if c.name == "Echo")


class _LeanService:
    """The answering side of :data:`PROTOCOL`: admit an ``Echo`` CreateProcess as a
    service does, journal it (with ``journal``), answer with its acknowledgement and its
    final update in one batch — without scheduler, tasks or outbox."""

    def __init__(self, journal: Any) -> None:
        from plugcell.framework.messages import Device

        self.command = _echo()
        self.device = Device(name=SERVICE, commands=(self.command,))
        self.journal = journal
        self.instance = "service-instance"

    def answer(self, payload: Any) -> bytes:
        from plugcell.framework import admission, wire
        from plugcell.framework.data import summary, to_data
        from plugcell.framework.messages import (
            Acknowledgement,
            ProcessStates,
            ProcessUpdateBatch,
            ProcessUpdateNotification,
        )

        received = time.time_ns()
        decoded = admission.decode_request(payload, wire.DEFAULT_MAX_PAYLOAD, SERVICE)
        if isinstance(decoded, str):
            raise RuntimeError(decoded)
        envelope, _ = decoded
        process = envelope.body
        reason = (admission.check_envelope(envelope, REQUESTER)
                  or admission.check_process(SERVICE, self.device, envelope, process, set()))
        array, reason = (None, reason) if reason else admission.check_input(
            self.command, process)
        if reason:
            raise RuntimeError(reason)
        output = to_data(array, self.command.output_data_type, self.command.output_data_size)
        if self.journal is not None:
            self.journal.record_process(
                sender=REQUESTER, identifier=process.identifier,
                sender_instance=envelope.instance, recipient_instance=self.instance,
                command=self.command.name, option="", command_type=self.command.type.value,
                input_summary=summary(process.data), received_ns=received,
                state=ProcessStates.Queued.value,
            )
            self.journal.record_update(REQUESTER, process.identifier, 1, "Running", "", "")
            self.journal.record_update(REQUESTER, process.identifier, 2, "Completed", "",
                                       summary(output))
            self.journal.commit()
        return wire.encode(SERVICE, self.instance, ProcessUpdateBatch(
            acks=[Acknowledgement(identifier=process.identifier, state=ProcessStates.Queued,
                                  instance=self.instance)],
            updates=[ProcessUpdateNotification(
                tag=process.tag, identifier=process.identifier,
                state=ProcessStates.Completed, data=output, seq=2)],
        ))


class _LeanRequester:
    """The requesting side of :data:`PROTOCOL`: an ``Echo`` CreateProcess of 4 bytes out
    (input checked and typed, identifier attached), its final update in."""

    def __init__(self) -> None:
        import numpy as np

        self.command = _echo()
        self.value = np.arange(4, dtype=np.uint8)
        self.identifier = 0

    def request(self) -> tuple[bytes, bytes]:
        """The next request's payload and attachment."""
        from plugcell.framework import wire
        from plugcell.framework.data import to_data
        from plugcell.framework.messages import Process, Tag

        self.identifier += 1
        data = to_data(self.value, self.command.input_data_type, self.command.input_data_size)
        process = Process(command=self.command, tag=Tag(REQUESTER, SERVICE),
                          identifier=self.identifier, data=data)
        return (wire.encode(REQUESTER, "requester-instance", process),
                wire.attach_identifier(self.identifier))

    def final(self, payload: bytes) -> bool:
        """Whether ``payload`` holds the final update of the last request (its data read)."""
        from plugcell.framework import wire
        from plugcell.framework.data import from_data
        from plugcell.framework.messages import process_acks, process_updates

        body = wire.decode(payload).body
        for ack in process_acks(body):
            if ack.identifier == self.identifier and ack.state.final:
                raise RuntimeError(f"request {ack.identifier} refused: {ack.reason}")
        for update in process_updates(body):
            if update.identifier == self.identifier and update.state.final:
                from_data(update.data)
                return True
        return False


def _serve(variant: str, key: str, folder: str) -> None:
    """Answer every ``key/ping`` on ``key/pong`` from an event loop, after ``variant``."""
    from plugcell.framework import eventloop
    from plugcell.framework.journal import TABLES, Journal
    from plugcell.framework.transport import TransportConfig, open_session

    session = open_session(TransportConfig.from_env())
    pong = session.declare_publisher(
        f"{key}/pong", express=True, congestion_control=zenoh.CongestionControl.BLOCK
    )
    loop = eventloop.new_event_loop()
    journal = (
        Journal(Path(folder) / "SERVICE.sqlite", SERVICE)
        if variant in ("Journal", "protocol + Journal") else None
    )
    lean = _LeanService(journal) if variant in PROTOCOL else None
    canned = _canned()[1] if variant == "protocol's bytes" else None
    log = (
        os.open(Path(folder) / "SERVICE.log", os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        if variant == "log append"
        else None
    )
    db = None
    if variant == "SQLite commit":
        db = sqlite3.connect(Path(folder) / "SERVICE.sqlite")
        db.execute("PRAGMA journal_mode=WAL")
        db.execute("PRAGMA synchronous=NORMAL")
        db.executescript(TABLES)
    encoder = msgspec.msgpack.Encoder()
    count = 0

    def answer(payload: Any) -> None:
        nonlocal count
        count += 1
        if lean is not None:
            pong.put(lean.answer(payload))
            return
        if canned is not None:
            pong.put(canned)
            return
        if journal is not None:
            journal.record_process(
                sender="REQUESTER", identifier=count, sender_instance="requester-instance",
                recipient_instance="service-instance", command="Echo", option="",
                command_type="Get", input_summary="Integer[1] [7]",
                received_ns=time.time_ns(), state="Queued",
            )
            journal.record_update("REQUESTER", count, 1, "Running", "", "")
            journal.record_update("REQUESTER", count, 2, "Completed", "", "Integer[1] [7]")
            journal.commit()
        elif db is not None:
            now = time.time_ns()
            db.execute(
                "INSERT INTO processes VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)",
                ("SERVICE", "REQUESTER", count, "service-instance", "requester-instance",
                 "Echo", "", "Get", "Integer[1] [7]", now, now, "Queued", ""),
            )
            db.executemany("INSERT INTO updates VALUES (?,?,?,?,?,?,?,?)", (
                ("SERVICE", "REQUESTER", count, 1, now, "Running", "", ""),
                ("SERVICE", "REQUESTER", count, 2, now, "Completed", "", "Integer[1] [7]"),
            ))
            db.commit()
        elif log is not None:
            now = time.time_ns()
            os.write(log, encoder.encode((
                ("SERVICE", "REQUESTER", count, "service-instance", "requester-instance",
                 "Echo", "", "Get", "Integer[1] [7]", now, now, "Queued", ""),
                ("SERVICE", "REQUESTER", count, 1, now, "Running", "", ""),
                ("SERVICE", "REQUESTER", count, 2, now, "Completed", "", "Integer[1] [7]"),
            )))
        pong.put(payload)

    session.declare_subscriber(  # the protocol's answer reads the payload as a service does
        f"{key}/ping",
        (lambda sample: loop.call_soon_threadsafe(answer, sample.payload)) if lean else
        (lambda sample: loop.call_soon_threadsafe(answer, sample.payload.to_bytes())),
    )
    print("ready", flush=True)
    loop.run_forever()


async def _ping(key: str, variant: str, cycles: int, warmup: int) -> float:
    """Average one-way latency in ms of ``cycles`` 4-byte round trips to ``key`` (of
    :data:`PROTOCOL` variants: ``Echo`` processes of 4 bytes)."""
    from plugcell.framework.transport import TransportConfig, open_session

    session = open_session(TransportConfig.from_env())
    loop = asyncio.get_running_loop()
    waiting: list[asyncio.Future[bytes]] = []
    lean = _LeanRequester() if variant in PROTOCOL else None
    canned = _canned()[0] if variant == "protocol's bytes" else None

    def arrived(answer: bytes) -> None:
        if waiting and not waiting[0].done() and (lean is None or lean.final(answer)):
            waiting[0].set_result(answer)

    session.declare_subscriber(
        f"{key}/pong", lambda sample: loop.call_soon_threadsafe(arrived, sample.payload.to_bytes())
    )
    ping = session.declare_publisher(
        f"{key}/ping", express=True, congestion_control=zenoh.CongestionControl.BLOCK
    )

    def put() -> None:
        if canned is not None:
            ping.put(canned)
        elif lean is None:
            ping.put(b"ping")
        else:
            payload, attachment = lean.request()
            ping.put(payload, attachment=attachment)

    try:
        for _ in range(200):  # until the answering side's subscriber is matched
            waiting[:] = [loop.create_future()]
            put()
            try:
                await asyncio.wait_for(waiting[0], 0.05)
                break
            except TimeoutError:
                continue
        else:
            raise RuntimeError("the answering process never answered")
        half_trips = []
        for i in range(warmup + cycles):
            waiting[:] = [loop.create_future()]
            started = time.perf_counter_ns()
            put()
            await asyncio.wait_for(waiting[0], 5.0)
            if i >= warmup:
                half_trips.append((time.perf_counter_ns() - started) / 2)
        return statistics.fmean(half_trips) / 1e6
    finally:
        session.close()


def _canned() -> tuple[bytes, bytes]:
    """A request of :data:`PROTOCOL` and its answer, as bytes."""
    request, _ = _LeanRequester().request()
    return request, _LeanService(None).answer(zenoh.ZBytes(request))


def _tight(cycles: int) -> float:
    """µs of the protocol's work of one round trip (request, answer, final update; no
    journal), the median of 5 tight loops of ``cycles`` round trips in this process."""
    requester, service = _LeanRequester(), _LeanService(None)
    runs = []
    for _ in range(5):
        started = time.perf_counter_ns()
        for _ in range(cycles):
            payload, _ = requester.request()
            if not requester.final(service.answer(zenoh.ZBytes(payload))):
                raise RuntimeError("the answer does not end the request")
        runs.append((time.perf_counter_ns() - started) / cycles / 1e3)
    return statistics.median(runs)


def _round(variant: str, cycles: int, warmup: int) -> float:
    from plugcell.framework import eventloop

    key = f"plugcell-bench/durability{os.getpid()}/{time.monotonic_ns()}"
    with tempfile.TemporaryDirectory(prefix="plugcell-durability-") as folder:
        server = subprocess.Popen(
            [sys.executable, __file__, "--serve", variant, key, folder],
            stdout=subprocess.PIPE, text=True,
        )
        try:
            assert server.stdout is not None
            if server.stdout.readline().strip() != "ready":
                raise RuntimeError(f"the answering process for {variant!r} did not start")
            return eventloop.run(_ping(key, variant, cycles, warmup))
        finally:
            server.kill()
            server.wait()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=4000)
    parser.add_argument("--warmup", type=int, default=500)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--serve", nargs=3, metavar=("VARIANT", "KEY", "FOLDER"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve:
        _serve(*args.serve)
        return 0
    if args.cycles < 1 or args.repeat < 1 or args.warmup < 0:
        parser.error("--cycles and --repeat must be at least 1, --warmup at least 0")
    results: dict[str, list[float]] = {v: [] for v in VARIANTS}
    for r in range(args.repeat):
        for variant in VARIANTS:
            results[variant].append(_round(variant, args.cycles, args.warmup))
            print(f"  … round {r + 1}/{args.repeat}: {variant}: "
                  f"{results[variant][-1]:.4f} ms", file=sys.stderr, flush=True)
    print(f"4-byte round trips between two processes through an event loop on each side, "
          f"{args.cycles} cycles × {args.repeat} rounds; {platform.machine()}, "
          f"Python {platform.python_version()}, eclipse-zenoh {metadata.version('eclipse-zenoh')}")
    floor = statistics.median(results[VARIANTS[0]])
    print(f"{'before each answer':<20} {'one-way ms':>11} {'added µs':>9} {'× floor':>8}  rounds")
    for variant in VARIANTS:
        med = statistics.median(results[variant])
        rounds = " ".join(f"{x:.4f}" for x in results[variant])
        print(f"{variant:<20} {med:11.4f} {(med - floor) * 1e3:9.1f} {med / floor:8.2f}  {rounds}")
    added = 2 * (statistics.median(results["protocol"]) - floor) * 1e3
    print(f"the protocol's work of one round trip (both sides): {_tight(args.cycles):.1f} µs "
          f"in a tight loop, {added:.1f} µs added to the round trip above")
    return 0


if __name__ == "__main__":
    sys.exit(main())
