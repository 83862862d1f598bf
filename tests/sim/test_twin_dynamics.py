"""The twin in time (plugcell.sim.twin.dynamics): what a simulated response shows is what
the parameters say — servo bandwidth and overshoot, mode frequency and damping, backlash
at a reversal, encoder counts, the dead time's following error — deterministic in its
seed, stable, and its parameters parsed with clear errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from plugcell.sim.twin.dynamics import (
    DynamicParameters,
    DynamicsError,
    DynamicTwin,
    servo_transfer,
)
from plugcell.sim.twin.scenario import TwinScenario

CYCLE = 0.004
#: No gravity (no preload, no sag), no lost motion: the servo and the mode alone.
BARE = TwinScenario(robot="smart_h4", gravity=False, backlash=False, bending=False)
NO_FF = dict(velocity_feedforward=0.0, acceleration_feedforward=0.0)


def _step(params: DynamicParameters, joint: int, size: float, cycles: int,
          scenario: TwinScenario = BARE) -> tuple[np.ndarray, dict, int]:
    dyn = DynamicTwin(scenario, params)
    q0 = dyn.measured.copy()
    dyn.reset(q0)
    cmd = np.tile(q0, (cycles, 1))
    k0 = 10
    cmd[k0:, joint] += size
    return q0, dyn.run(cmd), k0


def test_servo_step_follows_the_cascade_transfer_function() -> None:
    """Friction and feedforward off: the motor's step response is the continuous
    cascade's (servo_transfer) fed with the delayed, fine-interpolated reference."""
    p = DynamicParameters(**NO_FF, coulomb=(0.0,) * 6, viscous=(1e-6,) * 6)
    size, joint = 0.005, 0  # small enough that the torque stays below its limit
    q0, out, k0 = _step(p, joint, size, 150)
    y = out["motor"][:, joint] - q0[joint]
    num, den = servo_transfer(p, joint)
    h = CYCLE / p.substeps
    t = np.arange(150 * p.substeps + 1) * h
    start = (k0 + p.dead_time_cycles) * CYCLE  # the ramp of the fine interpolation
    r = np.clip(np.floor((t - start) / h + 1e-9) * h / CYCLE, 0.0, 1.0) * size  # held
    _, ys, _ = signal.lsim((num, den), r, t)
    expected = ys[p.substeps::p.substeps]  # at the end of each cycle
    assert np.max(np.abs(y - expected)) < 0.02 * size
    # the bandwidth: 63 % of the step one position-loop time constant 1/K_v after it
    t63 = (np.argmax(y >= 0.632 * size) + 1) * CYCLE - start
    assert t63 == pytest.approx(1.0 / p.position_gain[joint], rel=0.25)
    # overshoot as the transfer function predicts
    assert (y.max() - size) / size == pytest.approx((ys.max() - size) / size, abs=0.005)


def _crossings(e: np.ndarray, dt: float) -> np.ndarray:
    i = np.flatnonzero((e[:-1] < 0) & (e[1:] >= 0))
    return (i + e[i] / (e[i] - e[i + 1])) * dt


@pytest.mark.parametrize("joint", [0, 5])
def test_the_mode_rings_at_its_frequency_with_its_damping(joint: int) -> None:
    p = DynamicParameters(**NO_FF)
    _, out, k0 = _step(p, joint, 0.02, 500)
    e = out["link"][:, joint] - out["motor"][:, joint]
    ring = e[k0 + 60:]  # the motor has nearly settled; the link still rings
    up = _crossings(ring, CYCLE)
    f_d = 1.0 / np.mean(np.diff(up[:8]))
    fn, zeta = p.mode_frequency_hz[joint], p.mode_damping[joint]
    assert f_d == pytest.approx(fn * math.sqrt(1 - zeta**2), rel=0.02)
    # damping from the decay of successive peaks (logarithmic decrement)
    period = round(1.0 / f_d / CYCLE)
    peaks = [np.max(ring[k:k + period]) for k in range(0, 6 * period, period)]
    delta = np.log(peaks[0] / peaks[-1]) / (len(peaks) - 1)
    zeta_measured = delta / math.sqrt(4 * math.pi**2 + delta**2)
    assert zeta_measured == pytest.approx(zeta, rel=0.2)


