"""The tracker in the loop while the robot moves: one cycle's correction, and its record.

A robot streaming its own path (RSI's *the robot drives, plugcell corrects*, EGM's path
correction) gets, every cycle, a Cartesian offset ``g`` from a **corrector** fed with the
tracker's samples and the joint feedback::

    g = corrector.update(t, q, samples)       # (6,): Δx, Δy, Δz (m), rotation vector (rad)

(base frame: ``p = p_path + g[:3]``, ``R = exp(g[3:]) · R_path``).  :class:`TrackingLoop` is
the seam between a stream's correction source (:class:`~.stream.source.PathOffset` asks it
for ``g`` each cycle) and whatever supplies samples — the tracker service's Stream
Measurement, or the twin's in-process tracker model — and it records what each cycle
had: a fresh sample (*tracked*), tracking asked for but no fresh sample (*break*: the
beam is broken, the tracker is late or gone; the path goes on with what the corrector
holds), or tracking not asked for (*off*).

:class:`ModelErrorCorrector` is the corrector used until a better estimator is plugged
in: the TCP's pose error *of the model* — the tracker's measurement minus the nominal
model's pose at the joints the robot reported *at the sample's own time* (the joint
feedback interpolated at the acquisition time: age compensation) — low-pass filtered,
and commanded with the opposite sign::

    e_k = [p_meas − p_nom(q(t_k)),  log(R_meas · R_nom(q(t_k))ᵀ)]
    ê  ← ê + (1 − exp(−Δt/τ)) (e_k − ê),       g = −ê

The model error changes slowly along a path, so cancelling it does not feed the robot's
dynamics back into the loop (the servo's following error appears in ``q`` as well and is
not corrected: it is the controller's business).  With no fresh sample ``ê`` is held.
"""

from __future__ import annotations

import bisect
import threading
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from plugcell.kinematics import RobotDescription, forward
from plugcell.kinematics.parameters import GeometricParameters
from plugcell.kinematics.rotations import matrix_to_rpy
from plugcell.kinematics.transforms import so3_exp, so3_log

Array = NDArray[np.float64]

__all__ = ["Corrector", "CycleRecord", "ModelErrorCorrector", "TrackedSample", "TrackingLoop",
           "Window", "kuka_offset"]

#: The states of a cycle (module docstring).
TRACKED, BREAK, OFF = "tracked", "break", "off"


@dataclass(frozen=True)
class TrackedSample:
    """One tracker sample on the robot's clock.

    Attributes
    ----------
    t : float
        Acquisition time (middle of the integration), seconds on the robot's clock.
    tcp : (4, 4) array or None
        The TCP pose measured, robot base frame, m (None: no measurement).
    status : str
        ``"ok"`` or why there is no measurement (``line_of_sight``, ``tracking_speed`` …).
    six_dof : bool
        The orientation is measured (T-MAC); else only the position (SMR).
    """

    t: float
    tcp: Array | None
    status: str = "ok"
    six_dof: bool = True


@runtime_checkable
class Corrector(Protocol):
    """Turns tracker samples and joint feedback into this cycle's Cartesian offset."""

    def update(self, t: float, q: Array, samples: Sequence[TrackedSample]) -> Array:
        """The offset ``g`` (6,) for the cycle at ``t`` (s) with joints ``q`` (rad).

        ``samples`` are those that arrived since the last call (possibly none, possibly
        without a measurement); ``g[:3]`` in m, ``g[3:]`` a rotation vector (rad), base
        frame (module docstring).
        """
        ...


class ModelErrorCorrector:
    """The filtered model error, cancelled (module docstring).

    Parameters
    ----------
    description : RobotDescription
        The controller's model (its tool included).
    params : GeometricParameters, optional
        Calibrated parameters (default: nominal).
    tau_s : float
        ``τ`` of the low-pass filter (s).
    history_s : float
        How long joint feedback is kept to be interpolated at a sample's time (s).
    """

    def __init__(self, description: RobotDescription, params: GeometricParameters | None = None,
                 tau_s: float = 0.2, history_s: float = 1.0) -> None:
        if not (np.isfinite(tau_s) and tau_s > 0):
            raise ValueError(f"tau_s must be > 0, got {tau_s}")
        self.description, self.params = description, params
        self.tau_s = float(tau_s)
        self._times: deque[float] = deque()
        self._joints: deque[Array] = deque()
        self._history_s = float(history_s)
        self.estimate = np.zeros(6)
        self._t_last: float | None = None

    def joints_at(self, t: float) -> Array | None:
        """The joints at ``t`` interpolated from the feedback (None: outside the history)."""
        times = self._times
        if not times or t < times[0] or t > times[-1]:
            return None
        i = bisect.bisect_left(times, t)
        if times[i] == t or i == 0:
            return self._joints[i]
        w = (t - times[i - 1]) / (times[i] - times[i - 1])
        return (1 - w) * self._joints[i - 1] + w * self._joints[i]

    def error(self, sample: TrackedSample, q: Array) -> Array:
        """``e_k``: the measured TCP pose minus the model's at ``q`` (6,)."""
        assert sample.tcp is not None
        T = forward(self.description, self.params, q, "nominal").tcp
        e = np.zeros(6)
        e[:3] = sample.tcp[:3, 3] - T[:3, 3]
        if sample.six_dof:
            e[3:] = so3_log(sample.tcp[:3, :3] @ T[:3, :3].T)
        return e

    def update(self, t: float, q: Array, samples: Sequence[TrackedSample]) -> Array:
        self._times.append(float(t))
        self._joints.append(np.asarray(q, dtype=float).copy())
        while self._times and self._times[0] < t - self._history_s:
            self._times.popleft()
            self._joints.popleft()
        for s in samples:
            if s.tcp is None:
                continue
            q_s = self.joints_at(s.t)
            if q_s is None:
                continue  # older than the feedback kept, or from the future: unusable
            dt = s.t - self._t_last if self._t_last is not None else np.inf
            alpha = 1.0 - np.exp(-max(dt, 0.0) / self.tau_s)
            self.estimate = self.estimate + alpha * (self.error(s, q_s) - self.estimate)
            self._t_last = s.t
        return -self.estimate


