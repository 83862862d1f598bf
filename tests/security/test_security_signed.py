"""Signed requests through a Zenoh router: the sender is authenticated end to end.

Real processes: ``plugcell router`` (TLS, the cell's ACL) and two trackers behind it,
``TRACKER`` with ``identity = "signed"`` and ``TRACKER2`` with ``identity = "tls"``.
The requesters are Zenoh *clients* of the router, so every request reaches a tracker
over the router's link, never over one of the requester's own.  There, ``tls`` cannot
tell who sent a request (it refuses everyone); ``signed`` accepts the right sender and
refuses, with the reason and a journal row, an unsigned request, a wrong key, another
participant's certificate, a certificate of another CA, a stale timestamp and a replay
of the bytes of a real signed request.
"""

from __future__ import annotations

import asyncio
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import pytest
import zenoh
from framework_testlib import Proc, plugcell_argv, run, unique_cell
from sec_testlib import issue_cell_certificates

from plugcell.framework import Client, TransportConfig, codec
from plugcell.framework.journal import journal_files, read_journal
from plugcell.framework.keys import KeySpace
from plugcell.framework.messages import Acknowledgement, Command, Data, DataTypes, Process, Tag
from plugcell.framework.signing import RequestSigner
from plugcell.sim.ports import free_port

pytestmark = pytest.mark.timeout(240)

NAMES = ("TRACKER", "TRACKER2", "ROBOT1", "ROBOT2", "CONTROLLER", "ROUTER")
BASE = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
POLICY = """
default = "deny"
identity = "{identity}"

[[rule]]
actions = ["create"]
senders = ["ROBOT1"]
services = ["TRACKER*"]
commands = ["Set Base", "Set Probe", "Move", "Single Measurement"]

[[rule]]
actions = ["wire"]
senders = ["CONTROLLER"]
"""


@dataclass
class RoutedCell:
    name: str
    certs: Path
    rogue: Path
    home: Path
    router: str

    def transport(self, who: str, folder: Path | None = None, **kw: object) -> TransportConfig:
        """A Zenoh *client* of the router, with ``who``'s certificate."""
        folder = folder or self.certs
        return TransportConfig(
            mode="client", listen=(), connect=(self.router,), multicast=False,
            tls_ca=str(self.certs / "ca.pem"), tls_cert=str(folder / f"{who}.pem"),
            tls_key=str(folder / f"{who}.key"), **kw)  # type: ignore[arg-type]

    def journal(self, service: str = "TRACKER") -> list[dict]:
        return [r for r in read_journal(journal_files(self.name, self.home))
                if r["recipient"] == service]


@pytest.fixture(scope="module")
def routed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RoutedCell]:
    base = tmp_path_factory.mktemp("routed")
    certs, rogue, home = issue_cell_certificates(base, "routed", NAMES)
    for identity in ("signed", "tls"):
        (base / f"{identity}.toml").write_text(POLICY.format(identity=identity))
    router = f"tls/127.0.0.1:{free_port()}"
    env = {**os.environ, "PLUGCELL_HOME": str(home), "PYTHONUNBUFFERED": "1",
           "PLUGCELL_MULTICAST": "0", "PLUGCELL_TLS_CA": str(certs / "ca.pem"),
           "PLUGCELL_CELL_NAMES": ",".join(NAMES)}
    cell = unique_cell("sig")
    procs: list[Proc] = []
    try:
        procs.append(Proc(plugcell_argv("router", "--listen", router), {
            **env, "PLUGCELL_TLS_CERT": str(certs / "ROUTER.pem"),
            "PLUGCELL_TLS_KEY": str(certs / "ROUTER.key")}))
        procs[-1].wait_line(lambda line: "listening on" in line, 30.0)
        behind = {**env, "PLUGCELL_TLS_DIR": str(certs), "PLUGCELL_CONNECT": router,
                  "PLUGCELL_LISTEN": "tls/127.0.0.1:0"}
        behind.pop("PLUGCELL_CELL_NAMES")  # the router's ACL guards the cell
        for name, identity in (("TRACKER", "signed"), ("TRACKER2", "tls")):
            procs.append(Proc(
                plugcell_argv("serve", "tracker", "--cell", cell, "--name", name,
                              "--param", "seed=7"),
                {**behind, "PLUGCELL_ACL": str(base / f"{identity}.toml")}))
        for proc in procs[1:]:
            proc.wait_line(lambda line: "serving in cell" in line, 30.0)
        yield RoutedCell(cell, certs, rogue, home, router)
    finally:
        for proc in reversed(procs):
            proc.stop()


