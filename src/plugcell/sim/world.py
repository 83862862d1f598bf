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
* A reflector fixed *on* another (an SMR in a dowel hole of a robot's flange, whose
  T-MAC the controller publishes) is published once with its ``mount``: its pose is in
  the mount's frame, and whoever looks at the world places it with :func:`placed`,
  ``T = T_mount · T_rel``, from the same look — so it is where its mount is at that
  instant, never a step behind it.
* The simulated tracker driver keeps the latest state of every reflector
  (:class:`WorldView`): on start it queries them all, then follows the updates.

Poses are 4×4, metres, in the *tracker* frame (the world frame of the simulated
cell).  Messages are msgpack (msgspec).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping

import msgspec
import numpy as np

from plugcell.framework.bus import Bus
from plugcell.framework.keys import check_name


class ReflectorState(msgspec.Struct, frozen=True):
    """The true state of one reflector (sim-only)."""

    name: str
    kind: str  # "tmac" (6-DOF, on a robot) or "smr" (3-DOF, e.g. fixed in the cell)
    pose: list[float]  # 16 numbers, row-major 4x4, metres, tracker frame
    moving: bool = False
    seq: int = 0
    mount: str = ""  # the reflector it is fixed on ("": the cell); pose is then in its frame

    def matrix(self) -> np.ndarray:
        return np.asarray(self.pose, dtype=float).reshape(4, 4)


#: Longest chain of reflectors mounted on reflectors that :func:`placed` follows.
MAX_MOUNT_DEPTH = 4


def placed(states: Mapping[str, ReflectorState]) -> dict[str, ReflectorState]:
    """Every reflector of one look at the world with its pose in the tracker frame.

    A reflector fixed in the cell is as published.  A mounted one (``mount`` set) is
    placed on its mount's pose of the same look, ``T = T_mount · T_rel``, and moves
    when its mount moves (``moving`` is the mount's).  One whose mount is not in the
    world (a robot that is gone takes its SMRs with it), or whose mounts form a cycle
    or a chain longer than :data:`MAX_MOUNT_DEPTH`, is left out.

    Parameters
    ----------
    states : mapping of str to ReflectorState
        One look at the world, by reflector name (poses as published).

    Returns
    -------
    dict of str to ReflectorState
        The reflectors that are somewhere, every pose 4×4 in metres, tracker frame,
        ``mount`` empty.
    """
    out: dict[str, ReflectorState] = {}

    def place(state: ReflectorState, depth: int) -> ReflectorState | None:
        if not state.mount:
            return state
        mount = states.get(state.mount)
        if mount is None or depth >= MAX_MOUNT_DEPTH:
            return None
        carrier = place(mount, depth + 1)
        if carrier is None:
            return None
        pose = carrier.matrix() @ state.matrix()
        return msgspec.structs.replace(state, pose=pose.ravel().tolist(),
                                       moving=carrier.moving, mount="")

    for name, state in states.items():
        where = place(state, 0)
        if where is not None:
            out[name] = where
    return out


_ENCODER = msgspec.msgpack.Encoder()
_DECODER = msgspec.msgpack.Decoder(ReflectorState)


class ReflectorPublisher:
    """Publishes one reflector's true pose on ``bus``'s cell; answers queries with the
    latest one.  ``bus``: a :class:`~plugcell.framework.bus.Bus` whose handlers run on
    Zenoh's threads (no hand-off; of a participant's bus, its ``direct()`` view).

    ``current``: for a reflector that moves in time, a callable giving its true pose
    *now*: a query (a tracker's look at the world) is then answered with the pose at that
    instant — the pose a physical tracker would see — instead of the latest one published
    (flagged moving as the latest was).  ``mount``: the reflector this one is fixed on;
    its poses are then in the mount's frame (module docstring, :func:`placed`)."""

    def __init__(self, bus: Bus, name: str, kind: str = "tmac",
                 current: Callable[[], np.ndarray] | None = None, mount: str = "") -> None:
        check_name(name, "reflector name")
        if kind not in ("tmac", "smr"):
            raise ValueError(f"reflector kind must be 'tmac' or 'smr', got {kind!r}")
        if mount:
            check_name(mount, "reflector mount")
            if mount == name:
                raise ValueError(f"reflector {name} cannot be mounted on itself")
        self.name, self.kind, self.mount = name, kind, mount
        self._lock = threading.Lock()
        self._last: bytes | None = None
        self._moving = False
        self._seq = 0
        self._closed = False
        self._current = current
        self._publisher, self._queryable = bus.reflector(name, self._latest)

    def _latest(self) -> bytes | None:
        if self._current is not None:
            return self._encode(self._current(), None)
        with self._lock:
            return self._last

    def _encode(self, pose: np.ndarray, moving: bool | None) -> bytes:
        pose = np.asarray(pose, dtype=float)
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
            raise ValueError(f"reflector pose must be a finite 4x4 matrix, got shape {pose.shape}")
        with self._lock:
            self._seq += 1
            self._moving = self._moving if moving is None else moving
            state = ReflectorState(self.name, self.kind, pose.ravel().tolist(), self._moving,
                                   self._seq, self.mount)
            self._last = _ENCODER.encode(state)
            return self._last

    def publish(self, pose: np.ndarray, moving: bool = False) -> None:
        self._publisher.put(self._encode(pose, moving))

    def close(self) -> None:
        """Withdraw the reflector (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._queryable.undeclare()
        self._publisher.undeclare()


class WorldView:
    """The latest :class:`ReflectorState` of every reflector of ``bus``'s cell
    (thread-safe; ``bus`` without a hand-off, so ``on_change`` runs on Zenoh's thread)."""

    def __init__(self, bus: Bus,
                 on_change: Callable[[ReflectorState], None] | None = None) -> None:
        self._lock = threading.Lock()
        self._states: dict[str, ReflectorState] = {}
        self._on_change = on_change
        self._bus = bus
        self._subscriber = bus.watch_reflectors(self._store)
        self.refresh()

    def refresh(self, timeout: float = 1.0) -> None:
        """Ask every reflector publisher for its latest pose (a view created before
        discovery finished would otherwise miss a reflector until it next moves)."""
        for payload in self._bus.query_reflectors(timeout):
            self._store(payload)

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
