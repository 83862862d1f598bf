"""The gateway secured: Basic256Sha256 SignAndEncrypt with the cell's OPC UA certificates,
username/password users, anonymous off, and the service's access policy deciding on the
OPC UA user's name (node-opcua as the client; docs/opcua.md, "Security")."""

from __future__ import annotations

import json
import os
import socket
import subprocess
from pathlib import Path

import pytest
from opcua_testlib import UaCell, plugcell_argv, run_js, unique_cell, until, wait_shown

from plugcell.devices.opcua.users import hash_password

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def secure_cell(tmp_path_factory, node_harness, cell_certs):
    """CAMERA with an access policy (alice may take pictures, nobody else) and a gateway
    that only speaks Basic256Sha256 SignAndEncrypt to users alice and bob."""
    root = tmp_path_factory.mktemp("secure")
    certs, rogue = cell_certs
    users = root / "users.toml"
    users.write_text(f'[users]\nalice = "{hash_password("alice-pw")}"\n'
                     f'bob = "{hash_password("bob-pw")}"\n')
    policy = root / "policy.toml"
    policy.write_text('default = "deny"\n[[rule]]\nactions = ["create"]\nsenders = ["alice"]\n'
                      'services = ["CAMERA"]\ncommands = ["SnapShot"]\n')
    home = root / "home"
    cell = UaCell(unique_cell("uas"), home,
                  {**os.environ, "PLUGCELL_HOME": str(home), "PYTHONUNBUFFERED": "1"})
    try:
        cell.serve("camera", env={"PLUGCELL_ACL": str(policy)})
        _, cell.url = cell.gateway("--users", str(users), "--certs", str(certs))
        wait_shown_secure(cell, certs)
        yield cell, certs, rogue
    finally:
        cell.stop()


def wait_shown_secure(cell, certs: Path) -> None:
    """Wait (node-opcua, as alice) until CAMERA is in the address space."""
    until(lambda: run_js("client.js", "login", cell.url, cell.name,
                         options=client_options(certs, "alice", "alice-pw")).get("status")
          == "Good", 30.0, "CAMERA callable through the secured gateway")


def client_options(certs: Path, user: str | None, password: str | None, **extra) -> dict:
    options = {
        "secure": True, "certificate": str(certs / "HMI.opcua.pem"),
        "privateKey": str(certs / "HMI.opcua.key"), "applicationUri": "urn:plugcell:opcua:HMI",
        "trustCa": str(certs / "opcua-ca.pem"), "trustCrl": str(certs / "opcua-ca.crl"),
        "user": user, "password": password,
    }
    return {**options, **extra}


def test_the_cells_certificates_and_a_user_get_in_and_others_are_refused(secure_cell):
    cell, certs, rogue = secure_cell
    base = client_options(certs, "alice", "alice-pw")
    attempts = [
        {},                                                   # alice, the cell's certificate
        {"password": "wrong"},                                # a wrong password
        {"user": "mallory", "password": "alice-pw"},          # no such user
        {"user": None},                                       # anonymous: off
        {"secure": False},                                    # no security: not offered
        {"certificate": str(rogue / "HMI.opcua.pem"),         # a certificate of another CA
         "privateKey": str(rogue / "HMI.opcua.key")},
    ]
    got = run_js("client.js", "login", cell.url, cell.name, limit_s=60.0,
                 options={**base, "attempts": attempts})
    alice, wrong, unknown, anonymous, insecure, foreign = got
    assert alice["status"] == "Good" and alice["image"]["dimensions"] == [480, 640]
    for refused in (wrong, unknown):
        assert "BadUserAccessDenied" in refused["refused"], refused
    # the server offers neither anonymous logins nor SecurityPolicy None
    assert "Cannot find ANONYMOUS user token policy" in anonymous["refused"], anonymous
    assert "securityMode = None" in insecure["refused"], insecure
    assert "BadCertificateUntrusted" in foreign["refused"], foreign


def test_the_services_access_policy_decides_on_the_opc_ua_user_and_the_journal_records_it(
        secure_cell):
    cell, certs, _ = secure_cell
    attempts = [{}, {"user": "bob", "password": "bob-pw"}]
    alice, bob = run_js("client.js", "login", cell.url, cell.name, limit_s=45.0,
                        options={**client_options(certs, "alice", "alice-pw"),
                                 "attempts": attempts})
    assert alice["status"] == "Good"
    assert bob["status"] == "BadUserAccessDenied"
    assert bob["reason"].startswith("access denied: bob may not run SnapShot on CAMERA")
    out = subprocess.run(
        plugcell_argv("journal", "--json", "--cell", cell.name, "--service", "CAMERA"),
        capture_output=True, text=True, env=cell.env, timeout=60, check=True,
    ).stdout
    rows = json.loads(out)
    rows = rows.get("processes", rows) if isinstance(rows, dict) else rows
    by_sender = {}
    for row in rows:
        by_sender.setdefault(row["sender"], []).append(row)
    assert any(r["state"] == "Completed" for r in by_sender["alice"])
    refused = [r for r in by_sender["bob"] if r["state"] == "Failed"]
    assert refused and refused[-1]["reason"].startswith(
        "access denied: bob may not run SnapShot on CAMERA")


def test_a_gateway_that_cannot_start_says_why(tmp_path):
    bad = tmp_path / "users.toml"
    bad.write_text('[users]\n"no good" = "scrypt$1$2$3$zz$00"\n')
    proc = subprocess.run(plugcell_argv("opcua", "serve", "--users", str(bad)),
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert f"{bad}: user 'no good'" in proc.stderr
    proc = subprocess.run(plugcell_argv("opcua", "serve"), capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 2 and "no way to log in" in proc.stderr
    assert "(--allow-anonymous)" in proc.stderr and "--users FILE" in proc.stderr
    # a port in the host (issue 39 §5): one line naming it, no traceback
    proc = subprocess.run(plugcell_argv("opcua", "serve", "--host", "127.0.0.1:4850",
                                        "--allow-anonymous"), capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip() == (
        "plugcell: error: --host '127.0.0.1:4850' holds a port: --host takes a host name or "
        "address; give the port with --port (--host 127.0.0.1 --port 4850)")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        proc = subprocess.run(
            plugcell_argv("opcua", "serve", "--allow-anonymous", "--port", str(port), "--cell",
                          unique_cell("taken")), capture_output=True, text=True, timeout=60,
            env={**os.environ, "PLUGCELL_HOME": str(tmp_path)})
    assert proc.returncode == 2
    assert proc.stderr.strip() == (  # one line: asyncua's traceback of the bind is not shown
        f"plugcell: error: cannot serve at opc.tcp://127.0.0.1:{port}/plugcell: port {port} on "
        "127.0.0.1 is in use (another OPC UA server or gateway?): stop it, or choose another "
        "port with --port"), proc.stderr


def test_a_client_without_security_cannot_even_browse(secure_cell):
    cell, _, _ = secure_cell
    with pytest.raises(Exception):  # noqa: B017  (asyncua as the client: no endpoint for it)
        wait_shown(cell.url, cell.name, {"CAMERA"}, timeout=3.0)
