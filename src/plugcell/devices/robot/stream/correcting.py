"""The robot drives, the PC corrects (issue 37 §1, mode (b)): one correction at a time.

The controller runs its own program — KRL moves between ``RSI_ON`` and ``RSI_OFF``,
RAPID's ``EGMMoveL`` — and the link superimposes an offset on that path, blended in and
out by :class:`~.source.PathOffset`.  What is superimposed is a :class:`CorrectionSpec`, a
value that crosses a process boundary (the link may run in a child process,
:mod:`.process`), with one of three sources:

``offset``
    a constant ``g`` — a seam offset, a measured shift;
``compensation``
    a calibration's compensation, as the thesis's (6.5.1) but continuously: at every
    cycle the joints ``q`` of the controller's own path (joint corrections: ``q = q_set −
    o``, the packet's set-point joints less the offset commanded so far; Cartesian ones:
    the nominal inverse kinematics of the set-point pose with the offset taken off), the
    nominal pose ``T_n(q)`` the controller meant, and one Newton step of eq. 4.11 on the
    identified model from the last cycle's answer, ``Δq ← Δq + J_id(q + Δq)⁺ · e(T_n(q),
    T_id(q + Δq))`` — so ``T_id(q + Δq) → T_n(q)``: the arm is where the program says (the
    step converges in a few cycles and follows the path after, its change per cycle being
    the path's).  Sent as the stream's corrections: joints ``Δq``; RSI ``RKorr`` the exact
    Cartesian correction that makes the controller command ``q + Δq``,
    ``o = pose_correction(T_c(q), T_c(q + Δq))`` at its TCP in its frame
    (:mod:`plugcell.kinematics.pose_corrections`); EGM's path correction the shift of the
    compensated point, ``d = p(q + Δq) − p(q)``, in ABB's path coordinate system
    (:mod:`plugcell.kinematics.path_frame`: x the path's tangent, seen from the path's
    own poses cycle by cycle; y = x × z_tool; z = x × y), ``c = Rᵀ d`` — of which the
    controller corrects y and z only: the along-path part ``c_x`` is not sent (nothing
    before the path has moved, its frame unknown), and the controller keeps the
    orientation, so the rotation ``log(R(q + Δq) R(q)ᵀ)`` stays uncorrected (both
    reported by :meth:`Corrector.status`);
``external``
    ``g`` is whatever was last given to :meth:`Corrector.set_offset` — the hook of a
    tracker's correction loop or any other sensor, from any thread.

Every ``g`` is in the stream's *space* (:func:`correction_space`): joints (RSI
``AKorr``), Cartesian in the base or the tool frame (RSI ``RKorr``, ``RefCorrSys``), or
EGM's path coordinates (``EgmSensorPathCorr``).  A Cartesian offset asked of a joint stream
becomes joints each cycle through the nominal model at the path's joints:
``Δq = J_n(q)⁺ · o`` (base frame; a tool-frame offset is first turned into the base frame
by the TCP's rotation ``R(q)``), A, B, C taken as small rotations about Z, Y, X (KUKA's).
Every ``g`` is held to the spec's ``max_offset`` (the biggest correction the service
superimposes; beyond it the correction fails with the reason) and then, as any request,
to the link's limits.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.kinematics.path_frame import (
    TangentTracker,
    applied_displacement,
    path_frame,
    to_path,
)

from .drive import setpoint_base
from .errors import StreamLinkError
from .source import CycleState, PathOffset, unit_ramp

__all__ = ["SOURCES", "CorrectionSpec", "Corrector", "Superimposed", "controller_model",
           "correction_space", "make_source"]

Array = NDArray[np.float64]

#: The sources of a correction (module docstring).
SOURCES = ("offset", "compensation", "external")
#: The frames an offset may be given in.
FRAMES = ("joints", "base", "tool", "path")


@dataclass(frozen=True)
class CorrectionSpec:
    """One correction superimposed on the controller's own path (module docstring).

    Attributes
    ----------
    source : {"offset", "compensation", "external"}
        Where ``g`` comes from.
    offset : tuple of 6 float
        ``g`` of ``offset`` and the first ``g`` of ``external``, SI (rad; or m, m, m,
        rad, rad, rad) in ``frame``.
    frame : {"joints", "base", "tool", "path"}
        The frame of ``offset``.
    ramp_s : float
        The ramp in and the ramp out (s, :func:`~plugcell.motion.profile.unit_ramp`).
    duration_s : float or None
        Start the ramp out this long after the first cycle; ``None``: when asked
        (:meth:`Corrector.finish`).
    max_offset : tuple of 6 float
        The largest ``|g_i|`` in the stream's space (SI); beyond it the correction fails.
    robot : str
        The robot (a shipped name or a description file): the nominal model.
    calibration : str
        ``compensation``: a PARAMS.json written by ``plugcell calibrate``.
    payload_kg : float or None
        ``compensation``: the payload (default the calibration's reference payload).
    timeout_s : float
        The longest a correction may run (s).
    tcp : tuple of 6 float or None
        The controller's TCP in the flange frame (KUKA's ``$TOOL``: x, y, z in m and A, B,
        C in rad, ``R = Rz(A)·Ry(B)·Rx(C)``) where it is not the robot description's
        tool: the point a Cartesian correction moves (``None``: the description's).
    """

    source: str
    offset: tuple[float, ...] = (0.0,) * 6
    frame: str = "base"
    ramp_s: float = 0.5
    duration_s: float | None = None
    max_offset: tuple[float, ...] = (np.inf,) * 6
    robot: str = "smart_h4"
    calibration: str = ""
    payload_kg: float | None = None
    timeout_s: float = 24 * 3600.0
    tcp: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.tcp is not None:
            t = np.asarray(self.tcp, dtype=float).reshape(-1)
            if t.shape != (6,) or not np.isfinite(t).all():
                raise ValueError(f"tcp: six finite numbers, got {self.tcp!r}")
            object.__setattr__(self, "tcp", tuple(float(x) for x in t))
        if self.source not in SOURCES:
            raise ValueError(f"unknown correction source {self.source!r}: one of "
                             f"{', '.join(SOURCES)}")
        if self.frame not in FRAMES:
            raise ValueError(f"unknown frame {self.frame!r}: one of {', '.join(FRAMES)}")
        for name in ("offset", "max_offset"):
            v = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            if v.shape != (6,) or np.isnan(v).any() or (name == "offset"
                                                        and not np.isfinite(v).all()):
                raise ValueError(f"{name}: six finite numbers, got {getattr(self, name)!r}")
            object.__setattr__(self, name, tuple(float(x) for x in v))
        if not (np.isfinite(self.ramp_s) and self.ramp_s > 0):
            raise ValueError(f"ramp: a positive duration in seconds, got {self.ramp_s!r}")
        if self.duration_s is not None and not (np.isfinite(self.duration_s)
                                                and self.duration_s >= 0):
            raise ValueError(f"duration: seconds ≥ 0, got {self.duration_s!r}")
        if self.source == "compensation" and not self.calibration:
            raise ValueError("a compensation needs its calibration (a PARAMS.json)")


def correction_space(config: Any) -> str:
    """The space a stream's corrections are in: ``"joints"``, ``"base"``, ``"tool"`` or
    ``"path"``.

    Raises
    ------
    ValueError
        A stream that cannot correct the controller's own path (EGM joint or pose
        targets: there the PC drives).
    """
    if config.vendor == "EGM":
        if config.mode != "pathcorr":
            raise ValueError(f"EGM corrects the controller's own path with path corrections "
                             f"(EGMMoveL): the stream is in {config.mode} mode, where the PC "
                             f"drives (egm_mode=pathcorr, plugcell egm files --mode pathcorr)")
        return "path"
    return "joints" if config.correction == "joint" else str(config.frame)


def controller_model(robot: str, tcp: Any = None) -> Any:
    """The controller's nominal model: the robot's description, its tool the controller's
    TCP ``tcp`` (x, y, z in m, KUKA's A, B, C in rad) if given."""
    import dataclasses

    from plugcell.io.robots import load_robot
    from plugcell.kinematics.rotations import rpy_to_matrix

    desc = load_robot(robot)
    if tcp is None:
        return desc
    t = np.asarray(tcp, dtype=float)
    T = np.eye(4)
    T[:3, :3] = rpy_to_matrix(t[5], t[4], t[3])
    T[:3, 3] = t[:3]
    return dataclasses.replace(desc, tool=T)


class _InSpace:
    """``g`` of a frame brought into the stream's space, at the cycle's path joints."""

    def __init__(self, frame: str, space: str, robot: str, tcp: Any = None) -> None:
        if frame == space:
            self.convert = None
            return
        if space != "joints" or frame not in ("base", "tool"):
            frames = "the base, tool or joints" if space == "joints" else f"the {space}"
            raise ValueError(f"an offset in the {frame} frame cannot be sent as this "
                             f"stream's corrections ({_space_text(space)}): give it in "
                             f"{frames} frame")
        self.desc = controller_model(robot, tcp)
        self.tool = frame == "tool"
        self.convert = self._joints

    def _joints(self, g: Array, state: CycleState) -> Array:
        from plugcell.kinematics import forward
        from plugcell.kinematics.jacobian import jacobian_from_fk

        q = _path_joints(state)
        fk = forward(self.desc, None, q, "nominal")
        o = np.concatenate([g[:3], g[5:2:-1]])  # X Y Z, then ω = (C, B, A) about X, Y, Z
        if self.tool:
            R = fk.tcp[:3, :3]
            o = np.concatenate([R @ o[:3], R @ o[3:]])
        J = jacobian_from_fk(self.desc, fk, "tcp")
        return np.linalg.lstsq(J, o, rcond=None)[0]

    def __call__(self, g: Array, state: CycleState) -> Array:
        return g if self.convert is None else self.convert(g, state)


def _space_text(space: str) -> str:
    return {"joints": "joint corrections", "base": "Cartesian corrections in the base frame",
            "tool": "Cartesian corrections in the tool frame",
            "path": "EGM path corrections"}[space]


def _path_joints(state: CycleState) -> Array:
    q = setpoint_base(state)
    if q is None:
        raise ValueError("the controller's packets carry no joints")
    return q


#: Newton steps of the path's joints from the set-point (:meth:`_Compensation._newton`),
#: and the pose error (m and rad in one 6-vector) they stop at.
IK_STEPS, IK_TOL = 6, 1e-10


class _Compensation:
    """``g(state)`` of a calibration's compensation (module docstring) in the stream's
    space: joints (rad); a Cartesian correction in the base or the tool frame (m, rad,
    KUKA's A, B, C); or EGM's path correction (m, y and z in path coordinates;
    :attr:`along_path` the part along the path and :attr:`uncorrected` the rotation it
    cannot carry)."""

    def __init__(self, spec: CorrectionSpec, space: str, path_chord: Any = None) -> None:
        from plugcell.compensation import IdentifiedModel, NominalModel
        from plugcell.devices.robot.calibration_file import read_calibration

        result = read_calibration(spec.calibration)
        # the hybrid model with the calibration's learned layer, as plugcell compensate
        self.model = IdentifiedModel(result.model, residual=result.residual_model)
        self.nominal = NominalModel(self.model.description, tool=self.model.tool)
        self.payload = (result.model.payload_ref_kg if spec.payload_kg is None
                        else spec.payload_kg)
        self.space = space
        #: the controller's nominal model and TCP (Cartesian spaces)
        self.controller = (None if space == "joints"
                           else controller_model(spec.robot, spec.tcp))
        self.dq = np.zeros(6)
        #: the rotation (rotation vector, rad, base frame) a path correction leaves
        #: uncorrected: the identified model's orientation error at the path's pose
        self.uncorrected = np.zeros(3)
        #: the part of the shift along the path (m) a path correction leaves uncorrected
        self.along_path = 0.0
        #: the path frame (:func:`~plugcell.kinematics.path_frame.path_frame`; ``None``
        #: before the path has moved) and the tangent it comes from
        self.path_frame: Array | None = None
        self._tangent = TangentTracker() if space == "path" else None
        if space == "path" and path_chord is not None:
            self._seed(*path_chord)
        #: path: the shift ramps in (the spec's ramp) from the first cycle it has a frame
        #: to be sent in — no jump when the path starts to move under a running correction
        self._ramp = unit_ramp(spec.ramp_s)
        self._t_frame: float | None = None
        # a frame from the first cycle: the correction's own ramp in (PathOffset) does
        self._ramped = self.path_frame is not None

    def _seed(self, q_a: Array, q_b: Array) -> None:
        """The path frame of the path's last chord ``q_a → q_b`` (the link's
        :attr:`~plugcell.devices.robot.egm.link.EgmLink.path_chord`: the direction the
        path last moved in, where the arm may stand now)."""
        T_a, T_b = self._tcp(np.asarray(q_a, dtype=float)), self._tcp(np.asarray(q_b,
                                                                               dtype=float))
        d = T_b[:3, 3] - T_a[:3, 3]
        if np.linalg.norm(d) > 0:
            self._tangent.tangent = d / np.linalg.norm(d)  # type: ignore[union-attr]
            self.path_frame = path_frame(self._tangent.tangent,  # type: ignore[union-attr]
                                         T_b[:3, 2])

    def __call__(self, state: CycleState) -> Array:
        from plugcell.compensation import compensate_joints

        q = self._path_joints(state)
        T_n = self.nominal.evaluate(q)[0]
        step = compensate_joints(self.model, T_n, q + self.dq, self.payload, max_iterations=1,
                                 check_limits=False, raise_errors=False)
        self.dq = np.asarray(step.q, dtype=float).reshape(-1) - q
        g = self._in_space(q, q + self.dq)
        if self.space != "path" or self.path_frame is None or self._ramped:
            return g
        if self._t_frame is None:
            self._t_frame = state.t
        b = float(self._ramp.sample(state.t - self._t_frame).s)
        self._ramped = b >= 1.0
        return g * b

    def _tcp(self, q: Array) -> Array:
        from plugcell.kinematics import forward

        return forward(self.controller, None, q, "nominal").tcp

    def _path_joints(self, state: CycleState) -> Array:
        """The joints of the controller's own path this cycle: ``q_set − o`` (joints);
        else the nominal inverse kinematics, from the set-point joints, of the set-point
        pose ``T_n(q_set)`` with the offset so far taken off (:func:`uncorrect_pose`; EGM:
        its position less the displacement the controller made of the path correction,
        ``R · (0, o_y, o_z)``, in the last path frame; the path's position then gives the
        tangent of the next, :class:`~plugcell.kinematics.path_frame.TangentTracker`:
        chords of a moving path, longer than the change of that displacement)."""
        if self.space == "joints":
            return _path_joints(state)
        from plugcell.kinematics.pose_corrections import uncorrect_pose

        robot = state.robot
        q_set = robot.joints_setpoint if robot.joints_setpoint is not None else robot.joints
        if q_set is None:
            raise ValueError("the controller's packets carry no joints")
        q_set = np.asarray(q_set, dtype=float)
        T_set = self._tcp(q_set)
        o = np.asarray(state.offset, dtype=float)
        if self.space == "path":
            T_p = T_set.copy()
            d = (np.zeros(3) if self.path_frame is None
                 else applied_displacement(o[:3], self.path_frame))
            T_p[:3, 3] -= d
            tangent = self._tangent.update(T_p[:3, 3], state.t, d)  # type: ignore[union-attr]
            if tangent is not None:
                self.path_frame = path_frame(tangent, T_p[:3, 2])
        else:
            T_p = uncorrect_pose(T_set, o, self.space)
        return self._newton(T_p, q_set)

    def _newton(self, T: Array, q: Array) -> Array:
        """The nominal model's joints of the pose ``T`` near ``q`` (a correction away):
        Newton steps ``q ← q + J(q)⁺ e(T, T_c(q))`` until ``‖e‖ <`` :data:`IK_TOL`
        (quadratic: two or three), cheaper than a full inverse kinematics each cycle."""
        from plugcell.kinematics import forward
        from plugcell.kinematics.jacobian import jacobian_from_fk
        from plugcell.kinematics.transforms import so3_log

        for _ in range(IK_STEPS):
            fk = forward(self.controller, None, q, "nominal")
            e = np.concatenate([T[:3, 3] - fk.tcp[:3, 3], so3_log(T[:3, :3] @ fk.tcp[:3, :3].T)])
            if np.linalg.norm(e) < IK_TOL:
                return q
            J = jacobian_from_fk(self.controller, fk, "tcp")
            q = q + np.linalg.lstsq(J, e, rcond=None)[0]
        raise ValueError("the controller's path pose is out of the nominal model's reach "
                         f"(no joints within {IK_TOL:g} of it near the set-point)")

    def _in_space(self, q: Array, q_c: Array) -> Array:
        """The correction that makes the controller command ``q_c`` instead of ``q``:
        ``q_c − q`` (joints); ``o`` with ``correct_pose(T_n(q), o) = T_n(q_c)`` at the
        controller's TCP (base, tool: exact); the compensated point's shift
        ``p(q_c) − p(q)`` (path: a translation keeping the orientation moves every point
        of the tool alike; in path coordinates ``c = Rᵀ d``, its y and z sent, its x along
        the path left, :attr:`along_path`, and the rotation ``log(R(q_c) R(q)ᵀ)``,
        :attr:`uncorrected`)."""
        if self.space == "joints":
            return q_c - q
        if self.space == "path":
            from plugcell.kinematics.transforms import so3_log

            T_a, T_b = self.nominal.evaluate(np.stack([q, q_c]))[0]
            self.uncorrected = so3_log(T_b[:3, :3] @ T_a[:3, :3].T)
            if self.path_frame is None:  # the path has not moved yet: no frame to send in
                return np.zeros(6)
            c = to_path(T_b[:3, 3] - T_a[:3, 3], self.path_frame)
            self.along_path = float(c[0])
            return np.array([0.0, c[1], c[2], 0.0, 0.0, 0.0])
        from plugcell.kinematics.pose_corrections import pose_correction

        return pose_correction(self._tcp(q), self._tcp(q_c), self.space)


#: The interpreter's thread switch interval while a correction runs (s): the link's thread
#: must get the interpreter back from a computation beside it within a fraction of a 4 ms
#: cycle (the default is 5 ms).
SWITCH_INTERVAL_S = 0.0005


class _Beside:
    """Computes ``g(state)`` in a thread of its own, beside the link: :meth:`offer` hands
    it the newest cycle and returns, at once, the newest ``g`` it has (zeros before the
    first) — a compensation takes milliseconds, more than the cycle allows; ``g`` follows
    the path a few cycles late (its change over them is the path's over them: small).  A
    failure of ``g`` is raised by the next :meth:`offer`."""

    def __init__(self, g: Callable[[CycleState], Array]) -> None:
        self.g = g
        self._cond = threading.Condition()
        self._job: CycleState | None = None
        self._result = np.zeros(6)
        self._failure: Exception | None = None
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="correction-goal", daemon=True)
        self._thread.start()

    def offer(self, state: CycleState) -> Array:
        with self._cond:
            if self._failure is not None:
                raise self._failure
            self._job = state
            self._cond.notify()
            return self._result

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._job is None and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                job, self._job = self._job, None
            try:
                out = self.g(job)
            except Exception as exc:  # the next offer fails the correction with it
                with self._cond:
                    self._failure = exc
                return
            with self._cond:
                self._result = out

    def close(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify()
        self._thread.join(5.0)  # after the g being computed, if any


class Superimposed:
    """A correction as the link runs it: the :class:`~.source.PathOffset` asking for
    ``b(t) · g(t)``, ``g`` from the spec's source in the stream's space (:func:`make_source`).

    Attributes
    ----------
    source : PathOffset
        What the link follows.
    offset : ndarray, shape (6,)
        The offset the link had commanded at the last cycle (SI, the stream's space).
    """

    def __init__(self, spec: CorrectionSpec, space: str,
                 wanted: Any, in_space: _InSpace) -> None:
        self.spec, self.space = spec, space
        self._wanted, self._in_space = wanted, in_space
        self._value = np.asarray(spec.offset, dtype=float)
        self._limit = np.asarray(spec.max_offset, dtype=float)
        self._lock = threading.Lock()
        self.offset = np.zeros(6)
        # g is computed beside the link when it costs more than a few microseconds
        self._beside = (_Beside(self.goal_now) if wanted is not None
                        or in_space.convert is not None else None)
        self.source = PathOffset(self._goal, ramp=spec.ramp_s, finish_at=spec.duration_s)

    def goal_now(self, state: CycleState) -> Array:
        """``g`` of ``state``, computed now (SI, the stream's space); ``ValueError`` beyond
        ``max_offset``.  The link's cycle takes the newest one computed beside it."""
        if self._wanted is not None:
            g = self._wanted(state)
        else:
            with self._lock:
                value = self._value
            g = self._in_space(value, state)
        return _check(g, self._limit, self.space)

    def _goal(self, state: CycleState) -> Array:
        self.offset = state.offset
        return self.goal_now(state) if self._beside is None else self._beside.offer(state)

    @property
    def uncorrected(self) -> Array:
        """The rotation an EGM path correction leaves uncorrected (rotation vector, rad,
        base frame; zeros for every other correction)."""
        return np.array(getattr(self._wanted, "uncorrected", np.zeros(3)), dtype=float)

    @property
    def along_path(self) -> float:
        """The part of a compensation's shift along the path, which an EGM path correction
        leaves uncorrected (m; 0 for every other correction)."""
        return float(getattr(self._wanted, "along_path", 0.0))

    def close(self) -> None:
        """Stop computing ``g`` (the correction ended)."""
        if self._beside is not None:
            self._beside.close()

    def set(self, g: Array) -> None:
        """``g`` of an ``offset`` or ``external`` correction from the next cycle (SI, the
        spec's frame; thread-safe)."""
        with self._lock:
            self._value = g


def make_source(spec: CorrectionSpec, config: Any, path_chord: Any = None) -> Superimposed:
    """``spec`` as a link of ``config`` runs it (:class:`Superimposed`); ``path_chord``:
    an EGM path link's last chord of the controller's path (``(q_a, q_b)``, rad), the
    path frame of a compensation started where the arm stands.

    Raises
    ------
    ValueError
        A source or frame the stream cannot send, an offset beyond ``max_offset``, or a
        calibration that cannot be read: the reason.
    """
    space = correction_space(config)
    if spec.source == "compensation":
        return Superimposed(spec, space, _Compensation(spec, space, path_chord),
                            _InSpace(space, space, ""))
    in_space = _InSpace(spec.frame, space, spec.robot, spec.tcp)
    if space == "path" and any(spec.offset[3:]):
        raise ValueError("EGM path corrections carry a position only: A, B, C must be 0")
    if space == "path" and spec.frame == "path" and spec.offset[0]:
        raise ValueError(PATH_X)
    if spec.frame == space:
        _check(np.asarray(spec.offset), np.asarray(spec.max_offset), space)
    return Superimposed(spec, space, None, in_space)


#: Why an EGM path correction along the path is refused.
PATH_X = ("EGM path corrections carry y and z in path coordinates only: X is the path's "
          "direction, which the controller does not correct (ABB, Application manual EGM, "
          "limitations of EGM Path Correction): X must be 0")


def _check(g: Array, limit: Array, space: str) -> Array:
    over = np.flatnonzero(np.abs(g) > limit)
    if len(over):
        i = int(over[0])
        names = ("A1", "A2", "A3", "A4", "A5", "A6") if space == "joints" else \
            ("X", "Y", "Z", "A", "B", "C")
        unit, scale = ("°", 180 / np.pi) if space == "joints" or i >= 3 else ("mm", 1000.0)
        raise ValueError(f"correction {names[i]} {g[i] * scale:.4g} {unit} beyond the "
                         f"largest correction {limit[i] * scale:.4g} {unit}")
    return g


class Corrector:
    """Runs one correction (:class:`CorrectionSpec`) at a time on a link (module docstring).

    Parameters
    ----------
    link : StreamLink
        A started link (its :meth:`~.follow.Following.follow` runs the correction).
    """

    def __init__(self, link: Any) -> None:
        self.link = link
        self._running: Superimposed | None = None
        self._thread: threading.Thread | None = None
        self._outcome: str | None = None  # "" ended well, else why not; None: running
        self._lock = threading.Lock()
        self._switch = sys.getswitchinterval()

    @property
    def active(self) -> bool:
        """A correction runs (not yet ramped out or failed)."""
        thread = self._thread
        return thread is not None and thread.is_alive()

    def start(self, spec: CorrectionSpec) -> None:
        """Start superimposing ``spec`` (returns at once; :meth:`poll` for the end).

        Raises
        ------
        ValueError
            The stream cannot send it, or an offset beyond the limits: the reason.
        RuntimeError
            A correction runs already, or the controller is not streaming.
        """
        with self._lock:
            if self.active:
                raise RuntimeError(f"a correction ({self._running.spec.source}) runs "
                                   f"already: end it first")  # type: ignore[union-attr]
            if not self.link.streaming or self.link.failure is not None:
                why = self.link.failure or f"no {self.link.config.vendor} stream"
                raise RuntimeError(f"cannot correct: {why}")
            # from here to the correction's end the link's thread shares the interpreter
            # with computations of milliseconds (a calibration read, g beside the link):
            # it must get it back within a fraction of a cycle
            switch = sys.getswitchinterval()
            sys.setswitchinterval(min(switch, SWITCH_INTERVAL_S))
            try:
                running = make_source(spec, self.link.config,
                                      getattr(self.link, "path_chord", None))
            except BaseException:
                sys.setswitchinterval(switch)
                raise
            self._switch = switch
            self._running, self._outcome = running, None
            self._thread = threading.Thread(target=self._run, args=(running, spec),
                                            name="correction", daemon=True)
            self._thread.start()

    def _run(self, running: Superimposed, spec: CorrectionSpec) -> None:
        source = running.source

        def done(state: CycleState) -> bool:
            # ramped out, and what the link sent is zero again: a controller clock that
            # jumped (samples late on a loaded machine) ends the ramp faster than the
            # limits let the offset down, which then takes the cycles it needs
            return source.ended() and not np.any(state.offset)

        try:
            self.link.follow(source, done=done, timeout=spec.timeout_s)
        except (StreamLinkError, TimeoutError) as exc:
            self._outcome = f"the correction failed: {exc}"
        else:
            self._outcome = ""
        finally:
            running.close()
            sys.setswitchinterval(self._switch)

    def set_offset(self, g: Array) -> None:
        """The running ``external`` or ``offset`` correction's ``g`` from the next cycle (SI,
        in the spec's frame).

        Raises
        ------
        RuntimeError
            No correction runs, or it is a compensation.
        ValueError
            ``g`` is not six finite numbers, or beyond ``max_offset``.
        """
        running = self._running
        if not self.active or running is None:
            raise RuntimeError("no correction runs: start one (CORRECT) first")
        spec = running.spec
        if spec.source == "compensation":
            raise RuntimeError("the running correction is a compensation: its offset comes "
                               "from the calibration")
        g = np.asarray(g, dtype=float).reshape(-1)
        if g.shape != (6,) or not np.isfinite(g).all():
            raise ValueError(f"an offset is six finite numbers, got {g!r}")
        if spec.frame == running.space:
            _check(g, np.asarray(spec.max_offset), spec.frame)
        if running.space == "path" and spec.frame == "path" and g[0]:
            raise ValueError(PATH_X)
        running.set(g)

    def finish(self) -> None:
        """Ramp the running correction out (nothing if none runs)."""
        if self._running is not None and self.active:
            self._running.source.finish()

    def poll(self) -> str | None:
        """``None`` while a correction runs; then ``""`` (it ramped out) or why it failed."""
        if self.active:
            return None
        return "" if self._outcome is None else self._outcome

    def close(self, timeout: float = 5.0) -> None:
        """After the link's close (which ends a motion still running): wait, at most
        ``timeout`` s, for the correction's thread to end — none lingers."""
        thread = self._thread
        if thread is not None:
            thread.join(timeout)

    def status(self) -> tuple[float, Array]:
        """The blend factor ``b`` of the last cycle, and the link's offset so far (SI) —
        for an EGM path correction (y and z in path coordinates) its first value is the
        part along the path and its last three the rotation that a compensation leaves
        uncorrected (m; rotation vector, rad)."""
        running = self._running
        if running is None:
            return 0.0, np.zeros(6)
        offset = np.array(running.offset, dtype=float)
        if running.space == "path":
            offset[0] = running.along_path
            offset[3:] = running.uncorrected
        return running.source.blend, offset