def kuka_offset(g: Array) -> Array:
    """``g`` (Δp m, rotation vector rad) as RSI's RKorr ``X, Y, Z, A, B, C`` (m, rad).

    RKorr in the base frame rotates by ``R_o = Rz(A)·Ry(B)·Rx(C)``: ``R_o = exp(g[3:])``.
    """
    roll, pitch, yaw = matrix_to_rpy(so3_exp(np.asarray(g[3:], dtype=float)))
    return np.array([*g[:3], yaw, pitch, roll], dtype=float)


@dataclass(frozen=True)
class CycleRecord:
    """What one cycle had: time (s), joints (rad), offset asked for, state, last status."""

    t: float
    q: Array
    offset: Array
    state: str
    status: str


@dataclass
class Window:
    """A stretch of cycles in one state: ``t0``…``t1`` (s) and why (the samples' status)."""

    state: str
    t0: float
    t1: float
    reason: str = ""

    @property
    def duration(self) -> float:
        return self.t1 - self.t0


@dataclass
class TrackingLoop:
    """Samples and feedback in, the offset and the record out (module docstring).

    Parameters
    ----------
    corrector : Corrector
        What makes the offset.
    stale_s : float
        A cycle is *tracked* when its newest measurement is at most this old (s).
    enabled : bool
        Tracking asked for (a path's segment may switch it; thread-safe).
    switch_s : float
        Switching tracking off or on blends the offset out or in over this time (s):
        ``g · (3b² − 2b³)`` with ``b`` moving linearly between 0 and 1 — no step, no
        jump of the offset's rate at either end.
    """

    corrector: Corrector
    stale_s: float = 0.05
    enabled: bool = True
    switch_s: float = 0.2
    records: list[CycleRecord] = field(default_factory=list)
    _pending: list[TrackedSample] = field(default_factory=list)
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _t_ok: float = -np.inf
    _status: str = ""
    _offset: Array = field(default_factory=lambda: np.zeros(6))
    samples_ok: int = 0
    samples_lost: int = 0
    #: the cycle time at which the latest sample (with or without a measurement) came
    t_heard: float = -np.inf
    _b: float = 1.0
    _t: float | None = None

    def feed(self, samples: Iterable[TrackedSample]) -> None:
        """Samples that arrived (any thread)."""
        with self._lock:
            self._pending.extend(samples)

    def cycle(self, t: float, q: Array) -> Array:
        """This cycle's offset ``g`` (6,), recorded with the cycle's state."""
        with self._lock:
            samples, self._pending = self._pending, []
        if samples:
            self.t_heard = t
        for s in samples:
            self._status = s.status
            if s.tcp is not None:
                self._t_ok = max(self._t_ok, s.t)
                self.samples_ok += 1
            else:
                self.samples_lost += 1
        g = np.asarray(self.corrector.update(t, q, samples), dtype=float)
        dt = 0.0 if self._t is None else max(t - self._t, 0.0)
        self._t = t
        step = dt / self.switch_s
        self._b = min(self._b + step, 1.0) if self.enabled else max(self._b - step, 0.0)
        g = g * (3 * self._b**2 - 2 * self._b**3)
        fresh = t - self._t_ok <= self.stale_s
        state = OFF if not self.enabled else (TRACKED if fresh else BREAK)
        status = self._status if state == BREAK and self._status != "ok" else \
            ("late" if state == BREAK else "")
        self._offset = g
        self.records.append(CycleRecord(t, np.asarray(q, float).copy(), g, state, status))
        return g

    def windows(self) -> list[Window]:
        """The runs of cycles in one state, in order (a break names its first reason)."""
        out: list[Window] = []
        for r in self.records:
            if out and out[-1].state == r.state:
                out[-1].t1 = r.t
                if not out[-1].reason:
                    out[-1].reason = r.status
            else:
                out.append(Window(r.state, r.t, r.t, r.status))
        return out
