"""What the journal's durability rule and the protocol's messages cost *any* implementation
of the request path, beside raw Zenoh and plugcell itself.

    .venv/bin/python benchmarks/durability_floor.py [--cycles 4000] [--repeat 3]
        [--native] [--output FILE.json] [--plot FILE.png]
    .venv/bin/python benchmarks/durability_floor.py --replot FILE.json --plot FILE.png

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
  and typed, :func:`~plugcell.framework.codec.encode`, the identifier attached) and waits
  for the answer's final update, decoded and matched to the request; the answering
  side admits it as a service does (:func:`~plugcell.framework.admission.decode_request`,
  ``check_envelope``, ``check_process``, ``check_input``) and answers with the
  acknowledgement and the ``Completed`` update carrying the data, in one
  :class:`~plugcell.framework.messages.ProcessUpdateBatch` — the same bytes on the wire
  as plugcell's;
* ``protocol + Journal`` — the same, journaled as the service journals an ``Echo``
  (the process row, its Running and Completed updates, one commit) before the answer.

Two more rows put these on the scale of issue 20's target (4 B latency ≤ 1.5× raw
Zenoh), measured in the same rounds:

* ``raw Zenoh`` — plain Zenoh ping-pong between two Python processes, each callback
  handing the sample to a thread (``plugcell bench transport``'s floor: the raw peer of
  :mod:`plugcell.apps.bench.peer` and its :class:`~plugcell.apps.bench.peer.RawFloor`);
* ``plugcell`` — ``plugcell bench transport``'s 4 B latency test itself: a requesting
  service's ``create_process("PUBLISHER", "Echo", 4 bytes)`` until its update, against
  the benchmark's service, both with their journals.

With ``--native`` (Linux, needs cargo and crates.io or cargo's cache), four more rows do the
protocol's per-message work in Rust instead — the measuring device
``benchmarks/native_probe`` (PyO3, not part of plugcell), built first (≈ 15 s from
nothing): the same request and answer, byte for byte apart from the timestamp, and the
same checks, called from the Python callbacks of eclipse-zenoh's own session:

* ``native protocol`` — the requester's request and its reading of the answer, the
  service's decoding, checks and answer, each one call into Rust;
* ``native protocol + log`` — the same, the service appending the process and its two
  updates to a journal log as one record (the format of ``framework/journal_log.py``);
* ``native handler`` — ``native protocol + log`` with the device's handler in Python
  between the service's two calls into Rust: ``BenchService``'s ``Echo``, an ``async
  def`` taking a numpy view of the input and posting its output as data feedback, run to
  its end as a scheduler could run it on an idle device (the coroutine driven without a
  task), its success code checked — the least Python any framework with Python devices
  runs per process;
* ``native core`` — the same with the rest of the Python that plugcell's Python API
  keeps for every process: on the service, the handler's output typed against the
  catalogue (:func:`~plugcell.framework.data.to_data`); on the requester, the answer
  decoded into the
  :class:`~plugcell.framework.messages.ProcessUpdateNotification` a caller is handed
  (msgspec, :func:`~plugcell.framework.codec.decode`), routed to the waiting call's
  future by sender and identifier, and its data read as a numpy view.  The best a
  product with a native core behind today's API could reach.

Every round starts both ends afresh, each an OS process of its own (so that no variant
shares Zenoh's runtime threads with another, see docs/results/framework-performance.md on
thread states).
The variants run interleaved, ``--repeat`` rounds; the table gives each one's median
over the rounds of the average one-way latency (round trip ÷ 2), its ratio to raw Zenoh
and what it adds to the event-loop floor.  ``--output`` writes every round to a JSON
file, ``--plot`` draws the medians with the target (needs matplotlib), ``--replot``
redraws a saved run.  Last, the
protocol's work of one round trip (both sides, no journal) is timed in a tight loop in
this process: what the same Python costs with warm caches, beside what it adds between
the two processes, where each side's caches go cold between messages.
"""

from __future__ import annotations

import argparse
import asyncio
import importlib.util
import json
import os
import platform
import shutil
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from importlib import metadata
from pathlib import Path
from types import ModuleType
from typing import Any

import msgspec
import zenoh

VARIANTS = ("raw Zenoh", "nothing", "log append", "SQLite commit", "Journal",
            "protocol's bytes", "protocol", "protocol + Journal", "plugcell")
