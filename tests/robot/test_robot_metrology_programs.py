"""The program library through the robot service (thesis 8.2.2, 8.3.2, 9.3): issue 7.

One set of real service processes (metrology_cell.py) runs the thesis's EXAMPLE, the
calibration program of Fig. 8-4 and the compensation test of 8.3 — no restart, no
code change — then two robots share the tracker by program, one of them dies while
holding it.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from metrology_cell import MetrologyCell
from robot_cell import PNT0001, PNT0002

from plugcell.apps.reproduce.compensation_8_3 import ExperimentConfig, line_targets
from plugcell.calibration import CalibrationData, Calibrator
from plugcell.devices.robot.value_text import rows_text
from plugcell.framework import ProcessStates
from plugcell.io.units import robot_from_pose
from plugcell.sim.twin.campaign import measure_poses, working_volume_joints
from plugcell.sim.twin.robot import RobotTwin
from plugcell.sim.twin.scenario import TwinScenario
from plugcell.sim.twin.tracker import LaserTracker

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

C = ProcessStates.Completed
N_CAL, N_VAL = 60, 25
IDENTIFY = "params = calibrate(mJ, mT, model=5, payload=36); save_params(params, '{}')"


def _campaign_rows_text(ms) -> tuple[np.ndarray, np.ndarray]:
    """A campaign's measurement set as the program's mJ (deg) and mT (mm, deg ZYZ) rows."""
    return (np.rad2deg(ms.joints),
            np.hstack([ms.positions * 1e3, np.rad2deg(ms.angles)]))


def _calibrate_by_program(cell: MetrologyCell, q_cal: np.ndarray, route: bool, name: str):
    base, probe = cell.h4.estimates(np.random.default_rng(1))
    final = cell.activate(
        "H4", "calibration", f"configs={rows_text(np.rad2deg(q_cal))}", f"n_configs={len(q_cal)}",
        f"base_est={base}", f"probe_est={probe}", "duration_ms=1000",
        f"route={'TRUE' if route else 'FALSE'}", f"identify={IDENTIFY.format(name)}",
        timeout=240)
    assert final.state is C, final.reason
    return cell.status("H4")


def _line_usage(status: list[str]) -> tuple[int, int, float]:
    line = next(s for s in status if s.startswith("serial line:"))
    out, inn, secs = re.match(r"serial line: (\d+) characters out, (\d+) in, ([\d.]+) s", line
                              ).groups()
    return int(out), int(inn), float(secs)


def test_example_calibration_and_compensation_on_one_set_of_services(
        metrology_cell: MetrologyCell) -> None:
    cell = metrology_cell
    # 1. the thesis's EXAMPLE (camera and drill) on the same robot service
    final = cell.activate("H4", "example", f"pnt0001={PNT0001}", f"pnt0002={PNT0002}")
    assert final.state is C, final.reason

    # 2. the calibration program of Fig. 8-4, measurements routed straight to COMPUTE
    truth = cell.h4.twin.reveal_truth()
    desc = cell.h4.twin.description
    q_cal = working_volume_joints(desc, truth.profile, N_CAL, np.random.default_rng(11))
    q_val = working_volume_joints(desc, truth.profile, N_VAL, np.random.default_rng(12))
    routed = _calibrate_by_program(cell, q_cal, True, "h4")
    assert routed[1] == "FINISHED", routed

    # its parameters, on validation poses measured by the campaign of `plugcell twin`
    twin = RobotTwin(TwinScenario(seed=4, payload_kg=36.0))
    cal, _ = measure_poses(twin, LaserTracker(seed=99), q_cal, rotation="zyz")
    val, _ = measure_poses(twin, LaserTracker(seed=98), q_val, rotation="zyz")
    vJ, vT = _campaign_rows_text(val)
    cell.client.create_process("COMPUTE", "Set Matrix", "vJ", vJ).result()
    cell.client.create_process("COMPUTE", "Set Matrix", "vT", vT).result()
    cell.evaluate("p = load_params('h4'); v = validate(p, vJ, vT, payload=36)")
    poses, before, after = cell.matrix("v")[0][:3]
    engine = Calibrator(desc, model=5).fit(CalibrationData.from_measurements(cal),
                                           validation=CalibrationData.from_measurements(val))
    assert poses == N_VAL
    print(f"validation: {before:.3f} mm before, {after:.3f} mm after; engine "
          f"{engine.validation_before.position.norm.mean * 1e3:.3f} → "
          f"{engine.validation.position.norm.mean * 1e3:.3f} mm")
    assert before == pytest.approx(engine.validation_before.position.norm.mean * 1e3, rel=0.05)
    assert after < 0.5
    assert after == pytest.approx(engine.validation.position.norm.mean * 1e3, abs=0.05)
    # the program's data are in H4's workspace, readable by anyone as name@H4
    assert cell.matrix("mT@H4").shape == (N_CAL, 6)
    assert cell.matrix("mJ@H4").shape == (N_CAL, 6)

    # 3. the compensation test of 8.3 on the parameters the program saved
    targets = line_targets(ExperimentConfig.fast(), truth.probe).reshape(-1, 4, 4)
    vectors = np.array([robot_from_pose(T, "zyz") for T in targets])
    final = cell.activate("H4", "comp_test", f"targets={rows_text(vectors)}",
                          f"n_targets={len(vectors)}", "params_name=h4", "payload_kg=36",
                          "sensor=TRUE", "nominal=FALSE", timeout=240)
    assert final.state is C, final.reason
    status = cell.status("H4")
    assert status[1] == "FINISHED", status
    mM, mS, mI = cell.matrix("mM@H4"), cell.matrix("mS@H4"), cell.matrix("mI@H4")
    assert mM.shape == mS.shape == (len(vectors), 6) and mI.shape == (len(vectors), 1)
    model_mm = np.linalg.norm(mM[:, :3] - vectors[:, :3], axis=1)
    sensor_mm = np.linalg.norm(mS[:, :3] - vectors[:, :3], axis=1)
    assert np.all(mI >= 0), mI  # every target corrected within the tolerance
    assert model_mm.mean() < 0.6
    assert sensor_mm.max() < 0.15  # tolerance 0.08 mm + tracker noise of a 1 s check
    assert sensor_mm.mean() < model_mm.mean() / 2

    # 4. the same calibration with the data through the robot, as in the thesis: the
    # serial line to the PC carries every measurement back out to the compute service
    # (9.3); the program still gets each measurement (the requester keeps its data)
    thesis = _calibrate_by_program(cell, q_cal, False, "h4_thesis")
    out_r, in_r, s_r = _line_usage(routed)
    out_t, in_t, s_t = _line_usage(thesis)
    print(f"serial line: routed {out_r}/{in_r} characters out/in, {s_r:.2f} s; "
          f"through the robot {out_t}/{in_t}, {s_t:.2f} s")
    assert out_t > out_r + N_CAL * 60  # the pose's ACTIVATE string: > 60 characters a pose
    assert in_t > in_r  # and its answer
    assert s_t - s_r > N_CAL * 0.04  # s: > 40 ms a pose at 19.2 kbit/s
