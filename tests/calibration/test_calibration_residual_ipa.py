"""The learned residual layer on a few hundred real UR10 poses (IPA data set; skipped
where ../shared/data is absent).  The full figures: benchmarks/residual_ur10.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from calibration_testlib import ur10_description

from plugcell.calibration import CalibrationData, Calibrator
from plugcell.calibration.residual_model import ResidualLearner, hybrid_residuals
from plugcell.kinematics.rotations import angles_to_matrix

HERE = Path(__file__).resolve()
DATA = next((p / "shared" / "data" / "ipa-robot-accuracy" for p in HERE.parents
             if (p / "shared" / "data" / "ipa-robot-accuracy").is_dir()), None)
JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
          "wrist_2_joint", "wrist_3_joint")

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(DATA is None, reason="IPA data set not available")]


def _series(rel: str, step: int) -> CalibrationData:
    lines = (DATA / rel).read_text(encoding="utf-8").splitlines()  # type: ignore[operator]
    col = {h: i for i, h in enumerate(lines[0].split(";"))}
    rows = np.array([[float(x.replace(",", ".")) for x in ln.split(";")]
                     for ln in lines[1::step] if ln.strip()])
    q = rows[:, [col[c] for c in JOINTS]]
    p = rows[:, [col[f"measurement_{c}"] for c in "xyz"]] / 1e3
    a = np.radians(rows[:, [col[f"measurement_r{c}"] for c in "xyz"]])
    t = rows[:, col["measurement_temperature"]]
    return CalibrationData(q, p, angles_to_matrix(a, "xyz"), temperature_c=t)


def test_real_ur10_layer_learns_in_series_a_and_never_hurts_series_b():
    A = _series("Series_A/measurements_grid.csv", 20)       # ~600 poses
    B = _series("Series_B/measurements_joint_configurations.csv", 5)
    A = CalibrationData(A.q, A.positions, A.rotations)      # joints only
    B = CalibrationData(B.q, B.positions, B.rotations)
    res = Calibrator(ur10_description(), "serial+gravity").fit(A)
    layer = ResidualLearner(grid=({"max_leaf_nodes": 15, "min_samples_leaf": 20},),
                            trees=80).fit(res.model, A, robot="ur10")
    assert layer.useful and layer.cv.hybrid_mm < 0.8 * layer.cv.physical_mm
    r, pred = hybrid_residuals(res.model, layer, B, refit_base=True, refit_probe=True)
    # B's joint combinations lie outside A's region: the set-up's own stage is not used
    # there (only the arm-shape stage may apply, where B's shoulder and elbow are in A's)
    assert r.norms("after").mean() <= 1.02 * r.norms("before").mean()
    assert pred.local is not None and np.count_nonzero(~pred.local) > 0.5 * len(B)
