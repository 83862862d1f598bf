"""`plugcell serve opcua-device` checks the server it connects to (docs/opcua.md, "Which
servers the service trusts"): node-opcua servers (tests/opcua/js/gripper_server.js) with
a certificate of the cell, a rotated one, an impostor's, an expired one, one for
another host or application — the service connects only to the first two, and says why
it refuses the others."""

from __future__ import annotations

import asyncio
import datetime as dt
import json
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
from childproc import Proc
from opcua_testlib import JS, plugcell_argv, unique_cell

from plugcell.devices.opcua.certificates import certificate_paths, issue_application_certificate
from plugcell.devices.opcua.client import AsyncuaDriver
from plugcell.devices.opcua.device import OpcUaDevice
from plugcell.framework import DeviceError, GenericDevice
from plugcell.sim.ports import free_port

pytestmark = pytest.mark.slow

MAP = Path(__file__).resolve().parent / "gripper.toml"
PLC_URI = "urn:plugcell:opcua:GRIPPER_PLC"


class Servers:
    """node-opcua gripper servers, each with its own certificate, stopped at the end."""

    def __init__(self, certs: Path, env: dict[str, str]) -> None:
        self.certs = certs
        self.env = env
        self.procs: list[Proc] = []

    def start(self, cert: Path | None = None, key: Path | None = None, uri: str = PLC_URI,
              host: str = "127.0.0.1") -> str:
        """A server trusting the cell's clients (user plc), with ``cert`` (None: node-opcua's
        own self-signed certificate); its endpoint at ``host``."""
        port = free_port()
        args = ["node", str(JS / "gripper_server.js"), str(port),
                str(self.certs / "opcua-ca.pem"), str(self.certs / "opcua-ca.crl")]
        if cert is not None:
            args.append(json.dumps({"certificate": str(cert), "privateKey": str(key),
                                    "applicationUri": uri}))
        proc = Proc(args, self.env)
        self.procs.append(proc)
        proc.wait_line(lambda line: '"listening"' in line, 30.0)
        return f"opc.tcp://{host}:{port}/gripper"

    def stop(self) -> None:
        for proc in self.procs:
            proc.stop()


@pytest.fixture(scope="module")
def servers(cell_certs, node_harness, tmp_path_factory) -> Iterator[Servers]:
    import os

    certs, _ = cell_certs
    home = tmp_path_factory.mktemp("trust-home")
    got = Servers(certs, {**os.environ, "PLUGCELL_HOME": str(home), "PYTHONUNBUFFERED": "1"})
    try:
        yield got
    finally:
        got.stop()


def plc_certificate(certs: Path, folder: Path, **kw) -> tuple[Path, Path]:
    """A server certificate GRIPPER_PLC of the cell's CA, copied to ``folder``."""
    issue_application_certificate(certs, "GRIPPER_PLC", **kw)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for path in certificate_paths(certs, "GRIPPER_PLC"):
        paths.append(Path(shutil.copy(path, folder / path.name)))
    return paths[0], paths[1]


async def connect(endpoint: str, certs: Path, **kw) -> str:
    """Connect SECURE_GRIPPER as user plc; "" when connected, else the refusal."""
    device = GenericDevice(OpcUaDevice(AsyncuaDriver(endpoint=endpoint, certs=certs, user="plc",
                                                     **kw), map=MAP),
                           "SECURE_GRIPPER", journal=False).interface
    try:
        await device._open()  # connect() without the service's state reports
    except DeviceError as exc:
        return str(exc)
    await device._close_client()
    return ""


@pytest.fixture
def password(monkeypatch):
    monkeypatch.setenv("PLUGCELL_OPCUA_PASSWORD", "gripper-pw")


def test_a_server_of_the_cell_is_trusted_and_so_is_its_rotated_certificate(
        servers, tmp_path, password):
    certs = servers.certs
    first = servers.start(*plc_certificate(certs, tmp_path / "first"))
    rotated = servers.start(*plc_certificate(certs, tmp_path / "rotated"))  # new key, serial
    assert asyncio.run(connect(first, certs)) == ""
    assert asyncio.run(connect(rotated, certs)) == ""
    # the same, pinned: the server's own certificate in --trust DIR, a CA-less cell folder
    alone = tmp_path / "alone"
    alone.mkdir()
    for path in certificate_paths(certs, "SECURE_GRIPPER"):
        shutil.copy(path, alone / path.name)
    pinned = tmp_path / "pinned"
    pinned.mkdir()
    shutil.copy(tmp_path / "rotated" / "GRIPPER_PLC.opcua.pem", pinned / "plc.pem")
    assert asyncio.run(connect(rotated, alone, trust=pinned)) == ""
    why = asyncio.run(connect(first, alone, trust=pinned))
    assert "GRIPPER_PLC" in why and "is not trusted" in why


