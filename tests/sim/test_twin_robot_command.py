"""``plugcell twin rsi`` / ``twin egm``: the twin's robot side as a command — it streams to
the PC's port and reports what it counted; bad options are refused with the reason."""

from __future__ import annotations

import argparse
import re
import socket
import threading
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.apps.cli import CommandError, main
from plugcell.apps.commands.twin_robot import _rsi_side
from plugcell.devices.robot.rsi.codec import encode_sen
from plugcell.io.units import DEG
from plugcell.sim.twin.scenario import TwinScenario

pytestmark = pytest.mark.timeout(60)


class _Sensor:
    """A bare RSI sensor on loopback: answers every <Rob> with an absolute A1 offset."""

    def __init__(self, a1_deg: float) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.offset = np.array([a1_deg * DEG, 0, 0, 0, 0, 0])
        self.answered = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data, peer = self.sock.recvfrom(65535)
            except (TimeoutError, OSError):
                continue
            ipoc = int(re.search(rb"<IPOC>(\d+)</IPOC>", data).group(1))
            self.sock.sendto(encode_sen(ipoc, "joint", self.offset), peer)
            self.answered += 1

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        self.sock.close()


def test_twin_rsi_streams_to_the_pc_and_reports_its_counts(capsys) -> None:
    sensor = _Sensor(0.5)
    try:
        status = main(["twin", "rsi", "--port", str(sensor.port), "--timeout", "10000",
                       "--lockstep", "1", "--duration", "0.6"])
    finally:
        sensor.close()
    out = capsys.readouterr().out.splitlines()
    assert status == 0
    assert out[0].startswith("twin rsi: smart_h4 streaming RSI (joint, absolute, IPO_FAST) "
                             "from 127.0.0.1:") and out[0].endswith(f"127.0.0.1:{sensor.port}")
    m = re.fullmatch(r"twin rsi: (\d+) cycles, (\d+) answered, Delay (\d+), "
                     r"largest correction A1 (\S+)°", out[-1])
    assert m, out[-1]
    cycles, answered = int(m[1]), int(m[2])
    assert cycles > 10 and answered >= cycles - 2 and answered <= sensor.answered
    assert float(m[4]) == pytest.approx(0.5)  # the sensor's absolute A1 offset, applied


def test_twin_rsi_runs_its_own_program_under_the_pcs_corrections(capsys) -> None:
    """--lin: the controller's own LIN (mode (b)); the sensor's absolute A1 offset shifts
    its TCP, and the summary says so."""
    sensor = _Sensor(0.01)
    try:
        status = main(["twin", "rsi", "--port", str(sensor.port), "--timeout", "10000",
                       "--lockstep", "1", "--lin", "0,2,0", "--speed", "100", "--path-delay",
                       "0", "--duration", "1.0"])
    finally:
        sensor.close()
    out = capsys.readouterr().out.splitlines()
    assert status == 0
    m = re.fullmatch(r"twin rsi: \d+ cycles, \d+ answered, Delay \d+, largest correction A1 "
                     r"0\.01°, path (done|not done), largest shift (\S+) mm", out[-1])
    assert m, out[-1]
    # 0.01° of A1 at the TCP's distance from the A1 axis (about 1.7 m here): ≈ 0.3 mm
    assert 0.2 < float(m[2]) < 0.4, out[-1]


def test_twin_rsi_stops_at_timeout_with_the_reason(capsys) -> None:
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    try:
        status = main(["twin", "rsi", "--port", str(silent.getsockname()[1]), "--timeout", "5",
                       "--duration", "10"])
    finally:
        silent.close()
    captured = capsys.readouterr()
    assert status == 3
    assert "RSI stopped: 5 late sensor packets reached the Timeout of 5" in captured.err
    assert "5 cycles, 0 answered, Delay 5" in captured.out


def test_twin_egm_stops_after_its_comm_timeout(capsys) -> None:
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    try:
        status = main(["twin", "egm", "--port", str(silent.getsockname()[1]), "--timeout",
                       "0.2", "--duration", "10"])
        got = silent.recv(65535)  # an EgmRobot came
    finally:
        silent.close()
    captured = capsys.readouterr()
    assert status == 3 and got
    assert "EGM communication timeout: no message from the sensor" in captured.err
    assert captured.out.startswith("twin egm: smart_h4 streaming EGM (joint)")
    assert ", 0 answers, " in captured.out


