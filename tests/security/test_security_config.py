"""The access policy, the Zenoh security settings and ``plugcell certs`` (no network)."""

from __future__ import annotations

import json
import stat
from pathlib import Path

import pytest
import zenoh
from cryptography import x509

from plugcell.apps.cli import main
from plugcell.framework.security import AccessPolicy, PolicyError, tls_settings, usrpwd_settings
from plugcell.framework.transport import TransportConfig

POLICY = {
    "default": "deny",
    "rule": [
        {"effect": "deny", "actions": ["create"], "senders": ["ROBOT9"]},
        {"actions": ["create"], "senders": ["ROBOT*"], "services": ["TRACKER"],
         "commands": ["Set *", "Move"]},
        {"actions": ["create"], "senders": ["CELL*"], "roles": ["service"]},
        {"actions": ["wire"], "senders": ["CONTROLLER"]},
    ],
}


def test_policy_decisions() -> None:
    p = AccessPolicy.from_mapping(POLICY)
    assert p.decide("create", "ROBOT1", "TRACKER", "Set Base") == ""
    assert p.decide("create", "ROBOT1", "TRACKER", "Move") == ""
    assert "no rule allows it" in p.decide("create", "ROBOT1", "TRACKER", "Single Measurement")
    assert "denied by policy: rule 1" in p.decide("create", "ROBOT9", "TRACKER", "Move")
    assert p.decide("create", "CELL1", "X", "Y", role="service") == ""
    assert p.decide("create", "CELL1", "X", "Y", role="client") != ""
    assert p.decide("wire", "CONTROLLER", "ROBOT1", "TRACKER") == ""
    assert p.decide("wire", "ROBOT1", "ROBOT2", "TRACKER").startswith(
        "access denied: ROBOT1 may not do wiring ROBOT2 to TRACKER")
    assert AccessPolicy.allow_all().decide("create", "anyone", "any", "thing") == ""


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"default": "maybe"}, "default must be"),
        ({"identity": "x"}, "identity must be"),
        ({"rule": [{"effect": "perhaps"}]}, "rule 1: effect"),
        ({"rule": [{"actions": ["delete"]}]}, "rule 1.actions: unknown"),
        ({"rule": [{"senders": [1]}]}, "rule 1.senders"),
        ({"rule": [{"colour": "red"}]}, "unknown keys ['colour']"),
        ({"rule": ["x"]}, "rule 1 is not a table"),
        ({"rules": []}, "unknown keys ['rules']"),
    ],
)
def test_policy_errors_are_precise(data: dict, message: str) -> None:
    with pytest.raises(PolicyError, match=message.replace("[", r"\[").replace("]", r"\]")):
        AccessPolicy.from_mapping(data)


def test_policy_file_from_env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "acl.toml"
    path.write_text('default = "deny"\n[[rule]]\nsenders = ["A"]\n')
    monkeypatch.setenv("PLUGCELL_ACL", str(path))
    p = AccessPolicy.from_env()
    assert p.decide("create", "A", "S", "C") == "" and p.decide("create", "B", "S", "C")
    path.write_text("default = \n")
    with pytest.raises(PolicyError, match=str(path)):
        AccessPolicy.from_env()
    monkeypatch.delenv("PLUGCELL_ACL")
    assert AccessPolicy.from_env() == AccessPolicy.allow_all()


def test_default_transport_is_unchanged(monkeypatch: pytest.MonkeyPatch) -> None:
    for var in ("PLUGCELL_TLS_CA", "PLUGCELL_TLS_DIR", "PLUGCELL_USER", "PLUGCELL_LISTEN"):
        monkeypatch.delenv(var, raising=False)
    cfg = TransportConfig.from_env()
    assert not cfg.secure and cfg.listen == ("tcp/127.0.0.1:0",)
    assert cfg._security_settings() == {}


