"""Mode (b), the robot drives and the PC corrects: the robot service's CORRECT requests
read into a correction (bad input refused with the reason), the offsets brought into the
stream's space, and a calibration's compensation following the path (issue 37 §1).

No sockets here: the corrections over UDP, against the twin running its own program, are
``test_service_corrects.py``.
"""

from __future__ import annotations

import asyncio
import time
import types

import numpy as np
import pytest
from calibrated import calibrated
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.compensation import IdentifiedModel, NominalModel, compensate_joints
from plugcell.devices.robot.corrections import CORRECT_COMMANDS, PathCorrections
from plugcell.devices.robot.egm import EgmConfig
from plugcell.devices.robot.rsi import RsiConfig
from plugcell.devices.robot.stream.correcting import (
    CorrectionSpec,
    controller_model,
    correction_space,
    make_source,
)
from plugcell.devices.robot.stream.source import CycleState
from plugcell.framework.service import DeviceError
from plugcell.io.robots import load_robot
from plugcell.kinematics import forward, inverse
from plugcell.kinematics.path_frame import (
    applied_displacement,
    path_frame,
    path_tangents,
    to_path,
)
from plugcell.kinematics.pose_corrections import correct_pose
from plugcell.kinematics.transforms import so3_log
from plugcell.sim.twin.scenario import TwinScenario

Q = np.radians([-15.0, -75.0, -190.0, 0.0, 75.0, 0.0])
RSI_JOINT = RsiConfig(robot_host="127.0.0.1", correction="joint", mode="absolute")
RSI_TOOL = RsiConfig(robot_host="127.0.0.1", correction="cartesian", mode="relative",
                     frame="tool")
EGM_PATH = EgmConfig(robot_host="127.0.0.1", mode="pathcorr")
COMMANDS = {c.name: c for c in CORRECT_COMMANDS}


def _corrections(config, max_mm: float = 5.0, max_deg: float = 1.0) -> PathCorrections:
    controller = types.SimpleNamespace(config=config, correct_max=(max_mm, max_deg))
    return PathCorrections(controller, "smart_h4")


def _state(q_path, offset, t: float = 0.0) -> CycleState:
    """A cycle whose set-point joints are the path's plus the offset commanded so far."""
    offset = np.asarray(offset, dtype=float)
    robot = types.SimpleNamespace(joints=q_path + offset, joints_setpoint=q_path + offset)
    return CycleState(robot=robot, offset=offset, session=1, cycle=0, t=t)


def test_a_constant_offset_reads_in_robot_units_and_lands_in_si():
    spec = _corrections(RSI_JOINT).spec(["offset", "offset=1,-2,0.5,0,0,0.1", "ramp=0.25",
                                         "duration=3"])
    assert spec.source == "offset" and spec.frame == "base"
    np.testing.assert_allclose(spec.offset, [1e-3, -2e-3, 0.5e-3, 0, 0, np.radians(0.1)])
    assert spec.ramp_s == 0.25 and spec.duration_s == 3.0
    # the stream's space is joints: its largest correction is max_deg per joint
    np.testing.assert_allclose(spec.max_offset, np.radians([1.0] * 6))
    assert _corrections(RSI_TOOL).spec(["external"]).frame == "tool"  # the stream's frame
    assert _corrections(EGM_PATH).spec(["external"]).frame == "path"


