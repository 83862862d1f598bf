"""Robot programs drive the cell through the robot service (thesis 4.1.3.2, 5.2.3.6, 7.2).

Real service processes — CAMERA, TOOL, PROBE and a ROBOT with its simulated
controller — started once for the module; every program runs against the same
running services, with no restart and no code change.
"""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import pytest
from robot_cell import PNT0001, PNT0002, RobotCell
from robot_testlib import plugcell_argv, until

from plugcell.framework import KeySpace, ProcessStates, ProcessUpdateNotification, from_data
from plugcell.framework.journal import journal_files, read_journal
from plugcell.framework.transport import open_session

pytestmark = pytest.mark.timeout(120)

C, F = ProcessStates.Completed, ProcessStates.Failed


def _values(update: ProcessUpdateNotification) -> list[float]:
    return [float(v) for v in from_data(update.data).reshape(-1)]


def journal_rows(cell: RobotCell) -> list[dict]:
    return read_journal(journal_files(cell.cell, cell.home))


def test_the_thesis_example_drives_camera_and_drill(robot_cell: RobotCell) -> None:
    final = robot_cell.activate("example", f"pnt0001={PNT0001}", f"pnt0002={PNT0002}")
    assert final.state is C, final.reason
    program, state, sim_time, message, *_ = robot_cell.status()
    assert (program, state, message) == ("EXAMPLE", "FINISHED", "")
    assert float(sim_time) > 1.0  # two moves of simulated seconds
    rows = journal_rows(robot_cell)
    snap = [r for r in rows if r.get("command") == "SnapShot" and r["sender"] == "ROBOT"]
    drill = [r for r in rows if r.get("command") == "Drill" and r["sender"] == "ROBOT"]
    assert snap and snap[-1]["state"] == "Completed" and snap[-1]["recipient"] == "CAMERA"
    assert snap[-1]["input"] == "Integer[1] [500]"
    assert drill and drill[-1]["state"] == "Completed" and drill[-1]["recipient"] == "TOOL"
    assert drill[-1]["option"] == "Air" and drill[-1]["input"] == "Integer[2] [550, 1100]"
    assert snap[-1]["received_ns"] < drill[-1]["received_ns"]
    # the arm is where the program left it: pnt0002, by the controller's own account
    pos = robot_cell.client.create_process("ROBOT", "ARM_POS").result()
    x, y, z = _values(pos)[:3]
    assert abs(x - 1500) < 0.05 and abs(y - 200) < 0.05 and abs(z - 1000) < 0.05


def test_a_second_program_on_the_same_running_services(robot_cell: RobotCell) -> None:
    """A different application — by name from the program library — and nothing restarted."""
    final = robot_cell.activate("inspect")
    assert final.state is C, final.reason
    console = robot_cell.console()
    assert console[:3] == [
        f"snapshot {k}: 480×640 data (307200 values) does not fit ext_cmd_data (4096): "
        "not sent to the controller"
        for k in (1, 2, 3)
    ]
    assert "probe: 3 values 1.5,-2.0,10.0" in console  # SingleData into ext_cmd_data
    assert "frames: 3 of 3 values, x > 0: TRUE" in console  # MultipleData frames
    assert "track stopped" in console  # StopData
    assert "arm at 1500,200,1200" in console  # the robot service's own ARM_POS
    assert "probe is probe #7" in console  # String data into ext_cmd_text
    assert "CALC moved x by 0.5 mm" in console  # δθ = J⁻¹Δx delegated to the service
    assert any(line.startswith("drilled after ") for line in console)
    rows = journal_rows(robot_cell)
    commands = [(r["recipient"], r.get("command"), r["state"]) for r in rows
                if r["sender"] == "ROBOT"]
    assert commands.count(("CAMERA", "SnapShot", "Completed")) >= 4  # EXAMPLE's + 3
    assert ("PROBE", "Track", "Completed") in commands  # ended by the program's StopTrack
    assert ("PROBE", "StopTrack", "Completed") in commands


def test_every_bad_request_reaches_the_program_as_a_clear_error(robot_cell: RobotCell) -> None:
    final = robot_cell.activate(Path(__file__).parent / "programs" / "mistakes.pdl")
    assert final.state is C, final.reason
    console = dict(line.split(": ", 1) for line in robot_cell.console() if ": " in line)
    assert console["1"] == ("GRIPPER is not a partner of ROBOT (partners: CAMERA, PROBE, TOOL); "
                            "wire it: plugcell wire ROBOT GRIPPER")
    assert console["2"] == ("CAMERA has no command 'Snapshot' (commands: Connect, Disconnect, "
                            "SnapShot, MovieShot, StopMovie)")
    assert console["3"] == ("TOOL Drill: data '550' does not fit Integer[2]: size [1] does not "
                            "match the declared [2]")
    assert console["4"] == ("CAMERA SnapShot: data '5.5' does not fit Integer[1]: value 1 '5.5' "
                            "is not a whole number (Integer)")
    assert console["5"].startswith("FALSE garbled line: bad ACTIVATE string: expected '#' and a "
                                   "command after the device name CAMERA")
    assert console["6"].startswith("FALSE garbled line: unknown message 'PRINT'")
    assert console["7"] == "TOOL Drill: feed 5 mm/min outside 10…2000"
    assert console["8"] == "PROBE StopTrack: no MultipleData process of ROBOT is running"
    assert console["9"].startswith("ROBOT POS_TO_JNTP: POS_TO_JNTP(9000, 0, 0, 0, 0, 0): "
                                   "pose is out of reach")
    assert console["10"] == "TRUE"  # the thesis's own "##, 500" form (5.2.3.6) is accepted
    # a service's own command with an option it does not have: refused, the service serves on
    pose = [1500.0, 0.0, 1300.0, 0.0, 90.0, 0.0]
    bad = robot_cell.client.create_process("ROBOT", "JointIncrement", "sideways",
                                           pose + pose).result()
    assert bad.state is F
    assert bad.reason == "JointIncrement: unknown option 'sideways' ('' or 'errors')"
    good = robot_cell.client.create_process("ROBOT", "JointIncrement", "errors",
                                            pose + pose).result()
    assert good.state is C and _values(good)[:2] == [0.0, 0.0]  # no error: 0 mm, 0°


