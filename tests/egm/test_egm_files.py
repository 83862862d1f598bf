"""What the user loads into the ABB controller (``plugcell egm files``) and
``plugcell egm run`` against the simulated controller."""

from __future__ import annotations

import json
import socket
import threading
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plugcell.apps.cli import main
from plugcell.devices.robot.egm import EgmConfig
from plugcell.devices.robot.egm.controller_files import ExtMotion, controller_files
from plugcell.devices.robot.stream.limits import CorrectionLimits
from plugcell.io.abb_cfg import parse_cfg
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


def test_the_path_correction_motion_configuration_is_generated() -> None:
    """MOC_plugcell.cfg: the External Motion Interface Data entry the module's EGMSetupUC
    names, with the user's gain, filter, ramp and largest adjustment (the link's
    --max-offset, m); the SIOC entry reads as the same syntax."""
    cfg = EgmConfig(robot_host="192.168.125.1", listen_port=6513, mode="pathcorr",
                    limits=CorrectionLimits(max_step=(2e-4,) * 6,
                                            max_offset=(3e-3,) * 3 + (1e-3,) * 3,
                                            max_speed=(0.05,) * 6))
    files = controller_files(cfg, "192.168.125.100",
                             ext_motion=ExtMotion("seamCorr", 8.0, 15.0, 0.25, 2.0))
    domain, version, types = parse_cfg(files["MOC_plugcell.cfg"])
    assert domain == "MOC" and version == (6, 0) and list(types) == ["EXT_MOTION_DATA"]
    assert types["EXT_MOTION_DATA"] == [{
        "name": "seamCorr", "ext_motion_Kp": 8, "ext_motion_filter_bandwidth": 15,
        "ramp_time": 0.25, "max_external_pos_adjustment": 0.003,
        "max_allowed_speed_factor": 2}]
    assert '"seamCorr", "plugcellUC" \\PathCorr' in files["PlugcellEGM.mod"]
    assert "`MOC_plugcell.cfg`" in files["README.md"] and "`seamCorr`" in files["README.md"]
    domain, _, sioc = parse_cfg(files["SIOC_plugcell.cfg"])
    assert domain == "SIOC" and sioc["COM_TRP"] == [{
        "Name": "plugcellUC", "Type": "UDPUC", "RemoteAdress": "192.168.125.100",
        "RemotePortNumber": 6513, "LocalPortNumber": 0}]
    # the controller's default entry: no MOC for joint or pose targets
    joint = controller_files(EgmConfig(robot_host="192.168.125.1"), "192.168.125.100")
    assert "MOC_plugcell.cfg" not in joint and "`MOC_plugcell.cfg`" not in joint["README.md"]
    with pytest.raises(ValueError, match="External Motion Interface Data goes with path"):
        controller_files(EgmConfig(robot_host="192.168.125.1"), "192.168.125.100",
                         ext_motion=ExtMotion())


_positive = st.floats(1e-3, 1e3, allow_nan=False, allow_infinity=False)


@settings(max_examples=100, deadline=None)
@given(st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,15}", fullmatch=True), _positive, _positive,
       _positive, st.one_of(st.none(), _positive), st.floats(1e-5, 0.5),
       st.integers(1, 65535), st.ip_addresses(v=4).filter(lambda a: not a.is_unspecified))
def test_the_motion_configurations_values_round_trip(name, kp, bw, ramp, factor, adjust,
                                                      port, ip) -> None:
    cfg = EgmConfig(robot_host="192.168.125.1", listen_port=port, mode="pathcorr",
                    limits=CorrectionLimits(max_step=(1e-4,) * 6, max_offset=(adjust,) * 6,
                                            max_speed=(0.05,) * 6))
    files = controller_files(cfg, str(ip), ext_motion=ExtMotion(name, kp, bw, ramp, factor))
    got = parse_cfg(files["MOC_plugcell.cfg"])[2]["EXT_MOTION_DATA"][0]
    want = {"ext_motion_Kp": kp, "ext_motion_filter_bandwidth": bw, "ramp_time": ramp,
            "max_external_pos_adjustment": adjust}
    if factor is not None:
        want["max_allowed_speed_factor"] = factor
    assert got.pop("name") == name
    assert got == pytest.approx(want, rel=1e-8)
    trp = parse_cfg(files["SIOC_plugcell.cfg"])[2]["COM_TRP"][0]
    assert (trp["RemoteAdress"], trp["RemotePortNumber"]) == (str(ip), port)
    assert f'EGMSetupUC ROB_1, egm_id, "{name}", "plugcellUC"' in files["PlugcellEGM.mod"]


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
    (["--ip", "10.0.0.1", "--ext-kp", "3"], "--ext-kp: External Motion Interface Data goes "
                                            "with --mode pathcorr"),
    (["--ip", "10.0.0.1", "--mode", "pathcorr", "--ext-kp", "0"],
     "External Motion Interface Data Kp: a positive number, got 0.0"),
    (["--ip", "10.0.0.1", "--mode", "pathcorr", "--ext-ramp", "inf"],
     "External Motion Interface Data ramp time: a positive number"),
    (["--ip", "10.0.0.1", "--mode", "pathcorr", "--ext-config", "bad name"],
     "ExtConfigName 'bad name': expected a RAPID name"),
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
