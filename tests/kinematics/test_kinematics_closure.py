"""Parallelogram closure: nominal (6.10) and exact four-bar (App. C), derivatives, failures."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.kinematics import LoopClosureError, fourbar_closure, nominal_closure

RNG = np.random.default_rng(21)
A2, A2P = 1.05, 0.45  # Table 6-1: arm 2 and crank 2'; coupler 3' = 1.05, follower 4' = 0.45


def _driven(n: int) -> tuple[np.ndarray, np.ndarray]:
    """θ2, θ2' with θ2 − θ2' in [25°, 155°] (the Smart H4's coupled limit)."""
    t2 = RNG.uniform(-2.9, -0.3, n)
    diff = np.radians(RNG.uniform(25, 155, n))
    return t2, t2 - diff


def _residual(t2, t2p, a2, a2p, a3p, a4p, t3, t4):
    """Closure equation (6.8): end of 2'→3'→4' minus end of 2, in the loop plane."""
    p1, p2, p3 = t2p, t2p + t3, t2p + t3 + t4
    x = a2p * np.cos(p1) + a3p * np.cos(p2) + a4p * np.cos(p3) - a2 * np.cos(t2)
    y = a2p * np.sin(p1) + a3p * np.sin(p2) + a4p * np.sin(p3) - a2 * np.sin(t2)
    return np.hypot(x, y)


def test_nominal_closure_is_6_10():
    t2, t2p = _driven(100)
    r = nominal_closure(t2, t2p)
    np.testing.assert_allclose(r.coupler, t2 - t2p, atol=0)
    np.testing.assert_allclose(r.follower, np.pi - t2 + t2p, atol=0)
    np.testing.assert_array_equal(r.d_driven[0], [[1, -1], [-1, 1]])  # eq. 6.16
    assert r.valid.all()


def test_fourbar_equals_nominal_for_nominal_lengths():
    t2, t2p = _driven(1000)
    ex = fourbar_closure(t2, t2p, A2, A2P, A2, A2P)
    nom = nominal_closure(t2, t2p)
    np.testing.assert_allclose(ex.coupler, nom.coupler, atol=1e-12)
    np.testing.assert_allclose(ex.follower, nom.follower, atol=1e-12)
    np.testing.assert_allclose(ex.d_driven, nom.d_driven, atol=1e-9)


def test_fourbar_closes_the_loop_with_perturbed_lengths():
    n = 5000
    t2, t2p = _driven(n)
    a = np.array([A2, A2P, A2, A2P]) + RNG.normal(0, 1e-3, (n, 4))  # ~mm errors
    r = fourbar_closure(t2, t2p, *a.T)
    res = _residual(t2, t2p, *a.T, r.coupler, r.follower)
    assert res.max() < 1e-12
    # branch continuous with the parallelogram: Δθ ≈ Δa/(a sin ψ) — mrad, not a flip
    assert np.abs(r.coupler - (t2 - t2p)).max() < 0.05
    assert np.abs(r.follower - (np.pi - t2 + t2p)).max() < 0.05


def test_fourbar_closes_for_a_far_from_parallelogram_loop():
    t2, t2p = _driven(500)
    r = fourbar_closure(t2, t2p, 1.0, 0.4, 1.1, 0.5)
    assert _residual(t2, t2p, 1.0, 0.4, 1.1, 0.5, r.coupler, r.follower).max() < 1e-12


def test_fourbar_derivatives_match_finite_differences():
    n = 200
    t2, t2p = _driven(n)
    a = np.array([A2, A2P, A2, A2P]) + RNG.normal(0, 5e-3, (n, 4))
    r = fourbar_closure(t2, t2p, *a.T)
    h = 1e-6

    def f(t2_, t2p_, aa):
        rr = fourbar_closure(t2_, t2p_, *aa.T)
        return np.stack([rr.coupler, rr.follower], -1)

    fd_q = np.stack(
        [
            (f(t2 + h, t2p, a) - f(t2 - h, t2p, a)) / (2 * h),
            (f(t2, t2p + h, a) - f(t2, t2p - h, a)) / (2 * h),
        ],
        -1,
    )
    np.testing.assert_allclose(r.d_driven, fd_q, rtol=1e-7, atol=1e-8)
    fd_a = np.stack(
        [(f(t2, t2p, a + h * e) - f(t2, t2p, a - h * e)) / (2 * h) for e in np.eye(4)], -1
    )
    np.testing.assert_allclose(r.d_lengths, fd_a, rtol=1e-7, atol=1e-7)


def test_length_derivatives_at_nominal_reproduce_6_18_6_19():
    """Thesis (6.18): Δθ3' = m11(Δa3' − Δa2) + m12(Δa4' − Δa2'), Δθ4' likewise, with
    (primes restored, ψ = θ2 − θ2'):
    m11 = cos ψ/(a2 sin ψ), m12 = −1/(a2 sin ψ),
    m21 = 1/(a2' sin ψ) − m11, m22 = −cos ψ/(a2' sin ψ) − m12  — eq. (6.19) as printed,
    reading the garbled â as a2 in m11, m12 and a2' in m21, m22."""
    t2, t2p = _driven(100)
    r = fourbar_closure(t2, t2p, A2, A2P, A2, A2P)
    psi = t2 - t2p
    c, s = np.cos(psi), np.sin(psi)
    m11, m12 = c / (A2 * s), -1 / (A2 * s)
    m21, m22 = 1 / (A2P * s) - m11, -c / (A2P * s) - m12
    D = r.d_lengths  # columns: a2 (arm), a2' (crank), a3' (coupler), a4' (follower)
    np.testing.assert_allclose(D[:, 0, 2], m11, rtol=1e-9)
    np.testing.assert_allclose(D[:, 0, 0], -m11, rtol=1e-9)
    np.testing.assert_allclose(D[:, 0, 3], m12, rtol=1e-9)
    np.testing.assert_allclose(D[:, 0, 1], -m12, rtol=1e-9)
    np.testing.assert_allclose(D[:, 1, 2], m21, rtol=1e-9)
    np.testing.assert_allclose(D[:, 1, 3], m22, rtol=1e-9)


def test_cannot_assemble():
    with pytest.raises(LoopClosureError, match="cannot be assembled"):
        # coupler + follower (0.5 m) cannot span the ~1.4 m gap
        fourbar_closure(-1.5, -3.2, A2, A2P, 0.25, 0.25)
    r = fourbar_closure(
        np.array([-1.5, -1.5]), np.array([-3.2, -3.2]), A2, A2P, np.array([A2, 0.25]), A2P,
        raise_errors=False,
    )  # fmt: skip
    np.testing.assert_array_equal(r.valid, [True, False])
    assert np.isnan(r.coupler[1]) and np.isfinite(r.coupler[0])


@pytest.mark.parametrize("diff", [0.0, np.pi, -np.pi, 2 * np.pi])
def test_collapse(diff):
    t2 = -1.2
    with pytest.raises(LoopClosureError, match="collapses"):
        nominal_closure(t2, t2 - diff)
    with pytest.raises(LoopClosureError, match="collapses"):
        fourbar_closure(t2, t2 - diff, A2, A2P, A2, A2P)
    # perturbed lengths: still no defined branch when arm and crank are aligned
    with pytest.raises(LoopClosureError):
        fourbar_closure(t2, t2 - diff, A2 + 1e-3, A2P, A2, A2P - 1e-3)


def test_error_names_the_configuration():
    t2 = np.array([-1.0, -1.0, -1.0])
    t2p = np.array([-2.5, -1.0, -2.0])
    with pytest.raises(LoopClosureError, match=r"configuration 1\b") as exc:
        nominal_closure(t2, t2p)
    assert exc.value.index == (1,)


_ANGLE = st.floats(-7.0, 7.0, allow_nan=False)
_LENGTH = st.floats(0.05, 2.0, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(ta=_ANGLE, tc=_ANGLE, lengths=st.tuples(_LENGTH, _LENGTH, _LENGTH, _LENGTH),
       shape=st.sampled_from([(), (1,), (1, 1)]))
def test_one_configuration_is_the_batchs_row(ta, tc, lengths, shape):
    """One configuration (however batched) takes the float path: the same angles and
    derivatives as that configuration in a batch of three, the batch's shape, and where
    the loop fails the same refusal (or, without errors, NaN and invalid)."""
    others = np.array([ta + 0.3, ta, ta - 0.2]), np.array([tc, tc, tc - 0.1])
    batch = fourbar_closure(*others, *lengths, raise_errors=False)
    one = fourbar_closure(*(np.reshape(x, shape) for x in (ta, tc, *lengths)),
                          raise_errors=False)
    assert one.coupler.shape == one.follower.shape == one.valid.shape == shape
    assert one.d_driven.shape == (*shape, 2, 2) and one.d_lengths.shape == (*shape, 2, 4)
    assert bool(one.valid) == bool(batch.valid[1])
    for name in ("coupler", "follower", "d_driven", "d_lengths"):
        np.testing.assert_allclose(np.reshape(getattr(one, name), -1),
                                   np.reshape(getattr(batch, name)[1], -1),
                                   rtol=1e-13, atol=1e-15, err_msg=name)
    if not batch.valid[1]:
        with pytest.raises(LoopClosureError, match=r"cannot be assembled|collapses"):
            fourbar_closure(ta, tc, *lengths)


def test_one_configuration_fails_as_a_batch_does():
    """A single configuration that cannot assemble is refused with its reason, and a
    single valid one's derivatives still match finite differences."""
    with pytest.raises(LoopClosureError, match="cannot be assembled") as exc:
        fourbar_closure(np.array([-1.5]), np.array([-3.2]), A2, A2P, 0.25, 0.25)
    assert exc.value.index == (0,)
    h = 1e-6
    t2, t2p, a = -1.2, -2.4, (1.0, 0.4, 1.1, 0.5)
    r = fourbar_closure(t2, t2p, *a)
    fd = [(np.array([x.coupler, x.follower]) - np.array([y.coupler, y.follower])) / (2 * h)
          for x, y in ((fourbar_closure(t2 + h, t2p, *a), fourbar_closure(t2 - h, t2p, *a)),
                       (fourbar_closure(t2, t2p + h, *a), fourbar_closure(t2, t2p - h, *a)))]
    np.testing.assert_allclose(r.d_driven, np.stack(fd, -1), rtol=1e-7, atol=1e-8)
