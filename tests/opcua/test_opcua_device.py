"""`plugcell serve opcua-device`: an OPC UA server's device (a gripper written with
node-opcua, tests/opcua/js/gripper_server.js) becomes a plugcell service that a robot
program drives with ACTIVATE strings (docs/opcua.md, "OPC UA devices as services")."""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from opcua_testlib import JS, Proc, plugcell_argv, run_js, unique_cell, until

from plugcell.devices.opcua.certificates import issue_application_certificate
from plugcell.devices.opcua.client import AsyncuaDriver
from plugcell.devices.opcua.device import OpcUaDevice
from plugcell.devices.opcua.device_map import parse_device_map
from plugcell.framework import BlockingClient, DeviceError, GenericDevice, ProcessStates, from_data
from plugcell.sim.ports import free_port

pytestmark = pytest.mark.slow

HERE = Path(__file__).resolve().parent
MAP = HERE / "gripper.toml"
C, F = ProcessStates.Completed, ProcessStates.Failed


class GripperCell:
    """The node-opcua gripper server, GRIPPER (opcua-device) and a simulated ROBOT."""

    def __init__(self, home: Path) -> None:
        self.name = unique_cell("uad")
        self.home = home
        self.env = {**os.environ, "PLUGCELL_HOME": str(home), "PYTHONUNBUFFERED": "1"}
        self.port = free_port()
        self.endpoint = f"opc.tcp://127.0.0.1:{self.port}/gripper"
        self.procs: list[Proc] = []
        self.server: Proc | None = None
        self.gateway_url = ""

    def start_server(self) -> Proc:
        self.server = Proc(["node", str(JS / "gripper_server.js"), str(self.port)], self.env)
        self.procs.append(self.server)
        self.server.wait_line(lambda line: '"listening"' in line, 30.0)
        return self.server

    def serve(self, kind: str, *extra: str) -> Proc:
        proc = Proc(plugcell_argv("serve", kind, "--cell", self.name, *extra), self.env)
        self.procs.append(proc)
        proc.wait_line(lambda line: "serving in cell" in line, 30.0)
        return proc

    def calls(self) -> list[dict]:
        """What the gripper server was asked, in order."""
        assert self.server is not None
        return [json.loads(line) for line in self.server.lines if line.startswith('{"called"')]

    def stop(self) -> None:
        for proc in reversed(self.procs):
            proc.stop()


@pytest.fixture(scope="module")
def gripper_cell(tmp_path_factory, node_harness) -> Iterator[GripperCell]:
    cell = GripperCell(tmp_path_factory.mktemp("home"))
    try:
        cell.start_server()
        cell.serve("opcua-device", "--endpoint", cell.endpoint, "--map", str(MAP),
                   "--param", "watch_s=0.3", "--insecure-accept-any")  # SecurityPolicy None
        cell.serve("robot", "--param", "sim=true", "--param", "speed=1000", "--param", "seed=3",
                   "--param", f"library={HERE / 'programs'}")
        gateway = Proc(plugcell_argv("opcua", "serve", "--cell", cell.name, "--port",
                                     str(free_port()), "--allow-anonymous", "--robot-poll",
                                     "0.2"), cell.env)
        cell.procs.append(gateway)
        line = gateway.wait_line(lambda line: "OPC UA gateway" in line, 30.0)
        cell.gateway_url = line.split(" at ")[1].split()[0]
        yield cell
    finally:
        cell.stop()


def test_a_robot_program_drives_the_opc_ua_gripper_with_activate_strings(gripper_cell):
    with BlockingClient("tester", cell=gripper_cell.name) as client:
        assert client.wait_for("ROBOT", 10.0) and client.wait_for("GRIPPER", 10.0)
        assert client.ask_subscribe("ROBOT", "GRIPPER").ok
        final = client.create_process("ROBOT", "ACTIVATE", "Wait", ["grip"],
                                      timeout=60.0).result()
        assert final.state is C, final.reason
        status = client.create_process("ROBOT", "PROGRAM_STATUS").result()
        console = [str(s) for s in from_data(status.data).reshape(-1)][4:]
    assert console[0] == "closed at 20.0 N"
    assert console[1] == "holding 20 N"
    assert console[2].startswith("refused: ") and "BadOutOfRange" in console[2]
    assert console[3] == "released"
    assert gripper_cell.calls() == [{"called": "Close", "force": 20},
                                    {"called": "Close", "force": 500}, {"called": "Open"}]


