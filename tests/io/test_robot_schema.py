"""The robot description file schema (plugcell.io.robot_schema): a description → its file
dictionary → the same description, nothing lost; bad input → an error naming the key."""

from __future__ import annotations

import copy
import dataclasses
import math
import typing
from typing import Any

import msgspec
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from plugcell.io import robot_schema
from plugcell.io.robot_schema import (
    RobotFile,
    description_from_dict,
    description_from_document,
    description_to_dict,
    document_from_dict,
    document_of,
)
from plugcell.io.robots import available_robots, load_robot
from plugcell.kinematics import (
    Box,
    CoupledLimit,
    DescriptionError,
    JointCoupling,
    Link,
    PointMass,
    RobotDescription,
)
from plugcell.kinematics.description import JOINT_TYPES
from plugcell.kinematics.rotations import rpy_to_matrix


# ----------------------------------------------------------------------------- helpers
def assert_same(a: Any, b: Any, where: str = "desc", atol: float = 1e-9) -> None:
    """``a`` and ``b`` agree in every init field, recursively (floats to ``atol``):
    a field added to the model one day is compared without touching this test."""
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            if f.init:
                assert_same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}", atol)
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        assert a.shape == b.shape, where
        np.testing.assert_allclose(a, b, rtol=0, atol=atol, err_msg=where)
    elif isinstance(a, (tuple, list)):
        assert isinstance(b, (tuple, list)) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{i}]", atol)
    elif isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), where
        for k in a:
            assert_same(a[k], b[k], f"{where}.{k}", atol)
    elif isinstance(a, float) and not isinstance(a, bool):
        assert isinstance(b, float) and not isinstance(b, bool), where
        assert b == pytest.approx(a, rel=0, abs=atol), where
    else:
        assert type(a) is type(b) and a == b, where


def _err(d: Any) -> DescriptionError:
    with pytest.raises(DescriptionError) as exc:
        description_from_dict(d)
    return exc.value


# ----------------------------------------------------------------------------- random robots
_angle = st.floats(-math.pi, math.pi)
_length = st.floats(-2.0, 2.0)
_char = st.characters(codec="utf-8")
_name = st.text(_char, min_size=1, max_size=4).filter(lambda s: s != "base")


@st.composite
def _transform(draw: st.DrawFn) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rpy_to_matrix(draw(_angle), draw(st.floats(-1.5, 1.5)), draw(_angle))
    T[:3, 3] = [draw(_length) for _ in range(3)]
    return T


