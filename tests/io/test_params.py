"""PARAMS.json (plugcell.io.params): a result survives its document, and a bad document
is refused with a message naming what is wrong (the key, the robot, the format)."""

from __future__ import annotations

import copy
import json
import math
from typing import Any

import numpy as np
import pytest
from damaged_documents import damaged
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from plugcell.calibration.configs import MODELS
from plugcell.calibration.identifiability import random_configurations
from plugcell.calibration.model import ErrorModel
from plugcell.calibration.result import CalibrationResult
from plugcell.calibration.validity import ValidityRegion
from plugcell.io.params import (
    ParamsError,
    params_json,
    rebase_document,
    result_from_params,
)
from plugcell.io.robots import load_robot
from plugcell.kinematics.transforms import so3_exp

ROBOTS = {name: load_robot(name) for name in ("smart_h4", "elbow6")}


def _transform(rv: list[float], t: list[float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = so3_exp(np.asarray(rv))
    T[:3, 3] = t
    return T


_small = st.floats(-1e-3, 1e-3, allow_nan=False)
_vec3 = st.lists(st.floats(-2.0, 2.0, allow_nan=False), min_size=3, max_size=3)
_rot3 = st.lists(st.floats(-3.0, 3.0, allow_nan=False), min_size=3, max_size=3)


@st.composite
def _region(draw: st.DrawFn, n: int) -> ValidityRegion:
    lo = np.array(draw(st.lists(st.floats(-3.0, 0.0), min_size=n, max_size=n)))
    span = np.array(draw(st.lists(st.floats(0.0, 3.0), min_size=n, max_size=n)))
    p = draw(st.integers(1, 4))
    u = np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=p * n, max_size=p * n)))
    m = sorted(draw(st.lists(st.floats(0.0, 60.0), min_size=2, max_size=2)))
    box = np.array(draw(st.lists(st.floats(-2.0, 2.0), min_size=6, max_size=6)))
    return ValidityRegion(
        joint_lower=lo, joint_upper=lo + span,
        lever_m=np.array(draw(st.lists(st.floats(0.05, 2.0), min_size=n, max_size=n))),
        poses=lo + u.reshape(p, n) * span, threshold_m=draw(st.floats(0.0, 1.0)),
        cover_m=draw(st.floats(0.0, 1.0)), payload_kg=(m[0], m[1]),
        target_lower=np.minimum(box[:3], box[3:]), target_upper=np.maximum(box[:3], box[3:]),
        n_poses=draw(st.integers(p, 10**6)))


@st.composite
def results(draw: st.DrawFn) -> CalibrationResult:
    """A result as a fit makes one, without what PARAMS.json cannot bring back
    (statistics, history, residuals): any robot, model, harmonics, thermal expansion,
    values, frames, references and validity region."""
    robot = draw(st.sampled_from(sorted(ROBOTS)))
    desc = ROBOTS[robot]
    cfg = draw(st.sampled_from(MODELS))
    harmonics = draw(st.integers(0, 2))
    thermal = draw(st.booleans())
    t_ref = draw(st.floats(-20.0, 60.0)) if thermal else 0.0
    m_ref = draw(st.just(0.0) | st.floats(0.1, 60.0))  # none, or a payload a robot carries
    base = _transform(draw(_rot3), draw(_vec3))
    probe = _transform(draw(_rot3), draw(_vec3))
    empty = ErrorModel.create(desc, cfg.family, gravity=cfg.gravity, payload=cfg.payload,
                              base=base, probe=probe, payload_ref_kg=m_ref,
                              harmonics=harmonics, thermal=thermal, temperature_ref_c=t_ref)
    n = len(empty.space.keys)
    model = empty.with_values(draw(st.lists(_small, min_size=n, max_size=n)))
    nominal = empty.with_values(draw(st.lists(_small, min_size=n, max_size=n)))
    keys = draw(st.lists(st.sampled_from(empty.space.keys), unique=True, max_size=8))
    validity = draw(st.none() | _region(desc.n_readings))
    return CalibrationResult(
        config=cfg, robot=robot, model=model, nominal=nominal, keys=tuple(keys),
        identifiability=None, data_identifiability=None,
        iterations=draw(st.integers(0, 100)), converged=draw(st.booleans()), history=(),
        statistics=None, calibration=None, calibration_before=None,
        six_dof=draw(st.booleans()), n_poses=draw(st.integers(0, 10**6)),
        warnings=tuple(draw(st.lists(st.text(max_size=20), max_size=3))),
        validity=validity)


