"""The twin in time: a controller and an arm that move cycle by cycle.

:class:`DynamicTwin` advances the robot by one interface cycle ``T`` (4 ms, KUKA RSI's
``#IPO_FAST``, ABB EGM) per :meth:`DynamicTwin.step`, given that cycle's commanded joint
readings.  Per joint (all joints at once, vectorised), inside one cycle:

1. **Dead time**: the servo works on the command of ``d`` cycles ago,
   ``r_k = q_cmd[k − d]`` (the controller's interpolation and transfer to the drives).
2. **Fine interpolation**: over the cycle's ``S`` substeps of ``h = T/S`` the reference
   moves linearly from ``r_{k−1}`` to ``r_k``; velocity and acceleration feedforward are
   ``ṙ = (r_k − r_{k−1})/T`` and ``r̈ = (ṙ_k − ṙ_{k−1})/T``.
3. **Cascade servo** (discrete, every substep, on the motor side reflected to the joint):
   position P, velocity PI with anti-windup, feedforward, torque limit::

       y   = res · round(θ_m / res)                            (encoder counts)
       v*  = K_v (r − y) + f_v ṙ
       τ   = J ω_v (v* − ω_m) + I + f_a J r̈,   |τ| ≤ τ_max
       I  += J ω_v ω_i (v* − ω_m) h                            (not while saturated)

4. **Motor with friction**, ``J ω̇_m = τ − b ω_m − τ_c sgn(ω_m)``, integrated *exactly*
   over the substep with the torque held (``a = b/J``, ``u = τ − τ_c s``)::

       ω(h) = u/b + (ω₀ − u/b) e^{−a h}
       θ(h) = θ₀ + (u/b) h + (ω₀ − u/b)(1 − e^{−a h})/a

   A joint at rest sticks while ``|τ| ≤ τ_c``; a velocity that would cross zero stops
   at zero (at the exact time it reaches it).
5. **Backlash** (the reducer's lost motion ``β``): the link side is driven by the play
   operator ``x = clip(x, θ_m − β/2, θ_m + β/2)``, ``ẋ = ω_m`` while a flank is in
   contact, else 0 — the link lags the motor by ``β/2`` against the last direction of
   motion, as the static twin's ``move_joints``; where gravity loads the joint above
   the profile's preload torque the teeth stay on one flank, ``x = θ_m − (β/2) sgn τ_g``
   (``τ_g`` refreshed every ``gravity_update_cycles``).
6. **First structural mode** of each joint: the link angle is a base-excited oscillator
   ``θ̈_l = ω_n²(x − θ_l) + 2ζω_n(ẋ − θ̇_l)``, discretised exactly (zero-order hold,
   ``Φ = e^{A h}``, ``Γ = ∫₀ʰ e^{A s} ds B``).

The link angles then go through the twin's static physics
(:func:`~plugcell.sim.twin.robot.true_flange_poses`: transmission error, gravity and
payload compliance through the true loop, link bending) for the true flange.  The
gravity sag itself is the static twin's (the drives compensate gravity torque; the
link yields by ``τ/k``); the mode models deviations around it.

Assumptions (docs/twin.md, "The twin in time"): each joint's first mode is one
decoupled oscillator of constant frequency (real modes couple joints and shift with
the configuration and payload); the drive's velocity loop is stiff enough that the
link's reaction on the motor is neglected (colocated control).  Deterministic: the
seed only draws each joint's friction within ``±friction_spread`` of its nominal value
(one robot of a series).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.sim.twin.physics import gravity_torques
from plugcell.sim.twin.robot import RobotTwin, true_flange_poses
from plugcell.sim.twin.scenario import TwinScenario

Array = NDArray[np.float64]

__all__ = ["DynamicParameters", "DynamicTwin", "DynamicsError", "servo_transfer"]


class DynamicsError(ValueError):
    """Dynamic parameters that cannot be used; the message names the field and why."""


_PER_JOINT = ("position_gain", "velocity_bandwidth_hz", "inertia", "coulomb", "viscous",
              "torque_limit", "mode_frequency_hz", "mode_damping")


@dataclass(frozen=True)
class DynamicParameters:
    """The twin's dynamics, per joint reading (SI; frequencies in Hz).

    The defaults are those of a 200 kg-class six-axis robot (the Smart H4); each
    value's source is in docs/twin.md, "The twin in time".

    Attributes
    ----------
    cycle : float
        Interface cycle ``T`` (s).
    dead_time_cycles : int
        Cycles between a command and the servo acting on it.
    substeps : int
        Servo substeps per cycle (``h = T / substeps``).
    position_gain : tuple of float
        ``K_v`` (1/s), the position loop's gain: its bandwidth ``K_v/2π`` Hz.
    velocity_bandwidth_hz : tuple of float
        ``ω_v/2π``, the velocity loop's bandwidth.
    integral_ratio : float
        ``ω_i/ω_v``, the velocity PI's zero as a fraction of its bandwidth.
    velocity_feedforward, acceleration_feedforward : float
        ``f_v``, ``f_a`` in [0, 1].
    inertia : tuple of float
        ``J`` (kg·m²), motor and gear inertia reflected to the joint.
    coulomb, viscous : tuple of float
        ``τ_c`` (N·m) and ``b`` (N·m·s/rad), joint friction.
    torque_limit : tuple of float
        ``τ_max`` (N·m), the drive's torque limit at the joint.
    mode_frequency_hz, mode_damping : tuple of float
        ``f_n`` and ``ζ`` of each joint's first structural mode.
    friction_spread : float
        Each joint's friction is drawn once, uniformly within ``±friction_spread`` of
        its nominal value, from the seed.
    gravity_update_cycles : int
        How often the gravity torque that preloads the gears is recomputed.
    """

    cycle: float = 0.004
    dead_time_cycles: int = 2
    substeps: int = 8
    position_gain: tuple[float, ...] = (20.0, 20.0, 20.0, 20.0, 20.0, 20.0)
    velocity_bandwidth_hz: tuple[float, ...] = (40.0, 40.0, 40.0, 50.0, 50.0, 50.0)
    integral_ratio: float = 0.25
    velocity_feedforward: float = 1.0
    acceleration_feedforward: float = 1.0
    inertia: tuple[float, ...] = (180.0, 180.0, 120.0, 12.0, 12.0, 4.0)
    coulomb: tuple[float, ...] = (60.0, 60.0, 40.0, 12.0, 10.0, 6.0)
    viscous: tuple[float, ...] = (80.0, 80.0, 50.0, 8.0, 6.0, 3.0)
    torque_limit: tuple[float, ...] = (8000.0, 8000.0, 5000.0, 900.0, 900.0, 400.0)
    mode_frequency_hz: tuple[float, ...] = (9.0, 12.0, 14.0, 18.0, 20.0, 25.0)
    mode_damping: tuple[float, ...] = (0.04, 0.04, 0.04, 0.05, 0.05, 0.05)
    friction_spread: float = 0.2
    gravity_update_cycles: int = 25

    def __post_init__(self) -> None:
        def positive(name: str, v: object, zero: bool = False) -> float:
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise DynamicsError(f"{name} = {v!r}: expected a number")
            f = float(v)
            if not math.isfinite(f) or f < 0 or (f == 0 and not zero):
                raise DynamicsError(f"{name} = {v!r}: must be a finite number "
                                    f"{'≥' if zero else '>'} 0")
            return f

        def count(name: str, v: object, lo: int, hi: int) -> None:
            if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
                raise DynamicsError(f"{name} = {v!r}: expected an integer {lo}..{hi}")

        positive("cycle", self.cycle)
        if self.cycle > 0.1:
            raise DynamicsError(f"cycle = {self.cycle!r} s: expected at most 0.1 s")
        count("dead_time_cycles", self.dead_time_cycles, 0, 100)
        count("substeps", self.substeps, 1, 1000)
        count("gravity_update_cycles", self.gravity_update_cycles, 1, 100000)
        for name in ("velocity_feedforward", "acceleration_feedforward"):
            if positive(name, getattr(self, name), zero=True) > 1:
                raise DynamicsError(f"{name} = {getattr(self, name)!r}: expected 0..1")
        if positive("integral_ratio", self.integral_ratio, zero=True) > 1:
            raise DynamicsError(f"integral_ratio = {self.integral_ratio!r}: expected 0..1")
        if positive("friction_spread", self.friction_spread, zero=True) >= 1:
            raise DynamicsError(f"friction_spread = {self.friction_spread!r}: expected < 1")
        n = None
        for name in _PER_JOINT:
            vals = getattr(self, name)
            if isinstance(vals, (str, bytes)) or not hasattr(vals, "__len__"):
                raise DynamicsError(f"{name} = {vals!r}: expected one number per joint")
            zero = name == "coulomb"
            vals = tuple(positive(f"{name}[{i}]", v, zero) for i, v in enumerate(vals))
            if n is None:
                n = len(vals)
            if len(vals) != n or n == 0:
                raise DynamicsError(f"{name}: {len(vals)} values, expected {n} (one per "
                                    "joint, as position_gain)")
            object.__setattr__(self, name, vals)
        for i, z in enumerate(self.mode_damping):
            if z >= 1:
                raise DynamicsError(f"mode_damping[{i}] = {z!r}: a structural mode is "
                                    "underdamped, expected < 1")
        h = self.cycle / self.substeps
        for i, f in enumerate(self.mode_frequency_hz):
            if f * self.cycle >= 0.5:
                raise DynamicsError(f"mode_frequency_hz[{i}] = {f!r}: at or above the "
                                    f"cycle's Nyquist frequency {0.5 / self.cycle:g} Hz")
        for i, f in enumerate(self.velocity_bandwidth_hz):
            if 2 * math.pi * f * h > 0.5:
                raise DynamicsError(f"velocity_bandwidth_hz[{i}] = {f!r}: too fast for the "
                                    f"servo substep {h * 1e3:g} ms (ω_v·h > 0.5); raise "
                                    "substeps")

    @property
    def n(self) -> int:
        """Number of joints."""
        return len(self.position_gain)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], base: DynamicParameters | None = None
                  ) -> DynamicParameters:
        """Parameters from a mapping (a profile's ``[dynamics]`` table, JSON), over ``base``.

        Raises
        ------
        DynamicsError
            Not a mapping, an unknown key (named, with the known ones), or a bad value.
        """
        if not isinstance(data, Mapping):
            raise DynamicsError(f"dynamics: expected a table, got {type(data).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(str(k) for k in data if k not in known)
        if unknown:
            raise DynamicsError(f"dynamics: unknown keys {unknown}; known: {sorted(known)}")
        values = {k: (tuple(v) if isinstance(v, list) else v) for k, v in data.items()}
        return replace(base or cls(), **values)


def servo_transfer(params: DynamicParameters, joint: int) -> tuple[Array, Array]:
    """Continuous closed-loop transfer ``θ_m/r`` of one joint's cascade (no feedforward,
    no friction, no quantisation): numerator and denominator, highest power first.

    With ``ω_v``, ``ω_i = integral_ratio · ω_v`` and ``K_v``::

        θ_m/r = K_v ω_v (s + ω_i) / (s³ + ω_v s² + ω_v(ω_i + K_v) s + K_v ω_v ω_i)

    (the velocity loop ``ω/v* = ω_v (s + ω_i)/(s² + ω_v s + ω_v ω_i)`` inside the position
    loop).  Tests compare the simulated step with it.
    """
    wv = 2 * math.pi * params.velocity_bandwidth_hz[joint]
    wi = params.integral_ratio * wv
    kv = params.position_gain[joint]
    return (np.array([kv * wv, kv * wv * wi]),
            np.array([1.0, wv, wv * (wi + kv), kv * wv * wi]))


def _motion_integrals(a: float, t: float) -> tuple[float, float]:
    """``g₁ = (1 − e^{−at})/a`` and ``g₂ = (t − g₁)/a``: with a held acceleration ``α``
    (torque over inertia) a motor ``ω̇ = α − aω`` moves by ``ω₀ g₁ + α g₂`` and reaches
    ``ω₀ e^{−at} + α g₁`` — series where ``at`` is small (no cancellation as ``b → 0``)."""
    x = a * t
    if x < 1e-4:
        return t * (1 - x / 2 + x * x / 6), t * t * (0.5 - x / 6 + x * x / 24)
    g1 = -math.expm1(-x) / a
    return g1, (t - g1) / a


def _stop_time(w0: float, acc: float, a: float) -> float:
    """When ``ω₀ e^{−at} + α g₁(t)`` reaches zero (``ω₀``, ``α`` of opposite signs):
    ``t₀ = ln(1 − a ω₀/α)/a``, or ``−ω₀/α`` as ``a → 0``."""
    x = -a * w0 / acc
    return math.log1p(x) / a if abs(x) > 1e-12 else -w0 / acc


def _mode_transition(fn: float, zeta: float, h: float) -> tuple[Array, Array]:
    """Exact ZOH discretisation of ``θ̈ = ω²(x − θ) + 2ζω(ẋ − θ̇)`` over ``h``:
    ``[θ, θ̇]⁺ = Φ [θ, θ̇] + Γ [x, ẋ]``."""
    from scipy.linalg import expm  # here: the controller without --dynamics never loads SciPy

    w = 2 * math.pi * fn
    A = np.array([[0.0, 1.0], [-w * w, -2 * zeta * w]])
    B = np.array([[0.0, 0.0], [w * w, 2 * zeta * w]])
    M = np.zeros((4, 4))
    M[:2, :2], M[:2, 2:] = A * h, B * h
    E = expm(M)
    return E[:2, :2], E[:2, 2:]


@dataclass(frozen=True)
class DynamicState:
    """The arm after one cycle (rad, rad/s; joint readings).

    ``measured`` is what the controller reports (encoder counts), ``motor`` the true
    motor side, ``link`` the link side (backlash and structural mode) that goes into the
    static physics, ``reference`` what the servo was commanded (after the dead time).
    """

    cycle: int
    command: Array
    reference: Array
    measured: Array
    motor: Array
    motor_velocity: Array
    link: Array


class DynamicTwin:
    """A :class:`RobotTwin` that moves in time (module docstring).

    Parameters
    ----------
    twin : RobotTwin or TwinScenario
        The static twin: its truth (geometry, stiffness, transmission error), payload,
        encoder resolution, lost motion and preload are used.
    params : DynamicParameters, optional
        The dynamics (defaults: a 200 kg-class robot).
    q0 : array_like, shape (n,), optional
        Where the arm rests at the start (default: the description's home).
    seed : int, optional
        Draws the friction spread (default: the scenario's seed).
    """

    def __init__(self, twin: RobotTwin | TwinScenario, params: DynamicParameters | None = None,
                 *, q0: ArrayLike | None = None, seed: int | None = None) -> None:
        self.twin = twin if isinstance(twin, RobotTwin) else RobotTwin(twin)
        self.params = p = params or DynamicParameters()
        truth = self.twin.reveal_truth()
        desc = truth.description
        n = desc.n_readings
        if p.n != n:
            raise DynamicsError(f"dynamics for {p.n} joints, {desc.name} has {n} readings")
        rng = np.random.default_rng(truth.scenario.seed + 7_000_001 if seed is None else seed)
        spread = 1.0 + p.friction_spread * rng.uniform(-1.0, 1.0, (2, n))
        self._J = np.array(p.inertia)
        self._tc = np.array(p.coulomb) * spread[0]
        self._b = np.array(p.viscous) * spread[1]
        self._tmax = np.array(p.torque_limit)
        self._kv = np.array(p.position_gain)
        self._wv = 2 * np.pi * np.array(p.velocity_bandwidth_hz)
        self._wi = p.integral_ratio * self._wv
        self._h = p.cycle / p.substeps
        modes = [_mode_transition(f, z, self._h)
                 for f, z in zip(p.mode_frequency_hz, p.mode_damping, strict=True)]
        self._phi = np.array([m[0] for m in modes])  # (n, 2, 2)
        self._gam = np.array([m[1] for m in modes])
        self._res = truth.profile.encoder_resolution
        self._lost = truth.profile.lost_motion if truth.scenario.backlash else 0.0
        self._preload = truth.profile.preload_torque if truth.scenario.gravity else 0.0
        self._check_stability()
        self._c_J, self._c_kv, self._c_wv, self._c_wi = (self._J.tolist(), self._kv.tolist(),
                                                         self._wv.tolist(), self._wi.tolist())
        self._c_b, self._c_tc, self._c_tmax = self._b.tolist(), self._tc.tolist(), \
            self._tmax.tolist()
        self._c_a = (self._b / self._J).tolist()
        self._c_decay = np.exp(-self._b / self._J * self._h).tolist()
        self._c_g = [_motion_integrals(a, self._h) for a in self._c_a]
        self._c_phi, self._c_gam = self._phi.tolist(), self._gam.tolist()
        q = np.array(desc.home if q0 is None else q0, dtype=float)
        if q.shape != (n,) or not np.all(np.isfinite(q)):
            raise DynamicsError(f"q0: expected {n} finite joint angles, got {q!r}")
        self.reset(q)

    # ------------------------------------------------------------------ state
    def reset(self, q: ArrayLike) -> None:
        """Put the arm at rest at joint readings ``q`` (rad), the command there too."""
        q = np.array(q, dtype=float)
        self._theta = q.copy()
        self._omega = np.zeros_like(q)
        self._integral = np.zeros_like(q)
        self._x = q - 0.5 * self._lost  # gears on the positive flank, as RobotTwin
        self._link = np.stack([self._x.copy(), np.zeros_like(q)], axis=-1)  # (n, 2)
        self._queue = [q.copy() for _ in range(self.params.dead_time_cycles)]
        self._r_prev = q.copy()
        self._rd_prev = np.zeros_like(q)
        self._tau_g = np.zeros_like(q)
        self.cycle = 0
        self._update_gravity()
        self._apply_preload()
        self._link[:, 0] = self._x
        self._publish()

    @property
    def measured(self) -> Array:
        """Joint readings the controller reports: the motor position in encoder counts."""
        return np.round(self._theta / self._res) * self._res

    @property
    def motor(self) -> Array:
        return self._theta.copy()

    @property
    def link(self) -> Array:
        """Link-side joint angles (backlash, structural mode) — simulators only."""
        return self._link[:, 0].copy()

    def true_flange(self) -> Array:
        """True flange pose now (robot base frame, 4×4) — simulators only."""
        return self.twin.true_flange()

    # ------------------------------------------------------------------ motion
    def step(self, command: ArrayLike) -> DynamicState:
        """Advance one cycle with this cycle's commanded joint readings (rad)."""
        cmd = np.asarray(command, dtype=float)
        if cmd.shape != self._theta.shape or not np.all(np.isfinite(cmd)):
            raise ValueError(f"step: expected {self._theta.size} finite joint angles, "
                             f"got {command!r}")
        p = self.params
        self._queue.append(cmd.copy())
        r = self._queue.pop(0)
        T = p.cycle
        rd = (r - self._r_prev) / T
        rdd = (rd - self._rd_prev) / T
        for j in range(r.size):
            self._joint_cycle(j, float(self._r_prev[j]), float(r[j]), float(rd[j]),
                              float(rdd[j]))
        self._r_prev, self._rd_prev = r, rd
        self.cycle += 1
        if self.cycle % p.gravity_update_cycles == 0:
            self._update_gravity()
            self._apply_preload()
        self._publish()
        return DynamicState(self.cycle, cmd, r.copy(), self.measured, self._theta.copy(),
                            self._omega.copy(), self._link[:, 0].copy())

    def run(self, commands: ArrayLike) -> dict[str, Array]:
        """Step through commands ``(cycles, n)``; the states as arrays ``(cycles, n)``:
        ``command``, ``reference``, ``measured``, ``motor``, ``motor_velocity``, ``link``."""
        cmds = np.asarray(commands, dtype=float)
        if cmds.ndim != 2 or cmds.shape[1] != self._theta.size:
            raise ValueError(f"run: expected commands (cycles, {self._theta.size}), "
                             f"got shape {cmds.shape}")
        states = [self.step(c) for c in cmds]
        return {f: np.array([getattr(s, f) for s in states])
                for f in ("command", "reference", "measured", "motor", "motor_velocity",
                          "link")}

    def true_flanges(self, link: ArrayLike) -> Array:
        """True flange poses (..., 4, 4) for link-side angles (..., n), vectorised — the
        static physics of the twin (its payload included).  Simulators only."""
        return true_flange_poses(self.twin.reveal_truth(), link, self.twin.payload)

    # ------------------------------------------------------------------ internals
    def _joint_cycle(self, j: int, r0: float, r1: float, rd: float, rdd: float) -> None:
        """One cycle of joint ``j``'s servo, motor, backlash and mode (module docstring
        2–6), in scalar arithmetic: for six joints numpy's per-call cost would dominate."""
        p = self.params
        S, h = p.substeps, self._h
        J, kv, wv, wi = self._c_J[j], self._c_kv[j], self._c_wv[j], self._c_wi[j]
        tc, tmax, a, decay = self._c_tc[j], self._c_tmax[j], self._c_a[j], self._c_decay[j]
        g1, g2 = self._c_g[j]
        fv, fa, res, half = p.velocity_feedforward, p.acceleration_feedforward, self._res, \
            0.5 * self._lost
        (p00, p01), (p10, p11) = self._c_phi[j]
        (g00, g01), (g10, g11) = self._c_gam[j]
        held = self._c_held[j]
        theta, omega, integ = float(self._theta[j]), float(self._omega[j]), \
            float(self._integral[j])
        x, lq, lw = float(self._x[j]), float(self._link[j, 0]), float(self._link[j, 1])
        kint = J * wv * wi * h
        for i in range(S):
            ref = r0 + (r1 - r0) * (i / S)
            y = round(theta / res) * res
            ev = kv * (ref - y) + fv * rd - omega
            tau = J * wv * ev + integ + fa * J * rdd
            if tau > tmax or tau < -tmax:
                tau = tmax if tau > 0 else -tmax
                if (ev > 0) != (tau > 0):
                    integ += kint * ev
            else:
                integ += kint * ev
            # motor: J ω̇ = τ − bω − τ_c sgn ω, τ held over h, exactly
            if omega == 0.0 and abs(tau) <= tc:
                pass  # sticks
            else:
                sg = (1.0 if omega > 0 else -1.0) if omega != 0.0 else \
                    (1.0 if tau > 0 else -1.0)
                acc = (tau - tc * sg) / J
                w1 = omega * decay + acc * g1
                if w1 * sg < 0.0:  # friction stops it within the substep, at t0
                    t0 = _stop_time(omega, acc, a)
                    d1, d2 = _motion_integrals(a, t0)
                    theta += omega * d1 + acc * d2
                    omega = 0.0
                else:
                    theta += omega * g1 + acc * g2
                    omega = w1
            # backlash: the play operator, or the flank gravity holds
            if held:
                x, xd = theta - half * held, omega
            elif x < theta - half:
                x, xd = theta - half, omega
            elif x > theta + half:
                x, xd = theta + half, omega
            else:
                xd = 0.0
            # the structural mode, exact ZOH transition
            lq, lw = (p00 * lq + p01 * lw + g00 * x + g01 * xd,
                      p10 * lq + p11 * lw + g10 * x + g11 * xd)
        self._theta[j], self._omega[j], self._integral[j] = theta, omega, integ
        self._x[j], self._link[j, 0], self._link[j, 1] = x, lq, lw

    def _update_gravity(self) -> None:
        if self._preload > 0:
            truth = self.twin.reveal_truth()
            self._tau_g = gravity_torques(truth.description, truth.params, self._theta,
                                          self.twin.payload)

    def _apply_preload(self) -> None:
        """Which gears gravity holds on one flank (``_c_held``: sgn τ_g, or 0), and there
        the link side's input."""
        held = (np.abs(self._tau_g) > self._preload) if self._preload > 0 else \
            np.zeros(self._tau_g.size, dtype=bool)
        self._c_held = [float(np.sign(t)) if hd and self._lost > 0 else 0.0
                        for t, hd in zip(self._tau_g, held, strict=True)]
        for j, sg in enumerate(self._c_held):
            if sg:
                self._x[j] = self._theta[j] - 0.5 * self._lost * sg

    def _publish(self) -> None:
        """The static twin follows: its readings and true pose are this arm's."""
        self.twin.follow(self.measured, self._link[:, 0])

    def _check_stability(self) -> None:
        """The servo's linear part (no friction, no quantisation, no torque limit) over one
        substep: state ``[θ, ω, I]`` with zero reference; spectral radius < 1 per joint."""
        h = self._h
        for j in range(self._J.size):
            J, b, kv, wv, wi = self._J[j], self._b[j], self._kv[j], self._wv[j], self._wi[j]
            a = b / J
            e = math.exp(-a * h)
            g1, g2 = _motion_integrals(a, h)
            M = np.zeros((3, 3))
            for k, basis in enumerate(np.eye(3)):
                th, w, integ = basis
                ev = kv * (0.0 - th) - w
                acc = (J * wv * ev + integ) / J
                M[:, k] = (th + w * g1 + acc * g2, w * e + acc * g1,
                           integ + J * wv * wi * ev * h)
            rho = max(abs(np.linalg.eigvals(M)))
            if not rho < 1.0:
                raise DynamicsError(f"joint {j + 1}: the servo is unstable at the substep "
                                    f"{h * 1e3:g} ms (spectral radius {rho:.4f}); lower "
                                    "position_gain or velocity_bandwidth_hz, or raise "
                                    "substeps")
