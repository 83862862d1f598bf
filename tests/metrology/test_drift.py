"""The drift watch (issue 19 §3): BASE re-registered from re-measured nests, the nest
file parser (property-tested) and ``plugcell drift register/check``."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.apps.cli import main
from plugcell.calibration import CalibrationData, Calibrator, ErrorModel
from plugcell.calibration.identifiability import random_configurations
from plugcell.io.nests import NestFileError, format_nests, parse_nests
from plugcell.io.params import params_json
from plugcell.io.robots import load_robot
from plugcell.kinematics.transforms import so3_exp
from plugcell.metrology import MetrologyError
from plugcell.metrology.drift import estimate_base_drift, likely_mix_up, nests_in_base

NESTS = np.array([[1.2, -0.8, 0.0], [1.9, 0.7, 0.02], [0.4, 1.5, -0.01], [-0.6, -1.4, 0.3]])


def _frame(rng: np.random.Generator, angle: float, dist: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = so3_exp(rng.normal(size=3) * angle)
    T[:3, 3] = rng.normal(size=3) * dist
    return T


def test_recovers_a_6dof_drift_and_alarms_above_the_threshold():
    rng = np.random.default_rng(1)
    B = _frame(rng, 1.0, 3.0)
    D = _frame(rng, 2e-5, 40e-6)                 # 20 µrad, 40 µm: a warming hall
    measured_then = NESTS @ B[:3, :3].T + B[:3, 3]
    nests = nests_in_base(B, measured_then)
    np.testing.assert_allclose(nests, NESTS, atol=1e-12)
    B_now = D @ B
    est = estimate_base_drift(B, nests, NESTS @ B_now[:3, :3].T + B_now[:3, 3],
                              threshold_m=20e-6)
    np.testing.assert_allclose(est.base, B_now, atol=1e-12)
    np.testing.assert_allclose(est.drift, D, atol=1e-12)
    moved = np.linalg.norm(NESTS @ (B_now - B)[:3, :3].T + (B_now - B)[:3, 3], axis=1).max()
    assert est.displacement_m == pytest.approx(moved) and est.alarm and est.consistent
    quiet = estimate_base_drift(B, nests, measured_then, threshold_m=20e-6)
    assert not quiet.alarm and quiet.displacement_m < 1e-12


def test_a_moved_nest_breaks_the_fit_and_bad_input_is_named():
    B = np.eye(4)
    m = NESTS.copy()
    m[2] += [0.0, 0.0, 0.5e-3]
    est = estimate_base_drift(B, NESTS, m, fit_tolerance_m=50e-6)
    assert not est.consistent
    with pytest.raises(MetrologyError, match="4 registered nests but 3 measured"):
        estimate_base_drift(B, NESTS, NESTS[:3])
    with pytest.raises(MetrologyError, match="collinear"):
        line = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]])
        estimate_base_drift(B, line, line)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-5e3, 5e3), st.floats(-5e3, 5e3), st.floats(-5e3, 5e3)),
                min_size=3, max_size=8))
def test_nest_file_round_trip(points):
    p = np.array(points) / 1e3
    names = [f"N{i}" for i in range(len(p))]
    n2, p2 = parse_nests(format_nests(names, p))
    assert n2 == names
    np.testing.assert_allclose(p2, p, atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=200))
def test_nest_parser_raises_only_its_error(text):
    try:
        parse_nests(text, "x.csv")
    except NestFileError as exc:
        assert str(exc).startswith("x.csv:")


@pytest.mark.parametrize(("text", "message"), [
    ("", "empty"),
    ("name,x,y\nA,1,2\n", "header must be 'name,x,y,z'"),
    ("name,x,y,z\nA,1,2,3\nB,1,2,3\n", "2 nest"),
    ("name,x,y,z\nA,1,2,3\nA,4,5,6\nC,1,1,1\n", "line 3: nest 'A' named twice"),
    ("name,x,y,z\nA,1,2,3\nB,4,abc,6\nC,1,1,1\n", "line 3, column 'y': not a number"),
    ("name,x,y,z\nA,1,2,3\nB,4,6\nC,1,1,1\n", "line 3: expected 4 values"),
])
def test_nest_file_errors_name_line_and_column(text, message):
    with pytest.raises(NestFileError, match=message):
        parse_nests(text, "n.csv")


@pytest.fixture(scope="module")
def params(tmp_path_factory):
    """A loop-model calibration of the Smart H4 from simulated poses (exact data)."""
    desc = load_robot("smart_h4")
    rng = np.random.default_rng(2)
    truth = ErrorModel.create(desc, "loop", base=_frame(rng, 1.0, 3.0))
    q = random_configurations(truth, 60, seed=1)
    res = Calibrator(desc, "loop").fit(CalibrationData.from_poses(q, truth.predict(q)))
    path = tmp_path_factory.mktemp("drift") / "params.json"
    path.write_text(params_json(res))
    return path, res


def test_cli_register_check_alarm_and_rebase_in_place(params, tmp_path, capsys):
    path, res = params
    p = tmp_path / "params.json"
    p.write_text(path.read_text())
    B = res.model.base()
    (tmp_path / "then.csv").write_text(format_nests(["A", "B", "C", "D"],
                                                    NESTS @ B[:3, :3].T + B[:3, 3]))
    assert main(["drift", "register", "--params", str(p), "--measured",
                 str(tmp_path / "then.csv"), "--out", str(tmp_path / "ref.csv")]) == 0
    capsys.readouterr()
    D = np.eye(4)
    D[:3, 3] = [60e-6, -20e-6, 10e-6]
    B_now = D @ B
    # measured in another order: matched by name
    now = NESTS[::-1] @ B_now[:3, :3].T + B_now[:3, 3]
    (tmp_path / "now.csv").write_text(format_nests(["D", "C", "B", "A"], now))
    args = ["drift", "check", "--params", str(p), "--nests", str(tmp_path / "ref.csv"),
            "--measured", str(tmp_path / "now.csv")]
    assert main(args) == 1
    assert "ALARM (> 0.05 mm)" in capsys.readouterr().out
    assert main([*args, "--update", "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["updated"] and out["translation_mm"] == pytest.approx([0.06, -0.02, 0.01],
                                                                     abs=1e-5)
    d = json.loads(p.read_text())
    np.testing.assert_allclose(np.array(d["base"]["matrix"]), B_now, atol=1e-8)  # file: 1 nm
    assert len(d["drift_history"]) == 1
    # after re-registration the same measurement shows no drift
    assert main(args) == 0
    assert "ok (≤ 0.05 mm)" in capsys.readouterr().out
    # bad input: exit 2, one line, nothing written
    (tmp_path / "few.csv").write_text("name,x,y,z\nA,1,2,3\n")
    assert main([*args[:-1], str(tmp_path / "few.csv")]) == 2
    assert "few.csv: 1 nest(s)" in capsys.readouterr().err


def test_unit_mistakes_and_swapped_files_are_named_not_taken_for_a_drift():
    """Issue 39 §7: metres for mm, inches, swapped files — each named; a real drift not."""
    rng = np.random.default_rng(4)
    B = _frame(rng, 1.0, 3.0)
    then = NESTS @ B[:3, :3].T + B[:3, 3]
    ref = nests_in_base(B, then)
    D = _frame(rng, 2e-5, 40e-6)
    now = NESTS @ (D @ B)[:3, :3].T + (D @ B)[:3, 3]
    assert likely_mix_up(B, ref, now) == ""  # a real drift
    assert likely_mix_up(B, ref, now / 1000).startswith(  # measured file in metres
        "units: the measured nests are 1000× closer together than the registered ones")
    assert likely_mix_up(B, ref / 1000, now).startswith(  # registered from metres
        "units: the registered nests are 1000× closer together")
    assert "in inches?" in likely_mix_up(B, ref, now * 25.4)
    assert likely_mix_up(B, ref / 1000, now / 1000).startswith(  # both: nests mm apart
        "units: the registered nests are only")
    swapped = likely_mix_up(B, now, ref)
    assert swapped.startswith("swapped: the measured file fits as the registration"), swapped
    assert swapped.endswith("--nests and --measured swapped?")


@given(st.integers(0, 2**32 - 1), st.floats(0.0, 2e-4))
@settings(max_examples=60, deadline=None)
def test_no_mix_up_is_claimed_for_a_genuine_drift(seed, size):
    rng = np.random.default_rng(seed)
    B = _frame(rng, 1.0, 3.0)
    nests = rng.uniform(-2.0, 2.0, size=(int(rng.integers(3, 8)), 3))
    if np.median(np.linalg.norm(nests[:, None] - nests[None], axis=2)) < 0.05:
        return
    D = _frame(rng, size, size)
    B_now = D @ B
    assert likely_mix_up(B, nests, nests @ B_now[:3, :3].T + B_now[:3, 3]) == ""


def test_cli_refuses_metres_and_swapped_files_with_the_cause(params, tmp_path, capsys):
    path, res = params
    p = tmp_path / "params.json"
    p.write_text(path.read_text())
    B = res.model.base()
    then = NESTS @ B[:3, :3].T + B[:3, 3]
    (tmp_path / "then.csv").write_text(format_nests(["A", "B", "C", "D"], then))
    (tmp_path / "then_m.csv").write_text(format_nests(["A", "B", "C", "D"], then / 1000))
    reg = ["drift", "register", "--params", str(p), "--out", str(tmp_path / "ref.csv")]
    assert main([*reg, "--measured", str(tmp_path / "then_m.csv")]) == 2
    err = capsys.readouterr().err
    assert "then_m.csv: the nests are only" in err and "a file in metres?" in err
    assert not (tmp_path / "ref.csv").exists()
    assert main([*reg, "--measured", str(tmp_path / "then.csv")]) == 0
    capsys.readouterr()
    before = p.read_text()
    check = ["drift", "check", "--params", str(p), "--update"]
    # the measurement in metres
    assert main([*check, "--nests", str(tmp_path / "ref.csv"), "--measured",
                 str(tmp_path / "then_m.csv")]) == 2
    out = capsys.readouterr()
    assert out.out == "" and out.err.count("\n") == 1, out
    assert "drift of BASE not estimated" in out.err and "the measured file in metres?" in out.err
    # the files swapped
    assert main([*check, "--nests", str(tmp_path / "then.csv"), "--measured",
                 str(tmp_path / "ref.csv")]) == 2
    err = capsys.readouterr().err
    assert "--nests and --measured swapped?" in err, err
    assert p.read_text() == before  # nothing re-registered
