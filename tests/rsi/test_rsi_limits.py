"""Every correction is held to the limits — per-cycle step, speed, total offset — before
it leaves: clamped with the reason, or refused (never passed)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.devices.robot.rsi import CorrectionLimits, RsiConfig, RsiConfigError
from plugcell.devices.robot.stream.limits import OffsetLimiter
from plugcell.io.units import DEG

JOINTS = ("A1", "A2", "A3", "A4", "A5", "A6")
DEGS = (("deg", DEG),) * 6
T = 0.004


def limiter(policy: str = "clamp", step=0.1, speed=20.0, offset=10.0) -> OffsetLimiter:
    lim = CorrectionLimits((step * DEG,) * 6, (offset * DEG,) * 6, (speed * DEG,) * 6,
                           policy)
    return OffsetLimiter(lim, T, JOINTS, DEGS)


def test_within_the_limits_the_request_is_sent_as_is() -> None:
    lim = limiter()
    out = lim.apply(np.full(6, 0.05 * DEG))
    assert not (out.clamped or out.refused)
    np.testing.assert_allclose(out.step, 0.05 * DEG)
    out = lim.apply(np.full(6, 0.1 * DEG))
    np.testing.assert_allclose(out.step, 0.05 * DEG)
    np.testing.assert_allclose(out.offset, 0.1 * DEG)


def test_a_too_large_step_is_clamped_with_the_reason() -> None:
    lim = limiter(step=0.1, speed=100.0)  # the step binds: 0.1° < 100°/s · 4 ms = 0.4°
    out = lim.apply(np.array([0.5, 0, 0, 0, -0.3, 0]) * DEG)
    assert out.clamped and not out.refused
    np.testing.assert_allclose(out.step, np.array([0.1, 0, 0, 0, -0.1, 0]) * DEG)
    assert "A1 step 0.5 deg per cycle > 0.1 deg" in out.reason
    assert "A5 step 0.3 deg per cycle > 0.1 deg" in out.reason


def test_the_joint_speed_limit_caps_the_step() -> None:
    lim = limiter(step=1.0, speed=10.0)  # 10°/s · 4 ms = 0.04° < 1°
    out = lim.apply(np.array([0, 0.2, 0, 0, 0, 0]) * DEG)
    np.testing.assert_allclose(out.step[1], 0.04 * DEG)
    assert "A2 speed 50 deg/s > 10 deg/s" in out.reason


def test_the_total_offset_is_capped() -> None:
    lim = limiter(step=5.0, speed=10_000.0, offset=2.0)
    for _ in range(3):
        out = lim.apply(np.array([0, 0, -4.0, 0, 0, 0]) * DEG)
    np.testing.assert_allclose(out.offset[2], -2.0 * DEG)
    np.testing.assert_allclose(out.step[2], 0.0, atol=1e-15)
    assert "A3 offset 4 deg > 2 deg" in out.reason


def test_refuse_holds_and_keeps_the_offset() -> None:
    lim = limiter("refuse")
    lim.apply(np.full(6, 0.05 * DEG))
    out = lim.apply(np.full(6, 1.0 * DEG))
    assert out.refused and not out.clamped
    np.testing.assert_array_equal(out.step, 0.0)
    np.testing.assert_allclose(out.offset, 0.05 * DEG)
    np.testing.assert_allclose(lim.offset, 0.05 * DEG)  # nothing committed


@pytest.mark.parametrize("bad", [np.full(6, np.nan), np.array([0, 0, np.inf, 0, 0, 0]),
                                 np.zeros(5)])
def test_what_is_no_correction_is_refused_even_when_clamping(bad) -> None:
    out = limiter("clamp").apply(bad)
    assert out.refused
    np.testing.assert_array_equal(out.step, 0.0)


@settings(deadline=None)  # a loaded machine is slow, not wrong
@given(st.lists(st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6), min_size=1,
                max_size=30),
       st.sampled_from(["clamp", "refuse"]))
def test_nothing_beyond_the_limits_ever_leaves(requests, policy) -> None:
    lim = limiter(policy, step=0.1, speed=15.0, offset=0.5)
    bound = min(0.1, 15.0 * T) * DEG
    prev = np.zeros(6)
    for r in requests:
        out = lim.apply(np.array(r))
        assert np.all(np.abs(out.step) <= bound * (1 + 1e-12))
        assert np.all(np.abs(out.offset) <= 0.5 * DEG * (1 + 1e-12))
        np.testing.assert_allclose(out.offset - prev, out.step, atol=1e-15)
        prev = out.offset


@pytest.mark.parametrize(("kw", "message"), [
    ({"robot_host": "kuka.local"}, "robot_host 'kuka.local': expected an IP address"),
    ({"listen_port": 70000}, "listen_port 70000"),
    ({"robot_port": 0}, "robot_port 0"),
    ({"mode": "delta"}, "mode 'delta'"),
    ({"correction": "tool"}, "correction 'tool'"),
    ({"cycle": "1ms"}, "cycle '1ms'"),
    ({"timeout_packets": 0}, "timeout_packets 0"),
    ({"sentype": "Im Free"}, "sentype 'Im Free'"),
    ({"max_packet_bytes": 70000}, "max_packet_bytes 70000"),
])
def test_a_wrong_configuration_names_its_field(kw, message) -> None:
    args = {"robot_host": "192.168.1.147", **kw}
    with pytest.raises(RsiConfigError) as err:
        RsiConfig(**args)
    assert message in str(err.value)


def test_wrong_limits_name_their_field() -> None:
    with pytest.raises(RsiConfigError, match=r"max_offset\[2\] = -1.0"):
        CorrectionLimits((1,) * 6, (1, 1, -1, 1, 1, 1), (1,) * 6)
    with pytest.raises(RsiConfigError, match="max_step: expected 6 values"):
        CorrectionLimits((1,) * 5, (1,) * 6, (1,) * 6)
    with pytest.raises(RsiConfigError, match="policy 'ignore'"):
        CorrectionLimits((1,) * 6, (1,) * 6, (1,) * 6, "ignore")  # type: ignore[arg-type]


def test_the_configuration_knows_its_cycle_and_timeout() -> None:
    c = RsiConfig(robot_host="192.168.1.147", cycle="IPO", timeout_packets=50)
    assert (c.cycle_s, c.ipoc_step, c.timeout_s) == (0.012, 12, pytest.approx(0.6))
    assert c.limits.max_step == pytest.approx((0.1 * DEG,) * 6)  # the joint defaults