@pytest.mark.parametrize(("config", "items", "why"), [
    (RSI_JOINT, [], "unknown correction source ''"),
    (RSI_JOINT, ["tracker"], "unknown correction source 'tracker': one of offset, "
                             "compensation, external"),
    (RSI_JOINT, ["offset", "speed=3"], "bad CORRECT item 'speed=3': expected key=value"),
    (RSI_JOINT, ["offset", "offset"], "bad CORRECT item 'offset'"),
    (RSI_JOINT, ["offset", "offset=1,2,3"], "offset='1,2,3': expected 6 finite numbers"),
    (RSI_JOINT, ["offset", "offset=1,2,3,4,5,x"], "offset='x': expected a number"),
    (RSI_JOINT, ["offset", "offset=0,0,nan,0,0,0"], "expected 6 finite numbers"),
    (RSI_JOINT, ["offset", "offset=0,0,6,0,0,0"],
     "offset Z 6 mm beyond the largest correction 5 mm (correct_max_mm"),
    (RSI_JOINT, ["offset", "frame=joints", "offset=0,0,0,0,0,2"],
     "offset A6 2 ° beyond the largest correction 1 °"),
    (RSI_JOINT, ["offset", "frame=world"], "unknown frame 'world'"),
    (RSI_JOINT, ["offset", "ramp=0"], "ramp: a positive duration"),
    (RSI_JOINT, ["offset", "duration=-1"], "duration: seconds ≥ 0"),
    (RSI_JOINT, ["compensation"], "a compensation needs its calibration"),
    (RSI_JOINT, ["offset", "tcp=1,2,3"], "tcp='1,2,3': expected 6 finite numbers"),
    (RSI_TOOL, ["offset", "frame=base"], "an offset in the base frame cannot be sent as this "
                                         "stream's corrections (Cartesian corrections in the "
                                         "tool frame): give it in the tool frame"),
    (EGM_PATH, ["offset", "offset=0,0,1,0,0,0.5"], "EGM path corrections carry a position "
                                                   "only"),
    (EGM_PATH, ["offset", "offset=0.5,1,0,0,0,0"], "X is the path's direction, which the "
                                                   "controller does not correct"),
])
def test_bad_requests_are_refused_with_the_reason(config, items, why):
    with pytest.raises(ValueError) as err:
        make_source(_corrections(config).spec(items), config)
    assert why in str(err.value)


def test_a_stream_where_the_pc_drives_cannot_correct_the_controllers_path():
    with pytest.raises(ValueError, match=r"EGM corrects the controller's own path with path "
                                         r"corrections \(EGMMoveL\): the stream is in joint"):
        correction_space(EgmConfig(robot_host="127.0.0.1", mode="joint"))
    assert correction_space(RSI_JOINT) == "joints"
    assert correction_space(RSI_TOOL) == "tool"


def test_a_service_that_is_not_streamed_says_so():
    line = PathCorrections(None, "smart_h4")
    for name, command in COMMANDS.items():
        with pytest.raises(DeviceError, match=f"{name}: corrections on the controller's own "
                                              "path need a robot streamed over RSI or EGM"):
            asyncio.run(line.perform(command, "", None))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.text(max_size=30), max_size=6))
def test_any_request_reads_or_is_refused_with_a_value_error(items):
    corrections = _corrections(RSI_JOINT)
    try:
        spec = corrections.spec(items)
    except ValueError as exc:
        assert str(exc)
        return
    assert isinstance(spec, CorrectionSpec)
    assert np.all(np.abs(spec.offset) <= np.array([5e-3] * 3 + [np.radians(1)] * 3) + 1e-15)


@pytest.mark.parametrize("frame", ["base", "tool"])
def test_a_cartesian_offset_on_a_joint_stream_moves_the_tcp_by_it(frame):
    """Δq = J⁺(q)·o at the path's joints: the nominal TCP then moves by o to first order."""
    desc = load_robot("smart_h4")
    T0 = forward(desc, None, Q, "nominal").tcp
    errors = []
    for size in (1.0, 0.1):
        o = size * np.array([0.3e-3, -0.2e-3, 0.5e-3, 0, 0, 0])
        running = make_source(CorrectionSpec("offset", tuple(o), frame=frame,
                                             robot="smart_h4"), RSI_JOINT)
        running.close()
        dq = running.goal_now(_state(Q, np.zeros(6)))
        T1 = forward(desc, None, Q + dq, "nominal").tcp
        want = o[:3] if frame == "base" else T0[:3, :3] @ o[:3]
        errors.append(np.linalg.norm(T1[:3, 3] - T0[:3, 3] - want))
        assert errors[-1] < 1e-3 * np.linalg.norm(o)
        assert np.linalg.norm(so3_log(T1[:3, :3] @ T0[:3, :3].T)) < 1e-3 * np.linalg.norm(o)
    assert errors[1] < errors[0] / 50  # the error is second order: exact to first order


