"""The learned residual layer (hybrid model): grouped CV, in-domain fallback, base-frame
transfer, the skops side file, the CLI and the bad inputs of issue 19."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from calibration_testlib import harmonic_campaign, random_frame, ur10_toml

from plugcell.apps.cli import main
from plugcell.calibration import CalibrationData, Calibrator
from plugcell.calibration.residual_model import (
    MIN_POSES,
    ResidualLearner,
    ResidualModelError,
    hybrid_poses,
    hybrid_residuals,
    workspace_cells,
)
from plugcell.compensation import IdentifiedModel
from plugcell.io.measurements import (
    MeasurementFileError,
    MeasurementSet,
    parse_measurements,
    write_measurements,
)
from plugcell.io.residual_models import (
    ResidualFileError,
    load_residual,
    residual_path,
    save_residual,
)
from plugcell.kinematics.rotations import matrix_to_angles
from plugcell.kinematics.transforms import so3_exp

SMALL = ({"max_leaf_nodes": 15, "min_samples_leaf": 20},)


@pytest.fixture(scope="module")
def fitted():
    desc, cal = harmonic_campaign(400, seed=1)
    res = Calibrator(desc, "serial").fit(cal)
    layer = ResidualLearner(grid=SMALL, trees=60).fit(res.model, cal, robot=desc.name)
    return desc, cal, res, layer


def test_workspace_cells_group_contiguous_cubes():
    p = np.array([[0.05, 0.05, 0.05], [0.35, 0.1, 0.0], [0.45, 0.1, 0.0], [0.0, 0.0, 0.0],
                  [-0.8, 0.0, 0.0]])
    g = workspace_cells(p, 0.4)  # anchored at the lower corner (-0.8, 0, 0)
    assert g[0] == g[1] == g[3] and len({g[0], g[2], g[4]}) == 3


def test_layer_learns_what_the_physical_model_cannot(fitted):
    _desc, _cal, res, layer = fitted
    assert layer.useful and layer.cv.cells >= 5
    # held-out cells: the transmission error is learned, not memorised
    assert layer.cv.hybrid_mm < 0.6 * layer.cv.physical_mm
    _, val = harmonic_campaign(200, seed=2)
    r, pred = hybrid_residuals(res.model, layer, val)
    assert pred.in_domain.mean() > 0.9
    assert r.norms("after").mean() < 0.6 * r.norms("before").mean()
    assert r.accuracy("after").orientation.norm.mean < r.accuracy("before").orientation.norm.mean


def test_residuals_are_in_the_base_frame_so_they_transfer(fitted):
    """Validation measured with the tracker elsewhere: BASE + PROBE re-identified, the
    layer keeps its gain (it lives in the robot base frame)."""
    _desc, _cal, res, layer = fitted
    moved = random_frame(np.random.default_rng(5), angle=1.0, dist=2.0)
    _, val = harmonic_campaign(200, seed=3, base=moved)
    r, _pred = hybrid_residuals(res.model, layer, val, refit_base=True, refit_probe=True)
    assert r.norms("after").mean() < 0.6 * r.norms("before").mean()


def test_outside_the_trained_region_it_falls_back_to_the_physical_model(fitted):
    _desc, cal, res, layer = fitted
    q = cal.q[:20].copy()
    q[:, 1] += 2.5          # shoulder far outside the calibration range
    pred = layer.predict(q)
    assert pred.fallback_count == 20 and np.all(pred.correction == 0)
    P = res.model.predict(q)
    Ph, inside = res.with_residual_model(layer).predict_hybrid(q)
    assert not inside.any() and np.array_equal(P, Ph)


def test_hybrid_pose_and_compensation_model_agree(fitted):
    """IdentifiedModel with the layer (robot base frame, tool = PROBE) gives the same
    poses as the hybrid prediction in the tracker frame; the Jacobian is the physical one."""
    _desc, cal, res, layer = fitted
    hyb = res.with_residual_model(layer)
    q = cal.q[:10]
    P, inside = hyb.predict_hybrid(q)
    assert inside.all()
    im = IdentifiedModel(res.model, residual=layer)
    T, J = im.evaluate(q)
    Tm = im.base @ T  # tool = probe: the measured point
    np.testing.assert_allclose(Tm, P, atol=1e-12)
    np.testing.assert_array_equal(J, IdentifiedModel(res.model).evaluate(q)[1])
    # a tool elsewhere moves rigidly with the probe correction
    tool = res.model.probe().copy()
    tool[:3, 3] += [0.0, 0.0, 0.1]
    T2 = IdentifiedModel(res.model, tool, residual=layer).evaluate(q)[0]
    T0 = IdentifiedModel(res.model, tool).evaluate(q)[0]
    c = layer.predict(q).correction
    p_probe = IdentifiedModel(res.model).evaluate(q)[0][:, :3, 3]  # physical PROBE point
    R = so3_exp(c[:, 3:])
    expect = np.einsum("nij,nj->ni", R, T0[:, :3, 3] - p_probe) + p_probe + c[:, :3]
    np.testing.assert_allclose(T2[:, :3, 3], expect, atol=1e-12)
    np.testing.assert_allclose(T2[:, :3, :3], R @ T0[:, :3, :3], atol=1e-12)
    G = IdentifiedModel(res.model, tool, residual=layer).correction(q)
    np.testing.assert_allclose(G @ T0, T2, atol=1e-12)


def test_hybrid_compensation_reaches_the_hybrid_target(fitted):
    """compensate_joints on the hybrid model: the hybrid pose of the result is the
    target (outer fixed point on the correction), the physical pose is not."""
    from plugcell.compensation.model_based import compensate_joints

    _desc, cal, res, layer = fitted
    hyb = IdentifiedModel(res.model, residual=layer)
    phys = IdentifiedModel(res.model)
    q0 = cal.q[:40]
    T = phys.evaluate(q0 + 2e-3)[0]           # targets near the poses of the data
    out = compensate_joints(hyb, T, q0, raise_errors=False)
    assert out.hybrid_fallback is not None
    ok = ~out.hybrid_fallback
    assert out.converged.all() and ok.sum() >= 35
    Th = hyb.evaluate(out.q[ok])[0]
    np.testing.assert_allclose(Th[:, :3, 3], T[ok, :3, 3], atol=2e-6)
    moved = np.linalg.norm(phys.evaluate(out.q[ok])[0][:, :3, 3] - T[ok, :3, 3], axis=1)
    assert np.median(moved) > 10e-6            # the learned correction was compensated


def test_hybrid_poses_applies_a_base_frame_correction():
    rng = np.random.default_rng(0)
    B = random_frame(rng)
    T = np.stack([random_frame(rng) for _ in range(4)])
    c = rng.normal(scale=1e-4, size=(4, 6))
    H = hybrid_poses(T, B[:3, :3], c)
    np.testing.assert_allclose(B[:3, :3].T @ (H[:, :3, 3] - T[:, :3, 3]).T, c[:, :3].T,
                               atol=1e-15)
    for k in range(4):
        assert np.allclose(H[k, :3, :3] @ H[k, :3, :3].T, np.eye(3), atol=1e-12)


def test_too_few_poses_are_refused_with_the_number_needed(fitted):
    _desc, cal, res, _ = fitted
    with pytest.raises(ResidualModelError, match=f"too few poses .*: 150, at least {MIN_POSES}"):
        ResidualLearner(grid=SMALL).fit(res.model, cal.subset(slice(0, 150)))
    with pytest.raises(ResidualModelError, match="workspace cell"):
        ResidualLearner(grid=SMALL, trees=10, cell_size_m=50.0).fit(res.model, cal)


def test_temperature_column_with_missing_values_is_refused():
    text = "j1,j2,x,y,z,temperature_c\n0,0,1,2,3,20.5\n0,1,1,2,3,\n"
    with pytest.raises(MeasurementFileError, match="line 3, column 'temperature_c': missing"):
        parse_measurements(text, name="t.csv")
    ok = parse_measurements("j1,j2,x,y,z,temperature_c\n0,0,1,2,3,20.5\n", name="t.csv")
    assert ok.temperature_c is not None and ok.temperature_c[0] == 20.5
    with pytest.raises(ValueError, match=r"temperature_c: 1 missing .* pose 2"):
        CalibrationData(np.zeros((2, 6)), np.zeros((2, 3)), temperature_c=[20.0, np.nan])


def test_temperature_is_a_feature_when_the_data_have_it(fitted):
    _desc, cal, res, _ = fitted
    t = 20.0 + np.linspace(0, 1, len(cal))
    cal_t = CalibrationData(cal.q, cal.positions, cal.rotations, cal.payload_kg, t)
    layer = ResidualLearner(grid=SMALL, trees=20, orientation=False).fit(res.model, cal_t)
    assert layer.uses_temperature and "temperature / 2 K" in layer.summary()["features"]
    with pytest.raises(ResidualModelError, match="uses the temperature"):
        layer.predict(cal.q[:3])
    assert layer.predict(cal.q[:3], temperature_c=20.5).correction.shape == (3, 6)


def test_side_file_round_trip_and_refusals(fitted, tmp_path):
    desc, cal, res, layer = fitted
    params = tmp_path / "p.json"
    entry = save_residual(layer, residual_path(params))
    assert residual_path(params).name == "p.residual.skops"
    back = load_residual(entry, params, robot=desc.name, model=res.model)
    q = cal.q[:50]
    np.testing.assert_array_equal(back.predict(q).correction, layer.predict(q).correction)
    # a residual model from another robot
    with pytest.raises(ResidualFileError, match="robot 'ur10-test', the calibration is of 'h4'"):
        load_residual(entry, params, robot="h4", model=res.model)
    # on top of another calibration of the same robot
    other = Calibrator(desc, "serial").fit(cal.subset(slice(0, 300))).model
    with pytest.raises(ResidualFileError, match="another calibration"):
        load_residual(entry, params, robot=desc.name, model=other)
    # a file that is not the one PARAMS.json recorded
    with pytest.raises(ResidualFileError, match="SHA-256 differs"):
        load_residual({**entry, "sha256": "0" * 64}, params, robot=desc.name, model=res.model)
    with pytest.raises(ResidualFileError, match="cannot read"):
        load_residual({**entry, "file": "gone.skops"}, params, robot=desc.name, model=res.model)


def _write_set(path: Path, d: CalibrationData) -> None:
    write_measurements(path, MeasurementSet(d.q, d.positions,
                                            matrix_to_angles(d.rotations, "rpy"), "rpy"))


@pytest.mark.slow
def test_cli_calibrate_and_compensate_with_the_learned_layer(tmp_path, capsys):
    _, cal = harmonic_campaign(300, seed=1)
    _, val = harmonic_campaign(150, seed=2)
    (tmp_path / "ur10.toml").write_text(ur10_toml())
    _write_set(tmp_path / "cal.csv", cal)
    _write_set(tmp_path / "val.csv", val)
    out = tmp_path / "params.json"
    rc = main(["calibrate", "--robot", str(tmp_path / "ur10.toml"), "--model", "serial",
               "--data", str(tmp_path / "cal.csv"), "--validate", str(tmp_path / "val.csv"),
               "--residual-model", "learned", "--residual-trees", "40", "--out", str(out),
               "--report", str(tmp_path / "r.html"), "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "residual model: grouped 5-fold CV" in text and "hybrid" in text
    d = json.loads(out.read_text())
    hv = d["validation_hybrid"]
    assert hv["hybrid"]["mean_mm"] < hv["physical"]["mean_mm"]
    assert (tmp_path / d["residual_model"]["file"]).is_file()
    html = (tmp_path / "r.html").read_text()
    assert "Learned residual layer" in html and "validation, hybrid" in html
    # the arm-shape stage is shown in the summary and the report exactly when it was kept
    shape = d["residual_model"]["shape_stage"]
    assert ("arm-shape stage (joint-1 frame, sin/cos q2, sin/cos q3)" in text) == bool(shape)
    assert ("arm-shape stage (joint-1 frame, sin/cos of q2, q3)" in html) == bool(shape)
    # compensate: targets in the robot base frame (mm, deg, zyz)
    T = np.linalg.inv(np.array(d["base"]["matrix"])) @ cal.poses[:5]
    ang = np.degrees(matrix_to_angles(T[:, :3, :3], "zyz"))
    rows = ["x,y,z,rx,ry,rz"] + [",".join(f"{v:.6f}" for v in (*T[k, :3, 3] * 1e3, *ang[k]))
                                 for k in range(5)]
    (tmp_path / "targets.csv").write_text("\n".join(rows) + "\n")
    args = ["compensate", "--params", str(out), "--targets", str(tmp_path / "targets.csv"),
            "--robot", str(tmp_path / "ur10.toml")]
    assert main([*args, "--out", str(tmp_path / "hyb.csv")]) == 0
    # the IK may choose another branch (wrist flip) than the measured poses: those
    # targets lie outside the trained region and fall back to the physical model
    m = re.search(r"learned residual \((\d) in its trained region, (\d) physical only\)",
                  capsys.readouterr().out)
    assert m and int(m[1]) >= 1 and int(m[1]) + int(m[2]) == 5
    assert main([*args, "--physical-only", "--out", str(tmp_path / "phys.csv")]) == 0
    capsys.readouterr()

    def joints(p: Path) -> np.ndarray:
        lines = [ln for ln in p.read_text().splitlines() if not ln.startswith("#")][1:]
        return np.array([[float(x) for x in ln.split(",")[1:7]] for ln in lines])

    dq = np.abs(joints(tmp_path / "hyb.csv") - joints(tmp_path / "phys.csv"))
    assert 1e-5 < dq.max() < 0.1  # degrees: the learned correction, small
    # a side file that does not belong: clear error, exit 2
    other = tmp_path / "other.json"
    d2 = dict(d)
    d2["robot"] = str(tmp_path / "ur10.toml")
    other.write_text(json.dumps(d2))
    (tmp_path / "other.residual.skops").write_bytes((tmp_path / d["residual_model"]["file"])
                                                   .read_bytes())
    d2["residual_model"] = {**d["residual_model"], "file": "other.residual.skops"}
    other.write_text(json.dumps(d2))
    assert main(["compensate", "--params", str(other), "--targets",
                 str(tmp_path / "targets.csv"), "--out", str(tmp_path / "x.csv")]) == 2
    assert "residual model of robot 'ur10-test'" in capsys.readouterr().err


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="one core: every pool has one thread")
def test_fit_uses_n_threads_even_as_the_first_fit_of_a_process():
    """threadpoolctl limits only the pools loaded when its limit is entered: a first fit
    in a fresh interpreter must still run scikit-learn's OpenMP on ``n_threads``."""
    code = """
import numpy as np
from threadpoolctl import threadpool_info
from calibration_testlib import harmonic_campaign
from plugcell.calibration import Calibrator
from plugcell.calibration.residual_model import ResidualLearner

seen = []
class Spy(ResidualLearner):
    def _regressor(self, params):
        seen.extend(p["num_threads"] for p in threadpool_info() if p["user_api"] == "openmp")
        return super()._regressor(params)

desc, cal = harmonic_campaign(300, seed=2)
res = Calibrator(desc, "serial").fit(cal)
Spy(grid=({"max_leaf_nodes": 7, "min_samples_leaf": 20},), trees=5,
    shape_joints=()).fit(res.model, cal, robot=desc.name)
print(sorted(set(seen)))
"""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(Path(__file__).parent), *sys.path])}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "[1]", done.stdout


