"""Identifiability: the numerical method finds the thesis's parameter sets on its own.

Tables 6-2 (34 geometric), the 30 of the standardized serial model, G1–G3, and
Table 6-3 — which the numerical method corrects in two places (D5 is A5 scaled
by d6; A2 is −a2·G1 when every pose carries the same payload).  The analytic
rules of 6.2.3 are the cross-check.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from calibration_testlib import random_frame

from plugcell.calibration.identifiability import (
    THESIS_CONDITION_LIMIT,
    analyse,
    combinations_at,
    structural_identifiability,
)
from plugcell.calibration.model import ErrorModel

#: Table 6-2, primes restored: BASE, links, PROBE frame 7.
TABLE_6_2 = {
    "a0", "b0", "alpha0", "beta0",
    "theta1", "d1", "a1", "alpha1",
    "theta2", "a2",
    "theta2'", "a2'", "alpha2'", "beta2'",
    "a3'", "alpha3'", "beta3'",
    "d3", "a3", "alpha3",
    "theta4", "d4", "a4", "alpha4",
    "theta5", "d5", "a5", "alpha5",
    "theta6", "d6", "a6", "alpha6",
    "theta7", "d7",
}
#: The standardized serial model (eq. 6.3, rule 4.13): 4 + 4·6 + 2 = 30.
SERIAL_30 = {
    "a0", "b0", "alpha0", "beta0",
    "theta1", "d1", "a1", "alpha1",
    "theta2", "a2", "alpha2", "beta2",
    "theta3", "d3", "a3", "alpha3",
    "theta4", "d4", "a4", "alpha4",
    "theta5", "d5", "a5", "alpha5",
    "theta6", "d6", "a6", "alpha6",
    "theta7", "d7",
}
#: Table 6-3 (15) minus D5 (≡ A5·d6) and A2 (≡ −a2·G1 at one payload).
PAYLOAD_13 = {"A2'", "B2'", "C2'", "D2'", "A4", "B4", "C4", "D4", "A5", "B5", "C5", "B6", "C6"}


@pytest.fixture(scope="module")
def full(h4):
    m = ErrorModel.create(h4, "loop", gravity=True, payload=True, payload_ref_kg=36.0)
    probe = np.eye(4)
    probe[:3, 3] = (0.045, -0.03, 0.14)
    m = m.with_references(probe=probe)
    return m, structural_identifiability(m)


def _kinds(model, keys, *kinds):
    return {k for k in keys if model.space[k].kind in kinds}


def test_smart_h4_loop_model_lands_on_table_6_2_and_g1_g3(full):
    model, ident = full
    assert _kinds(model, ident.kept, "base", "link", "probe") == TABLE_6_2
    assert _kinds(model, ident.kept, "gravity") == {"G1", "G2", "G3"}
    assert _kinds(model, ident.kept, "payload") == PAYLOAD_13
    assert len(ident.kept) == 34 + 3 + 13
    # thesis 4.10: well conditioned on spread configurations (the thesis: 92.04)
    assert ident.condition_number < THESIS_CONDITION_LIMIT


def test_table_6_3_zero_columns_and_its_two_dependencies(full):
    model, ident = full
    assert set(ident.zero) == {"A1", "B1", "C1", "D1", "B2", "C2", "D2", "A6", "D6"}
    d6 = model.structure.desc.link("6").d
    # D5's column is A5's divided by d6 (a5 = a6 = 0): z4 × (p6 − p4) = d6 (z4 × a)
    assert dict(ident.combinations["A5"])["D5"] == pytest.approx(1.0 / d6, rel=1e-9)
    # one payload for every pose: K_(2,3) = −a2 cos θ2, the regressor of G1
    a2 = model.structure.desc.link("2").a
    assert dict(ident.combinations["G1"])["A2"] == pytest.approx(-a2, rel=1e-9)


def test_mixed_payloads_separate_a2_from_g1(h4):
    m = ErrorModel.create(h4, "loop", gravity=True, payload=True, payload_ref_kg=36.0)
    from plugcell.calibration.identifiability import random_configurations
    from plugcell.calibration.jacobian import identification_jacobian

    keys = m.space.by_priority()
    q = random_configurations(m, 60, 0)
    H = identification_jacobian(m, m.batch(q, np.resize([0.0, 18.0, 36.0], 60)), keys).H
    ident = analyse(H.reshape(-1, len(keys)), keys)
    assert _kinds(m, ident.kept, "payload") == PAYLOAD_13 | {"A2"}


def test_combinations_are_those_of_6_2_3_and_table_8_1(full):
    model, ident = full
    c = {k: dict(v) for k, v in ident.combinations.items()}
    # 6.2.3: x4' = −x2' → a4' identified through a2'; θ3 through θ2'
    assert c["a2'"] == {"a2'": 1.0, "a4'": -1.0}
    assert c["theta2'"] == {"theta2'": 1.0, "theta3": 1.0}
    # BASE θ0, d0 grouped into θ1, d1 (6.2.2)
    assert c["theta1"] == {"theta1": 1.0, "theta0": 1.0}
    assert c["d1"] == {"d1": 1.0, "d0": 1.0}
    # translations along the parallel loop axes: d3 stands for d2' + d3' + d4' + d3
    for k in ("d2'", "d3'", "d4'"):
        assert c["d3"][k] == 1.0
    # α4', β4' through (α3, θ4) — Table 8-1 with sin and cos in their right places
    s7, c7 = math.sin(math.radians(7)), math.cos(math.radians(7))
    assert c["alpha3"]["alpha4'"] == pytest.approx(s7, rel=1e-9)
    assert c["theta4"]["alpha4'"] == pytest.approx(c7, rel=1e-9)
    assert set(ident.via["beta4'"]) >= {"alpha3", "theta4"}
    names = dict(zip(model.space.keys, model.space.names, strict=True))
    assert ident.stands_for("a2'", names) == "Δa2' − Δa4'"


def test_serial_model_has_the_standard_30(h4):
    m = ErrorModel.create(h4, "serial", gravity=True)
    ident = structural_identifiability(m)
    assert _kinds(m, ident.kept, "base", "link", "probe") == SERIAL_30
    assert _kinds(m, ident.kept, "gravity") == {"G1", "G2", "G3"}
    assert dict(ident.combinations["d3"]) == {"d3": 1.0, "d2": 1.0}


def test_position_only_data_lose_the_target_orientation(full, h4):
    model, _ = full
    ident = structural_identifiability(model, position_only=True)
    geo = _kinds(model, ident.kept, "base", "link", "probe")
    # the target point's offset stays as three translations (d6, a6, d7)
    assert len(geo) == 31 and TABLE_6_2 - geo == {"theta6", "alpha6", "theta7"}


def test_serial_robot_without_loop(ur10):
    m = ErrorModel.create(ur10, "loop", gravity=True, payload=True, payload_ref_kg=5.0)
    assert m.structure.family == "serial"
    rng = np.random.default_rng(0)
    m = m.with_references(random_frame(rng), random_frame(rng, 0.3, 0.1))
    ident = structural_identifiability(m)
    geo = _kinds(m, ident.kept, "base", "link", "probe")
    assert len(geo) == 4 * 6 + 6  # Schröer: 4R + 2P + 6
    assert {"beta2", "beta3"} <= geo and not {"d2", "d3"} & geo  # parallel axes 2-3-4
    grav = _kinds(m, ident.kept, "gravity")
    assert "c1" not in grav and {"c2", "c3"} <= grav  # joint 1 vertical: no gravity torque


def test_rank_revealing_order_and_condition_rule():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(200, 4))
    H = np.column_stack([A, A[:, 0] - 2 * A[:, 1], A[:, 2] + 1e-4 * rng.normal(size=200)])
    keys = ["p", "q", "r", "s", "dup", "weak"]
    ident = analyse(H, keys)
    assert ident.dropped == ("dup",) and dict(ident.combinations["q"])["dup"] == pytest.approx(-2)
    assert ident.condition_number > 1e3
    # (4.10): remove the parameter dominating the last right singular vector
    ruled = analyse(H, keys, condition_limit=100.0)
    assert ruled.eliminated in (("weak",), ("r",)) and ruled.condition_number < 100
    # priority decides which of two dependent parameters is kept
    order = [4, 1, 0, 2, 3, 5]
    assert analyse(H[:, order], [keys[i] for i in order]).dropped == ("p",)


def test_combinations_at_a_perturbed_point_stay_close_to_nominal(full):
    model, ident = full
    geo = [k for k in ident.kept if model.space[k].is_geometric]
    dropped = [k for k in ident.dropped if model.space[k].is_geometric]
    moved = model.updated({"a2'": 2e-3, "a4'": -4e-3, "a2": -1e-3, "a3'": -3e-3})
    c = combinations_at(moved, geo, dropped)
    coef = dict(c["a2'"])["a4'"]
    assert coef != -1.0 and coef == pytest.approx(-1.0, abs=2e-2)
