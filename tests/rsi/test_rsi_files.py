"""The files the user copies to the controller, read back by rsipi's own parsers (an
independent reader of the ethernet configuration and the signal flow), and the
``plugcell rsi`` command that writes them and streams."""

from __future__ import annotations

import json
import threading
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from rsi_testlib import BareRobot

from plugcell.apps.cli import main
from plugcell.devices.robot.rsi import CorrectionLimits, OutputSignal, RsiConfig
from plugcell.devices.robot.rsi.controller_files import (
    IoRouting,
    controller_files,
    write_controller_files,
)
from plugcell.io.units import DEG
from plugcell.sim.ports import free_port

config_parser = pytest.importorskip("RSIPI.config_parser")
limit_parser = pytest.importorskip("RSIPI.rsi_limit_parser")


def written(tmp_path, **kw):
    config = RsiConfig(robot_host="192.168.1.147", listen_port=49200,
                       outputs=(OutputSignal("DiO", 16),), **kw)
    paths = write_controller_files(tmp_path, config, "192.168.1.100",
                                   IoRouting(outputs={"DiO": 33}, input_tag="DiL"))
    return {p.name: p for p in paths}


@pytest.mark.parametrize(("mode", "hold"), [("relative", 0), ("absolute", 1)])
def test_rsipi_reads_the_ethernet_configuration(tmp_path, mode, hold) -> None:
    files = written(tmp_path, mode=mode)
    parsed = config_parser.ConfigParser(str(files["plugcell_rsi_ethernet.xml"]))
    assert parsed.get_network_settings() == {"ip": "192.168.1.100", "port": 49200,
                                             "sentype": "ImFree", "onlysend": False}
    assert {"RIst", "RSol", "AIPos", "ASPos", "MACur", "Delay", "DiL"} <= set(
        parsed.send_variables)
    assert set(parsed.receive_variables) == {"AKorr", "DiO"}
    # HOLDON by mode: relative 0 (no drift while the PC is silent), absolute 1 (no jump)
    assert {parsed.holdon_map[f"AKorr.A{i}"] for i in range(1, 7)} == {hold}
    assert parsed.holdon_map["DiO"] == 1


def test_cartesian_streams_receive_rkorr(tmp_path) -> None:
    files = written(tmp_path, correction="cartesian")
    parsed = config_parser.ConfigParser(str(files["plugcell_rsi_ethernet.xml"]))
    assert set(parsed.receive_variables) == {"RKorr", "DiO"}
    limits = limit_parser.parse_rsi_limits(str(files["plugcell_rsi.rsi.xml"]))
    assert limits["RKorr.X"] == pytest.approx((-50.0, 50.0))  # the default box, in mm
    assert limits["RKorr.C"] == pytest.approx((-5.0, 5.0))  # MaxRotAngle, degrees


def test_the_signal_flow_carries_the_timeout_and_the_pcs_limits(tmp_path) -> None:
    lim = CorrectionLimits((0.1 * DEG,) * 6, tuple(np.array([5, 6, 7, 8, 9, 10]) * DEG),
                           (20 * DEG,) * 6)
    files = written(tmp_path, timeout_packets=60, limits=lim)
    flow = str(files["plugcell_rsi.rsi.xml"])
    assert limit_parser.parse_ethernet_timeout(flow) == 60
    limits = limit_parser.parse_rsi_limits(flow)
    for i, v in enumerate([5, 6, 7, 8, 9, 10], start=1):
        assert limits[f"AKorr.A{i}"] == pytest.approx((-v, v))
    root = ET.parse(flow).getroot()
    objs = {o.get("ObjID"): o for o in root.iter("RSIObject")}
    assert set(objs) == {"ETHERNET1", "AXISCORR1", "AXISCORRMON1", "MAP2DIGOUT1", "DIGIN1"}
    dio = objs["MAP2DIGOUT1"]
    assert dio.find("Inputs/Input").get("OutIdx") == "7"  # RECEIVE INDX 7 = DiO
    assert dio.find("Parameters/Parameter[@Name='Index']").get("ParamValue") == "33"