@st.composite
def descriptions(draw: st.DrawFn) -> RobotDescription:
    """A valid serial robot: revolute, prismatic and fixed joints, Hayati rows, masses,
    stiffnesses, BASE/tool, point masses, a working volume, a coupling, coupled limits."""
    n = draw(st.integers(1, 7))
    names = draw(st.lists(_name, min_size=n, max_size=n, unique=True))
    kinds = draw(st.lists(st.sampled_from(["actuated", "actuated", "prismatic", "fixed"]),
                          min_size=n, max_size=n))
    kinds[draw(st.integers(0, n - 1))] = "actuated"  # at least one revolute reading
    links = []
    for i, (nm, kind) in enumerate(zip(names, kinds, strict=True)):
        hayati = draw(st.booleans())
        links.append(Link(
            name=nm, parent="base" if i == 0 else names[i - 1], joint=kind,
            theta=draw(_angle), d=draw(_length), a=draw(_length), alpha=draw(_angle),
            beta=draw(st.floats(-0.1, 0.1)) if hayati else 0.0, hayati=hayati,
            mass=draw(st.floats(0.0, 500.0)),
            com=tuple(draw(_length) for _ in range(3)),  # type: ignore[arg-type]
        ))
    actuated = [lk.name for lk in links if lk.is_actuated]
    actuated = draw(st.permutations(actuated))
    na = len(actuated)
    prismatic = [next(lk for lk in links if lk.name == a).is_prismatic for a in actuated]
    coupling = None
    if not any(prismatic) and draw(st.booleans()):
        M = np.diag([draw(st.sampled_from([1.0, -1.0])) for _ in range(na)])
        for r in range(1, na):  # lower-triangular: injective whatever the entries
            M[r, r - 1] = draw(st.sampled_from([0.0, 1.0, -1.0, 0.5]))
        readings = draw(st.lists(_name, min_size=na, max_size=na, unique=True))
        coupling = JointCoupling(tuple(readings), M,
                                 np.array([draw(_angle) for _ in range(na)]))
    limits, home = [], []
    for _ in range(na):
        lo = draw(st.floats(-3.0, 0.0))
        hi = lo + draw(st.floats(0.01, 3.0))
        limits.append((lo, hi))
        home.append(lo + (hi - lo) * draw(st.floats(0.1, 0.9)))  # off the limits' ulps
    stiffness = (np.array([draw(st.floats(1e3, 1e7)) for _ in range(na)])
                 if draw(st.booleans()) else None)
    reading_names = coupling.readings if coupling is not None else tuple(actuated)
    coupled = []
    revolute = [j for j in range(na) if not prismatic[j]]
    if len(revolute) >= 2 and draw(st.booleans()):
        i, j = draw(st.permutations(revolute))[:2]
        diff = home[i] - home[j]
        coupled.append(CoupledLimit((reading_names[i], reading_names[j]),
                                    diff - draw(st.floats(0.01, 1.0)),
                                    diff + draw(st.floats(0.01, 1.0))))
    pms = tuple(PointMass(draw(_name), draw(st.sampled_from(names)), draw(st.floats(0, 100)),
                          tuple(draw(_length) for _ in range(3)))  # type: ignore[arg-type]
                for _ in range(draw(st.integers(0, 2))))
    box = None
    if draw(st.booleans()):
        box = Box(tuple(draw(_length) for _ in range(3)),  # type: ignore[arg-type]
                  tuple(draw(st.floats(0.01, 4.0)) for _ in range(3)))  # type: ignore[arg-type]
    return RobotDescription(
        name=draw(_name), links=tuple(links), actuated=tuple(actuated), flange=names[-1],
        loops=(), base=draw(_transform()), tool=draw(_transform()),
        joint_limits=np.array(limits).reshape(na, 2), stiffness=stiffness,
        notes=draw(st.text(_char, max_size=20)), coupled_limits=tuple(coupled),
        home=np.array(home), point_masses=pms, working_volume=box, coupling=coupling,
    )


# ----------------------------------------------------------------------------- round trip
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(descriptions())
def test_description_dict_description_loses_nothing(desc):
    d = description_to_dict(desc)
    back = description_from_dict(copy.deepcopy(d))
    assert_same(desc, back)
    assert_same(d, description_to_dict(back))  # and the dictionary is a fixed point


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(descriptions())
def test_the_dictionary_is_plain_toml_data(desc):
    """Only dicts, lists, str, float, int, bool: what tomllib/json give back."""
    def plain(v: Any) -> bool:
        if isinstance(v, dict):
            return all(isinstance(k, str) and plain(x) for k, x in v.items())
        if isinstance(v, list):
            return all(plain(x) for x in v)
        return type(v) in (str, float, int, bool)

    d = description_to_dict(desc)
    assert plain(d)
    assert msgspec.json.decode(msgspec.json.encode(d)) == d


@pytest.mark.parametrize("name", available_robots())
def test_shipped_robots_round_trip(name):
    desc = load_robot(name)
    assert_same(desc, description_from_dict(description_to_dict(desc)), atol=1e-12)
    assert_same(desc, description_from_document(document_of(desc)), atol=1e-12)