@pytest.fixture(scope="module")
def calibration(tmp_path_factory):
    return calibrated(tmp_path_factory.mktemp("params"))


def test_the_compensation_follows_the_path_to_the_thesis_compensation(calibration):
    """Cycle by cycle on a moving path, one Newton step each: the offset becomes the model's
    compensation of the path's joints (eq. 4.11, as compensate_joints)."""
    result, path = calibration
    spec = _corrections(RSI_JOINT, max_deg=1.0).spec(["compensation", f"calibration={path}",
                                                      "ramp=0.1"])
    running = make_source(spec, RSI_JOINT)
    running.close()  # g computed here, cycle by cycle (the link's cycle takes it from a thread)
    model = IdentifiedModel(result.model)
    nominal = NominalModel(model.description, tool=model.tool)
    offset = np.zeros(6)
    for k in range(150):  # 0.6 s at 4 ms; the path turns A1 at 10 °/s
        q_path = Q + np.radians([10.0 * 0.004 * k, 0, 0, 0, 0, 0])
        offset = running.goal_now(_state(q_path, offset, 0.004 * k))
    want = compensate_joints(model, nominal.evaluate(q_path)[0], q_path,
                             result.model.payload_ref_kg).q.reshape(-1) - q_path
    assert np.max(np.abs(want)) > np.radians(0.005)  # a real correction
    np.testing.assert_allclose(offset, want, atol=np.radians(2e-5))
    T = model.evaluate(q_path + offset, result.model.payload_ref_kg)[0][0]
    np.testing.assert_allclose(T[:3, 3], nominal.evaluate(q_path)[0][0][:3, 3], atol=2e-6)


def _compensated(result, q_path):
    """The thesis's compensation of the path's joints: ``q_path + Δq`` (rad), and the
    identified and nominal models."""
    model = IdentifiedModel(result.model)
    nominal = NominalModel(model.description, tool=model.tool)
    q_c = compensate_joints(model, nominal.evaluate(q_path)[0], q_path,
                            result.model.payload_ref_kg).q.reshape(-1)
    return q_c, model, nominal


def _controller_joints(desc, T, seed):
    """What the controller commands for the pose T: its nominal inverse kinematics."""
    ik = inverse(desc, None, T, seed=seed, target="tcp", closure="nominal")
    return np.asarray(ik.q, dtype=float)


@pytest.mark.parametrize(("frame", "tcp"), [("base", ""), ("tool", ""),
                                           ("base", "tcp=50,-30,240,20,5,-10"),
                                           ("tool", "tcp=50,-30,240,20,5,-10")])
