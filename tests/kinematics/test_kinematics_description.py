"""Robot descriptions: shipped files, precise errors, and a property test of from_dict."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from damaged_documents import damaged
from hypothesis import HealthCheck, given, settings

from plugcell.io.robot_schema import description_from_dict, description_to_dict
from plugcell.io.robots import RobotNotFoundError, available_robots, load_robot
from plugcell.kinematics import DescriptionError, GeometricParameters, RobotDescription


@pytest.fixture(scope="module")
def h4_dict(h4) -> dict[str, Any]:
    return description_to_dict(h4)


def _err(d: dict[str, Any]) -> str:
    with pytest.raises(DescriptionError) as exc:
        description_from_dict(d)
    return str(exc.value)


# ----------------------------------------------------------------------------- shipped
def test_shipped_robots(h4, elbow):
    assert set(available_robots()) >= {"smart_h4", "elbow6"}
    assert h4.actuated == ("1", "2", "2'", "4", "5", "6")
    assert h4.link_names == ("1", "2", "2'", "3'", "4'", "3", "4", "5", "6")
    assert [h4.links[i].name for i in h4.chain] == ["1", "2'", "3'", "4'", "3", "4", "5", "6"]
    assert h4.passive == ("3'", "4'")
    assert h4.link("5").d == pytest.approx(0.1588)  # not Table 6-1's 1.1588 (design.md)
    assert h4.link("3").theta == pytest.approx(math.radians(-83))
    assert [lk.name for lk in h4.links if lk.hayati] == ["2'", "3'", "4'"]
    assert h4.stiffness is not None and h4.stiffness.shape == (6,)
    assert any(pm.name == "counterweight" and pm.link == "2'" for pm in h4.point_masses)
    assert 800 < sum(lk.mass for lk in h4.links) + sum(p.mass for p in h4.point_masses) < 2000
    assert h4.working_volume is not None
    np.testing.assert_allclose(h4.working_volume.size, [0.8, 2.0, 1.4])
    assert h4.within_limits(h4.home)
    assert elbow.loops == () and elbow.n_actuated == 6


def test_the_link_tree_is_read_once(h4):
    """What forward kinematics asks every call is made once and cannot be changed: the
    parents' positions, the revolute joints' links, which joints are prismatic."""
    names = h4.link_names
    assert h4.parent_indices == tuple(-1 if lk.parent == "base" else names.index(lk.parent)
                                      for lk in h4.links)
    j, i = h4.revolute_links
    assert [h4.actuated[k] for k in j] == [names[k] for k in i] == list(h4.actuated)
    assert h4.prismatic_links is h4.prismatic_links
    (loop,) = h4.loops
    assert h4.loop_indices == ((*(names.index(n) for n in loop.links),
                                h4.actuated.index(loop.arm), h4.actuated.index(loop.crank)),)
    for a in (h4.prismatic_links, j, i):
        with pytest.raises(ValueError, match="read-only"):
            a[0] = 1


def test_coupled_limit_keeps_loop_away_from_collapse(h4):
    (cl,) = h4.coupled_limits
    assert cl.joints == ("2", "2'")
    assert math.radians(30) >= cl.lower and cl.upper >= math.radians(150)
    assert min(math.sin(cl.lower), math.sin(cl.upper)) > 0.3


def test_to_dict_round_trip(h4, elbow):
    for desc in (h4, elbow):
        back = description_from_dict(description_to_dict(desc))
        assert back.links == desc.links or all(
            a.name == b.name
            and np.allclose(
                [a.theta, a.d, a.a, a.alpha, a.beta], [b.theta, b.d, b.a, b.alpha, b.beta]
            )
            for a, b in zip(back.links, desc.links, strict=True)
        )
        np.testing.assert_allclose(back.joint_limits, desc.joint_limits)
        np.testing.assert_allclose(back.home, desc.home)
        np.testing.assert_allclose(back.base, desc.base, atol=1e-15)
        assert back.loops == desc.loops and back.coupled_limits == desc.coupled_limits


def test_nominal_parameters_and_perturbed(h4):
    p = h4.nominal_parameters()
    assert isinstance(p, GeometricParameters)
    assert p.link_names == h4.link_names
    q = p.perturbed({("3'", "beta"): 1e-3, ("2", "a"): -2e-3})
    assert q.get("3'", "beta") == pytest.approx(1e-3)
    assert q.get("2", "a") == pytest.approx(1.05 - 2e-3)
    assert p.get("2", "a") == 1.05  # immutable original
    with pytest.raises(ValueError):
        p.a[0] = 1.0  # read-only arrays
    with pytest.raises(KeyError, match="unknown link"):
        p.perturbed({("9", "a"): 1.0})
    with pytest.raises(KeyError, match="field"):
        p.perturbed({("2", "length"): 1.0})
    np.testing.assert_array_equal(p.with_vector(p.to_vector()).table(), p.table())
    assert len(p.labels()) == p.to_vector().size == 5 * 9


# ----------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    ("mutate", "expected"),
    [
        (lambda d: d["links"][3].pop("a"), "links[3].a: missing required key"),
        (lambda d: d["links"][3].update(alpha="x"), "links[3].alpha: expected a number, got 'x'"),
        (lambda d: d["links"][3].update(alpha=True), "links[3].alpha: expected a number, got True"),
        (lambda d: d["links"][3].update(d=math.nan), "links[3].d: expected a finite number"),
        (lambda d: d["links"][2].update(parent="7"), "links[2].parent: unknown parent link '7'"),
        (lambda d: d["links"][1].update(parent="6"), "links[1].parent: parent '6' is listed after"),
        (
            lambda d: d["links"][0].update(parent="2"),
            "links[0].parent: the first link must have parent 'base'",
        ),
        (lambda d: d["links"][2].update(joint="spherical"), "links[2].joint: expected one of"),
        (lambda d: d["links"][2].update(joint="prismatic"), "must be revolute, not prismatic"),
        (
            lambda d: d["links"][2].update(limits=[10, -10]),
            "links[2].limits: lower limit 10 must be below",
        ),
        (lambda d: d["links"][2].update(limits=[10]), "links[2].limits: expected 2 numbers, got 1"),
        (lambda d: d["links"][2].pop("limits"), "links[2].limits: missing required key"),
        (
            lambda d: d["links"][3].update(limits=[0, 1]),
            "links[3].limits: only actuated joints take",
        ),
        (lambda d: d["links"][5].update(beta=1.0), "links[5].beta: beta requires hayati = true"),
        (lambda d: d["links"][5].update(mass=-1), "links[5].mass: must be ≥ 0"),
        (lambda d: d["links"][5].update(com=[0, 0]), "links[5].com: expected 3 numbers, got 2"),
        (lambda d: d["links"][5].update(colour="red"), "links[5].colour: unknown key"),
        (lambda d: d["links"][4].update(name="3'"), 'links[4].name: duplicate link name "3\'"'),
        (lambda d: d["links"][6].pop("stiffness"), "links[6].stiffness: missing"),
        (lambda d: d["loops"][0].update(coupler="5'"), 'loops[0].coupler: unknown link "5\'"'),
        (
            lambda d: d["loops"][0].update(follower="3"),
            "loops[0].follower: link '3' must be passive",
        ),
        (lambda d: d["loops"][0].update(arm="4"), "loops[0].arm: arm '4' and crank"),
        (lambda d: d["loops"][0].pop("crank"), "loops[0].crank: missing required key"),
        (
            lambda d: d.update(loops=[]),
            "links[1]: actuated link '2' is neither on the chain to the flange nor a loop arm",
        ),
        (
            lambda d: d["links"][5].update(joint="passive"),
            "links[5].joint: passive link '3' belongs to no loop",
        ),
        (lambda d: d["links"][3].update(a=1.2), "links[3].a: only parallelogram loops"),
        (lambda d: d["links"][3].update(alpha=5.0), "must be planar nominally"),
        (
            lambda d: d["coupled_limits"][0].update(min=-10.0),
            "coupled_limits[0]: the range of 2 − 2' lets the loop collapse",
        ),
        (
            lambda d: d["coupled_limits"][0].update(min=160.0),
            "coupled_limits[0]: min 160 must be below max 155",
        ),
        (
            lambda d: d["coupled_limits"][0].update(joints=["2", "3'"]),
            'coupled_limits[0].joints[1]: "3\'" is not an actuated joint',
        ),
        (lambda d: d.update(coupled_limits=[]), "coupled_limits: loops[0] needs a coupled limit"),
        (
            lambda d: d.update(actuated=["1", "2", "2'", "4", "5"]),
            "actuated: actuated link '6' (links[8]) is missing",
        ),
        (
            lambda d: d.update(actuated=["1", "2", "2'", "4", "5", "3'"]),
            "actuated[5]: link \"3'\" has joint 'passive'",
        ),
        (lambda d: d.update(flange="7"), "flange: unknown link '7'"),
        (
            lambda d: d.update(home=[0, 0, 0, 0, 0, 0]),
            "home[1]: joint 2 = 0° is outside its limits",
        ),
        (
            lambda d: d.update(home=[0, -90]),
            "home: expected 6 numbers (one per actuated joint), got 2",
        ),
        (
            lambda d: d.update(base={"xyz": [0, 0], "rpy": [0, 0, 0]}),
            "base.xyz: expected 3 numbers, got 2",
        ),
        (
            lambda d: d.update(
                tool={"matrix": [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}
            ),
            "tool.matrix: rotation part is not a proper rotation",
        ),
        (
            lambda d: d.update(working_volume={"center": [0, 0, 0], "size": [1, 0, 1]}),
            "working_volume.size[1]: must be positive",
        ),
        (
            lambda d: d.update(
                point_masses=[{"name": "cw", "link": "9", "mass": 1.0, "com": [0, 0, 0]}]
            ),
            "point_masses[0].link: unknown link '9'",
        ),
        (lambda d: d.pop("links"), "links: missing required key"),
        (lambda d: d.update(links="1,2,3"), "links: expected an array, got '1,2,3'"),
        (lambda d: d.update(format_version=2), "format_version: unsupported format version 2"),
        (lambda d: d.update(lnks=[]), "lnks: unknown key"),
    ],
)
def test_precise_errors(h4_dict, mutate, expected):
    d = copy.deepcopy(h4_dict)
    mutate(d)
    assert expected in _err(d)


def test_top_level_must_be_a_table():
    assert _err([1, 2]) == "expected a table, got list"  # type: ignore[arg-type]


# ----------------------------------------------------------------------------- property
_BASE = description_to_dict(load_robot("smart_h4"))


def _assert_description_or_its_error(d) -> None:
    """A damaged document gives a robot, or a DescriptionError that says why — nothing
    else."""
    try:
        desc = description_from_dict(d)
    except DescriptionError as exc:
        assert str(exc)
        return
    assert isinstance(desc, RobotDescription)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(damaged(_BASE))
def test_from_dict_raises_only_description_errors(d):
    _assert_description_or_its_error(d)


_FANUC = description_to_dict(load_robot("fanuc_m20ia"))  # with a [coupling] table


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(damaged(_FANUC))
def test_from_dict_of_a_coupled_robot_raises_only_description_errors(d):
    _assert_description_or_its_error(d)


# ----------------------------------------------------------------------------- files
def test_load_by_path_and_file_errors(tmp_path: Path):
    src = Path(__file__).parents[2] / "src" / "plugcell" / "robots" / "smart_h4.toml"
    text = src.read_text(encoding="utf-8")
    good = tmp_path / "my_robot.toml"
    good.write_text(text, encoding="utf-8")
    assert load_robot(good).name == "smart_h4"
    assert load_robot(str(good)).name == "smart_h4"

    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("alpha = -60.0", 'alpha = "x"'), encoding="utf-8")
    with pytest.raises(
        DescriptionError, match=r"^bad\.toml: links\[6\]\.alpha: expected a number, got 'x'$"
    ):
        load_robot(bad)

    broken = tmp_path / "broken.toml"
    broken.write_text("name = \n", encoding="utf-8")
    with pytest.raises(DescriptionError, match=r"^broken\.toml: invalid TOML"):
        load_robot(broken)

    missing = tmp_path / "nope.toml"
    with pytest.raises(RobotNotFoundError, match="file not found"):
        load_robot(missing)
    with pytest.raises(
        RobotNotFoundError, match=r"unknown robot 'kuka'; available robots: .*smart_h4"
    ):
        load_robot("kuka")