def test_an_impostor_is_refused_with_the_reason_and_its_certificate_kept(
        servers, tmp_path, password):
    """A server at the device's address with a certificate of its own (node-opcua's
    self-signed one): refused before the user's password is sent."""
    certs = servers.certs
    impostor = servers.start()
    trust = tmp_path / "trust"
    trust.mkdir()
    why = asyncio.run(connect(impostor, certs, trust=trust))
    assert why.startswith(f"cannot connect to {impostor}: the server certificate of "
                          f"{impostor} (")
    assert "is not trusted: neither in the trust list nor issued by a trusted authority" in why
    assert str(certs / "opcua-ca.pem") in why
    assert len(list((trust / "rejected").glob("*.der"))) == 1
    # the service itself stops at start with the reason (exit code 2)
    proc = subprocess.run(
        plugcell_argv("serve", "opcua-device", "--cell", unique_cell("imp"), "--no-journal",
                      "--endpoint", impostor, "--map", str(MAP), "--name", "SECURE_GRIPPER",
                      "--param", f"certs={certs}", "--param", "user=plc"),
        capture_output=True, text=True, env={**servers.env, "PLUGCELL_OPCUA_PASSWORD": "x"},
        timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert "is not trusted: neither in the trust list" in proc.stderr


def test_an_expired_certificate_and_one_for_another_host_or_application_are_refused(
        servers, tmp_path, password):
    certs = servers.certs
    old = dt.datetime.now(dt.UTC) - dt.timedelta(days=30)
    expired = servers.start(*plc_certificate(certs, tmp_path / "expired", start=old, days=10))
    why = asyncio.run(connect(expired, certs))
    assert f"expired on {old + dt.timedelta(days=10):%Y-%m-%d %H:%M} UTC" in why, why
    valid = servers.start(*plc_certificate(certs, tmp_path / "valid"), host="127.0.0.2")
    why = asyncio.run(connect(valid, certs))
    assert why.endswith("is for the hosts localhost, 127.0.0.1, not 127.0.0.2 of the "
                        "endpoint"), why
    local = valid.replace("127.0.0.2", "127.0.0.1")
    assert asyncio.run(connect(local, certs)) == ""
    why = asyncio.run(connect(local, certs, server_uri="urn:plant:press7"))
    assert why.endswith(f"is the application {PLC_URI}, not the expected urn:plant:press7 "
                        "(server_uri)"), why
    assert asyncio.run(connect(local, certs, server_uri=PLC_URI)) == ""
    # a server that says it is another application than its certificate names
    liar = servers.start(*plc_certificate(certs, tmp_path / "liar"), uri="urn:plant:press7")
    why = asyncio.run(connect(liar, certs))
    assert f"names the application URI {PLC_URI}, but the server says it is " \
        "urn:plant:press7" in why, why


def test_accepting_any_server_is_explicit_and_logged(servers, tmp_path, password):
    certs = servers.certs
    impostor = servers.start()
    assert asyncio.run(connect(impostor, certs, insecure_accept_any=True)) == ""
    env = {**servers.env, "PLUGCELL_OPCUA_PASSWORD": "gripper-pw"}
    proc = Proc(plugcell_argv("serve", "opcua-device", "--cell", unique_cell("any"),
                              "--no-journal", "--endpoint", impostor, "--map", str(MAP),
                              "--name", "SECURE_GRIPPER", "--param", f"certs={certs}",
                              "--param", "user=plc", "--insecure-accept-any"), env)
    try:
        proc.wait_line(lambda line: "serving in cell" in line, 30.0)
        assert any(f"--insecure-accept-any: accepting whatever server answers at {impostor}"
                   in line for line in proc.errors), proc.errors
    finally:
        proc.stop()
    with pytest.raises(ValueError, match=r"cannot authenticate the server of .* without a "
                       r"certificate of its own"):
        AsyncuaDriver(endpoint=impostor)
    with pytest.raises(ValueError, match="only a secured connection has"):
        AsyncuaDriver(endpoint=impostor, trust=tmp_path, insecure_accept_any=True)