@pytest.mark.parametrize("argv, message", [
    (["rsi", "--port", "49152", "--joints", "1,2,3"], "twin rsi: q0: expected 6"),
    (["rsi", "--port", "49152", "--joints", "a,b,c,d,e,f"], "twin rsi: could not convert"),
    (["rsi", "--port", "70000"], "twin rsi: "),
    (["rsi", "--port", "49152", "--joints", "0,-170,-187,0,90,0"],
     "twin rsi: --joints outside the joint limits: joint 2 = -170.0000° outside"),
    (["egm", "--joints", "0,-170,-187,0,90,0"], "twin egm: --joints outside the joint limits"),
    (["rsi", "--port", "49152", "--timeout", "0"], "twin rsi: timeout_packets 0"),
    (["rsi", "--port", "49152", "--lockstep", "-1"], "twin rsi: lockstep_s must be 0"),
    (["rsi", "--port", "49152", "--duration", "-1"], "--duration must be 0 or positive"),
    (["rsi", "--port", "49152", "--lin", "0,30,0", "--end-after", "-1"],
     "--end-after must be 0 or positive seconds, not -1.0"),
    (["egm", "--mode", "pathcorr", "--lin", "0,30,0", "--end-after", "nan"],
     "--end-after must be 0 or positive seconds, not nan"),
    (["rsi", "--port", "49152", "--end-after", "1"],
     "twin rsi: --end-after ends the stream after the controller's own program: give it "
     "with --lin or --program"),
    (["egm", "--end-after", "1"], "twin egm: --end-after ends the stream after"),
    (["rsi", "--port", "49152", "--payload-kg", "-3"], "twin rsi: payload_kg must be ≥ 0"),
    (["egm", "--timeout", "0"], "twin egm: --timeout must be positive seconds, not 0.0"),
    (["rsi", "--port", "49152", "--lin", "0,300"], "twin rsi: --lin '0,300': expected "
                                                   "DX,DY,DZ in mm"),
    (["rsi", "--port", "49152", "--lin", "0,3000,0"],
     "twin rsi: the controller's program: move 0 (LIN): target unreachable"),
    (["rsi", "--port", "49152", "--lin", "0,30,0", "--speed", "0"],
     "twin rsi: the TCP speed must be positive"),
    (["egm", "--mode", "pathcorr"], "twin egm: --mode pathcorr runs the controller's own "
                                    "program: give it with --lin DX,DY,DZ or --program FILE"),
    (["rsi", "--port", "49152", "--program", "p.csv", "--lin", "0,30,0"],
     "twin rsi: --program or --lin: the controller runs one program"),
    (["rsi", "--port", "49152", "--program", "p.csv", "--joints", "0,-90,-187,0,90,0"],
     "twin rsi: --joints with --program: the program starts at its first point"),
    (["rsi", "--port", "49152", "--calibration", "c.json"],
     "twin rsi: --calibration reports the error of a program of its own"),
    (["rsi", "--port", "49152", "--lin", "0,30,0", "--library", "lib"],
     "twin rsi: --library goes with a .pdl --program"),
    (["rsi", "--port", "49152", "--program", "/nonexistent/p.csv"],
     "twin rsi: p.csv: cannot read"),
    (["egm", "--program", "/nonexistent/p.csv"], "twin egm: p.csv: cannot read"),
    (["rsi", "--port", "49152", "--lin", "0,30,0", "--calibration", "/nonexistent/c.json"],
     "twin rsi: calibration /nonexistent/c.json: cannot read"),
    (["egm", "--lin", "0,30,0"], "twin egm: --lin is the controller's own program of --mode "
                                 "pathcorr"),
    (["egm", "--mode", "pathcorr", "--lin", "0,30,0", "--path-delay", "-1"],
     "twin egm: path_delay_s must be ≥ 0"),
    (["egm", "--rt-priority", "0"], "twin egm: --rt-priority: rt_priority 0: expected 1..99"),
    (["rsi", "--port", "49152", "--rt-priority", "100"],
     "twin rsi: --rt-priority: rt_priority 100: expected 1..99"),
    (["rsi", "--port", "49152", "--cpu", "9999"], "twin rsi: --cpu '9999': CPU 9999 is not one "
                                                  "of this machine's"),
    (["egm", "--cpu", "1-x"], "twin egm: --cpu: CPU list '1-x': '1-x' is not a CPU number"),
])
def test_bad_options_are_refused_with_the_reason(argv, message, capsys) -> None:
    assert main(["twin", *argv]) == 2
    assert message in capsys.readouterr().err