def _same(a: Any, b: Any, path: str = "") -> None:
    """Equal documents; floats of the validity region (stored in mm and degrees, read
    back in m and rad) to the last bits."""
    assert type(a) is type(b), path
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and path.startswith(".validity"):
        assert math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-12), (path, a, b)
    else:
        assert a == b, path


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(results())
def test_result_document_result_document_is_the_same(result):
    first = json.loads(params_json(result))
    back = result_from_params(first, ROBOTS[result.robot])
    second = json.loads(params_json(back))
    validity = (first.pop("validity"), second.pop("validity"))
    assert second == first  # everything but the region exactly
    _same(*validity, ".validity")
    q = random_configurations(result.model, 3, 0)
    np.testing.assert_array_equal(back.predict(q, 10.0, 25.0), result.predict(q, 10.0, 25.0))
    assert back.keys == result.keys and back.warnings == result.warnings


@pytest.fixture(scope="module")
def document() -> dict[str, Any]:
    desc = ROBOTS["smart_h4"]
    model = ErrorModel.create(desc, "loop", gravity=True, payload=True, harmonics=1,
                              thermal=True, temperature_ref_c=20.0)
    q = np.random.default_rng(3).uniform(-1.0, 1.0, (12, desc.n_readings))
    result = CalibrationResult(
        config=MODELS[4], robot="smart_h4", model=model, nominal=model,
        keys=model.space.keys[:3], identifiability=None, data_identifiability=None,
        iterations=3, converged=True, history=(), statistics=None, calibration=None,
        calibration_before=None, six_dof=True, n_poses=12,
        validity=ValidityRegion.from_poses(model, q))
    return json.loads(params_json(result))


def _without(d: dict[str, Any], *path: str) -> dict[str, Any]:
    d = copy.deepcopy(d)
    parent = d
    for k in path[:-1]:
        parent = parent[k]
    del parent[path[-1]]
    return d


def _with(d: dict[str, Any], value: Any, *path: str | int) -> dict[str, Any]:
    d = copy.deepcopy(d)
    parent = d
    for k in path[:-1]:
        parent = parent[k]
    parent[path[-1]] = value
    return d


@pytest.mark.parametrize(("change", "message"), [
    (lambda d: _without(d, "format"), r"^not a plugcell calibration \(missing 'format'\)$"),
    (lambda d: _with(d, "other", "format"), r"not a plugcell calibration"),
    (lambda d: _with(d, 2, "format_version"), r"^format_version 2: this plugcell reads up to 1"),
    (lambda d: _without(d, "robot"), r"^missing key 'robot'$"),
    (lambda d: _with(d, 4, "robot"), r"^robot: expected a name, got the number 4$"),
    (lambda d: _with(d, "elbow6", "robot"),
     r"^a calibration of robot 'elbow6', not of 'smart_h4'$"),
    (lambda d: _without(d, "references"), r"^missing key 'references'$"),
    (lambda d: _without(d, "references", "base"), r"^missing key 'references.base'$"),
    (lambda d: _with(d, [[1.0, 0.0]], "references", "probe"),
     r"^references.probe: expected a finite 4x4 matrix$"),
    (lambda d: _with(d, [], "model"), r"^model: expected an object, got a list$"),
    (lambda d: _without(d, "model", "number"), r"^missing key 'model.number'$"),
    (lambda d: _with(d, 9, "model", "number"), r"^model.number: unknown model 9"),
    (lambda d: _with(d, 3, "model", "harmonics"), r"^model.harmonics: 0, 1 or 2, got 3$"),
    (lambda d: _with(d, "yes", "model", "thermal"),
     r"^model.thermal: expected true or false, got the string 'yes'$"),
    (lambda d: _with(d, None, "data", "payload_ref_kg"),
     r"^data.payload_ref_kg: expected a finite number, got null$"),
    (lambda d: _with(d, 5e-324, "data", "payload_ref_kg"),
     r"^data.payload_ref_kg: 0 \(no payload\) or at least 0.001 kg, got 4.94066e-324$"),
    (lambda d: _with(d, -2.0, "data", "payload_ref_kg"),
     r"^data.payload_ref_kg: 0 \(no payload\) or at least 0.001 kg, got -2$"),
    (lambda d: _with(d, 1, "data", "six_dof"),
     r"^data.six_dof: expected true or false, got the number 1$"),
    (lambda d: _with(d, 2.5, "data", "poses"),
     r"^data.poses: expected an integer, got the number 2.5$"),
    (lambda d: _with(d, "3", "iterations"), r"^iterations: expected an integer"),
    (lambda d: _without(d, "converged"), r"^missing key 'converged'$"),
    (lambda d: _with(d, "x", "values", "a2'"),
     r"^values.a2': expected a finite number, got the string 'x'$"),
    (lambda d: _with(d, [], "nominal_frames", "values"),
     r"^nominal_frames.values: expected an object, got a list$"),
    (lambda d: _with(d, {}, "parameters"), r"^parameters: expected a list, got an object$"),
    (lambda d: _with(d, "a2'", "parameters", 0), r"^parameters\[0\]: expected an object"),
    (lambda d: _with(d, {"key": "zz"}, "parameters", 1),
     r"^parameters: 'zz' not in model 5 \(full\) of 'smart_h4'$"),
    (lambda d: _with(d, [1], "warnings"), r"^warnings: expected a list of strings$"),
    (lambda d: _with(d, [1], "validity"), r"^validity: expected an object, got a list$"),
    (lambda d: _without(d, "validity", "threshold_mm"),
     r"^validity: missing key 'threshold_mm'$"),
    (lambda d: _with(d, [[1.0]], "validity", "poses_deg"), r"^validity: "),
])
def test_bad_documents_are_refused_naming_what_is_wrong(document, change, message):
    with pytest.raises(ParamsError, match=message):
        result_from_params(change(document), ROBOTS["smart_h4"])