async def _create(cell: RoutedCell, name: str, transport: TransportConfig,
                  service: str = "TRACKER", signer: RequestSigner | None = None,
                  spy: list[bytes] | None = None) -> tuple[str, str]:
    async with Client(name, cell=cell.name, transport=transport) as client:
        if signer is not None:
            client.signer = signer
        if spy is not None:
            encode = client.encode

            def recording(body: object, to: str = "") -> bytes:
                out = encode(body, to)  # type: ignore[arg-type]
                if isinstance(body, Process):
                    spy.append(out)
                return out

            client.encode = recording  # type: ignore[method-assign]
        assert await client.wait_for(service, 10.0)
        call = await client.create_process(service, "Set Base", data=BASE, timeout=10.0)
        final = call.final or await asyncio.wait_for(call.result(), 10.0)
        return final.state.value, final.reason


def _send_raw(cell: RoutedCell, who: str, payload: bytes) -> Acknowledgement:
    """Put ``payload`` on TRACKER's create key from a raw Zenoh session of ``who``."""
    session = zenoh.open(cell.transport(who).zenoh_config())
    try:
        key = KeySpace(cell.name).create("TRACKER")
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            for reply in session.get(key, payload=payload, timeout=5.0):
                if reply.ok is not None:
                    body = codec.decode(reply.ok.payload.to_bytes()).body
                    assert isinstance(body, Acknowledgement)
                    return body
            time.sleep(0.2)  # the route to the queryable is not known yet
    finally:
        session.close()
    raise AssertionError("no acknowledgement from TRACKER")


def _refused(cell: RoutedCell, reason: str) -> None:
    rows = [r for r in cell.journal() if r["reason"] == reason]
    assert rows and rows[-1]["state"] == "Failed" and rows[-1].get("rejected"), reason


def test_signed_request_passes_through_the_router_where_tls_cannot(routed: RoutedCell) -> None:
    state, reason = run(_create(routed, "ROBOT1", routed.transport("ROBOT1")))
    assert (state, reason) == ("Completed", "")
    done = [r for r in routed.journal() if r["sender"] == "ROBOT1" and r["state"] == "Completed"]
    assert done and done[-1]["command"] == "Set Base"
    # the same robot, the same request: identity = "tls" sees only the router's link
    state, reason = run(_create(routed, "ROBOT1", routed.transport("ROBOT1"), "TRACKER2"))
    assert state == "Failed" and reason == (
        "access denied: sender ROBOT1 is not authenticated "
        "(certificate of its session: no authenticated link)")


def test_unsigned_request_is_refused_and_journaled(routed: RoutedCell) -> None:
    transport = replace(routed.transport("ROBOT1"), sign_requests=False)
    state, reason = run(_create(routed, "ROBOT1", transport))
    assert (state, reason) == ("Failed", "access denied: request of ROBOT1 not signed")
    _refused(routed, reason)


def test_wrong_key_is_refused(routed: RoutedCell) -> None:
    own = RequestSigner.load(routed.certs / "ROBOT1.pem", routed.certs / "ROBOT1.key")
    other = RequestSigner.load(routed.certs / "ROBOT2.pem", routed.certs / "ROBOT2.key")
    forged = RequestSigner(own.cert_der, other.key, "ROBOT1")  # ROBOT1's certificate, not its key
    state, reason = run(_create(routed, "ROBOT1", routed.transport("ROBOT2"), signer=forged))
    assert (state, reason) == ("Failed",
                               "access denied: request of ROBOT1: signature does not verify")
    _refused(routed, reason)


def test_another_participants_certificate_is_refused(routed: RoutedCell) -> None:
    """ROBOT2 (a certified peer) calling itself ROBOT1: its own certificate signs."""
    state, reason = run(_create(routed, "ROBOT1", routed.transport("ROBOT2")))
    assert (state, reason) == (
        "Failed", "access denied: request of ROBOT1: certificate CN ROBOT2 is not the sender "
                  "ROBOT1")
    _refused(routed, reason)