def test_the_krl_program_starts_rsi_as_configured(tmp_path) -> None:
    files = written(tmp_path, mode="absolute", cycle="IPO")
    raw = files["plugcell_rsi.src"].read_bytes()
    assert b"\r\n" in raw and b"\n" not in raw.replace(b"\r\n", b"")  # CRLF, as KRL files
    src = raw.decode()
    assert 'RSI_CREATE("plugcell_rsi.rsi", CONTID, TRUE)' in src
    assert "RSI_ON(#ABSOLUTE, #IPO)" in src
    assert "RSI_MOVECORR()" in src and "RSI_OFF()" in src
    assert "$STOPMESS" in src and "{{" not in src
    readme = files["README.md"].read_text()
    assert "HOLDON of the correction elements is 1" in readme


@pytest.mark.parametrize(("mode", "hold"), [("relative", 0), ("absolute", 1)])
def test_when_the_robot_drives_its_own_moves_run_between_rsi_on_and_off(tmp_path, mode,
                                                                        hold) -> None:
    """Mode (b): the user's moves between RSI_ON and RSI_OFF (no RSI_MOVECORR), a wait
    for the PC to end its correction, and the HOLDON of the mode in a well-formed file."""
    config = RsiConfig(robot_host="192.168.1.147", listen_port=49200, mode=mode,
                       correction="cartesian", frame="tool")
    paths = {p.name: p for p in write_controller_files(tmp_path, config, "192.168.1.100",
                                                       drives="robot", settle_s=1.5)}
    raw = paths["plugcell_rsi.src"].read_bytes()
    assert b"\n" not in raw.replace(b"\r\n", b"")  # CRLF, as KRL files
    lines = [ln.strip() for ln in raw.decode().splitlines()
             if ln.strip() and not ln.strip().startswith(";")]
    on = lines.index(f"ret = RSI_ON(#{mode.upper()}, #IPO_FAST)")
    off = lines.index("ret = RSI_OFF()")
    inside = lines[on:off]
    assert [ln for ln in inside if ln.startswith(("LIN", "PTP", "CIRC"))] == [
        "LIN_REL {Y 200.0}", "LIN_REL {Y -200.0}"]
    assert inside[-1] == "WAIT SEC 1.5"  # the PC ends its correction before RSI_OFF
    assert "RSI_MOVECORR()" not in raw.decode() and "{{" not in raw.decode()
    assert lines.index('ret = RSI_CREATE("plugcell_rsi.rsi", CONTID, TRUE)') < on
    assert lines.index("PTP $AXIS_ACT") < on
    root = ET.parse(paths["plugcell_rsi_ethernet.xml"]).getroot()  # well-formed
    assert {e.get("HOLDON") for e in root.iter("ELEMENT")
            if e.get("TAG", "").startswith("RKorr.")} == {str(hold)}
    parsed = config_parser.ConfigParser(str(paths["plugcell_rsi_ethernet.xml"]))
    assert {parsed.holdon_map[f"RKorr.{a}"] for a in "XYZABC"} == {hold}
    ET.parse(paths["plugcell_rsi.rsi.xml"])
    assert "your own moves (the robot drives, the PC corrects)" in \
        paths["README.md"].read_text()
    with pytest.raises(ValueError, match="drives 'both'"):
        controller_files(config, "192.168.1.100", drives="both")
    with pytest.raises(ValueError, match="settle -1"):
        controller_files(config, "192.168.1.100", drives="robot", settle_s=-1)


def test_plugcell_rsi_files_for_the_robot_driving(tmp_path, capsys) -> None:
    out = tmp_path / "kuka"
    assert main(["rsi", "files", "--out", str(out), "--ip", "192.168.1.100", "--mode",
                 "absolute", "--drives", "robot", "--settle", "2"]) == 0
    printed = capsys.readouterr().out
    assert "plugcell serve robot --rsi 192.168.1.100:49152 --rsi-robot CONTROLLER_IP" in printed
    assert "--param rsi_mode=absolute" in printed and "CORRECT" in printed
    assert "WAIT SEC 2\r\n" in (out / "plugcell_rsi.src").read_bytes().decode()