def test_the_compensation_over_cartesian_corrections_commands_the_compensated_joints(
        calibration, frame, tcp):
    """RSI RKorr: cycle by cycle on a moving path, the controller applying each answer in
    its frame about its TCP (its nominal IK of the corrected pose), the compensation's
    Cartesian correction makes it command the thesis's compensated joints (eq. 4.11) — with
    the description's tool as the TCP, or the one CORRECT's tcp= names."""
    result, path = calibration
    config = RsiConfig(robot_host="127.0.0.1", correction="cartesian", mode="absolute",
                       frame=frame)
    spec = _corrections(config, max_mm=5.0, max_deg=1.0).spec(
        ["compensation", f"calibration={path}", *([tcp] if tcp else [])])
    running = make_source(spec, config)
    running.close()
    desc = controller_model("smart_h4", spec.tcp)
    if tcp:
        np.testing.assert_allclose(desc.tool[:3, 3], [0.05, -0.03, 0.24])
    o = np.zeros(6)
    q_set = Q.copy()
    for k in range(60):  # the path turns A1 at 10 °/s
        q_path = Q + np.radians([10.0 * 0.004 * k, 0, 0, 0, 0, 0])
        T_c = correct_pose(forward(desc, None, q_path, "nominal").tcp, o, frame)
        q_set = _controller_joints(desc, T_c, q_set)
        robot = types.SimpleNamespace(joints=q_set, joints_setpoint=q_set)
        o = running.goal_now(CycleState(robot=robot, offset=o, session=1, cycle=k,
                                        t=0.004 * k))
    q_c, _, _ = _compensated(result, q_path)
    assert np.max(np.abs(o[:3])) > 0.1e-3  # a real correction: tenths of a millimetre
    T_c = correct_pose(forward(desc, None, q_path, "nominal").tcp, o, frame)
    np.testing.assert_allclose(_controller_joints(desc, T_c, q_set), q_c,
                               atol=np.radians(2e-5))


def test_the_compensation_over_egm_path_corrections_corrects_across_the_path(calibration):
    """EGM path correction: the compensated point's shift in ABB's path coordinate system,
    y and z sent, x (the path's direction) not; the controller displacing its TCP by
    ``R · (0, c_y, c_z)`` (its own path frame, the program's tangent) puts that point where
    the program meant it across the path, the part along the path and the rotation it
    cannot carry reported (CORRECT_STATUS's X and A, B, C)."""
    result, path = calibration
    spec = _corrections(EGM_PATH).spec(["compensation", f"calibration={path}", "ramp=0.1"])
    running = make_source(spec, EGM_PATH)
    running.close()
    desc = load_robot("smart_h4")
    n = 60  # the path turns A1 at 10 °/s, 4 ms a cycle
    q_prog = Q + np.radians(10.0 * 0.004 * np.arange(n + 1))[:, None] * np.eye(6)[0]
    T_prog = forward(desc, None, q_prog, "nominal").tcp
    frames = path_frame(path_tangents(T_prog[:, :3, 3]), T_prog[:, :3, 2])
    c = np.zeros(6)
    q_set = Q.copy()
    sent = []
    for k in range(n):
        T_c = T_prog[k].copy()
        T_c[:3, 3] += applied_displacement(c[:3], frames[k])  # as the controller does
        q_set = _controller_joints(desc, T_c, q_set)
        robot = types.SimpleNamespace(joints=q_set, joints_setpoint=q_set)
        c = running.goal_now(CycleState(robot=robot, offset=c, session=1, cycle=k,
                                        t=0.004 * k))
        if k <= 1:  # no frame before the path moves, then the shift ramps in from 0
            assert not np.any(c)
        sent.append(np.linalg.norm(c))
    assert 0 < sent[3] < sent[10] < sent[-1]  # ramped in, not a jump
    q_path = q_prog[n - 1]
    q_c, model, nominal = _compensated(result, q_path)
    assert c[0] == 0 and np.all(c[3:] == 0)
    p = nominal.evaluate(np.stack([q_path, q_c]))[0][:, :3, 3]
    R = frames[n - 1]
    want = to_path(p[1] - p[0], R)
    # the sensor's tangent is the chord of the last cycle: half a cycle behind the
    # controller's (10 °/s · 2 ms = 0.35 mrad of a millimetre: well under a micrometre)
    np.testing.assert_allclose(c[1:3], want[1:], atol=1e-6)
    assert running.along_path == pytest.approx(want[0], abs=1e-6)
    T_c = T_prog[n - 1].copy()
    T_c[:3, 3] += applied_displacement(c[:3], R)
    reached = model.evaluate(_controller_joints(desc, T_c, q_set),
                             result.model.payload_ref_kg)[0][0][:3, 3]
    before = model.evaluate(q_path, result.model.payload_ref_kg)[0][0][:3, 3]
    error_off = np.linalg.norm(before - p[0])
    assert error_off > 0.3e-3
    left = to_path(reached - p[0], R)
    assert np.linalg.norm(left[1:]) < error_off / 20  # across the path: corrected
    assert left[0] == pytest.approx(-want[0], abs=error_off / 20)  # along it: left
    Rn = nominal.evaluate(np.stack([q_path, q_c]))[0][:, :3, :3]
    np.testing.assert_allclose(running.uncorrected, so3_log(Rn[1] @ Rn[0].T), atol=1e-8)
    assert np.linalg.norm(running.uncorrected) > np.radians(0.001)