def test_every_schema_key_is_written_or_an_input_alternative():
    """Nothing of the model is left out of the file: every key of every table is written
    for some shipped robot, except the alternatives a file may use instead."""
    written: set[str] = set()

    def keys(v: Any, prefix: str) -> None:
        if isinstance(v, dict):
            for k, x in v.items():
                written.add(f"{prefix}{k}")
                keys(x, f"{prefix}{k}.")
        elif isinstance(v, list):
            for x in v:
                keys(x, prefix)

    for name in available_robots():
        keys(description_to_dict(load_robot(name)), "")
    declared: set[str] = set()

    def fields(t: Any, prefix: str) -> None:
        for f in msgspec.structs.fields(t):
            declared.add(f"{prefix}{f.encode_name}")
            for arg in (f.type, *typing.get_args(f.type)):
                for sub in (arg, *typing.get_args(arg)):
                    if isinstance(sub, type) and issubclass(sub, msgspec.Struct):
                        fields(sub, f"{prefix}{f.encode_name}.")

    fields(RobotFile, "")
    alternatives = {"base.zyz", "base.matrix", "tool.zyz", "tool.matrix", "loops.type"}
    # the nameplate is read from the file by robot_identification, not carried by the
    # kinematic model (a written description has none)
    nameplate = {"identification", "identification.manufacturer", "identification.model",
                 "identification.serial_number", "identification.product_code"}
    assert declared - written == alternatives | nameplate


def test_schema_joint_types_are_the_models():
    assert typing.get_args(robot_schema.JointType) == JOINT_TYPES


def test_input_forms_give_the_same_robot():
    d = description_to_dict(load_robot("elbow6"))
    d["notes"] = ["two", "lines"]
    d["base"] = {"xyz": [0.1, 0.2, 0.3], "zyz": [10.0, 20.0, 30.0]}
    T = description_from_dict(d).base
    d["base"] = {"matrix": T.tolist()}
    d["links"][0] = {k: tuple(v) if isinstance(v, list) else v for k, v in d["links"][0].items()}
    back = description_from_dict(d)
    np.testing.assert_allclose(back.base, T, atol=1e-15)
    assert back.notes == "two\nlines"
    del d["format_version"], d["base"]
    assert description_from_dict(d).links == back.links


# ----------------------------------------------------------------------------- bad input
_NUMBER_KEYS = ["theta", "d", "a", "alpha", "mass"]
_REQUIRED = ["name", "parent", "joint", "d", "a", "alpha"]


@st.composite
def _link_key(draw: st.DrawFn, keys: list[str]) -> tuple[dict[str, Any], int, str]:
    d = description_to_dict(load_robot(draw(st.sampled_from(["smart_h4", "elbow6"]))))
    return d, draw(st.integers(0, len(d["links"]) - 1)), draw(st.sampled_from(keys))


@settings(max_examples=60, deadline=None)
@given(_link_key(_NUMBER_KEYS), st.sampled_from(["x", True, None, [1.0], {"a": 1}]))
def test_a_wrong_type_is_named(case, value):
    d, i, key = case
    d["links"][i][key] = value
    got = "'x'" if value == "x" else ("True" if value is True else type(value).__name__)
    assert str(_err(d)) == f"links[{i}].{key}: expected a number, got {got}"


@settings(max_examples=60, deadline=None)
@given(_link_key(_REQUIRED))
def test_a_missing_key_is_named(case):
    d, i, key = case
    del d["links"][i][key]
    e = _err(d)
    assert (e.location, e.reason) == (f"links[{i}].{key}", "missing required key")


@settings(max_examples=60, deadline=None)
@given(_link_key(["x"]), st.text(min_size=1, max_size=6).filter(
    lambda k: k not in {f.encode_name for f in msgspec.structs.fields(robot_schema.LinkTable)}))
def test_an_unknown_key_is_named(case, key):
    d, i, _ = case
    d["links"][i][key] = 1.0
    e = _err(d)
    assert e.location == f"links[{i}].{key}"
    assert e.reason == ("unknown key (allowed: a, alpha, beta, com, d, hayati, joint, limits, "
                        "mass, name, parent, stiffness, theta)")


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(["links.com", "point_masses.com", "base.xyz", "tool.rpy",
                        "working_volume.center", "working_volume.size"]),
       st.integers(0, 6).filter(lambda n: n != 3), st.data())
def test_a_wrong_vector_length_is_named(where, n, data):
    d = description_to_dict(load_robot("smart_h4"))
    table, key = where.split(".")
    if isinstance(d[table], list):
        i = data.draw(st.integers(0, len(d[table]) - 1))
        d[table][i][key] = [0.0] * n
        loc = f"{table}[{i}].{key}"
    else:
        d[table][key] = [0.0] * n
        loc = where
    assert str(_err(d)) == f"{loc}: expected 3 numbers, got {n}"