#: ``--native``: the protocol's per-message work in Rust (benchmarks/native_probe).
NATIVE = ("native protocol", "native protocol + log", "native handler", "native core")
#: What each variant's row says it is.
LABELS = {
    "raw Zenoh": "raw Zenoh (thread hop)",
    "nothing": "event loops (their floor)",
    "log append": "+ a log append",
    "SQLite commit": "+ an SQLite commit",
    "Journal": "+ plugcell's Journal",
    "protocol's bytes": "+ the protocol's bytes",
    "protocol": "+ the protocol's messages",
    "protocol + Journal": "+ messages and Journal",
    "plugcell": "plugcell (service, requester)",
    "native protocol": "+ the messages, in Rust",
    "native protocol + log": "+ messages and log, in Rust",
    "native handler": "+ Rust core, Python handler",
    "native core": "+ the same, Python API",
}
#: The variants whose far end is a peer of ``plugcell bench transport`` (a cell, not a key).
BENCH_PEER = {"raw Zenoh": "raw", "plugcell": "service"}
#: The measuring device's crate, and the variable that tells a round's processes where
#: its built module is.
PROBE, PROBE_DIR = Path(__file__).with_name("native_probe"), "PLUGCELL_NATIVE_PROBE"
#: Issue 20's latency target, in multiples of raw Zenoh's; the thesis's own 4 B latency.
TARGET_VS_RAW, THESIS_MS = 1.5, 0.23
#: The variants whose messages are plugcell's CreateProcess and its answer.
PROTOCOL = ("protocol", "protocol + Journal")
REQUESTER, SERVICE = "REQUESTER", "SERVICE"