def test_a_partner_that_dies_mid_command_fails_the_command(robot_cell: RobotCell,
                                                           tmp_path: Path) -> None:
    launcher = robot_cell.launcher
    slow = launcher.serve("drill", "--param", "time_scale=100", name="TOOL2")  # 109 s per hole
    launcher.ready(slow)
    assert robot_cell.client.ask_subscribe("ROBOT", "TOOL2").ok
    program = tmp_path / "die.pdl"
    program.write_text(
        "PROGRAM die\n"
        "IMPORT 'services'\n"
        "BEGIN\n"
        "  IF EXT_CMD('TOOL2', 'Drill', 'Air', '550,1100', 0) THEN\n"
        "    WRITE LUN_CRT ('drilled')\n"
        "  ELSE\n"
        "    WRITE LUN_CRT ('drill failed: ', ext_cmd_message)\n"
        "  ENDIF\n"
        "END die\n"
    )
    # watch TOOL2's updates to ROBOT on the wire, as a cell monitor would (protocol.md §2):
    # the journal has Running before the acknowledgement is even sent
    session = open_session()
    updates: list[object] = []
    keys = KeySpace(robot_cell.cell)
    watch = session.declare_subscriber(keys.process("TOOL2", "ROBOT"), updates.append)
    # a fresh session hears TOOL2's one Running update only once it is linked to TOOL2's
    # peer: wait until TOOL2's presence answers through it
    until(lambda: list(session.liveliness().get(keys.live_services("TOOL2"), timeout=1.0)),
          20.0, "the watching session linked to TOOL2")
    try:
        assert robot_cell.activate(program, wait=False).state is C  # started
        until(lambda: updates, 20.0, "TOOL2 drilling")  # its Running update was sent
        time.sleep(0.1)
        slow.kill9()
    finally:
        watch.undeclare()
        session.close()
    until(lambda: robot_cell.status()[1] == "FINISHED", 20.0, "the program's end")
    assert robot_cell.console() == [
        "drill failed: TOOL2 Drill: service TOOL2 lost (liveliness token withdrawn)"
    ]


def test_malformed_programs_come_back_with_file_and_line(robot_cell: RobotCell,
                                                         tmp_path: Path) -> None:
    cases = {
        "syntax.pdl": ("PROGRAM syntax\nVAR n : INTEGER\nBEGIN\n  n = 5\nEND syntax\n",
                       "syntax.pdl:4:5: expected"),
        "types.pdl": ("PROGRAM types\nVAR n : INTEGER\nBEGIN\n  n := 'five'\nEND types\n",
                      "types.pdl:4:3: cannot assign a STRING[4] to n (INTEGER)"),
        "library.pdl": ("PROGRAM library\nIMPORT 'nowhere'\nBEGIN\nEND library\n",
                        "library.pdl:2:1: cannot find library 'nowhere'"),
    }
    for name, (text, expected) in cases.items():
        path = tmp_path / name
        path.write_text(text)
        final = robot_cell.activate(path)
        assert final.state is F
        assert final.reason.startswith("ACTIVATE: /"), final.reason
        assert expected in final.reason, final.reason
    # a run-time error: the thesis's EXAMPLE without its taught points
    final = robot_cell.activate("example")
    assert final.state is F
    assert final.reason.endswith("example.pdl:36:10: pnt0001 is uninitialized"), final.reason
    assert final.reason.startswith("ACTIVATE: program EXAMPLE failed: /")
    # and what is not a program at all
    final = robot_cell.activate("nosuch")
    assert final.state is F and "no program 'nosuch' in the program library" in final.reason
    final = robot_cell.activate("progs/nosuch.pdl")  # relative: the controller's folder
    assert final.state is F
    assert "no such program file: progs/nosuch.pdl (looked for /" in final.reason, final.reason
    assert "taken from the robot controller's folder /" in final.reason, final.reason
    final = robot_cell.activate("example", "pnt0001=1,2")
    assert final.state is F
    assert final.reason.endswith("example.pdl:14:5: cannot set pnt0001 (POSITION): list [1.0, "
                                 "2.0] is not a POSITION (6 or 7 values, or a 4×4 matrix)")