@pytest.mark.parametrize(("mutate", "expected"), [
    (lambda d: d.update(home=[0, 0, "x", 0, 0, 0]), "home[2]: expected a number, got 'x'"),
    (lambda d: d["coupling"]["matrix"][1].__setitem__(2, None),
     "coupling.matrix[1][2]: expected a number, got NoneType"),
    (lambda d: d["coupling"].update(readings=["J1", "", *d["coupling"]["readings"][2:]]),
     "coupling.readings[1]: must not be empty"),
    (lambda d: d["coupling"]["limits"].__setitem__(3, [1.0, 2.0, 3.0]),
     "coupling.limits[3]: expected 2 numbers, got 3"),
    (lambda d: d.update(tool={"matrix": [[1, 0, 0, 0]] * 3}),
     "tool.matrix: expected 4 rows, got 3"),
    (lambda d: d.update(tool={"matrix": [[1, 0, 0]] * 4}),
     "tool.matrix[0]: expected 4 numbers, got 3"),
    (lambda d: d.update(tool={"xyz": [0, 0, 0], "matrix": np.eye(4).tolist()}),
     "tool: give either 'matrix' or 'xyz' with 'rpy'/'zyz', not both"),
    (lambda d: d.update(base={"rpy": [0, 0, 0], "zyz": [0, 0, 0]}),
     "base: give one of 'rpy' or 'zyz', not both"),
    (lambda d: d.update(base=None), "base: expected a table, got NoneType"),
    (lambda d: d["links"][0].update(joint=""), "links[0].joint: must not be empty"),
    (lambda d: d.update(coupled_limits=[{"joints": ["J1"], "min": 0, "max": 1}]),
     "coupled_limits[0].joints: expected 2 joint names, got 1"),
    (lambda d: d.update(loops=[{"type": "fivebar", "arm": "1", "crank": "2", "coupler": "3",
                                "follower": "4"}]),
     "loops[0].type: expected 'parallelogram', got 'fivebar'"),
    (lambda d: d.update(notes=3), "notes: expected an array, got 3"),
    (lambda d: d.update(notes=["a", 3]), "notes[1]: expected a string, got 3"),
    (lambda d: d.update(format_version=True), "format_version: unsupported format version True"),
    (lambda d: d["links"][2].update(theta=10**400), "links[2].theta: expected a finite number"),
    (lambda d: d["links"][2].__setitem__(7, 1.0), "links[2]: keys must be strings, got 7"),
    (lambda d: d["links"][5].update(joint="fixed", theta=None),
     "links[5].theta: expected a number, got NoneType"),
    (lambda d: (d["links"][5].update(joint="fixed"), d["links"][5].pop("theta")),
     "links[5].theta: missing required key"),
])
def test_precise_errors_of_the_schema(mutate, expected):
    d = description_to_dict(load_robot("fanuc_m20ia"))
    mutate(d)
    assert str(_err(d)).startswith(expected)


def test_document_from_dict_keeps_file_units():
    d = description_to_dict(load_robot("smart_h4"))
    doc = document_from_dict(d)
    assert isinstance(doc, RobotFile)
    assert doc.links[2].alpha == d["links"][2]["alpha"]  # degrees, as in the file
    assert doc.coupled_limits[0].lower == d["coupled_limits"][0]["min"]
    with pytest.raises(DescriptionError, match=r"^links\[1\]\.a: expected a number, got 'x'$"):
        document_from_dict({**d, "links": [d["links"][0], {**d["links"][1], "a": "x"}]})


def test_numpy_floats_are_numbers():
    """A dictionary built with numpy (np.float64 is a float) reads as before."""
    d = description_to_dict(load_robot("elbow6"))
    d["links"][1]["a"] = np.float64(d["links"][1]["a"])
    d["home"] = tuple(np.float64(x) for x in d["home"])
    assert_same(description_from_dict(d), load_robot("elbow6"), atol=1e-12)
    d["links"][1]["a"] = np.int64(1)  # not a Python int: refused, as before
    assert str(_err(d)) == "links[1].a: expected a number, got int64"