def _args(joints: str) -> argparse.Namespace:
    return argparse.Namespace(ip="127.0.0.1", port=49152, bind="127.0.0.1:0", joints=joints,
                              correction="joint", mode="absolute", cycle="IPO_FAST",
                              timeout=100, lockstep=0.0, lin=[], speed=100.0, path_delay=1.0,
                              frame="base", program=None, library=[])


@settings(max_examples=60, deadline=None)
@given(st.one_of(
    st.text(alphabet="0123456789.,-e+ naN", max_size=40),
    st.lists(st.floats(-200, 200), min_size=5, max_size=7).map(
        lambda q: ",".join(f"{v:.3f}" for v in q))))
def test_any_joints_text_starts_the_arm_there_or_is_refused(text: str) -> None:
    try:
        arm, robot, _ = _rsi_side(_args(text), TwinScenario())
    except CommandError as exc:
        assert str(exc).startswith("twin rsi: ")
        return
    robot.stop()
    q = np.array([float(v) for v in text.split(",")]) if text else None
    if q is not None:
        assert np.allclose(np.degrees(arm.measured), q, atol=0.001)
        assert not arm.twin.description.limit_violations(arm.measured, tol=1e-6)


# ---------------------------------------------------------------- --program FILE (mode (b))
PATH_CSV = """# the controller's own program: 100 mm along y, then 30 mm down
x,y,z,a,b,c,speed
1473.3,-231.7,2488.4,-60,30,-90,
1473.3,-131.7,2488.4,-60,30,-90,100
1473.3,-131.7,2458.4,-60,30,-90,50
"""
PROGRAM_PDL = """PROGRAM own
VAR start, p : POSITION
BEGIN
  start := POS(1473.3, -231.7, 2488.4, -60, 30, -90)
  p := start
  p.Y := p.Y + 100
  MOVE TO start
  MOVE LINEAR TO p
  MOVE LINEAR TO start
END own
"""


def _program_args(program: str) -> argparse.Namespace:
    args = _args("")
    args.joints, args.program, args.path_delay = None, program, 0.0
    return args


@pytest.mark.parametrize(("name", "text", "points"), [
    ("path.csv", PATH_CSV, [[1473.3, -231.7, 2488.4], [1473.3, -131.7, 2458.4]]),
    ("own.pdl", PROGRAM_PDL, [[1473.3, -231.7, 2488.4], [1473.3, -231.7, 2488.4]]),
])
def test_a_program_file_is_the_controllers_own_path_from_its_first_point(
        tmp_path, name, text, points) -> None:
    """A path CSV (plugcell path run --path's) or a .pdl's straight moves: the arm starts
    at the first point and the controller's path ends at the last."""
    f = tmp_path / name
    f.write_text(text)
    arm, robot, _ = _rsi_side(_program_args(str(f)), TwinScenario())
    robot.stop()
    poses = robot.path_poses
    np.testing.assert_allclose(poses[0][:3, 3] * 1e3, points[0], atol=1e-3)
    np.testing.assert_allclose(poses[-1][:3, 3] * 1e3, points[1], atol=1e-3)
    # both go 100 mm along y (the CSV then down, the program back)
    assert np.max(poses[:, 1, 3]) * 1e3 == pytest.approx(-131.7, abs=1e-3)
    from plugcell.kinematics import forward

    T = forward(arm.twin.description, None, arm.measured, "nominal").tcp
    np.testing.assert_allclose(T[:3, 3] * 1e3, points[0], atol=0.05)  # encoder counts


@pytest.mark.parametrize(("text", "why"), [
    (PATH_CSV.replace(",100\n", ",-5\n"), "path.csv: line 4, column 'speed': speed must be > 0"),
    (PATH_CSV.replace("1473.3,-131.7,2458.4", "1473.3,-131.7,x"), "path.csv: line 5, column "
                                                                  "'z'"),
    (PATH_CSV.replace("2458.4", "9458.4"), "line 5"),
    ("x,y\n1,2\n", "path.csv: line 1"),
])
def test_a_bad_program_file_is_refused_naming_the_line(tmp_path, text, why, capsys) -> None:
    f = tmp_path / "path.csv"
    f.write_text(text)
    assert main(["twin", "rsi", "--port", "49152", "--program", str(f)]) == 2
    err = capsys.readouterr().err
    assert "twin rsi: " in err and why in err, err


