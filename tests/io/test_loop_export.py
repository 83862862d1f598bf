"""Issue 39, defect 2: the calibrated Smart H4 leaves plugcell.

The README's path — ``plugcell twin measure`` + ``plugcell calibrate --robot smart_h4
--model 5`` (a small campaign) — then ``plugcell export`` in every format:

* ``toml`` loads back to a robot whose FK *is* the calibrated geometric model
  (1e-9 m / rad over random configurations within the limits);
* ``urdf`` is the closest tree: its independent joints are the readings (mimic joints
  for the rest), yourdfpy's FK of the file is the fitted tree to 1e-9 m, the error it
  reports is its error on the configurations it names, and fresh configurations stay
  near it; for the nominal parallelogram the tree and its mimic joints are exact;
* ``ur-kinematics`` is refused, and every format an error recommends then works.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from yourdfpy_fk import yourdfpy_tip_poses

from plugcell.apps.cli import main
from plugcell.apps.commands.files import read_calibration
from plugcell.calibration import CalibrationData, Calibrator
from plugcell.calibration.planning import sample_candidates
from plugcell.io.export import export_calibration
from plugcell.io.robots import load_robot
from plugcell.kinematics import forward
from plugcell.kinematics.pose_error import rotation_error
from plugcell.kinematics.transforms import dh_hayati


def _loop_model(res, q: np.ndarray) -> np.ndarray:
    """The calibrated geometric model ``BASE · T_n^0(q; g) · PROBE`` (eq. 6.23, no Δθ)."""
    m = res.model
    fk = forward(m.structure.desc, m.geometric_parameters(), q, closure="fourbar")
    return m.base() @ fk.flange @ m.probe()


def _dp(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    return np.linalg.norm(A[:, :3, 3] - B[:, :3, 3], axis=1)


@pytest.fixture(scope="module")
def h4(tmp_path_factory: pytest.TempPathFactory):
    """PARAMS.json of the README's model-5 calibration, on a 40-pose twin campaign."""
    d = tmp_path_factory.mktemp("h4")
    cal, params = d / "cal.csv", d / "params.json"
    assert main(["twin", "measure", "--poses", "40", "--payload-kg", "36", "--out", str(cal),
                 "--quiet"]) == 0
    assert main(["calibrate", "--robot", "smart_h4", "--model", "5", "--data", str(cal),
                 "--out", str(params), "--quiet"]) == 0
    _, res = read_calibration(params)
    assert res.config.number == 5 and res.model.structure.family == "loop"
    return d, params, res


def _q(desc, n: int, seed: int) -> np.ndarray:
    lim = desc.joint_limits
    q = np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], size=(n, desc.n_actuated))
    return q[desc.within_limits(q)]


def test_model5_toml_export_is_the_calibrated_loop(h4, capsys) -> None:
    d, params, res = h4
    out = d / "h4_calibrated.toml"
    assert main(["export", "--params", str(params), "--format", "toml", "--out",
                 str(out)]) == 0
    printed = capsys.readouterr().out
    back = load_robot(out)
    assert [lp.kind for lp in back.loops] == ["fourbar"]
    q = _q(back, 3000, 7)
    got = forward(back, None, q).world_tcp
    ref = _loop_model(res, q)
    assert len(q) > 1000
    assert _dp(got, ref).max() < 1e-9 and rotation_error(got, ref).max() < 1e-9
    # every identified parameter of the loop is in the file (not the nominal numbers)
    nominal = load_robot("smart_h4").nominal_parameters()
    gp, bp = res.model.geometric_parameters(), back.nominal_parameters()
    for key in ("a2", "a2'", "alpha2'", "beta2'", "a3'", "alpha3'", "beta3'", "theta2'"):
        field = re.match(r"[a-z]+", key).group(0)
        link = key[len(field):]
        i = gp.index(link)
        assert getattr(bp, field)[i] == pytest.approx(getattr(gp, field)[i], abs=1e-15)
        assert getattr(bp, field)[i] != getattr(nominal, field)[i], key
    # what TOML cannot carry is named, with its values: the compliance of model 5
    side = json.loads((d / "h4_calibrated.toml.extra.json").read_text())
    keys = {c["key"] for c in side["compliance"]}
    assert {"G1", "A4"} <= keys and set(res.model.compliance_keys) == keys
    assert "compliance/payload terms" in printed and "extra.json" in printed