def test_a_program_that_deactivates_itself_fails_the_wait(robot_cell: RobotCell,
                                                          tmp_path: Path) -> None:
    """Issue 39 §1: a program's own DEACTIVATE (the shipped programs' REQUIRE after a
    failed step) ends it before its END — ACTIVATE Wait is Failed with what the program
    said last and where it stopped, never Completed; without Wait it is Completed at start."""
    program = tmp_path / "gives_up.pdl"
    program.write_text(
        "PROGRAM gives_up\n"
        "BEGIN\n"
        "  WRITE LUN_CRT ('gives_up: starting')\n"
        "  WRITE LUN_CRT ('gives_up: Move failed: TRACKER Move: beam not locked')\n"
        "  DEACTIVATE\n"
        "  WRITE LUN_CRT ('gives_up: not reached')\n"
        "END gives_up\n"
    )
    final = robot_cell.activate(program)
    assert final.state is F, final.reason
    assert final.reason.startswith("ACTIVATE: program gives_up deactivated itself: gives_up: "
                                   "Move failed: TRACKER Move: beam not locked"), final.reason
    assert final.reason.endswith("gives_up.pdl:5:3)"), final.reason
    program_name, state, _, message, *console = robot_cell.status()
    assert (program_name, state) == ("gives_up", "DEACTIVATED")
    assert message.startswith("gives_up: Move failed"), message
    assert "gives_up: not reached" not in console
    # without Wait: Completed once it runs, as before
    started = robot_cell.activate(program, wait=False)
    assert started.state is C, started.reason
    until(lambda: robot_cell.status()[1] != "RUNNING", 10.0, "gives_up ended")
    # and as a user sees it: `plugcell call … --option Wait` prints Failed and exits 1
    argv = plugcell_argv("call", "ROBOT", "ACTIVATE", "--option", "Wait", "--data",
                         json.dumps([str(program)]), "--cell", robot_cell.cell)
    done = subprocess.run(argv, env=robot_cell.launcher.env, capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 1, (done.stdout, done.stderr)
    final = json.loads(done.stdout.strip().splitlines()[-1])
    assert final["state"] == "Failed", final
    assert "deactivated itself: gives_up: Move failed" in final["reason"], final


def test_deactivate_stops_a_running_program(robot_cell: RobotCell) -> None:
    assert robot_cell.activate("forever", wait=False).state is C
    assert robot_cell.status()[:2] == ["forever", "RUNNING"]
    busy = robot_cell.activate("inspect", wait=False)
    assert busy.state is F and "program forever is already running" in busy.reason
    wrong = robot_cell.client.create_process("ROBOT", "DEACTIVATE", "", ["inspect"]).result()
    assert wrong.state is F and "program inspect is not running (running: forever)" in wrong.reason
    stop = robot_cell.client.create_process("ROBOT", "DEACTIVATE", "", ["forever"]).result()
    assert stop.state is C, stop.reason
    program, state, sim_time, message, *_ = robot_cell.status()
    assert (program, state, message) == ("forever", "STOPPED", "stopped by the robot service")
    assert float(sim_time) > 0
    again = robot_cell.client.create_process("ROBOT", "DEACTIVATE", "", [""]).result()
    assert again.state is F and "no program is running" in again.reason


def test_streams_a_program_leaves_running_are_stopped_when_it_ends(robot_cell: RobotCell,
                                                                    tmp_path: Path) -> None:
    program = tmp_path / "careless.pdl"
    program.write_text(
        "PROGRAM careless\n"
        "IMPORT 'services'\n"
        "BEGIN\n"
        "  IF EXT_CMD('CAMERA', 'MovieShot', '', '20', 0) THEN\n"
        "    WRITE LUN_CRT ('filming: ', ext_cmd_message)\n"
        "  ENDIF\n"
        "  IF EXT_CMD('PROBE', 'Track', '', '50', 0) THEN\n"
        "    WRITE LUN_CRT ('tracking')\n"
        "  ENDIF\n"
        "  IF NOT EXT_CMD('PROBE', 'Track', '', '50', 0) THEN\n"
        "    WRITE LUN_CRT ('again: ', ext_cmd_message)\n"
        "  ENDIF\n"
        "END careless\n"
    )
    assert robot_cell.activate(program).state is C
    assert robot_cell.console() == [
        "filming: ", "tracking",
        "again: PROBE Track is still streaming to this robot: stop it first",
    ]

    def stopped() -> bool:
        rows = [r for r in journal_rows(robot_cell)
                if r["sender"] == "ROBOT" and r["recipient"] in ("CAMERA", "PROBE")]
        ended = {(r["recipient"], r.get("command")) for r in rows if r["state"] == "Completed"}
        return {("CAMERA", "MovieShot"), ("CAMERA", "StopMovie"), ("PROBE", "Track"),
                ("PROBE", "StopTrack")} <= ended and not any(
            r["state"] == "Running" for r in rows)

    until(stopped, 15.0, "the streams stopped by the robot service")
