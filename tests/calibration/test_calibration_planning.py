"""The campaign planner (plugcell.calibration.planning): criteria, search, candidates."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.calibration import ErrorModel
from plugcell.calibration.identifiability import random_configurations
from plugcell.calibration.planning import (
    Candidates,
    PlanningError,
    PosePlanner,
    Visibility,
    _Search,
    criterion_value,
    filter_candidates,
    planning_keys,
    sample_candidates,
)
from plugcell.calibration.statistics import parameter_statistics
from plugcell.kinematics import Box

TRACKER = (4.6, 1.1, 0.35)  # the twin's tracker, robot base frame (m)


@pytest.fixture(scope="module")
def setup(h4):
    model = ErrorModel.create(h4, "loop", gravity=True)
    vis = Visibility(TRACKER, np.radians(45.0))
    cands = sample_candidates(model, 600, volume=h4.working_volume, visibility=vis, seed=3)
    keys = planning_keys(model)
    planner = PosePlanner(model, keys)
    return model, cands, keys, planner, planner.blocks(cands, keys)


def _scaled(H):
    return H / (np.linalg.norm(H.reshape(-1, H.shape[2]), axis=0) / np.sqrt(len(H)))


def _direct(Hs, criterion, region=None):
    """The criterion from the singular values of the stacked scaled Jacobian."""
    n, k = Hs.shape[0], Hs.shape[2]
    if criterion == "I":
        R = region.reshape(-1, k)
        Hf = Hs.reshape(-1, k)
        return -np.trace(R.T @ R / len(region) @ np.linalg.inv(Hf.T @ Hf / n))
    s = np.linalg.svd(Hs.reshape(-1, k), compute_uv=False) / np.sqrt(n)
    lam = s**2
    return {"D": 2 * np.sum(np.log(s)) / k, "A": -np.sum(1 / lam), "E": lam.min(),
            "O": lam.min() / np.sqrt(lam.max())}[criterion]


@pytest.mark.parametrize("criterion", ["D", "A", "E", "O", "I"])
def test_criterion_value_matches_direct_computation(setup, criterion):
    model, cands, keys, _, H = setup
    plan = PosePlanner(model, keys, criterion=criterion).plan(cands, 25, blocks=H)
    Hs = _scaled(H)
    assert plan.value == pytest.approx(_direct(Hs[plan.index], criterion, Hs), rel=1e-8)
    assert criterion_value(Hs[plan.index], criterion, region=Hs) == pytest.approx(
        plan.value, rel=1e-8)
    # I does not depend on the column scaling; D only by a constant
    if criterion == "I":
        assert criterion_value(H[plan.index], "I", region=H) == pytest.approx(plan.value,
                                                                                rel=1e-8)


def test_predicted_sigma_and_kappa_are_the_identifications(setup):
    _model, cands, keys, planner, H = setup
    plan = planner.plan(cands, 20, blocks=H)
    Hp = H[plan.index].reshape(-1, len(keys))
    # the identification's statistics with residuals whose σ² is the planner's noise²
    rng = np.random.default_rng(0)
    r = rng.standard_normal(Hp.shape[0])
    r *= plan.noise_m * np.sqrt((Hp.shape[0] - Hp.shape[1]) / (r @ r))
    stats = parameter_statistics(Hp, r)
    np.testing.assert_allclose(plan.sigma, stats.sigma, rtol=1e-6)
    assert plan.condition_number == pytest.approx(stats.condition_number, rel=1e-6)


@pytest.mark.parametrize("criterion", ["D", "A", "E", "O"])
def test_exchange_never_worsens_the_criterion(setup, criterion):
    *_, H = setup
    sel, history, exchanges = _Search(_scaled(H), criterion, None).run(18)
    assert len(sel) == 18 and len(set(sel.tolist())) == 18
    assert exchanges == len(history) - 1
    assert all(b > a for a, b in itertools.pairwise(history))


def test_rank_r_updates_match_a_fresh_factorisation(setup):
    *_, H = setup
    s = _Search(_scaled(H), "A", None)
    s.run(15)
    D, T = s.D.copy(), s.T.copy()
    s._update(7, +1.0)
    s._update(3, +1.0)
    s._update(7, -1.0)
    D1, T1 = s.D.copy(), s.T.copy()
    s._refresh()
    np.testing.assert_allclose(D1, s.D, rtol=1e-7, atol=1e-9 * np.abs(D).max())
    np.testing.assert_allclose(T1, s.T, rtol=1e-7, atol=1e-9 * np.abs(T).max())


def test_planned_beats_random(setup):
    model, cands, keys, planner, H = setup
    n = 20
    plan = planner.plan(cands, n, blocks=H)
    Hs = _scaled(H)
    rng = np.random.default_rng(7)
    random = [criterion_value(Hs[rng.choice(len(cands), n, replace=False)], "D")
              for _ in range(20)]
    assert plan.value > max(random)
    sig_random = [PosePlanner(model, keys).plan(cands.subset(rng.choice(len(cands), n, False)),
                                                n).sigma for _ in range(3)]
    assert np.median(plan.sigma) < min(np.median(s) for s in sig_random)


def test_deterministic(setup, h4):
    model, cands, keys, planner, H = setup
    a = planner.plan(cands, 20, blocks=H)
    b = PosePlanner(model, keys).plan(cands, 20)
    np.testing.assert_array_equal(a.index, b.index)
    c = sample_candidates(model, 600, volume=h4.working_volume,
                          visibility=Visibility(TRACKER, np.radians(45.0)), seed=3)
    np.testing.assert_array_equal(c.q, cands.q)


def test_plan_is_grouped_by_payload_for_model_5(h4):
    model = ErrorModel.create(h4, "loop", gravity=True, payload=True, payload_ref_kg=36.0)
    cands = sample_candidates(model, 900, payloads=(0, 18, 36), volume=h4.working_volume,
                              visibility=Visibility(TRACKER, np.radians(45.0)), seed=1)
    assert set(np.unique(cands.payload_kg)) == {0.0, 18.0, 36.0}
    keys = planning_keys(model, (0, 18, 36))
    plan = PosePlanner(model, keys).plan(cands, 30)
    assert "A2" in keys and not plan.unidentifiable
    m = plan.payload_kg
    assert np.all(np.diff(m) >= 0), "one payload change per group"
    assert len(np.unique(m)) >= 2, "payload constants need at least two payloads"


def test_candidates_are_feasible(setup, h4):
    model, cands, *_ = setup
    assert np.all(h4.within_limits(cands.q))
    T = model.with_references(base=np.eye(4)).predict(cands.q)
    assert np.all(h4.working_volume.contains(T[:, :3, 3]))
    np.testing.assert_allclose(T[:, :3, 3], cands.targets, atol=1e-12)
    assert np.all(Visibility(TRACKER, np.radians(45.0)).angles(T) <= np.radians(45.0))


def test_visibility_angle():
    vis = Visibility((10.0, 0.0, 0.0), np.radians(30.0))
    T = np.broadcast_to(np.eye(4), (3, 4, 4)).copy()
    T[0, :3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]  # z axis along +x: facing the tracker
    T[2, :3, 3] = (10.0, 5.0, 0.0)                       # z up, tracker level: 90°
    np.testing.assert_allclose(np.degrees(vis.angles(T)), [0.0, 90.0, 90.0], atol=1e-9)
    assert vis.visible(T).tolist() == [True, False, False]


def test_filter_candidates_from_configurations(setup, h4):
    model = setup[0]
    q = random_configurations(model, 300, 5)
    c = filter_candidates(model, q, payloads=(0.0, 36.0), volume=h4.working_volume)
    assert len(c) % 2 == 0 and len(c) > 0
    np.testing.assert_array_equal(c.q[::2], q[c.source[::2]])
    own = filter_candidates(model, q, payload_kg=np.full(300, 5.0))
    assert len(own) == 300 and np.all(own.payload_kg == 5.0)


# ---------------------------------------------------------------------- bad input
def test_no_candidate_visible_is_a_clear_error(setup, h4):
    model = setup[0]
    behind = Visibility((-4.0, 0.0, 1.0), np.radians(2.0))
    with pytest.raises(PlanningError, match="line of sight"):
        sample_candidates(model, 50, volume=h4.working_volume, visibility=behind,
                          max_draws=20_000)
    with pytest.raises(PlanningError, match="volume"):
        sample_candidates(model, 50, volume=Box((30.0, 0.0, 0.0), (0.1, 0.1, 0.1)),
                          max_draws=20_000)
    with pytest.raises(PlanningError, match="none of the 40"):
        filter_candidates(model, random_configurations(model, 40, 1), visibility=behind)


def test_bad_arguments(setup):
    model, cands, keys, planner, H = setup
    with pytest.raises(PlanningError, match="only 600 candidates"):
        planner.plan(cands, 601, blocks=H)
    with pytest.raises(PlanningError, match="unknown criterion 'X'"):
        PosePlanner(model, keys, criterion="X")
    with pytest.raises(PlanningError, match="equations for"):
        planner.plan(cands, 3, blocks=H)
    with pytest.raises(PlanningError, match="positive"):
        planner.plan(cands, 0, blocks=H)
    with pytest.raises(PlanningError, match="region"):
        criterion_value(H, "I")
    with pytest.raises(PlanningError, match="acceptance"):
        Visibility(TRACKER, 0.0)
    with pytest.raises(PlanningError, match="payloads"):
        sample_candidates(model, 10, payloads=(-1.0,))
    with pytest.raises(PlanningError, match="joints"):
        filter_candidates(model, np.zeros((3, 4)))
    assert isinstance(cands, Candidates)


# ---------------------------------------------------------------------- properties


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from(["D", "A", "E", "O"]), st.integers(3, 6),
       st.sampled_from([3, 6]))
def test_search_on_random_problems(seed, criterion, n, r):
    """Any information structure: the exchanges only improve, the design has n distinct
    poses, and the tracked value equals the criterion recomputed from scratch."""
    rng = np.random.default_rng(seed)
    k = 5
    X = rng.standard_normal((30, r, k)) * rng.uniform(0.1, 3.0, k)
    n = max(n, -(-k // r))
    sel, history, _ = _Search(X, criterion, None).run(n)
    assert len(set(sel.tolist())) == n
    assert all(b > a for a, b in itertools.pairwise(history))
    Xs = X[sel].reshape(-1, k)
    M = Xs.T @ Xs
    M = M + 1e-10 * np.trace(M) / k * np.eye(k)  # the search's tiny ridge
    lam = np.linalg.eigvalsh(M / n)
    direct = {"D": np.sum(np.log(lam)) / k, "A": -np.sum(1 / lam), "E": lam[0],
              "O": lam[0] / np.sqrt(lam[-1])}[criterion]
    assert history[-1] == pytest.approx(direct, rel=1e-6, abs=1e-12)
