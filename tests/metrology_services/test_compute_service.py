"""The compute service (Table 7-2) as a real OS process: Set/Get/Evaluate, workspaces per
requester, calibration on twin data, and refusals that never stop it."""

from __future__ import annotations

import json

import numpy as np
import pytest
from metrology_testlib import run
from test_compute_functions import rows

from plugcell.calibration import CalibrationData, Calibrator
from plugcell.framework import Client, ProcessCall, ProcessStates
from plugcell.io.robots import load_robot
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker

pytestmark = pytest.mark.timeout(90)

C, F = ProcessStates.Completed, ProcessStates.Failed


async def call(client: Client, command: str, option: str = "", data=None):
    final = await (await client.create_process("COMPUTE", command, option, data,
                                               timeout=60)).result()
    return final, (None if final.data is None else ProcessCall.array(final))


async def ok(client: Client, command: str, option: str = "", data=None):
    final, value = await call(client, command, option, data)
    assert final.state is C, f"{command} {option}: {final.reason}"
    return value


def test_set_get_and_append_round_trip(cell):
    async def body():
        async with Client("ROBOT", cell=cell.name) as robot:
            assert await robot.wait_for("COMPUTE")
            m = np.arange(12.0).reshape(3, 4) / 7.0
            await ok(robot, "Set Matrix", "M", m)
            np.testing.assert_array_equal(await ok(robot, "Get Matrix", "M"), m)  # bit-exact
            await ok(robot, "Set Matrix", "v", [1.0, 2.0, 3.0])  # a vector is one row
            assert (await ok(robot, "Get Matrix", "v")).shape == (1, 3)
            for k in range(3):  # how the calibration program builds mT and mJ (8.2.2)
                await ok(robot, "Set Matrix", "mT:append", [k, k + 0.5, 2.0 * k])
            np.testing.assert_array_equal(await ok(robot, "Get Matrix", "mT"),
                                          [[0, 0.5, 0], [1, 1.5, 2], [2, 2.5, 4]])
            final, _ = await call(robot, "Set Matrix", "mT:append", [1.0, 2.0])
            assert final.state is F
            assert final.reason == ("Set Matrix: cannot append 2 columns to mT, which has 3")
            final, _ = await call(robot, "Get Matrix", "nothing")
            assert final.reason == ("Get Matrix: 'nothing' is not defined in the workspace of "
                                    "ROBOT")
            final, _ = await call(robot, "Set Matrix", "2bad", [1.0])
            assert "bad matrix name '2bad'" in final.reason
            final, _ = await call(robot, "Set Matrix", "cube", np.zeros((2, 2, 2)))
            assert "a matrix has 2 dimensions, got 3" in final.reason

    run(body())


def test_each_requester_has_its_own_workspace(cell):
    async def body():
        async with Client("COMAU", cell=cell.name) as a, Client("KUKA", cell=cell.name) as b:
            assert await a.wait_for("COMPUTE") and await b.wait_for("COMPUTE")
            await ok(a, "Set Matrix", "mT", [[1.0, 2.0]])
            await ok(b, "Set Matrix", "mT", [[3.0, 4.0, 5.0]])
            await ok(a, "Evaluate", "", "n = size(mT)")
            await ok(b, "Evaluate", "", "n = size(mT)")
            np.testing.assert_array_equal(await ok(a, "Get Matrix", "n"), [[1, 2]])
            np.testing.assert_array_equal(await ok(b, "Get Matrix", "n"), [[1, 3]])
            await ok(a, "Evaluate", "", "clear()")
            final, _ = await call(a, "Get Matrix", "mT")
            assert final.state is F
            np.testing.assert_array_equal(await ok(b, "Get Matrix", "mT"), [[3.0, 4.0, 5.0]])
            # name@OWNER reads another requester's workspace, and only reads it
            np.testing.assert_array_equal(await ok(a, "Get Matrix", "mT@KUKA"),
                                          [[3.0, 4.0, 5.0]])
            for ref, reason in (
                ("mT@NOBODY", "no workspace of 'NOBODY' (workspaces: "),  # all, by name
                ("nope@KUKA", "nope"),
                ("1x@KUKA", "bad matrix name '1x'"),
            ):
                final, _ = await call(a, "Get Matrix", ref)
                assert final.state is F and reason in final.reason, final.reason
                if "NOBODY" in ref:
                    assert "COMAU" in final.reason and "KUKA" in final.reason
            final, _ = await call(a, "Set Matrix", "mT@KUKA", [[0.0]])
            assert final.state is F and "bad matrix name" in final.reason
            np.testing.assert_array_equal(await ok(b, "Get Matrix", "mT"), [[3.0, 4.0, 5.0]])

    run(body())


ATTEMPTS = [
    ("__import__('os').system('touch {marker}')",
     "Evaluate: column 1: names may not begin with '_' ('__import__')"),
    ("os.system('ls')", "Evaluate: column 3: attribute access ('os.') is not allowed"),
    ("x = mT.__class__", "Evaluate: column 7: attribute access ('mT.') is not allowed"),
    ("eval(\"__import__('os')\")", "Evaluate: column 1: unknown function 'eval' (functions: "),
    ("exec('import os')", "Evaluate: column 1: unknown function 'exec'"),
    ("open('/etc/passwd')", "Evaluate: column 1: unknown function 'open'"),
    ("system('ls')", "Evaluate: column 1: unknown function 'system'"),
    ("load_params('../../../etc/passwd')",
     "Evaluate: column 1: load_params(): invalid parameter set name"),
    ("calibrate(mT, mT, robot='/etc/passwd')", "robot '/etc/passwd' unknown"),
    ("mT(1)", "Evaluate: column 1: 'mT' is a workspace value, not a function"),
    ("x = mT + 1", "Evaluate: column 8: operator '+' is not part of Evaluate expressions"),
    ("import os", "Evaluate: column 8: expected ';' or the end, found 'os'"),
    ("x = `ls`", "Evaluate: column 5: operator '`'"),
]