def test_certificate_of_another_ca_is_refused(routed: RoutedCell) -> None:
    """A link with a certificate of the cell, a signature with one of another CA."""
    rogue = RequestSigner.load(routed.rogue / "ROBOT1.pem", routed.rogue / "ROBOT1.key")
    state, reason = run(_create(routed, "ROBOT1", routed.transport("ROBOT1"), signer=rogue))
    assert (state, reason) == (
        "Failed", "access denied: request of ROBOT1: certificate not issued by the cell's CA "
                  "(issuer: plugcell cell rogue CA)")
    _refused(routed, reason)


def test_stale_request_is_refused(routed: RoutedCell) -> None:
    signer = RequestSigner.load(routed.certs / "ROBOT1.pem", routed.certs / "ROBOT1.key")
    process = Process(command=Command(name="Set Base"), tag=Tag("ROBOT1", "TRACKER"),
                      identifier=time.time_ns(),
                      data=Data(DataTypes.Double, (6,), b"\0" * 48))
    old = time.time_ns() - 120 * 10**9
    payload = signer.encode("ROBOT1", f"{old:016x}" + "ab" * 16, process, cell=routed.name,
                            to="TRACKER", time_ns=old)
    ack = _send_raw(routed, "ROBOT1", payload)
    assert ack.state.value == "Failed"
    assert ack.reason.startswith("access denied: request of ROBOT1: timestamp 120.")
    assert ack.reason.endswith("s in the past, outside the window of ±30 s")
    _refused(routed, ack.reason)


def test_replayed_request_is_refused(routed: RoutedCell) -> None:
    """The bytes of a real signed request, sent again by another certified peer."""
    captured: list[bytes] = []
    state, _ = run(_create(routed, "ROBOT1", routed.transport("ROBOT1"), spy=captured))
    assert state == "Completed" and len(captured) == 1
    envelope = codec.decode(captured[0])
    assert envelope.auth is not None and envelope.auth.to == "TRACKER"
    ack = _send_raw(routed, "ROBOT2", captured[0])
    assert ack.state.value == "Failed"
    assert ack.reason == (f"access denied: request of ROBOT1: replayed request "
                          f"(nonce {envelope.auth.nonce.hex()} already seen)")
    _refused(routed, ack.reason)
    # the process ran once
    runs = [r for r in routed.journal() if r["sender"] == "ROBOT1"
            and r.get("identifier") == envelope.body.identifier]  # type: ignore[union-attr]
    assert [r["state"] for r in runs if not r.get("rejected")] == ["Completed"]


def test_wiring_is_signed_too(routed: RoutedCell) -> None:
    async def ask(name: str, who: str) -> tuple[bool, str]:
        async with Client(name, cell=routed.name, transport=routed.transport(who)) as client:
            assert await client.wait_for("TRACKER", 10.0)
            r = await client.ask_subscribe("TRACKER", "NOBODY", subscribe=False, timeout=10.0)
            return r.ok, r.reason

    assert run(ask("CONTROLLER", "CONTROLLER")) == (False, "NOBODY was not a partner of TRACKER")
    ok, reason = run(ask("CONTROLLER", "ROBOT2"))
    assert not ok and reason == ("access denied: request of CONTROLLER: certificate CN ROBOT2 "
                                 "is not the sender CONTROLLER")
    rows = [r for r in routed.journal() if r["reason"] == reason]
    assert rows and rows[-1]["command"] == "UnsubscribeRequest"


def test_a_service_checking_signatures_needs_the_cells_ca() -> None:
    from framework_testlib import scripted

    from plugcell.framework.security import AccessPolicy
    from plugcell.framework.signing import SigningError

    async def body() -> None:
        dev = scripted(cell=unique_cell(), journal=False,
                             transport=TransportConfig(multicast=False),
                             access=AccessPolicy(identity="signed"))
        with pytest.raises(SigningError, match="identity = 'signed' needs the cell's CA"):
            await dev.start()
        assert dev.participant.session is None or dev.participant.session.is_closed()

    run(body())
