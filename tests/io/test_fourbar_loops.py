"""``[[loops]] type = "fourbar"``: a description file carries a calibrated loop exactly
(unequal sides, twists, offsets) — FK equals the model FK with those parameters — and
rejects one that cannot assemble, at the key; the nominal ``parallelogram`` is unchanged."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from plugcell.io.robot_schema import description_from_dict, description_to_dict
from plugcell.io.robots import description_to_toml, load_robot
from plugcell.kinematics import DescriptionError, forward

LOOP = ("2", "2'", "3'", "4'")
NOMINAL = load_robot("smart_h4")
Q_FEW = np.radians([[0, -90, -187, 0, 90, 0], [30, -40, -100, 20, -60, 10],
                    [-20, -150, -280, 0, 45, 0]])


@pytest.fixture(scope="module")
def h4_doc() -> dict[str, Any]:
    return description_to_dict(load_robot("smart_h4"))


def _fourbar(doc: dict[str, Any], **rows: dict[str, float]) -> dict[str, Any]:
    d = copy.deepcopy(doc)
    d["loops"][0]["type"] = "fourbar"
    by_name = {lk["name"]: lk for lk in d["links"]}
    for name, vals in rows.items():
        lk = by_name[name.replace("p", "'")]
        if "beta" in vals:
            lk["hayati"] = True
        lk.update(vals)
    return d


def _q(desc: Any, n: int = 400) -> np.ndarray:
    lim = desc.joint_limits
    q = np.random.default_rng(3).uniform(lim[:, 0], lim[:, 1], size=(n, desc.n_actuated))
    return q[desc.within_limits(q)]


def test_the_shipped_parallelogram_is_unchanged(h4_doc: dict[str, Any]) -> None:
    h4 = load_robot("smart_h4")
    assert [lp.kind for lp in h4.loops] == ["parallelogram"]
    assert "type" not in h4_doc["loops"][0]  # written as before: the default is left out


def test_a_calibrated_loop_loads_and_its_fk_is_the_parameters_fk(
        h4_doc: dict[str, Any]) -> None:
    d = _fourbar(h4_doc, **{"2": {"a": 1.0504, "theta": 0.004},
                            "2p": {"a": 0.4497, "alpha": -0.031, "beta": -0.024, "d": 2e-4},
                            "3p": {"a": 1.0493, "alpha": -0.0035, "beta": -0.035, "d": -1e-4},
                            "4p": {"a": 0.4503, "alpha": 0.01, "d": 3e-4}})
    desc = description_from_dict(d)
    assert desc.loops[0].kind == "fourbar"
    nominal = load_robot("smart_h4")
    q = _q(desc)
    got = forward(desc, None, q).flange
    # the same numbers as a perturbation of the nominal robot's parameters
    ref = forward(nominal, desc.nominal_parameters(), q).flange
    assert len(q) > 100 and np.abs(got - ref).max() < 1e-12
    # and not the nominal robot: the loop's parameters act
    assert np.abs(got - forward(nominal, None, q).flange)[:, :3, 3].max() > 1e-4
    # a file round trip keeps the type and the numbers
    back = load_robot_text(description_to_toml(desc))
    assert back.loops[0].kind == "fourbar"
    np.testing.assert_allclose(back.nominal_parameters().table(),
                               desc.nominal_parameters().table(), atol=1e-14, rtol=0)


def load_robot_text(text: str) -> Any:
    import tomllib

    return description_from_dict(tomllib.loads(text))


@pytest.mark.parametrize(
    ("rows", "message"),
    [
        ({"3p": {"a": 0.5}},
         "coupled_limits[0]: loops[0] (fourbar) cannot be assembled at arm − crank = 155°"),
        ({"3p": {"a": 1.8}},
         "coupled_limits[0]: loops[0] (fourbar) cannot be assembled at arm − crank = 25°, "
         "inside this limit: the gap between the crank and arm ends is 0.669731 m"),
        ({"4p": {"a": 0.0}}, "links[4].a: loop link lengths must be positive"),
    ],
)
def test_a_fourbar_that_cannot_assemble_is_rejected_at_the_key(
        h4_doc: dict[str, Any], rows: dict[str, dict[str, float]], message: str) -> None:
    with pytest.raises(DescriptionError) as exc:
        description_from_dict(_fourbar(h4_doc, **rows))
    assert message in str(exc.value)


def test_a_parallelogram_with_twists_names_the_fourbar_type(h4_doc: dict[str, Any]) -> None:
    d = copy.deepcopy(h4_doc)
    d["links"][3]["alpha"] = 0.1
    with pytest.raises(DescriptionError, match=r'must be planar nominally.*type = "fourbar"'):
        description_from_dict(d)
    d = copy.deepcopy(h4_doc)
    d["links"][3]["a"] = 1.0493
    with pytest.raises(DescriptionError, match=r'only parallelogram loops.*type = "fourbar"'):
        description_from_dict(d)


small = st.floats(-2e-3, 2e-3, allow_nan=False)
tilt = st.floats(-0.2, 0.2, allow_nan=False)  # degrees


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(da=st.tuples(small, small, small, small), dd=st.tuples(small, small, small),
       dalpha=st.tuples(tilt, tilt, tilt), dbeta=st.tuples(tilt, tilt))
def test_property_any_calibrated_loop_round_trips_exactly(
        h4_doc: dict[str, Any], da: tuple[float, ...], dd: tuple[float, ...],
        dalpha: tuple[float, ...], dbeta: tuple[float, ...]) -> None:
    """Calibration-sized errors of every loop parameter: the file loads, writes and loads
    back to the same robot, whose FK is that of the parameters."""
    base = {lk["name"]: lk for lk in h4_doc["links"]}
    rows: dict[str, dict[str, float]] = {}
    for k, name in enumerate(LOOP):
        r: dict[str, float] = {"a": base[name]["a"] + da[k]}
        if name != "2":
            r["d"] = dd[k - 1]
            r["alpha"] = dalpha[k - 1]
        if name in ("2'", "3'"):
            r["beta"] = dbeta[k - 1]
        rows[name.replace("'", "p")] = r
    desc = description_from_dict(_fourbar(h4_doc, **rows))
    back = description_from_dict(description_to_dict(desc))
    assert back.loops == desc.loops
    # equal up to the round-off of radians → degrees → radians (files hold degrees)
    np.testing.assert_allclose(back.nominal_parameters().table(),
                               desc.nominal_parameters().table(), atol=1e-14, rtol=0)
    q = Q_FEW[desc.within_limits(Q_FEW)]
    ref = forward(NOMINAL, desc.nominal_parameters(), q).flange
    assert len(q) == len(Q_FEW) and np.abs(forward(back, None, q).flange - ref).max() < 1e-12