@pytest.mark.parametrize(("text", "reason"), ATTEMPTS)
def test_code_execution_attempts_are_refused_and_the_service_keeps_running(cell, text, reason,
                                                                         tmp_path):
    marker = tmp_path / "pwned"
    text = text.replace("{marker}", str(marker))

    async def body():
        async with Client("MALLORY", cell=cell.name) as robot:
            assert await robot.wait_for("COMPUTE")
            await ok(robot, "Set Matrix", "mT", [[1.0, 2.0, 3.0]])
            final, _ = await call(robot, "Evaluate", "", text)
            assert final.state is F
            assert final.reason.startswith(reason) or reason in final.reason, final.reason
            # still serving, workspace intact
            await ok(robot, "Evaluate", "", "n = size(mT)")
            np.testing.assert_array_equal(await ok(robot, "Get Matrix", "n"), [[1, 3]])

    run(body())
    assert not marker.exists()


def test_the_calibration_functions_in_the_service_match_the_engine(cell):
    """Thesis 8.2.2: mJ and mT in the workspace, then H4Calibration — here calibrate()."""
    robot_twin = RobotTwin(TwinScenario(seed=2))
    tracker = LaserTracker(seed=2)
    profile = robot_twin.reveal_truth().profile
    q = working_volume_joints(robot_twin.description, profile, 50, np.random.default_rng(3))
    qv = working_volume_joints(robot_twin.description, profile, 20, np.random.default_rng(4))
    cal, _ = measure_poses(robot_twin, tracker, q, rotation="zyz")
    val, _ = measure_poses(robot_twin, tracker, qv, rotation="zyz")
    direct = Calibrator(load_robot("smart_h4"), model=4).fit(
        CalibrationData.from_measurements(cal), validation=CalibrationData.from_measurements(val))

    async def body():
        async with Client("H4", cell=cell.name) as robot:
            assert await robot.wait_for("COMPUTE")
            mJ, mT = rows(cal)
            vJ, vT = rows(val)
            for name, value in (("mJ", mJ), ("mT", mT), ("vJ", vJ), ("vT", vT)):
                await ok(robot, "Set Matrix", name, value)
            await ok(robot, "Evaluate", "",
                     "params = calibrate(mJ, mT, model=4)\n"
                     "v = validate(params, vJ, vT); save_params(params, 'h4_unloaded')\n"
                     "base = frame(params, 'base'); probe = frame(params, 'probe')")
            v = (await ok(robot, "Get Matrix", "v"))[0]
            assert v[0] == 20
            assert v[2] == pytest.approx(direct.validation.position.norm.mean * 1e3, rel=1e-9)
            assert v[1] == pytest.approx(direct.validation_before.position.norm.mean * 1e3,
                                         rel=1e-9)
            final, _ = await call(robot, "Get Matrix", "params")
            assert final.reason == "Get Matrix: params is identified parameters, not a matrix"
            assert (await ok(robot, "Get Matrix", "base")).shape == (1, 6)
            # INITIALIZE of 8.3.2 in another program run: LoadParams
            await ok(robot, "Evaluate", "", "clear(); p = load_params('h4_unloaded')")
            final, _ = await call(robot, "Evaluate", "", "w = validate(p, vJ, vT)")
            assert final.reason == "Evaluate: column 17: 'vJ' is not defined in the workspace"
            await ok(robot, "Set Matrix", "vJ", vJ)
            await ok(robot, "Set Matrix", "vT", vT)
            await ok(robot, "Evaluate", "", "w = validate(p, vJ, vT)")
            np.testing.assert_allclose(await ok(robot, "Get Matrix", "w"), [v], rtol=1e-12)
            # a compensation target outside the calibrated region: Completed, with a note
            # two poses well inside the calibrated joint ranges (compensation moves a
            # joint by up to ~0.1°: a pose at a range's edge may step beyond it)
            k = np.argsort(np.abs((mJ - np.median(mJ, axis=0)) / np.ptp(mJ, axis=0)).max(1))[:2]
            far = mJ[k].copy()
            far[1, 0] = mJ[:, 0].max() + 25.0
            await ok(robot, "Set Matrix", "far", far)
            await ok(robot, "Set Matrix", "near", mJ[k])
            final, _ = await call(robot, "Evaluate", "", "qc = compensate_joints(p, far)")
            assert final.state is C
            assert "1 of 2 targets outside the calibrated region" in final.reason
            final, _ = await call(robot, "Evaluate", "", "qn = compensate_joints(p, near)")
            assert (final.state, final.reason) == (C, "")

    run(body())
    saved = json.loads((cell.home / "compute" / "params" / "h4_unloaded.json").read_text())
    assert saved["robot"] == "smart_h4" and saved["model"]["number"] == 4