def test_a_generic_client_finds_the_robot_by_its_opc_40010_type_and_reads_its_axes(
        gripper_cell):
    """node-opcua, knowing only DI and OPC 40010, browses the whole address space by type:
    the robot is the one MotionDeviceType, its axes' ActualPosition are what the robot
    service answers (ARM_JNTP), standing still (ActualSpeed 0 °/s); the gripper (an
    opcua-device service) is a DI device; the flange pose is the service's ARM_POS."""
    with BlockingClient("direct", cell=gripper_cell.name) as client:
        assert client.wait_for("ROBOT", 10.0)
        joints = from_data(client.create_process("ROBOT", "ARM_JNTP").result().data)
        pose = from_data(client.create_process("ROBOT", "ARM_POS").result().data)
    seen: dict = {}

    def shown() -> bool:
        seen.clear()
        seen.update(run_js("client.js", "types", gripper_cell.gateway_url, gripper_cell.name,
                           limit_s=60.0))
        devices = seen["motionDevices"]
        return (len(devices) == 1 and len(devices[0]["axes"]) == len(joints)
                and all(a["position"]["status"] == "Good" and a["speed"]["status"] == "Good"
                        for a in devices[0]["axes"])
                and np.allclose([a["position"]["value"] for a in devices[0]["axes"]], joints,
                                atol=1e-9))

    until(shown, 60.0, "the robot's axes, by type, in the address space")
    robot = seen["motionDevices"][0]
    assert robot["name"] == "ROBOT" and robot["category"] == 1  # ARTICULATED_ROBOT
    # DI identification from the robot file (smart_h4.toml's [identification])
    assert (robot["Manufacturer"], robot["Model"]) == ("Comau", "Smart H4")
    assert (robot["SerialNumber"], robot["ProductCode"]) == ("", "")
    assert [a["name"] for a in robot["axes"]] == [f"Axis{k}" for k in range(1, 7)]
    assert all(a["type"] and a["unit"] == "°" for a in robot["axes"])
    assert [a["speed"]["value"] for a in robot["axes"]] == [0.0] * 6
    assert robot["powerTrains"] == 6
    assert seen["devices"] == ["GRIPPER"]
    flange = run_js("client.js", "robot", gripper_cell.gateway_url, gripper_cell.name)["flange"]
    np.testing.assert_allclose(flange, pose, atol=1e-9)


def test_a_lost_connection_fails_the_stream_and_the_service_reconnects(gripper_cell):
    with BlockingClient("watcher", cell=gripper_cell.name) as client:
        assert client.wait_for("GRIPPER", 10.0)
        assert client.create_process("GRIPPER", "Close", "", 10.0).result().state is C
        stream = client.create_process("GRIPPER", "WatchForce", timeout=30.0)  # it creeps
        frames = 0
        updates = iter(stream)
        for update in updates:
            frames += update.data is not None
            if frames == 2:
                break
        assert gripper_cell.server is not None
        gripper_cell.server.kill9()  # the device's server dies
        final = stream.result()
        assert final.state is F
        assert final.reason.startswith(
            f"WatchForce: device feedback 'connection to {gripper_cell.endpoint} lost: "
        ) and final.reason.endswith("' while streaming"), final.reason
        down = client.create_process("GRIPPER", "Force").result()
        assert down.state is F and f"connection to {gripper_cell.endpoint} lost" in down.reason
        assert client.get("GRIPPER").device_info.connection.value == "Error"
        gripper_cell.start_server()  # back on the same port

        def force_read() -> bool:
            return client.create_process("GRIPPER", "Force").result().state is C

        until(force_read, 30.0, "GRIPPER reading the force again")
        assert client.get("GRIPPER").device_info.connection.value == "Online"


def _serve_with(cell: GripperCell, map_text: str, tmp_path: Path) -> subprocess.CompletedProcess:
    path = tmp_path / "device.toml"
    path.write_text(map_text)
    return subprocess.run(
        plugcell_argv("serve", "opcua-device", "--cell", unique_cell("bad"), "--no-journal",
                      "--endpoint", cell.endpoint, "--map", str(path), "--name", "BROKEN",
                      "--insecure-accept-any"),
        capture_output=True, text=True, env=cell.env, timeout=60,
    )


async def _connect_with(cell: GripperCell, maps: list[str]) -> list[str]:
    """Why the device interface refuses each map (its DeviceError at connect)."""
    reasons = []
    for text in maps:
        device = GenericDevice(OpcUaDevice(
            AsyncuaDriver(endpoint=cell.endpoint, insecure_accept_any=True),
            map=parse_device_map(text, "device.toml")), "BROKEN", journal=False).interface
        with pytest.raises(DeviceError) as err:
            await device.connect()
        assert str(err.value).startswith("device.toml: command ")
        reasons.append(str(err.value))
    return reasons