_LINES = [*PATH_CSV.splitlines(), "", "x,y,z", "1,2", "a,b,c,d", "1473.3,-181.7,2488.4,,,,",
          "1473.3,-181.7,2488.4,-60,30,-90,0"]


@settings(max_examples=25, deadline=None)
@given(st.lists(st.sampled_from(_LINES), max_size=6))
def test_any_program_file_plans_or_is_refused_with_a_reason(tmp_path_factory, lines) -> None:
    f = tmp_path_factory.mktemp("p") / "path.csv"
    f.write_text("\n".join(lines) + "\n")
    try:
        _, robot, _ = _rsi_side(_program_args(str(f)), TwinScenario())
    except CommandError as exc:
        assert str(exc).startswith("twin rsi: ") and "path.csv" in str(exc), str(exc)
        return
    robot.stop()
    assert len(robot.path_poses) > 1


@pytest.mark.parametrize("side", ["rsi", "egm"])
def test_end_after_ends_the_stream_that_long_after_the_program(side, capsys) -> None:
    """--end-after S: the twin stops by itself S seconds after its program ended (exit 0,
    "path done"), as a controller whose program is done — a script waits for it instead
    of sleeping (docs/abb-egm.md, kuka-rsi.md).  The 20 mm LIN at 100 mm/s takes ~0.2 s
    plus its ramps, so the twin must end long before the 60 s --duration."""
    sensor = _Sensor(0.0) if side == "rsi" else None  # EGM: a PC that never answers
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    port = sensor.port if sensor is not None else silent.getsockname()[1]
    start = time.monotonic()
    try:
        mode = ["--lockstep", "1"] if side == "rsi" else ["--mode", "pathcorr"]
        status = main(["twin", side, "--port", str(port), "--timeout", "10000", *mode,
                       "--lin", "0,20,0", "--path-delay", "0", "--end-after", "0.5",
                       "--duration", "60"])
    finally:
        silent.close()
        if sensor is not None:
            sensor.close()
    took = time.monotonic() - start
    out = capsys.readouterr().out.splitlines()
    assert status == 0 and ", path done, " in out[-1], out[-1]
    assert took < 30, took  # ended by --end-after, not by --duration (a loose bound)


def test_twin_rsi_runs_a_program_file_under_the_pcs_corrections(tmp_path, capsys) -> None:
    f = tmp_path / "path.csv"
    f.write_text(PATH_CSV)
    sensor = _Sensor(0.01)
    try:
        status = main(["twin", "rsi", "--port", str(sensor.port), "--timeout", "10000",
                       "--lockstep", "1", "--program", str(f), "--path-delay", "0",
                       "--duration", "1.0"])
    finally:
        sensor.close()
    out = capsys.readouterr().out.splitlines()
    assert status == 0
    assert re.fullmatch(r"twin rsi: \d+ cycles, \d+ answered, Delay \d+, largest correction A1 "
                        r"0\.01°, path (done|not done), largest shift \S+ mm", out[-1]), out[-1]


def test_twin_egm_runs_a_program_file_with_egmmovel(tmp_path, capsys) -> None:
    """--mode pathcorr --program: the controller's own path from a file over EGM."""
    f = tmp_path / "path.csv"
    f.write_text(PATH_CSV)
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    try:
        status = main(["twin", "egm", "--port", str(silent.getsockname()[1]), "--timeout", "10",
                       "--mode", "pathcorr", "--program", str(f), "--path-delay", "0",
                       "--duration", "1"])
    finally:
        silent.close()
    out = capsys.readouterr().out.splitlines()
    assert status == 0
    assert out[0].startswith("twin egm: smart_h4 streaming EGM (pathcorr) from 127.0.0.1:")
    assert re.fullmatch(r"twin egm: \d+ samples, 0 answers, \d+ unanswered, largest path "
                        r"correction X 0\.00 mm, path (done|not done), largest shift "
                        r"0\.000 mm", out[-1]), out[-1]


