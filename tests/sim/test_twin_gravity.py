"""The twin's gravity torques (virtual work, joint by joint through the exact closure)
are the negative gradient of its potential energy, checked against central differences
of ``potential_energy`` on every kind of arm: the Smart H4's parallelograms with the
twin's true (perturbed) geometry, a coupled arm (readings ≠ kinematic joints), a serial
one, and a 6R arm on a tilted linear track (a prismatic joint: a force, N)."""

from __future__ import annotations

import numpy as np
import pytest
from derivatives import central_differences
from track_robot import TRACK_ROBOT

from plugcell.io.robots import load_robot
from plugcell.io.urdf import import_urdf
from plugcell.sim.twin.campaign import working_volume_joints
from plugcell.sim.twin.physics import Payload, gravity_torques, potential_energy
from plugcell.sim.twin.scenario import TwinScenario, make_truth

PAYLOADS = [Payload(), Payload(36.0, (0.15, -0.05, 0.10))]


def _check(desc, params, q, payload) -> None:
    tau = gravity_torques(desc, params, q, payload)
    fd = -central_differences(lambda x: potential_energy(desc, params, x, payload)[..., None],
                              q)[..., 0, :]
    assert tau.shape == q.shape
    scale = np.abs(fd).max()
    assert scale > 1.0  # torques of N·m, not a vanishing comparison
    np.testing.assert_allclose(tau, fd, rtol=0, atol=1e-6 * scale)


@pytest.mark.parametrize("payload", PAYLOADS)
@pytest.mark.parametrize("robot", ["smart_h4", "fanuc_m20ia"])
def test_the_torques_are_minus_the_gradient_of_the_potential(robot, payload):
    truth = make_truth(TwinScenario(robot=robot, seed=7))
    q = working_volume_joints(truth.description, truth.profile, 8,
                              np.random.default_rng(3))
    _check(truth.description, truth.params, q, payload)  # a batch
    _check(truth.description, truth.params, q[0], payload)  # one configuration
    if truth.description.coupling is not None:  # and on the kinematic joints
        kin = truth.description.uncoupled()
        _check(kin, truth.params, truth.description.kinematic_joints(q), payload)


@pytest.mark.parametrize("payload", PAYLOADS)
def test_a_serial_arm_and_a_prismatic_track(payload, tmp_path):
    elbow = load_robot("elbow6")
    rng = np.random.default_rng(5)
    lim = np.asarray(elbow.joint_limits, dtype=float)
    q = rng.uniform(0.8 * lim[:, 0], 0.8 * lim[:, 1], (6, elbow.n_readings))
    _check(elbow, elbow.nominal_parameters(), q, payload)
    (tmp_path / "track.urdf").write_text(TRACK_ROBOT)
    track = import_urdf(tmp_path / "track.urdf").description
    lim = np.asarray(track.joint_limits, dtype=float)
    q = rng.uniform(0.8 * lim[:, 0] + 0.1, 0.8 * lim[:, 1], (6, track.n_readings))
    tau = gravity_torques(track, track.nominal_parameters(), q, payload)
    assert track.links[track.index(track.actuated[0])].is_prismatic
    assert np.all(np.abs(tau[:, 0]) > 0.01)  # the tilted track: gravity along it
    _check(track, track.nominal_parameters(), q, payload)


@pytest.mark.parametrize(("q", "says"), [
    (np.zeros(5), r"q: expected shape \(\.\.\., 6\)"),
    (np.full(6, np.nan), "q: joint values must be finite"),
])
def test_bad_joints_are_refused_with_the_reason(q, says):
    desc = load_robot("smart_h4")
    for f in (gravity_torques, potential_energy):
        with pytest.raises(ValueError, match=says):
            f(desc, desc.nominal_parameters(), q)
