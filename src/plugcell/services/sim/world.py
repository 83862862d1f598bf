"""The simulated world: where every reflector really is, shared by simulated devices.

A real laser tracker finds a robot's T-MAC because the T-MAC is physically there.
Between simulated devices in separate processes that physical fact travels on a
**sim-only** part of the key space, which only simulated device drivers use —
service logic never reads it, and a real device has no use for it:

=============================================  ==========  ===========================
key                                            Zenoh       payload
=============================================  ==========  ===========================
``plugcell/<cell>/sim/reflector/<name>``       pub/sub     :class:`ReflectorState`
``plugcell/<cell>/sim/reflector/<name>``       queryable   the latest ReflectorState
=============================================  ==========  ===========================

* The simulated robot controller publishes its T-MAC's true pose after every
  move (:class:`ReflectorPublisher`); a fixed SMR in the cell is published once.
* The simulated tracker driver keeps the latest state of every reflector
  (:class:`WorldView`): on start it queries them all, then follows the updates.

Poses are 4×4, metres, in the *tracker* frame (the world frame of the simulated
cell).  Messages are msgpack (msgspec).
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import msgspec
import numpy as np
import zenoh

from plugcell.framework.keys import DEFAULT_CELL, KeySpace, check_name


class ReflectorState(msgspec.Struct, frozen=True):
    """The true state of one reflector (sim-only)."""

    name: str
    kind: str  # "tmac" (6-DOF, on a robot) or "smr" (3-DOF, e.g. fixed in the cell)
    pose: list[float]  # 16 numbers, row-major 4x4, metres, tracker frame
    moving: bool = False
    seq: int = 0

    def matrix(self) -> np.ndarray:
        return np.asarray(self.pose, dtype=float).reshape(4, 4)


_ENCODER = msgspec.msgpack.Encoder()
_DECODER = msgspec.msgpack.Decoder(ReflectorState)


def reflector_key(cell: str, name: str = "*") -> str:
    """The key of reflector ``name`` in ``cell`` (the framework's key space owns it)."""
    return KeySpace(cell).reflector(name)


class ReflectorPublisher:
    """Publishes one reflector's true pose; answers queries with the latest one."""

    def __init__(self, session: zenoh.Session, name: str, kind: str = "tmac",
                 cell: str = DEFAULT_CELL) -> None:
        check_name(name, "reflector name")
        if kind not in ("tmac", "smr"):
            raise ValueError(f"reflector kind must be 'tmac' or 'smr', got {kind!r}")
        self.name, self.kind = name, kind
        self._key = reflector_key(cell, name)
        self._lock = threading.Lock()
        self._last: bytes | None = None
        self._seq = 0
        self._closed = False
        self._publisher = session.declare_publisher(self._key)
        self._queryable = session.declare_queryable(self._key, self._on_query)

    def _on_query(self, query: zenoh.Query) -> None:
        with self._lock:
            last = self._last
        if last is not None:
            query.reply(self._key, last)

    def publish(self, pose: np.ndarray, moving: bool = False) -> None:
        pose = np.asarray(pose, dtype=float)
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
            raise ValueError(f"reflector pose must be a finite 4x4 matrix, got shape {pose.shape}")
        with self._lock:
            self._seq += 1
            state = ReflectorState(self.name, self.kind, pose.ravel().tolist(), moving, self._seq)
            self._last = _ENCODER.encode(state)
            payload = self._last
        self._publisher.put(payload)

    def close(self) -> None:
        """Withdraw the reflector (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._queryable.undeclare()
        self._publisher.undeclare()


class WorldView:
    """The latest :class:`ReflectorState` of every reflector of a cell (thread-safe)."""

    def __init__(self, session: zenoh.Session, cell: str = DEFAULT_CELL,
                 on_change: Callable[[ReflectorState], None] | None = None) -> None:
        self._lock = threading.Lock()
        self._states: dict[str, ReflectorState] = {}
        self._on_change = on_change
        self._session = session
        self._key = reflector_key(cell)
        self._subscriber = session.declare_subscriber(self._key, self._on_sample)
        self.refresh()

    def refresh(self, timeout: float = 1.0) -> None:
        """Ask every reflector publisher for its latest pose (a view created before
        discovery finished would otherwise miss a reflector until it next moves)."""
        for reply in self._session.get(self._key, timeout=timeout):
            if reply.ok is not None:
                self._store(bytes(reply.ok.payload.to_bytes()))

    def _on_sample(self, sample: zenoh.Sample) -> None:
        self._store(bytes(sample.payload.to_bytes()))

    def _store(self, payload: bytes) -> None:
        try:
            state = _DECODER.decode(payload)
        except msgspec.DecodeError:
            return  # not ours to judge: a malformed sim message is ignored
        with self._lock:  # Zenoh delivers one publisher's samples in order: latest wins
            self._states[state.name] = state
        if self._on_change is not None:
            self._on_change(state)

    def get(self, name: str) -> ReflectorState | None:
        with self._lock:
            state = self._states.get(name)
        if state is None:
            self.refresh(timeout=0.5)
            with self._lock:
                state = self._states.get(name)
        return state

    def all(self, refresh: bool = False) -> dict[str, ReflectorState]:
        if refresh:
            self.refresh(timeout=0.5)
        with self._lock:
            return dict(self._states)

    def close(self) -> None:
        self._subscriber.undeclare()