def test_tls_from_env_and_zenoh_accepts_the_keys(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert main(["certs", "init", "--dir", str(tmp_path)]) == 0
    assert main(["certs", "issue", "CAMERA", "--dir", str(tmp_path), "--host", "cell.lab"]) == 0
    monkeypatch.setenv("PLUGCELL_TLS_DIR", str(tmp_path))
    monkeypatch.setenv("PLUGCELL_USER", "cell")
    monkeypatch.setenv("PLUGCELL_PASSWORD", "secret")
    monkeypatch.delenv("PLUGCELL_LISTEN", raising=False)
    cfg = TransportConfig.from_env().for_participant("CAMERA")
    assert cfg.listen == ("tls/127.0.0.1:0",) and cfg.tls_cert.endswith("CAMERA.pem")
    conf = cfg.zenoh_config()  # zenoh validates every key on insert
    assert json.loads(conf.get_json("transport/link/tls/enable_mtls")) is True
    assert json.loads(conf.get_json("transport/link/protocols")) == ["tls"]
    assert json.loads(conf.get_json("transport/auth/usrpwd/user")) == "cell"
    cert = x509.load_pem_x509_certificate((tmp_path / "CAMERA.pem").read_bytes())
    assert cert.subject.rfc4514_string() == "CN=CAMERA"
    assert "cell.lab" in str(cert.extensions.get_extension_for_class(x509.SubjectAlternativeName))
    assert stat.S_IMODE((tmp_path / "CAMERA.key").stat().st_mode) == 0o600
    assert main(["certs", "init", "--dir", str(tmp_path)]) == 2  # refuses to overwrite
    with pytest.raises(ValueError, match="plugcell certs issue ROBOT7"):
        TransportConfig.from_env().for_participant("ROBOT7")


def test_settings_helpers() -> None:
    with pytest.raises(ValueError, match="needs its private key"):
        tls_settings("ca.pem", cert="a.pem")
    assert usrpwd_settings() == {}
    assert usrpwd_settings(dictionary="users.txt") == {
        "transport/auth/usrpwd": {"dictionary_file": "users.txt"}}


def test_usrpwd_wrong_password_gets_no_link(tmp_path: Path) -> None:
    """Zenoh user/password authentication on loopback: a wrong password never links."""
    from plugcell.sim.ports import free_port

    users = tmp_path / "users.txt"
    users.write_text("cell:secret\n")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    server = TransportConfig(listen=(endpoint,), multicast=False, username="cell",
                             password="secret", users_file=str(users))
    s = zenoh.open(server.zenoh_config())
    try:
        q = s.declare_queryable("sec/ping", lambda query: query.reply("sec/ping", b"pong"))
        results = {}
        for password in ("secret", "wrong"):
            cfg = TransportConfig(listen=(), connect=(endpoint,), multicast=False,
                                  username="cell", password=password)
            c = zenoh.open(cfg.zenoh_config())
            try:
                results[password] = len([r for r in c.get("sec/ping", timeout=1.0) if r.ok])
            finally:
                c.close()
        q.undeclare()
    finally:
        s.close()
    assert results == {"secret": 1, "wrong": 0}


def test_the_documented_policy_is_valid() -> None:
    """The policy of docs/security.md parses and means what the text says."""
    import re
    import tomllib

    doc = (Path(__file__).resolve().parents[2] / "docs" / "security.md").read_text()
    block = re.search(r"```toml\n(.*?)```", doc, re.S)
    assert block is not None
    text = "\n".join(line.removeprefix("   ") for line in block.group(1).splitlines())
    p = AccessPolicy.from_mapping(tomllib.loads(text), "docs/security.md")
    assert p.identity == "signed" and p.default == "deny"
    assert p.decide("create", "ROBOT1", "TRACKER", "Move", role="service") == ""
    assert p.decide("create", "ROBOT1", "TRACKER", "Move", role="client") != ""
    assert p.decide("create", "TRACKER", "COMPUTE", "Evaluate", role="service") == ""
    assert p.decide("wire", "CONTROLLER", "ROBOT1", "TRACKER") == ""
    assert p.decide("wire", "ROBOT1", "ROBOT1", "TRACKER") != ""
    assert "denied by" in p.decide("create", "OPERATOR", "TRACKER", "Move", role="client")
