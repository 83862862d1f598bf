"""joint_tour: a measuring order of joint configurations (nearest neighbours, largest
joint move as the distance), what plugcell plan and the RSI demo measure along."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from plugcell.calibration.planning import joint_tour


@settings(max_examples=80, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(0, 25), st.integers(1, 6)),
              elements=st.floats(-3.0, 3.0)))
def test_every_pose_once_from_the_one_nearest_the_mean_to_the_nearest_left(q) -> None:
    order = joint_tour(q)
    assert sorted(order.tolist()) == list(range(len(q)))
    if len(q) == 0:
        return
    d = lambda a, b: float(np.max(np.abs(a - b)))  # noqa: E731
    mean = q.mean(axis=0)
    assert d(q[order[0]], mean) == min(d(x, mean) for x in q)
    for i in range(1, len(order)):
        left = order[i:]
        assert d(q[order[i]], q[order[i - 1]]) == min(d(q[j], q[order[i - 1]]) for j in left)


def test_a_tour_is_shorter_than_the_random_order() -> None:
    q = np.random.default_rng(3).uniform(-2, 2, (40, 6))
    step = lambda x: np.max(np.abs(np.diff(x, axis=0)), axis=1).sum()  # noqa: E731
    assert step(q[joint_tour(q)]) < 0.6 * step(q)