def test_a_compensation_where_the_arm_stands_takes_the_frame_the_path_last_moved_in(
        calibration):
    """The EGM link's last chord of the path (``path_chord``, taken while it sent no
    correction) gives a compensation started at a fine point its path frame at once."""
    from plugcell.devices.robot.egm.link import PATH_CHORD_RAD, EgmLink
    from plugcell.devices.robot.egm.messages import EgmState

    result, path = calibration
    link = EgmLink(EGM_PATH)
    q_b = Q + np.radians([0.5, 0, 0, 0, 0, 0])
    for k, q in enumerate([Q, Q + 0.3 * PATH_CHORD_RAD, q_b, q_b, q_b]):
        link._watch_path(EgmState(seqno=k, tm=4 * k, joints=q, planned_joints=q))
    a, b = link.path_chord
    np.testing.assert_array_equal(a, Q)
    np.testing.assert_array_equal(b, q_b)
    spec = _corrections(EGM_PATH).spec(["compensation", f"calibration={path}"])
    running = make_source(spec, EGM_PATH, (a, b))
    running.close()
    robot = types.SimpleNamespace(joints=q_b, joints_setpoint=q_b)
    c = running.goal_now(CycleState(robot=robot, offset=np.zeros(6), session=1, cycle=0, t=0))
    assert np.linalg.norm(c) > 1e-4  # sent from the first cycle: no frame to wait for
    for k in range(1, 8):  # Newton's steps converge where it stands (the shift not applied)
        c = running.goal_now(CycleState(robot=robot, offset=np.zeros(6), session=1, cycle=k,
                                        t=0.004 * k))
    desc = load_robot("smart_h4")
    T = forward(desc, None, np.stack([Q, q_b]), "nominal").tcp
    R = path_frame(T[1, :3, 3] - T[0, :3, 3], T[1, :3, 2])
    q_c, _, nominal = _compensated(result, q_b)
    p = nominal.evaluate(np.stack([q_b, q_c]))[0][:, :3, 3]
    want = to_path(p[1] - p[0], R)
    np.testing.assert_allclose(c[:3], [0.0, *want[1:]], atol=2e-7)
    assert running.along_path == pytest.approx(want[0], abs=2e-7)
    # a correction sent: the joints are the path's and more, no chord of the path
    link._limiter.offset = np.array([0, 1e-3, 0, 0, 0, 0])
    link._watch_path(EgmState(seqno=9, tm=36, joints=Q, planned_joints=Q))
    np.testing.assert_array_equal(link.path_chord[1], q_b)


def test_the_link_takes_the_newest_goal_computed_beside_it():
    """A conversion costs milliseconds: the cycle gets the newest g at once (zeros before
    the first), blended in; a failing g fails the next cycle with its reason."""
    spec = CorrectionSpec("offset", (0, 0, 0.5e-3, 0, 0, 0), frame="base", ramp_s=0.004,
                          max_offset=(np.radians(1),) * 6)
    running = make_source(spec, RSI_JOINT)
    try:
        want = running.goal_now(_state(Q, np.zeros(6)))
        got = np.zeros(6)
        for k in range(2000):
            got = np.asarray(running.source.correction(_state(Q, np.zeros(6), 1 + k)).offset)
            if np.any(got):
                break
            time.sleep(0.005)
        np.testing.assert_allclose(got, want, atol=1e-12)
        running.set(np.array([0, 0, 1.0, 0, 0, 0]))  # 1 m: beyond 1° on some joint
        with pytest.raises(ValueError, match="beyond the largest correction 1 °"):
            for k in range(2000):
                running.source.correction(_state(Q, np.zeros(6), 100 + k))
                time.sleep(0.005)
    finally:
        running.close()