@pytest.mark.slow
def test_model5_urdf_export_is_the_closest_tree_with_its_error(h4, capsys) -> None:
    d, params, res = h4
    out = d / "h4_calibrated.urdf"
    assert main(["export", "--params", str(params), "--format", "urdf", "--include-base",
                 "--include-probe", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    text = out.read_text()
    worst = re.findall(r"error of this tree vs the calibrated loop: worst ([0-9.]+) mm / "
                       r"([0-9.]+)° \(mean [0-9.]+ mm / [0-9.]+°\) over 2000 configurations in "
                       r"the (working volume|joint limits)", text)
    assert [w[2] for w in worst] == ["working volume", "joint limits"]
    assert printed.count("the tree's error vs the calibrated loop: worst") == 2
    desc = res.model.structure.source
    # the same fit as the export's (seeded): the file's FK is the fitted tree exactly
    from plugcell.calibration.tree import closest_serial_tree

    tree = closest_serial_tree(res.model)
    check = sample_candidates(res.model, 2000, seed=2).q  # the joint-limits check set
    urdf = yourdfpy_tip_poses(text, desc.reading_names, "probe", check,
                              root="measurement")
    assert np.abs(urdf - tree.result.model.predict(check)).max() < 1e-9
    # the reported worst error is the file's error on those configurations
    err = _dp(urdf, _loop_model(res, check))
    assert err.max() * 1e3 == pytest.approx(float(worst[1][0]), abs=5e-4)
    assert np.degrees(rotation_error(urdf, _loop_model(res, check)).max()) == pytest.approx(
        float(worst[1][1]), abs=5e-5)
    # fresh configurations of the working volume stay within the reported figure's reach
    fresh = sample_candidates(res.model, 300, volume=desc.working_volume, seed=99).q
    e = _dp(yourdfpy_tip_poses(text, desc.reading_names, "probe", fresh, root="measurement"),
            _loop_model(res, fresh))
    assert e.max() * 1e3 <= 1.25 * float(worst[0][0])
    # plugcell reads the file back (the cut joint's mimic becomes a joint coupling) with
    # the robot's readings, the same FK
    from plugcell.io.urdf import import_urdf

    again = import_urdf(out, base_link="measurement", tip_link="probe").description
    assert again.reading_names == desc.reading_names
    assert np.abs(forward(again, None, fresh[:50]).world_tcp
                  - yourdfpy_tip_poses(text, desc.reading_names, "probe", fresh[:50],
                                       root="measurement")).max() < 1e-9
    # the tree is worth having: well below the nominal robot's error
    nominal_err = _dp(res.model.base() @ forward(desc, None, fresh).flange @ res.model.probe(),
                      _loop_model(res, fresh))
    assert e.mean() < 0.5 * nominal_err.mean()


@pytest.mark.slow
def test_the_nominal_parallelogram_tree_and_its_mimics_are_exact() -> None:
    """A calibration that found no error: the tree is exact, and the crank, coupler and
    follower (mimic joints) close the parallelogram at the cut joint."""
    desc = load_robot("smart_h4")
    base = np.eye(4)
    base[:3, 3] = [3.0, 0.5, -0.2]
    probe = np.eye(4)
    probe[:3, 3] = [0.05, 0.0, 0.12]
    q = _q(desc, 400, 1)[:80]
    poses = base @ forward(desc, None, q).flange @ probe
    res = Calibrator(desc, "loop").fit(CalibrationData.from_poses(q, poses))
    out = export_calibration(res, desc, "urdf", include_base=True, include_probe=True)
    worst = [float(x) for x in re.findall(r"worst ([0-9.]+) mm", " ".join(out.notes))]
    assert len(worst) == 2 and max(worst) < 1e-6
    qc = _q(desc, 200, 4)
    got = yourdfpy_tip_poses(out.text, desc.reading_names, "probe", qc, root="measurement")
    assert _dp(got, _loop_model(res, qc)).max() < 1e-8
    nom = desc.nominal_parameters()
    i = nom.index("4'")
    M4 = dh_hayati(0.0, nom.d[i], nom.a[i], nom.alpha[i], nom.beta[i])
    follower_end = yourdfpy_tip_poses(out.text, desc.reading_names, "link_4'", qc) @ M4
    cut = yourdfpy_tip_poses(out.text, desc.reading_names, "link_3_cut", qc)
    assert _dp(follower_end, cut).max() < 1e-8
    # the follower is parallel to the crank, reversed (eq. 6.10): its x axis is −x_crank
    crank = yourdfpy_tip_poses(out.text, desc.reading_names, "link_2'", qc)
    assert np.abs(follower_end[:, :3, 0] + crank[:, :3, 0]).max() < 1e-9


@pytest.mark.slow
def test_every_format_of_a_loop_robot_and_no_error_recommends_a_refused_one(
        h4, capsys) -> None:
    d, params, _ = h4
    codes = {}
    for fmt in ("toml", "urdf", "ur-kinematics"):
        codes[fmt] = main(["export", "--params", str(params), "--format", fmt, "--out",
                           str(d / f"all.{fmt}")])
    assert codes == {"toml": 0, "urdf": 0, "ur-kinematics": 2}
    err = capsys.readouterr().err
    assert "cannot export as ur-kinematics" in err and "has a closed loop" in err
    recommended = set(re.findall(r"--format ([a-z-]+)", err))
    assert recommended == {"urdf", "toml"}
    assert all(codes[f] == 0 for f in recommended)
    # --serial-equivalent on a loop calibration: refused, naming what works
    assert main(["export", "--params", str(params), "--format", "urdf", "--serial-equivalent",
                 "--out", str(d / "se.urdf")]) == 2
    err = capsys.readouterr().err
    assert "without --serial-equivalent" in err
    assert all(codes[f] == 0 for f in re.findall(r"--format ([a-z-]+)", err))