def test_a_reversal_shows_the_backlash() -> None:
    """The link lags the motor by half the lost motion against the last direction of
    motion: after a reversal the offset flips by the whole lost motion."""
    sc = TwinScenario(robot="smart_h4", gravity=False)
    dyn = DynamicTwin(sc)
    lost = dyn.twin.reveal_truth().profile.lost_motion
    q0 = dyn.measured.copy()
    ramp = np.linspace(0, 0.01, 250)
    up = q0 + np.outer(np.concatenate([ramp, np.full(250, 0.01)]), np.eye(6)[3])
    down = q0 + np.outer(np.concatenate([ramp[::-1], np.zeros(250)]), np.eye(6)[3])
    a = dyn.run(up)
    b = dyn.run(down)
    # while the motor moves (mid-ramp; at rest friction and the encoder counts let the
    # motor hunt within the play)
    off_up = np.mean(a["link"][150:240, 3] - a["motor"][150:240, 3])
    off_down = np.mean(b["link"][150:240, 3] - b["motor"][150:240, 3])
    # (the mode's input is held over each substep: it lags by h/2 · v, 4 % here)
    assert off_up == pytest.approx(-lost / 2, rel=0.05)
    assert off_down == pytest.approx(+lost / 2, rel=0.05)
    assert off_down - off_up == pytest.approx(lost, rel=0.05)


def test_gravity_holds_a_loaded_gear_on_one_flank() -> None:
    dyn = DynamicTwin(TwinScenario(robot="smart_h4", payload_kg=36.0))
    prof = dyn.twin.reveal_truth().profile
    q0 = dyn.measured.copy()
    down = q0 - np.outer(np.linspace(0, 0.01, 200), np.eye(6)[2])  # joint 2' reverses
    out = dyn.run(np.vstack([down, np.repeat(down[-1:], 500, 0)]))
    # joint 2' carries ~600 N·m > preload: it stays on the flank gravity pushes it to
    tau = dyn._tau_g[2]
    assert abs(tau) > prof.preload_torque
    off = out["link"][-1, 2] - out["motor"][-1, 2]
    assert off == pytest.approx(-0.5 * prof.lost_motion * np.sign(tau), rel=0.02)


def test_readings_are_encoder_counts() -> None:
    dyn = DynamicTwin(BARE)
    res = dyn.twin.reveal_truth().profile.encoder_resolution
    q0 = dyn.measured.copy()
    out = dyn.run(q0 + np.outer(np.linspace(0, 0.003, 100), np.ones(6)))
    counts = out["measured"] / res
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    assert np.any(out["motor"] != out["measured"])  # the true motor is finer
    np.testing.assert_array_equal(dyn.twin.joint_readings(), out["measured"][-1])


def test_following_error_at_constant_speed_is_the_dead_time() -> None:
    """With feedforward the servo follows a ramp without lag: the motor is where the
    command was ``dead_time_cycles`` ago, to a few encoder counts."""
    p = DynamicParameters()
    dyn = DynamicTwin(BARE, p)
    res = dyn.twin.reveal_truth().profile.encoder_resolution
    q0 = dyn.measured.copy()
    v = np.array([0.3, 0.2, 0.2, 0.5, 0.5, 0.5])  # rad/s
    cmd = q0 + np.outer(np.arange(400) * CYCLE, v)
    out = dyn.run(cmd)
    d = p.dead_time_cycles
    lag = cmd[300 - d:400 - d] - out["motor"][300:400]
    assert np.max(np.abs(lag)) < 5 * res
    # against the command of *this* cycle the error is the dead time at speed
    np.testing.assert_allclose((cmd[300:400] - out["motor"][300:400]).mean(0), v * d * CYCLE,
                               atol=5 * res)