def test_a_calibration_that_does_not_read_is_refused(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    for path, why in ((tmp_path / "missing.json", "cannot read"),
                      (bad, "not a plugcell calibration")):
        spec = _corrections(RSI_JOINT).spec(["compensation", f"calibration={path}"])
        with pytest.raises(ValueError, match=f"calibration .*{why}"):
            make_source(spec, RSI_JOINT)


@pytest.mark.slow
def test_the_corrector_superimposes_and_ends_ramped_out_on_the_twins_path():
    """In one process (the service's link in a thread): a Corrector on an RsiLink lifts the
    twin controller's own LIN by 0.5 mm in the base frame and puts it back."""
    import dataclasses

    from plugcell.devices.robot.rsi import RsiLink
    from plugcell.devices.robot.stream.correcting import Corrector
    from plugcell.sim.controller.own_program import linear_program, path_shift
    from plugcell.sim.controller.rsi_robot import RsiRobot
    from plugcell.sim.twin.dynamics import DynamicTwin

    arm = DynamicTwin(TwinScenario(robot="smart_h4", payload_kg=36.0), q0=Q)
    desc = arm.twin.description
    program = linear_program(desc, Q, [[0.0, 0.2, 0.0]], 0.1)
    config = RsiConfig(robot_host="127.0.0.1", listen_host="127.0.0.1", listen_port=0,
                       correction="joint", mode="absolute", timeout_packets=5000)
    shifts = []
    with RsiLink(config) as link:
        robot = RsiRobot(arm, dataclasses.replace(config, listen_port=link.address[1]),
                         path=program, path_delay_s=0.2, lockstep_s=0.5).start()
        try:
            assert link.wait(lambda lk: lk.streaming, 10)
            corrector = Corrector(link)
            corrector.start(CorrectionSpec("offset", (0, 0, 0.5e-3, 0, 0, 0), frame="base",
                                           ramp_s=0.3, duration_s=0.8))
            with pytest.raises(RuntimeError, match=r"a correction \(offset\) runs already"):
                corrector.start(CorrectionSpec("offset"))
            deadline = time.monotonic() + 60
            while corrector.poll() is None and time.monotonic() < deadline:
                k, q = robot.setpoint
                shifts.append(path_shift(desc, q, robot.path_poses[k]))
                time.sleep(0.01)
            assert corrector.poll() == "", corrector.poll()
            k, q = robot.setpoint
            np.testing.assert_allclose(path_shift(desc, q, robot.path_poses[k]), 0, atol=1e-9)
        finally:
            robot.stop()
    shifts = np.array(shifts)
    top = shifts[np.argmax(shifts[:, 2])]
    np.testing.assert_allclose(top, [0, 0, 0.5e-3], atol=2e-6)


def test_the_hooks_offset_beyond_the_limit_is_refused_before_it_reaches_the_stream():
    corrections = _corrections(RSI_JOINT)
    corrections.frame = "base"
    corrections.controller.corrector = types.SimpleNamespace(
        set_offset=lambda g: pytest.fail("an offset beyond the limit reached the corrector"))
    with pytest.raises(DeviceError, match="offset X 7 mm beyond the largest correction 5 mm"):
        asyncio.run(corrections.perform(COMMANDS["CORRECT_SET"], "", np.array([7.0, 0, 0, 0,
                                                                                 0, 0])))