# ------------------------------------------------ --rt-priority, --cpu, --mlock (the twin's)
class _Scheduler:
    """os.sched_setscheduler and sched_setaffinity as the kernel would answer them, recorded
    (never applied to the test's own process): granted, or refused as to a user without
    CAP_SYS_NICE."""

    def __init__(self, refuse: bool) -> None:
        self.refuse, self.calls, self.pinned = refuse, [], []

    def setscheduler(self, pid, policy, param) -> None:
        self.calls.append((threading.current_thread().name, policy, param.sched_priority))
        if self.refuse:
            raise PermissionError(1, "Operation not permitted")

    def setaffinity(self, pid, cpus) -> None:
        self.pinned.append(frozenset(cpus))


@pytest.mark.parametrize("refuse", [False, True])
def test_the_twins_cycle_thread_takes_the_links_scheduling(refuse, monkeypatch, capsys):
    """``--rt-priority 20 --cpu 0``: the cycle thread asks SCHED_FIFO 20 (the process's
    other threads 19) on CPU 0, as a link's loop does; refused (not root, no
    CAP_SYS_NICE), the twin says why on stderr and runs at normal priority."""
    import os

    kernel = _Scheduler(refuse)
    monkeypatch.setattr(os, "sched_setscheduler", kernel.setscheduler)
    monkeypatch.setattr(os, "sched_setaffinity", kernel.setaffinity)
    sensor = _Sensor(0.5)
    try:
        status = main(["twin", "rsi", "--port", str(sensor.port), "--timeout", "10000",
                       "--lockstep", "1", "--duration", "0.5", "--rt-priority", "20",
                       "--cpu", "0"])
    finally:
        sensor.close()
    out, err = capsys.readouterr()
    assert status == 0
    cycles = int(re.search(r"twin rsi: (\d+) cycles", out.splitlines()[-1])[1])
    assert cycles > 10  # it ran either way
    assert ("rsi-robot", os.SCHED_FIFO, 20) in kernel.calls
    assert (threading.current_thread().name, os.SCHED_FIFO, 19) in kernel.calls
    assert frozenset({0}) in kernel.pinned
    line = [x for x in err.splitlines() if x.startswith("twin rsi: cycle thread: ")]
    assert len(line) == 1, err
    if refuse:
        assert line[0].startswith("twin rsi: cycle thread: SCHED_FIFO refused (not "
                                  "permitted: priority 20 needs root or CAP_SYS_NICE")
        assert "; normal priority, CPU 0" in line[0]
        assert "other threads at normal priority (SCHED_FIFO refused (not permitted" in line[0]
    else:
        assert line[0] == ("twin rsi: cycle thread: SCHED_FIFO priority 20, CPU 0; CPU 0, "
                           "other threads SCHED_FIFO priority 19")


def test_without_the_options_the_twin_schedules_nothing(monkeypatch, capsys):
    import os

    kernel = _Scheduler(False)
    monkeypatch.setattr(os, "sched_setscheduler", kernel.setscheduler)
    assert main(["twin", "egm", "--port", "9", "--duration", "0.3"]) == 0
    assert kernel.calls == [] and "cycle thread" not in capsys.readouterr().err


@pytest.mark.slow
def test_without_cap_sys_nice_the_twin_says_why_and_runs(tmp_path):
    """A real refusal: the twin in a process without CAP_SYS_NICE (util-linux's setpriv)."""
    import os
    import shutil
    import subprocess
    import sys

    setpriv = shutil.which("setpriv")
    if setpriv is None:
        pytest.skip("no setpriv here")
    run = subprocess.run([setpriv, "--inh-caps=-sys_nice", "--bounding-set=-sys_nice",
                          sys.executable, "-m", "plugcell", "twin", "egm", "--port", "9",
                          "--timeout", "30", "--duration", "1", "--rt-priority", "10"],
                         capture_output=True, text=True, timeout=120, env=dict(os.environ))
    if os.geteuid() != 0 and "bounding" in run.stderr:
        pytest.skip(f"setpriv cannot drop the capability here: {run.stderr.strip()}")
    assert run.returncode == 0, run.stderr
    assert "twin egm: cycle thread: SCHED_FIFO refused (not permitted: priority 10 needs " \
           "root or CAP_SYS_NICE" in run.stderr, run.stderr
    assert "; normal priority" in run.stderr
    assert re.search(r"twin egm: (\d+) samples", run.stdout.splitlines()[-1]), run.stdout