@pytest.mark.slow
def test_cli_calibrate_on_a_prior_arm_shape_stage_and_its_refusals(tmp_path, capsys):
    _, cal_a = harmonic_campaign(300, seed=1)
    _, cal_b = harmonic_campaign(200, seed=3)
    (tmp_path / "ur10.toml").write_text(ur10_toml())
    _write_set(tmp_path / "a.csv", cal_a)
    _write_set(tmp_path / "b.csv", cal_b)
    common = ["calibrate", "--robot", str(tmp_path / "ur10.toml"), "--model", "serial",
              "--residual-trees", "40", "--quiet"]
    on_b = [*common, "--data", str(tmp_path / "b.csv"), "--out", str(tmp_path / "b.json")]
    assert main([*common, "--data", str(tmp_path / "a.csv"),
                 "--out", str(tmp_path / "plain.json")]) == 0
    capsys.readouterr()
    # a calibration without a learned layer is no prior; the prior needs a layer here too
    assert main([*on_b, "--residual-model", "learned",
                 "--residual-prior", str(tmp_path / "plain.json")]) == 2
    assert "has no learned residual layer" in capsys.readouterr().err
    assert main([*on_b, "--residual-prior", str(tmp_path / "plain.json")]) == 2
    assert "--residual-prior needs --residual-model learned" in capsys.readouterr().err
    assert main([*common, "--data", str(tmp_path / "a.csv"), "--residual-model", "learned",
                 "--out", str(tmp_path / "a.json")]) == 0
    capsys.readouterr()
    assert main([*on_b, "--residual-model", "learned",
                 "--residual-prior", str(tmp_path / "a.json")]) == 0
    assert "on top of a prior arm-shape stage (sin/cos q2, sin/cos q3" in capsys.readouterr().out
    a, b = (json.loads((tmp_path / f"{k}.json").read_text())["residual_model"] for k in "ab")
    assert b["prior_stage"] == a["shape_stage"] and b["prior_stage"]["joints"] == [2, 3]
    # a prior calibrated on another robot is refused with the reason
    (tmp_path / "other.toml").write_text(ur10_toml().replace('"ur10-test"', '"ur10-other"'))
    other = [*on_b, "--residual-model", "learned", "--residual-prior", str(tmp_path / "a.json")]
    other[other.index("--robot") + 1] = str(tmp_path / "other.toml")
    assert main(other) == 2
    err = capsys.readouterr().err
    assert "a.json" in err and "ur10-test" in err and "ur10-other" in err, err


def test_cli_refuses_too_few_poses_for_the_layer_before_identifying(tmp_path, capsys):
    """Issue 39 §8: the pose count is checked first, not after the whole identification."""
    _, cal = harmonic_campaign(150, seed=1)
    (tmp_path / "ur10.toml").write_text(ur10_toml())
    _write_set(tmp_path / "cal.csv", cal)
    out = tmp_path / "params.json"
    rc = main(["calibrate", "--robot", str(tmp_path / "ur10.toml"), "--model", "serial",
               "--data", str(tmp_path / "cal.csv"), "--residual-model", "learned",
               "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2
    assert (f"--residual-model learned: too few poses to learn the residual from: 150, at least "
            f"{MIN_POSES}") in err, err
    assert "initial BASE/PROBE" not in err  # the identification never started
    assert not out.exists()