def test_a_map_naming_nodes_that_do_not_exist_stops_the_service_at_start(gripper_cell,
                                                                          tmp_path):
    until(lambda: gripper_cell.server is not None and gripper_cell.server.popen.poll() is None,
          5.0, "the gripper server")
    text = MAP.read_text()
    missing = _serve_with(gripper_cell, text.replace("s=Gripper.Open", "s=Gripper.Twist"),
                          tmp_path)
    assert missing.returncode == 2
    assert ("command 'Open': method nsu=urn:plugcell:test:gripper;s=Gripper.Twist does not "
            f"exist on {gripper_cell.endpoint} (BadNodeIdUnknown)") in missing.stderr
    # the same checks, straight from the device interface (no service process each)
    reasons = asyncio.run(_connect_with(gripper_cell, [
        text.replace("nsu=urn:plugcell:test:gripper;s=Gripper.Force",
                     "nsu=urn:nowhere;s=Gripper.Force"),
        text.replace('read = "nsu=urn:plugcell:test:gripper;s=Gripper.Force"\n'
                     'output = { type = "Double"',
                     'read = "nsu=urn:plugcell:test:gripper;s=Gripper.Force"\n'
                     'output = { type = "Integer"'),
        text.replace('read = "nsu=urn:plugcell:test:gripper;s=Gripper.Force"',
                     'read = "nsu=urn:plugcell:test:gripper;s=Gripper.Open"'),
        text.replace('object = "nsu=urn:plugcell:test:gripper;s=Gripper"',
                     'object = "nsu=urn:plugcell:test:gripper;s=Gripper.Hand"'),
    ]))
    assert "command 'Force': read nsu=urn:nowhere;s=Gripper.Force: the server has no " \
        "namespace urn:nowhere" in reasons[0]
    assert "variable nsu=urn:plugcell:test:gripper;s=Gripper.Force holds i=11, but the map " \
        "declares Integer (i=6)" \
        in reasons[1]
    assert ";s=Gripper.Open is a Method, not a Variable" in reasons[2]
    assert "command 'Open': object nsu=urn:plugcell:test:gripper;s=Gripper.Hand does not " \
        "exist" in reasons[3]
    nobody = subprocess.run(
        plugcell_argv("serve", "opcua-device", "--cell", unique_cell("bad"), "--no-journal",
                      "--endpoint", f"opc.tcp://127.0.0.1:{free_port()}/none", "--map",
                      str(MAP), "--insecure-accept-any"),
        capture_output=True, text=True, env=gripper_cell.env, timeout=60)
    assert nobody.returncode == 2 and "cannot connect to opc.tcp://127.0.0.1:" in nobody.stderr


def test_a_secured_device_server_is_reached_with_the_cells_certificate_and_a_user(
        gripper_cell, cell_certs, monkeypatch):
    """Basic256Sha256 SignAndEncrypt, the cell's application certificate of the service,
    the user plc (password from $PLUGCELL_OPCUA_PASSWORD), the server's certificate one of
    the cell's (test_opcua_device_trust.py checks the others are refused); a wrong password
    is refused at connection with the server's reason."""
    from plugcell.devices.opcua.certificates import certificate_paths

    certs, _ = cell_certs
    port = free_port()
    endpoint = f"opc.tcp://127.0.0.1:{port}/gripper"
    issue_application_certificate(certs, "GRIPPER_PLC")
    cert, key = certificate_paths(certs, "GRIPPER_PLC")
    own = {"certificate": str(cert), "privateKey": str(key),
           "applicationUri": "urn:plugcell:opcua:GRIPPER_PLC"}
    server = Proc(["node", str(JS / "gripper_server.js"), str(port), str(certs / "opcua-ca.pem"),
                   str(certs / "opcua-ca.crl"), json.dumps(own)], gripper_cell.env)
    gripper_cell.procs.append(server)
    server.wait_line(lambda line: '"listening"' in line, 30.0)

    async def refused() -> str:
        device = GenericDevice(OpcUaDevice(AsyncuaDriver(endpoint=endpoint, certs=certs,
                                                         user="plc"), map=MAP),
                               "SECURE_GRIPPER", journal=False).interface
        with pytest.raises(DeviceError) as err:
            await device.connect()
        return str(err.value)

    monkeypatch.setenv("PLUGCELL_OPCUA_PASSWORD", "wrong")
    assert "BadUserAccessDenied" in asyncio.run(refused())
    service = Proc(plugcell_argv(
        "serve", "opcua-device", "--cell", gripper_cell.name, "--endpoint", endpoint, "--map",
        str(MAP), "--name", "SECURE_GRIPPER", "--param", f"certs={certs}", "--param",
        "user=plc", "--no-journal"), {**gripper_cell.env, "PLUGCELL_OPCUA_PASSWORD": "gripper-pw"})
    gripper_cell.procs.append(service)
    service.wait_line(lambda line: "serving in cell" in line, 30.0)
    with BlockingClient("secure-tester", cell=gripper_cell.name) as client:
        assert client.wait_for("SECURE_GRIPPER", 10.0)
        closed = client.create_process("SECURE_GRIPPER", "Close", "", 30.0).result()
        assert closed.state is C and float(from_data(closed.data)[0]) == 30.0
    assert [json.loads(line) for line in server.lines if '"called"' in line] == [
        {"called": "Close", "force": 30}]