def test_another_robot_is_refused(document):
    with pytest.raises(ParamsError, match=r"calibration of robot 'smart_h4', not of 'elbow6'"):
        result_from_params(document, ROBOTS["elbow6"])
    # unchecked (the caller took the description from the document itself)
    renamed = _with(document, "my_h4", "robot")
    with pytest.raises(ParamsError, match=r"robot 'my_h4', not of 'smart_h4'"):
        result_from_params(renamed, ROBOTS["smart_h4"])
    assert result_from_params(renamed, ROBOTS["smart_h4"], check_robot=False).robot == "my_h4"


def test_old_documents_still_load(document):
    """What files written before harmonics, thermal expansion, warnings, the format
    version and the validity region were recorded lack."""
    old = copy.deepcopy(document)
    for key in ("format_version", "warnings", "validity"):
        del old[key]
    old["model"] = {k: v for k, v in old["model"].items()
                    if k not in ("harmonics", "thermal", "temperature_ref_c")}
    res = result_from_params(old, ROBOTS["smart_h4"])
    assert res.validity is None and res.warnings == ()
    assert not any(k.startswith("h1") for k in res.model.space.keys)


def test_rebase_document_moves_base_and_records_the_event(document):
    desc = ROBOTS["smart_h4"]
    result = result_from_params(document, desc)
    new_base = _transform([0.0, 0.0, 0.01], [0.002, 0.0, 0.0]) @ result.model.base()
    d = rebase_document(document, result, new_base, {"displacement_mm": 2.0})
    assert d is not document and "drift_history" not in document
    back = result_from_params(d, desc)
    np.testing.assert_allclose(back.model.base(), new_base, atol=1e-12)
    assert d["drift_history"] == [{"displacement_mm": 2.0}]
    with pytest.raises(ValueError, match="expected a finite 4x4 transform"):
        rebase_document(document, result, np.eye(3))


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_any_damaged_document_loads_or_raises_params_error(document, data):
    d = data.draw(damaged(document, actions=("replace", "delete")))
    try:
        res = result_from_params(d, ROBOTS["smart_h4"])
    except ParamsError as exc:
        assert str(exc)
        return
    assert isinstance(res, CalibrationResult)


def test_commands_name_the_file_and_what_is_wrong(document, tmp_path, capsys):
    from plugcell.apps.cli import main

    targets = tmp_path / "t.csv"
    targets.write_text("x,y,z,rx,ry,rz\n1400,0,800,0,90,0\n")
    params = tmp_path / "P.json"
    params.write_text(json.dumps(document))
    out = ["--targets", str(targets), "--out", str(tmp_path / "o.csv")]
    assert main(["compensate", "--params", str(params), "--robot", "elbow6", *out]) == 2
    assert ("P.json: a calibration of robot 'smart_h4', not of 'elbow6'"
            in capsys.readouterr().err)
    params.write_text(json.dumps(_without(document, "references", "probe")))
    assert main(["compensate", "--params", str(params), *out]) == 2
    assert "P.json: missing key 'references.probe'" in capsys.readouterr().err
