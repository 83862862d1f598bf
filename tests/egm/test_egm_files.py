"""What the user loads into the ABB controller (``plugcell egm files``) and
``plugcell egm run`` against the simulated controller."""

from __future__ import annotations

import json
import socket
import threading
import time

import pytest

from plugcell.apps.cli import main
from plugcell.devices.robot.egm import EgmConfig
from plugcell.devices.robot.egm.controller_files import controller_files
from plugcell.io.units import DEG
from plugcell.sim.controller.egm_robot import EgmRobotSim


@pytest.mark.parametrize(("mode", "act", "run"), [
    ("joint", "EGMActJoint egm_id", "EGMRunJoint egm_id, EGM_STOP_HOLD"),
    ("pose", "EGMActPose egm_id", "EGMRunPose egm_id, EGM_STOP_HOLD"),
    ("pathcorr", "EGMActMove egm_id", "EGMMoveL egm_id, p_end"),
])
def test_the_rapid_module_of_each_mode(mode, act, run) -> None:
    cfg = EgmConfig(robot_host="192.168.125.1", listen_port=6511, mode=mode,
                    sample_rate_ms=8, comm_timeout_s=2.5)
    files = controller_files(cfg, "192.168.125.100", device="pcUC")
    mod = files["PlugcellEGM.mod"]
    assert mod.startswith("MODULE PlugcellEGM") and mod.rstrip().endswith("ENDMODULE")
    assert act in mod and run in mod and "EGMReset egm_id;" in mod
    assert '"pcUC"' in mod and "\\SampleRate:=8" in mod
    assert "\\CommTimeout:=2.5" in mod
    assert "{{" not in mod
    sioc = files["SIOC_plugcell.cfg"]
    assert '-Name "pcUC" -Type "UDPUC" -RemoteAdress "192.168.125.100"' in sioc
    assert "-RemotePortNumber 6511" in sioc


def test_the_path_correction_module_corrects_the_robots_own_moves() -> None:
    """Mode (b): EGMSetupUC with \\PathCorr, EGMActMove with the sensor frame (a pose) and
    the sample rate, the user's EGMMoveL moves after it, EGMReset at the end and on a lost
    PC; the UDP unit device the module names is the one configured."""
    cfg = EgmConfig(robot_host="192.168.125.1", listen_port=6512, mode="pathcorr",
                    sample_rate_ms=4, comm_timeout_s=1.5)
    files = controller_files(cfg, "192.168.125.100")
    lines = [ln.strip() for ln in files["PlugcellEGM.mod"].splitlines()
             if ln.strip() and not ln.strip().startswith("!")]
    setup = lines.index('EGMSetupUC ROB_1, egm_id, "pathCorr", "plugcellUC" \\PathCorr '
                        '\\APTR \\CommTimeout:=1.5;')
    act = lines.index("EGMActMove egm_id, egm_sensor_frame \\SampleRate:=4;")
    reset = lines.index("EGMReset egm_id;")
    moves = [ln for ln in lines[act:reset] if ln.startswith("EGMMoveL egm_id,")]
    assert setup < act < reset and len(moves) == 2
    assert "CONST pose egm_sensor_frame := [[0, 0, 0], [1, 0, 0, 0]];" in lines
    assert lines[lines.index("ERROR"):].count("EGMReset egm_id;") == 1
    assert "--param egm_mode=pathcorr" in files["PlugcellEGM.mod"]
    sioc = files["SIOC_plugcell.cfg"]
    assert sioc.startswith("SIOC:CFG_1.0:") and "COM_TRP:" in sioc
    assert '-Name "plugcellUC" -Type "UDPUC" -RemoteAdress "192.168.125.100"' in sioc
    assert "-RemotePortNumber 6512 -LocalPortNumber 0" in sioc
    assert "`EGMActMove`, `EGMMoveL`" in files["README.md"]


def test_plugcell_egm_files_writes_them(tmp_path, capsys) -> None:
    code = main(["egm", "files", "--out", str(tmp_path), "--ip", "10.0.0.5", "--port", "6600",
                 "--mode", "joint", "--max-speed", "10"])
    assert code == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["PlugcellEGM.mod", "README.md", "SIOC_plugcell.cfg"]
    mod = (tmp_path / "PlugcellEGM.mod").read_bytes()
    assert b"\r\n" in mod and b"\\MaxSpeedDeviation:=10" in mod
    assert "plugcell egm run --robot-ip CONTROLLER_IP --port 6600" in capsys.readouterr().out


@pytest.mark.parametrize(("argv", "message"), [
    (["--ip", "abb"], "--ip 'abb': expected the PC's IPv4 address"),
    (["--ip", "0.0.0.0"], "RemoteAdress '0.0.0.0'"),
    (["--ip", "10.0.0.1", "--sample-ms", "5"], "multiple of 4"),
    (["--ip", "10.0.0.1", "--max-step", "1,2"], "--max-step '1,2': expected 1 or 6"),
    (["--ip", "10.0.0.1", "--device", "bad name"], "device 'bad name'"),
])
def test_plugcell_egm_files_errors(tmp_path, capsys, argv, message) -> None:
    assert main(["egm", "files", "--out", str(tmp_path), *argv]) == 2
    assert message in capsys.readouterr().err


def test_plugcell_egm_run_swings_one_joint_of_the_simulated_robot(capsys) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    done: dict[str, int] = {}
    cmd = threading.Thread(target=lambda: done.setdefault("code", main(
        ["egm", "run", "--robot-ip", "127.0.0.1", "--listen", "127.0.0.1", "--port",
         str(port), "--sine", "A6:0.5:0.4", "--duration", "1.5", "--json"])))
    cmd.start()
    time.sleep(0.2)
    robot = EgmRobotSim(("127.0.0.1", port)).start()
    peak = 0.0
    try:
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            peak = max(peak, float(robot.state()["joint_targets"][5]))
            time.sleep(0.002)
    finally:
        robot.stop()
        cmd.join(timeout=10)
    assert done["code"] == 0
    assert peak == pytest.approx(0.5 * DEG, abs=0.02 * DEG)  # the swing's top
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines() if x.startswith("{")]
    assert lines and lines[-1]["answered"] > 50