def test_deterministic_in_its_seed() -> None:
    q = None
    runs = []
    for seed in (3, 3, 4):
        dyn = DynamicTwin(BARE, seed=seed)
        q = dyn.measured.copy() if q is None else q
        cmd = q + np.outer(np.sin(np.linspace(0, 3, 150)) * 0.02, np.ones(6))
        runs.append(dyn.run(cmd)["motor"])
    np.testing.assert_array_equal(runs[0], runs[1])
    assert np.any(runs[0] != runs[2])  # another robot of the series: other friction


def test_at_rest_it_stays_put_and_the_true_pose_moves_with_it() -> None:
    dyn = DynamicTwin(TwinScenario(robot="smart_h4", payload_kg=36.0))
    res = dyn.twin.reveal_truth().profile.encoder_resolution
    q0 = dyn.measured.copy()
    T0 = dyn.true_flange().copy()
    out = dyn.run(np.tile(q0, (1500, 1)))  # six seconds at rest
    assert np.all(np.isfinite(out["link"]))
    assert np.max(np.abs(out["motor"] - q0)) < 3 * res
    dyn.run(np.tile(q0 + 0.01 * np.eye(6)[0], (200, 1)))
    assert np.linalg.norm(dyn.true_flange()[:3, 3] - T0[:3, 3]) > 0.01  # it moved


def test_an_unstable_servo_is_refused_naming_the_joint() -> None:
    with pytest.raises(DynamicsError, match="joint 1: the servo is unstable"):
        DynamicTwin(BARE, DynamicParameters(position_gain=(5000.0, 20, 20, 20, 20, 20)))
    with pytest.raises(DynamicsError, match="for 3 joints, smart_h4 has 6"):
        DynamicTwin(BARE, DynamicParameters.from_dict({k: [1.0] * 3 for k in (
            "position_gain", "velocity_bandwidth_hz", "inertia", "coulomb", "viscous",
            "torque_limit", "mode_frequency_hz")} | {"mode_damping": [0.05] * 3}))
    dyn = DynamicTwin(BARE)
    with pytest.raises(ValueError, match="expected 6 finite joint angles"):
        dyn.step([0.0, math.nan, 0, 0, 0, 0])


@pytest.mark.parametrize(("data", "message"), [
    ({"cycel": 0.004}, "unknown keys \\['cycel'\\]"),
    ({"cycle": -1}, "cycle = -1: must be a finite number > 0"),
    ({"substeps": 2.5}, "substeps = 2.5: expected an integer"),
    ({"dead_time_cycles": True}, "dead_time_cycles = True"),
    ({"mode_damping": [0.05] * 5}, "mode_damping: 5 values, expected 6"),
    ({"mode_damping": [1.5] * 6}, "mode_damping\\[0\\] = 1.5: a structural mode is "
                                  "underdamped"),
    ({"mode_frequency_hz": [200.0] * 6}, "Nyquist frequency 125 Hz"),
    ({"velocity_bandwidth_hz": [400.0] * 6}, "too fast for the servo substep"),
    ({"inertia": "heavy"}, "inertia = 'heavy': expected one number per joint"),
    ({"coulomb": [-1, 0, 0, 0, 0, 0]}, "coulomb\\[0\\] = -1: must be a finite number ≥ 0"),
    ({"velocity_feedforward": 2}, "velocity_feedforward = 2: expected 0..1"),
    ([1, 2], "expected a table, got list"),
])
def test_bad_parameters_are_named(data, message) -> None:
    with pytest.raises(DynamicsError, match=message):
        DynamicParameters.from_dict(data)


_values = st.one_of(st.none(), st.booleans(), st.integers(-5, 1000),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=4),
                    st.lists(st.floats(-10, 1e4), max_size=7))


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(st.sampled_from(["cycle", "substeps", "dead_time_cycles",
                                        "position_gain", "mode_damping", "inertia",
                                        "coulomb", "velocity_feedforward", "friction_spread",
                                        "mode_frequency_hz", "other"]), _values, max_size=4))
def test_parsing_never_fails_otherwise(data) -> None:
    """Any table gives valid parameters or a DynamicsError — nothing else."""
    try:
        p = DynamicParameters.from_dict(data)
    except DynamicsError:
        return
    assert p.n == len(p.mode_damping) and all(math.isfinite(v) for v in p.inertia)