@pytest.mark.parametrize(("frame", "ref"), [("base", "1"), ("tool", "2")])
def test_plugcell_rsi_files_for_cartesian_corrections_in_a_frame(tmp_path, capsys, frame,
                                                                  ref) -> None:
    """--frame: POSCORR's RefCorrSys, and the service's rsi_frame the files go with."""
    out = tmp_path / "kuka"
    assert main(["rsi", "files", "--out", str(out), "--ip", "192.168.1.100", "--mode",
                 "absolute", "--drives", "robot", "--correction", "cartesian", "--frame",
                 frame]) == 0
    printed = capsys.readouterr().out
    assert (f"--param rsi_correction=cartesian --param rsi_frame={frame} "
            "--param rsi_mode=absolute") in printed
    ref_corr = [p for p in ET.parse(out / "plugcell_rsi.rsi.xml").iter("Parameter")
                if p.get("Name") == "RefCorrSys"]
    assert [p.get("ParamValue") for p in ref_corr] == [ref]


def test_the_controller_needs_a_real_address_and_port() -> None:
    config = RsiConfig(robot_host="192.168.1.147")
    with pytest.raises(ValueError, match=r"IP_NUMBER '0\.0\.0\.0'"):
        controller_files(config, "0.0.0.0")
    with pytest.raises(ValueError, match="PORT 0"):
        controller_files(RsiConfig(robot_host="192.168.1.147", listen_port=0), "10.0.0.1")


def test_plugcell_rsi_files(tmp_path, capsys) -> None:
    out = tmp_path / "kuka"
    code = main(["rsi", "files", "--out", str(out), "--ip", "192.168.1.100", "--port",
                 "49300", "--correction", "cartesian", "--max-offset", "20,20,20,2,2,2",
                 "--dio", "17"])
    assert code == 0
    printed = capsys.readouterr().out
    assert "plugcell rsi run --robot-ip CONTROLLER_IP --port 49300" in printed
    limits = limit_parser.parse_rsi_limits(str(out / "plugcell_rsi.rsi.xml"))
    assert limits["RKorr.Y"] == pytest.approx((-20.0, 20.0))
    assert "<PORT>49300</PORT>" in (out / "plugcell_rsi_ethernet.xml").read_text()


@pytest.mark.parametrize(("argv", "message"), [
    (["--ip", "kuka"], "does not appear to be an IPv4 or IPv6 address"),
    (["--ip", "10.0.0.1", "--max-step", "1,2"], "--max-step '1,2': expected 1 or 6"),
    (["--ip", "10.0.0.1", "--max-speed", "fast"], "--max-speed 'fast': expected numbers"),
    (["--ip", "10.0.0.1", "--max-offset", "-1"],
     "--max-offset '-1': -1 deg is not a finite number > 0"),
    (["--ip", "10.0.0.1", "--timeout", "0"], "--timeout 0: expected an integer 1..10000"),
])
def test_plugcell_rsi_files_errors(tmp_path, capsys, argv, message) -> None:
    assert main(["rsi", "files", "--out", str(tmp_path), *argv]) == 2
    assert message in capsys.readouterr().err


def test_plugcell_rsi_run_swings_one_axis(capsys) -> None:
    port = free_port("udp")
    done: dict[str, int] = {}
    cmd = threading.Thread(target=lambda: done.setdefault("code", main(
        ["rsi", "run", "--robot-ip", "127.0.0.1", "--listen", "127.0.0.1", "--port",
         str(port), "--mode", "absolute", "--sine", "A6:0.5:0.2", "--duration", "1.2",
         "--json"])))
    cmd.start()
    robot = BareRobot(("127.0.0.1", port))
    peak = 0.0
    try:
        for _ in range(200):
            try:
                answer = robot.cycle()
            except (TimeoutError, ConnectionRefusedError):
                continue  # the command is still starting
            peak = max(peak, float(ET.fromstring(answer).find("AKorr").get("A6")))
    finally:
        robot.close()
        cmd.join(timeout=10)
    assert done["code"] == 0
    assert peak == pytest.approx(0.5, abs=0.01)  # the swing's top, degrees
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines() if x.startswith("{")]
    assert lines and lines[-1]["answered"] > 0
    # the robot stopped before the command's end: the silence is how the stream ended
    assert lines[-1]["failure"] == "" or "no packet" in lines[-1]["failure"]