def _echo() -> Any:
    """The ``Echo`` command of the transport benchmark's service (its catalogue entry)."""
    from plugcell.apps.bench.device import BenchService

    return next(c for c in BenchService.declaration.commands if c.name == "Echo")


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
        from plugcell.framework import admission, codec
        from plugcell.framework.data import summary, to_data
        from plugcell.framework.messages import (
            Acknowledgement,
            ProcessStates,
            ProcessUpdateBatch,
            ProcessUpdateNotification,
        )

        received = time.time_ns()
        decoded = admission.decode_request(payload, codec.DEFAULT_MAX_PAYLOAD, SERVICE)
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
        return codec.encode(SERVICE, self.instance, ProcessUpdateBatch(
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
        from plugcell.framework import codec
        from plugcell.framework.data import to_data
        from plugcell.framework.messages import Process, Tag

        self.identifier += 1
        data = to_data(self.value, self.command.input_data_type, self.command.input_data_size)
        process = Process(command=self.command, tag=Tag(REQUESTER, SERVICE),
                          identifier=self.identifier, data=data)
        return (codec.encode(REQUESTER, "requester-instance", process),
                codec.attach_identifier(self.identifier))

    def final(self, payload: bytes) -> bool:
        """Whether ``payload`` holds the final update of the last request (its data read)."""
        from plugcell.framework import codec
        from plugcell.framework.data import from_data
        from plugcell.framework.messages import process_acks, process_updates

        body = codec.decode(payload).body
        for ack in process_acks(body):
            if ack.identifier == self.identifier and ack.state.final:
                raise RuntimeError(f"request {ack.identifier} refused: {ack.reason}")
        for update in process_updates(body):
            if update.identifier == self.identifier and update.state.final:
                from_data(update.data)
                return True
        return False


class _EchoDevice:
    """The service's Python in ``native handler`` and ``native core``: the transport
    benchmark's ``Echo`` handler (as :class:`~plugcell.apps.bench.device.BenchService` has
    it: the input posted as data feedback, success reported) run as a scheduler could run
    a SingleData process on an idle device."""

    def __init__(self) -> None:
        self.command = _echo()
        self.fed: list[Any] = []

    async def dispatch(self, command: Any, option: str, data: Any) -> str:
        self.fed.append(data)  # BenchService: self.data_feedback.post(data)
        return "OK"

    def run(self, input_bytes: bytes, *, typed: bool = True) -> bytes:
        """The output of the process whose input is ``input_bytes`` (Byte elements),
        checked against the catalogue with ``to_data`` when ``typed``."""
        import numpy as np

        from plugcell.framework.data import to_data

        command = self.command
        steps = self.dispatch(command, "", np.frombuffer(input_bytes, np.uint8))
        try:
            steps.send(None)
        except StopIteration as done:
            code = done.value
        else:  # a handler that waits would go through the scheduler's task instead
            steps.close()
            raise RuntimeError("the Echo handler waited")
        if code != command.success_code or not self.fed:
            raise RuntimeError(f"Echo failed: feedback {code!r}")
        if not typed:
            return self.fed.pop().tobytes()
        output = to_data(self.fed.pop(), command.output_data_type, command.output_data_size,
                         f"{command.name} output")
        return bytes(output.buffer)


class _Calls:
    """The requester's Python in ``native core``: each answer decoded into the messages a
    caller is handed, routed to the waiting call by sender and identifier."""

    def __init__(self) -> None:
        self.waiting: dict[tuple[str, int], asyncio.Future[Any]] = {}

    def expect(self, partner: str, identifier: int, future: asyncio.Future[Any]) -> None:
        self.waiting[(partner, identifier)] = future

    def arrived(self, payload: bytes) -> None:
        from plugcell.framework import codec
        from plugcell.framework.messages import process_acks, process_updates

        envelope = codec.decode(payload)
        for ack in process_acks(envelope.body):
            future = self.waiting.get((envelope.sender, ack.identifier))
            if future is not None and ack.state.final and not future.done():
                future.set_exception(RuntimeError(f"request refused: {ack.reason}"))
        for update in process_updates(envelope.body):
            future = self.waiting.get((envelope.sender, update.identifier))
            if future is not None and update.state.final and not future.done():
                del self.waiting[(envelope.sender, update.identifier)]
                future.set_result(update)

    @staticmethod
    def read(update: Any) -> Any:
        """The final update's data as the caller reads it (a numpy view)."""
        from plugcell.framework.data import from_data

        if update.data is None:
            raise RuntimeError(f"Echo failed: {update.reason}")
        return from_data(update.data)


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
    native = None
    device = _EchoDevice() if variant in ("native handler", "native core") else None
    if variant in NATIVE:
        log_path = Path(folder) / "SERVICE.sqlite.log" if variant != "native protocol" else None
        native = _load_probe(Path(os.environ[PROBE_DIR])).Service(
            SERVICE, "service-instance", None if log_path is None else str(log_path))
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
        if device is not None:
            admitted = native.admit(payload.to_bytes(), REQUESTER)
            output = device.run(admitted.input, typed=variant == "native core")
            pong.put(native.complete(admitted, output))
            return
        if native is not None:
            pong.put(native.answer(payload.to_bytes(), REQUESTER))
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
        (lambda sample: loop.call_soon_threadsafe(answer, sample.payload))
        if lean or native else
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
    native = None
    if variant in NATIVE:
        native = _load_probe(Path(os.environ[PROBE_DIR])).Requester(
            REQUESTER, "requester-instance", SERVICE)
    value = bytes(range(4))
    calls = _Calls() if variant == "native core" else None

    def arrived(answer: bytes) -> None:
        if calls is not None:
            calls.arrived(answer)
        elif (waiting and not waiting[0].done()
                and (lean is None or lean.final(answer))
                and (native is None or native.is_final(answer))):
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
        elif native is not None:
            payload, attachment = native.request(value)
            if calls is not None:
                calls.expect(SERVICE, int.from_bytes(attachment, "little"), waiting[0])
            ping.put(payload, attachment=attachment)
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
            answered = await asyncio.wait_for(waiting[0], 5.0)
            if calls is not None:
                calls.read(answered)
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


def _tight_edges(cycles: int) -> dict[str, float]:
    """µs of the Python of ``native handler`` and ``native core`` in one round trip (the
    handler's run; with the output typed, the answer decoded and routed and its data
    read), each the median of 5 tight loops of ``cycles`` round trips in this process."""
    probe = _load_probe(Path(os.environ[PROBE_DIR]))
    requester = probe.Requester(REQUESTER, "requester-instance", SERVICE)
    service = probe.Service(SERVICE, "service-instance")
    device, calls = _EchoDevice(), _Calls()
    loop = asyncio.new_event_loop()

    def handler_only(admitted: Any) -> None:
        device.run(admitted.input, typed=False)

    def python_api(admitted: Any) -> None:
        answer = service.complete(admitted, device.run(admitted.input))
        future = loop.create_future()
        calls.expect(SERVICE, admitted.identifier, future)
        calls.arrived(answer)
        calls.read(future.result())

    timed = {}
    try:
        for name, edges in (("handler", handler_only), ("Python API", python_api)):
            runs = []
            for _ in range(5):
                admitted = [service.admit(requester.request(b"\x07" * 4)[0], REQUESTER)
                            for _ in range(cycles)]
                native = time.perf_counter_ns()
                for one in admitted:  # what the Rust calls alone take, to subtract
                    service.complete(one, b"\x07" * 4)
                native = time.perf_counter_ns() - native
                started = time.perf_counter_ns()
                for one in admitted:
                    edges(one)
                spent = time.perf_counter_ns() - started
                runs.append((spent - (native if edges is python_api else 0)) / cycles / 1e3)
            timed[name] = statistics.median(runs)
    finally:
        loop.close()
    return timed


async def _plugcell(cell: str, cycles: int, warmup: int) -> float:
    """``plugcell bench transport``'s 4 B latency test against its service in ``cell``:
    the average one-way latency in ms."""
    from plugcell.apps.bench.device import bench_service
    from plugcell.apps.bench.transport import PAYLOADS, our_latency
    from plugcell.framework.transport import TransportConfig

    consumer = bench_service("CONSUMER", cell=cell, transport=TransportConfig.from_env())
    await consumer.start()
    try:
        if not await consumer.participant.wait_for("PUBLISHER", 15):
            raise RuntimeError("the benchmark's service did not appear")
        await consumer.participant.subscribe("PUBLISHER")
        four = next(p for p in PAYLOADS if p.nbytes == 4)
        return float((await our_latency(consumer.participant, four, cycles, warmup))["avg"])
    finally:
        await consumer.close()


def _ask(variant: str, where: str, cycles: int, warmup: int) -> float:
    """The requesting end of one round, in a process of its own: the average one-way
    latency in ms (``where``: the variant's key, or the cell of a bench peer)."""
    from plugcell.framework import eventloop

    if variant == "raw Zenoh":
        from plugcell.apps.bench.peer import RawFloor
        from plugcell.framework.transport import TransportConfig

        floor = RawFloor(where, TransportConfig.from_env())
        try:
            return float(floor.latency(4, cycles, warmup)["avg"])
        finally:
            floor.close()
    if variant == "plugcell":
        return eventloop.run(_plugcell(where, cycles, warmup))
    return eventloop.run(_ping(where, variant, cycles, warmup))


def _round(variant: str, cycles: int, warmup: int) -> float:
    """One round of ``variant``: both ends started afresh, the average one-way ms."""
    tag = f"{os.getpid()}x{time.monotonic_ns()}"
    with tempfile.TemporaryDirectory(prefix="plugcell-durability-") as folder:
        env = {**os.environ, "PLUGCELL_HOME": folder}
        if variant in BENCH_PEER:
            where = f"floor{tag}"
            argv = [sys.executable, "-m", "plugcell.apps.bench.peer", BENCH_PEER[variant],
                    "--cell", where]
        else:
            where = f"plugcell-bench/durability{tag}"
            argv = [sys.executable, __file__, "--serve", variant, where, folder]
        server = subprocess.Popen(argv, stdout=subprocess.PIPE, text=True, env=env)
        try:
            assert server.stdout is not None
            if server.stdout.readline().strip() != "ready":
                raise RuntimeError(f"the answering process for {variant!r} did not start")
            asked = subprocess.run(
                [sys.executable, __file__, "--ask", variant, where, str(cycles), str(warmup)],
                capture_output=True, text=True, env=env, timeout=600,
            )
            if asked.returncode != 0:
                raise RuntimeError(f"the requesting process for {variant!r} failed:\n"
                                   f"{asked.stderr.strip()}")
            return float(asked.stdout.split()[-1])
        finally:
            server.terminate()
            try:
                server.wait(15)
            except subprocess.TimeoutExpired:
                server.kill()
                server.wait()


def _plot(results: dict[str, list[float]], path: Path, title: str) -> None:
    """The medians as horizontal bars (whiskers: the rounds' spread), with the target."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(reversed(results))
    med = [statistics.median(results[v]) for v in names]
    low = [m - min(results[v]) for m, v in zip(med, names, strict=True)]
    high = [max(results[v]) - m for m, v in zip(med, names, strict=True)]
    colours = ["tab:orange" if v == "plugcell" else "tab:gray" if v in ("raw Zenoh", "nothing")
               else "tab:green" if v in NATIVE else "tab:blue" for v in names]
    raw = statistics.median(results["raw Zenoh"])
    fig, ax = plt.subplots(figsize=(8, 2.2 + 0.23 * len(names)))
    ax.barh([LABELS[v] for v in names], med, xerr=[low, high], color=colours, capsize=3)
    ax.axvline(TARGET_VS_RAW * raw, color="tab:red", linestyle="--",
               label=f"issue 20's target: {TARGET_VS_RAW:g}× raw Zenoh")
    ax.axvline(THESIS_MS, color="black", linestyle=":", label=f"the thesis's {THESIS_MS} ms")
    for y, (m, v) in enumerate(zip(med, names, strict=True)):
        ax.text(max(results[v]), y, f"  {m:.3f} ({m / raw:.2f}×)", va="center", fontsize=8)
    ax.set_xlabel("one-way latency of a 4-byte round trip, ms (median of the rounds)")
    longest = max(max(max(results[v]) for v in names), THESIS_MS, TARGET_VS_RAW * raw)
    ax.set_xlim(0, longest * 1.3)
    ax.set_title(title.replace("; ", ";\n", 1), fontsize=9)
    ax.legend(loc="upper right", fontsize=8, framealpha=1)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _load_probe(folder: Path) -> ModuleType:
    """The measuring device's module that :func:`_build_probe` put in ``folder``."""
    spec = importlib.util.spec_from_file_location(
        "plugcell_native_probe", folder / "plugcell_native_probe.so")
    if spec is None or spec.loader is None:
        raise RuntimeError(f"no native probe in {folder}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _build_probe() -> Path:
    """Build the measuring device ``benchmarks/native_probe`` (cargo, release) and return
    a fresh folder holding its module; SystemExit with the reason if it cannot."""
    cargo = shutil.which("cargo")
    if cargo is None:
        raise SystemExit("--native needs cargo (a Rust toolchain), and none is on PATH")
    target = Path(tempfile.gettempdir()) / "plugcell-native-probe-target"
    print(f"  … building {PROBE} (cargo build --release)", file=sys.stderr, flush=True)
    done = subprocess.run([cargo, "build", "--release", "--quiet"], cwd=PROBE,
                          env={**os.environ, "CARGO_TARGET_DIR": str(target)},
                          capture_output=True, text=True)
    built = target / "release" / "libplugcell_native_probe.so"
    if done.returncode != 0 or not built.is_file():
        raise SystemExit(f"building {PROBE} failed:\n{done.stderr[-3000:]}")
    folder = Path(tempfile.mkdtemp(prefix="plugcell-native-probe-"))
    shutil.copy(built, folder / "plugcell_native_probe.so")
    return folder


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=4000)
    parser.add_argument("--warmup", type=int, default=500)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--native", action="store_true",
                        help="also the protocol's work in Rust (builds benchmarks/native_probe)")
    parser.add_argument("--output", type=Path, help="write every round to this JSON file")
    parser.add_argument("--plot", type=Path, help="draw the medians into this PNG")
    parser.add_argument("--replot", type=Path, metavar="JSON",
                        help="only draw --plot from the rounds an earlier --output saved")
    parser.add_argument("--serve", nargs=3, metavar=("VARIANT", "KEY", "FOLDER"),
                        help=argparse.SUPPRESS)
    parser.add_argument("--ask", nargs=4, metavar=("VARIANT", "WHERE", "CYCLES", "WARMUP"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve:
        _serve(*args.serve)
        return 0
    if args.ask:
        variant, where, cycles, warmup = args.ask
        print(f"{_ask(variant, where, int(cycles), int(warmup)):.6f}")
        return 0
    if args.cycles < 1 or args.repeat < 1 or args.warmup < 0:
        parser.error("--cycles and --repeat must be at least 1, --warmup at least 0")
    for path in (args.output, args.plot):
        if path is not None and not path.parent.is_dir():
            parser.error(f"no folder {path.parent} for {path.name}")
    if args.replot is not None:
        if args.plot is None:
            parser.error("--replot needs --plot FILE.png")
        try:
            saved = json.loads(args.replot.read_text())
            rounds = {str(v): [float(x) for x in saved["one_way_ms"][v]]
                      for v in saved["one_way_ms"] if v in LABELS}
            missing = [v for v in VARIANTS if v not in rounds]
            if missing:
                raise KeyError(", ".join(missing))
            title = str(saved["title"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            parser.error(f"{args.replot} is not a run of this script: {exc!r}")
        _plot(rounds, args.plot, title)
        print(f"wrote {args.plot}")
        return 0
    chosen = [*VARIANTS[:-1], *NATIVE, VARIANTS[-1]] if args.native else list(VARIANTS)
    probe = _build_probe() if args.native else None
    if probe is not None:
        os.environ[PROBE_DIR] = str(probe)
    results: dict[str, list[float]] = {v: [] for v in chosen}
    for r in range(args.repeat):
        for variant in chosen:
            results[variant].append(_round(variant, args.cycles, args.warmup))
            print(f"  … round {r + 1}/{args.repeat}: {variant}: "
                  f"{results[variant][-1]:.4f} ms", file=sys.stderr, flush=True)
    title = (f"4-byte round trips between two processes, {args.cycles} cycles × "
             f"{args.repeat} rounds; {platform.machine()}, {os.cpu_count()} cores, "
             f"Python {platform.python_version()}, "
             f"eclipse-zenoh {metadata.version('eclipse-zenoh')}")
    print(title)
    raw = statistics.median(results["raw Zenoh"])
    floor = statistics.median(results["nothing"])
    print(f"{'path':<31} {'one-way ms':>10} {'× raw':>6} {'added µs':>9} {'× floor':>8}  rounds")
    for variant in chosen:
        med = statistics.median(results[variant])
        rounds = " ".join(f"{x:.4f}" for x in results[variant])
        print(f"{LABELS[variant]:<31} {med:10.4f} {med / raw:6.2f} "
              f"{(med - floor) * 1e3:9.1f} {med / floor:8.2f}  {rounds}")
    print(f"issue 20's target, {TARGET_VS_RAW:g}× raw Zenoh: {TARGET_VS_RAW * raw:.4f} ms; "
          f"plugcell {statistics.median(results['plugcell']) / raw:.2f}×, the lean path "
          f"with the Journal {statistics.median(results['protocol + Journal']) / raw:.2f}×"
          + (f", in Rust with its log "
             f"{statistics.median(results['native protocol + log']) / raw:.2f}×, "
             f"with the handler in Python "
             f"{statistics.median(results['native handler']) / raw:.2f}×, behind the "
             f"Python API {statistics.median(results['native core']) / raw:.2f}×"
             if args.native else ""))
    tight = _tight(args.cycles)
    added = 2 * (statistics.median(results["protocol"]) - floor) * 1e3
    print(f"the protocol's work of one round trip (both sides): {tight:.1f} µs "
          f"in a tight loop, {added:.1f} µs added to the round trip above")
    edges = _tight_edges(args.cycles) if args.native else {}
    if edges:
        rust = statistics.median(results["native protocol + log"])
        print("the Python around the Rust core in one round trip, in a tight loop and added "
              "to the round trip above: " + ", ".join(
                  f"{name} {edges[name]:.1f} µs and "
                  f"{2 * (statistics.median(results[variant]) - rust) * 1e3:.1f} µs"
                  for name, variant in (("handler", "native handler"),
                                        ("Python API", "native core"))))
    if args.output is not None:
        args.output.write_text(json.dumps({
            "title": title, "cycles": args.cycles, "warmup": args.warmup,
            "one_way_ms": results, "tight_loop_us": tight,
            **({"tight_python_around_rust_us": edges} if edges else {}),
            "target_ms": TARGET_VS_RAW * raw,
        }, indent=1) + "\n")
        print(f"wrote {args.output}")
    if args.plot is not None:
        _plot(results, args.plot, title)
        print(f"wrote {args.plot}")
    if probe is not None:
        shutil.rmtree(probe, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
