"""The simulated robot: commanded joints in, joint readings and a true pose out.

:class:`RobotTwin` is a mutable device (Drake's *context* side) around an
immutable :class:`~plugcell.sim.twin.scenario.TwinTruth`.  A move goes through what a
real arm does:

1. the commanded joint angles are quantised to the encoder resolution — the
   controller can only servo to encoder counts, and reports those counts as its
   joint readings;
2. the servo settles within its repeatability (a fresh random joint error per move);
   the reducer adds its lost motion (backlash: the link lags the motor by half the
   lost motion against the direction of the last move — unless gravity presses the
   gear teeth to one flank, then on that flank) and its periodic transmission error;
3. the link side yields to gravity, counterweight and payload through the joint
   stiffnesses (:func:`~plugcell.sim.twin.physics.deflected_joints`), the passive
   joints follow the *exact* four-bar closure of the true loop;
4. the links bend (:func:`~plugcell.sim.twin.physics.bending`).

Motors, encoders and reducers (steps 1–2) act on the joint *readings*; a
description with a joint ``coupling`` (vendor convention) maps them to its
kinematic joints before the joints yield (step 3) — the joint stiffnesses are
those of the links.  Without a coupling readings and kinematic joints coincide.

Only simulated devices (the tracker model, the simulated controller) may ask for
:meth:`RobotTwin.true_flange`.  Service and calibration code see joint readings
and tracker measurements, like with a real robot.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.kinematics import RobotDescription, forward
from plugcell.sim.twin.physics import Payload, bending, deflected_joints, gravity_torques
from plugcell.sim.twin.scenario import TwinScenario, TwinTruth, make_truth
from plugcell.sim.twin.thermal import ThermalDrift

Array = NDArray[np.float64]


def true_flange_poses(truth: TwinTruth, q_motor: ArrayLike, payload: Payload | None = None,
                      *, gravity: bool | None = None, bend: bool | None = None) -> Array:
    """True flange poses (..., 4, 4) in the robot base frame for motor angles (..., n).

    Noise-free (no quantisation, no repeatability): the deterministic physics.
    ``gravity``/``bend`` default to the scenario's switches.
    """
    sc = truth.scenario
    payload = sc.payload if payload is None else payload
    gravity = sc.gravity if gravity is None else gravity
    bend = sc.bending if bend is None else bend
    q = np.asarray(q_motor, dtype=float)
    desc, q = _link_joints(truth, q + truth.transmission(q), payload, gravity)
    fk = forward(desc, truth.params, q, closure="fourbar")
    flange = fk.flange
    if bend and gravity and truth.profile.beams:
        bent = bending(desc, fk.frames, flange, truth.profile.beams, payload)
        flange = bent @ flange
    return flange


def _link_joints(truth: TwinTruth, q_reached: Array, payload: Payload, gravity: bool
                 ) -> tuple[RobotDescription, Array]:
    """The robot on its kinematic joints and their link-side angles for reached readings.

    θ = θ_kin(q) (the description's coupling), then the joints yield to gravity.
    """
    desc = truth.description
    q = desc.kinematic_joints(q_reached)
    kin = desc.uncoupled()
    if gravity:
        q = deflected_joints(kin, truth.params, q, truth.stiffness, payload)
    return kin, q


class RobotTwin:
    """A simulated robot arm (see module docstring).

    ``seed`` drives the per-move noise (repeatability); the hidden errors come from
    the scenario's own seed.
    """

    def __init__(self, scenario: TwinScenario | TwinTruth, *, seed: int | None = None) -> None:
        self._truth = scenario if isinstance(scenario, TwinTruth) else make_truth(scenario)
        sc = self._truth.scenario
        self._rng = np.random.default_rng(sc.seed + 1_000_003 if seed is None else seed)
        self._payload = sc.payload
        desc = self._truth.description
        self._motor = np.array(desc.home, dtype=float)
        self._reached = self._motor.copy()
        self._flank = np.ones(desc.n_readings)  # side of the backlash each gear sits on
        self.moves = 0
        self._thermal: ThermalDrift | None = None
        self._temperature_c = 20.0
        # the last true flange: the same reached angles and payload give the same pose
        # (the physics is deterministic), asked again by every tracker sample at rest
        self._last_flange: tuple[bytes, Payload, Array] | None = None

    # ------------------------------------------------------------------ thermal drift
    def set_thermal_drift(self, drift: ThermalDrift | None, temperature_c: float | None = None
                          ) -> None:
        """Let the cell drift with temperature (:mod:`plugcell.sim.twin.thermal`; ``None``:
        no drift); ``temperature_c`` default the drift's reference."""
        self._thermal = drift
        if drift is not None:
            self._temperature_c = drift.reference_c if temperature_c is None else temperature_c

    def set_temperature(self, temperature_c: float) -> None:
        """The hall's temperature now (°C): moves BASE and scales the arm's lengths."""
        if not np.isfinite(temperature_c):
            raise ValueError(f"temperature_c must be finite, got {temperature_c!r}")
        self._temperature_c = float(temperature_c)

    @property
    def temperature_c(self) -> float:
        """The temperature a sensor in the cell reads (°C)."""
        return self._temperature_c

    def true_base(self) -> Array:
        """True BASE now (robot base in the tracker frame) — simulators only."""
        if self._thermal is None:
            return self._truth.base
        return self._thermal.base_drift(self._temperature_c) @ self._truth.base

    def true_point_in_tracker(self, point_base: ArrayLike) -> Array:
        """Where a point fixed to the robot's foundation (robot base frame, m) is in the
        tracker frame now (a reference nest) — simulators only."""
        B = self.true_base()
        return B[:3, :3] @ np.asarray(point_base, float) + B[:3, 3]

    # ------------------------------------------------------------------ public face
    @property
    def description(self):
        """The nominal description: what the robot's maker publishes."""
        return self._truth.description

    @property
    def payload(self) -> Payload:
        return self._payload

    def set_payload(self, mass_kg: float, com_m: tuple[float, float, float] | None = None) -> None:
        """Mount (or remove, mass 0) a dead weight on the flange."""
        self._payload = Payload(mass_kg, self._payload.com if com_m is None else com_m)

    def quantise(self, q: ArrayLike) -> Array:
        """Joint angles rounded to encoder counts (what the controller can servo to)."""
        res = self._truth.profile.encoder_resolution
        return np.round(np.asarray(q, dtype=float) / res) * res

    def move_joints(self, q_command: ArrayLike) -> Array:
        """Servo to ``q_command`` (joint readings, rad); returns the joint readings.

        Joint limits are the controller's business (the simulated controller checks
        them before calling this); the arm goes where it is told.
        """
        q = np.asarray(q_command, dtype=float)
        n = self.description.n_readings
        if q.shape != (n,) or not np.all(np.isfinite(q)):
            raise ValueError(f"move_joints: expected {n} finite joint angles, got {q!r}")
        motor = self.quantise(q)
        step = motor - self._motor
        self._flank = np.where(step > 0, 1.0, np.where(step < 0, -1.0, self._flank))
        self._motor = motor
        profile = self._truth.profile
        flank = self._flank
        if self._truth.scenario.gravity and profile.preload_torque > 0:
            tau = gravity_torques(self.description, self._truth.params, motor, self._payload)
            flank = np.where(np.abs(tau) > profile.preload_torque, np.sign(tau), flank)
        noise = 0.0
        if self._truth.scenario.noise:
            noise = profile.repeatability * self._rng.standard_normal(n)
        lost = profile.lost_motion if self._truth.scenario.backlash else 0.0
        self._reached = self._motor - 0.5 * lost * flank + noise
        self.moves += 1
        return self.joint_readings()

    def follow(self, readings: ArrayLike, reached: ArrayLike) -> None:
        """Take the state of an arm that moves in time (:mod:`plugcell.sim.twin.dynamics`):
        the encoder ``readings`` the controller reports and the link-side angles
        ``reached`` (rad) that :meth:`true_flange` puts through the static physics."""
        self._motor = np.array(readings, dtype=float)
        self._reached = np.array(reached, dtype=float)

    def joint_readings(self) -> Array:
        """The encoder readings the controller reports (rad)."""
        return self._motor.copy()

    # ------------------------------------------------------------------ truth (simulators only)
    def true_flange(self) -> Array:
        """True flange pose in the robot base frame — for simulated devices only."""
        reached, payload, last = self._reached, self._payload, self._last_flange
        if last is None or last[0] != reached.tobytes() or last[1] != payload:
            last = (reached.tobytes(), payload, true_flange_poses(self._truth, reached, payload))
            self._last_flange = last
        T = np.array(last[2], copy=True)
        if self._thermal is not None:
            T[..., :3, 3] *= self._thermal.length_scale(self._temperature_c)
        return T

    def true_reflector_in_tracker(self) -> Array:
        """True T-MAC pose in the tracker frame, BASE·T6·PROBE (eq. 6.23)."""
        return self.true_base() @ self.true_flange() @ self._truth.probe

    def reveal_truth(self) -> TwinTruth:
        """The hidden truth — for tests and error budgets, never for calibration."""
        return self._truth


def true_link_frames(truth: TwinTruth, q_motor: ArrayLike, payload: Payload | None = None
                     ) -> Array:
    """True frames (..., n_links, 4, 4) of every link in the robot base frame (deflected,
    without link bending) — where a reflector fixed on a link really is.  Simulators only."""
    sc = truth.scenario
    payload = sc.payload if payload is None else payload
    q = np.asarray(q_motor, dtype=float)
    desc, q = _link_joints(truth, q + truth.transmission(q), payload, sc.gravity)
    return forward(desc, truth.params, q, closure="fourbar").frames
