"""An unauthorised peer cannot create a process on the tracker (issue 10 §1).

The tracker runs as an OS process in a TLS cell (mutual TLS, certificates from
``plugcell certs``, access policy from ``PLUGCELL_ACL``).  Peers without a
certificate or with one from another CA never get a link (the TLS handshake fails,
so nothing reaches the service); a peer with a good certificate that the policy
does not allow, or that claims another name than its certificate's, is refused
``access denied: …`` and the refusal is in the tracker's journal with its reason.
"""

from __future__ import annotations

import asyncio
import time

from framework_testlib import run
from sec_testlib import SecureCell

from plugcell.framework import Client, ProcessStates, TransportConfig
from plugcell.framework.journal import journal_files, read_journal

BASE = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]


async def _create(cell: SecureCell, name: str, transport: TransportConfig, command: str,
                  timeout: float = 5.0, data: object = BASE) -> tuple[str, str]:
    async with Client(name, cell=cell.name, transport=transport) as client:
        call = await client.create_process("TRACKER", command, data=data, timeout=timeout)
        if call.final is not None:
            return call.final.state.value, call.final.reason
        final = await asyncio.wait_for(call.result(), timeout)
        return final.state.value, final.reason


def _journal(cell: SecureCell) -> list[dict]:
    return read_journal(journal_files(cell.name, cell.home))


def test_allowed_robot_commands_the_tracker(secure_cell: SecureCell) -> None:
    state, reason = run(_create(secure_cell, "ROBOT1", secure_cell.transport("ROBOT1"),
                                "Set Base"))
    assert (state, reason) == ("Completed", "")


def test_peer_without_certificate_gets_no_link(secure_cell: SecureCell) -> None:
    before = len(_journal(secure_cell))
    state, reason = run(_create(secure_cell, "ROBOT1", secure_cell.transport(None),
                                "Set Base", timeout=2.0))
    assert state == "Failed" and "TRACKER" in reason
    plain = TransportConfig(listen=(), connect=(secure_cell.endpoint.replace("tls/", "tcp/"),),
                            multicast=False)
    state, reason = run(_create(secure_cell, "ROBOT1", plain, "Set Base", timeout=2.0))
    assert state == "Failed" and "TRACKER" in reason
    assert len(_journal(secure_cell)) == before  # nothing reached the service


def test_certificate_of_another_ca_gets_no_link(secure_cell: SecureCell) -> None:
    before = len(_journal(secure_cell))
    rogue = secure_cell.transport("ROBOT1", secure_cell.rogue)
    state, reason = run(_create(secure_cell, "ROBOT1", rogue, "Set Base", timeout=2.0))
    assert state == "Failed" and "TRACKER" in reason
    assert len(_journal(secure_cell)) == before  # the handshake failed: nothing reached it


def test_valid_certificate_not_allowed_is_refused_and_journaled(
    secure_cell: SecureCell,
) -> None:
    state, reason = run(_create(secure_cell, "ROBOT2", secure_cell.transport("ROBOT2"),
                                "Set Base"))
    assert state == ProcessStates.Failed.value
    assert reason == ("access denied: ROBOT2 may not run Set Base on TRACKER "
                      "(no rule allows it)")
    refused = [p for p in _journal(secure_cell) if p["sender"] == "ROBOT2"]
    assert refused and refused[-1]["state"] == "Failed" and refused[-1]["reason"] == reason


def test_command_not_allowed_is_refused(secure_cell: SecureCell) -> None:
    state, reason = run(_create(secure_cell, "ROBOT1", secure_cell.transport("ROBOT1"),
                                "Continuous Measurement", data=[100]))
    assert state == "Failed" and reason.startswith("access denied: ROBOT1 may not run "
                                                   "Continuous Measurement on TRACKER")


def test_impersonation_is_refused_and_journaled(secure_cell: SecureCell) -> None:
    """ROBOT2's certificate, calling itself ROBOT1 in the Tag."""
    state, reason = run(_create(secure_cell, "ROBOT1", secure_cell.transport("ROBOT2"),
                                "Set Base"))
    assert state == "Failed"
    assert reason == ("access denied: sender ROBOT1 is not authenticated "
                      "(certificate of its session: ROBOT2)")
    assert any(p["reason"] == reason for p in _journal(secure_cell))


def test_only_the_controller_may_wire(secure_cell: SecureCell) -> None:
    async def ask(name: str) -> tuple[bool, str]:
        async with Client(name, cell=secure_cell.name,
                          transport=secure_cell.transport(name)) as client:
            await client.wait_for("TRACKER", 5.0)
            r = await client.ask_subscribe("TRACKER", "NOBODY", subscribe=False, timeout=5.0)
            return r.ok, r.reason

    ok, reason = run(ask("ROBOT1"))
    assert not ok and reason.startswith("access denied: ROBOT1 may not do wiring TRACKER")
    ok, reason = run(ask("CONTROLLER"))  # allowed: the answer is about the partner
    assert not ok and reason == "NOBODY was not a partner of TRACKER"


def test_zenoh_acl_stops_a_forged_presence_and_shutdown(secure_cell: SecureCell) -> None:
    """ROBOT2 (valid certificate) declares a TRACKER token older than the real one and
    publishes a TRACKER Shutdown: Zenoh's ACL drops both, the tracker keeps serving."""
    import zenoh

    from plugcell.framework.keys import KeySpace

    keys = KeySpace(secure_cell.name)
    session = zenoh.open(secure_cell.transport("ROBOT2").zenoh_config())
    try:
        token = session.liveliness().declare_token(keys.live("service", "TRACKER", "0" * 16))
        session.put(keys.shutdown("TRACKER"), b"forged")
        import time

        time.sleep(0.5)  # what would have made the tracker withdraw (younger instance)
        token.undeclare()
    finally:
        session.close()
    assert secure_cell.tracker.popen.poll() is None
    assert not any("withdrawing" in line or "already running" in line
                   for line in secure_cell.tracker.lines)
    state, reason = run(_create(secure_cell, "ROBOT1", secure_cell.transport("ROBOT1"),
                                "Set Base"))
    assert (state, reason) == ("Completed", "")


def test_robot_refuses_an_unauthorised_peer(secure_cell: SecureCell) -> None:
    """The robot service R1 (simulated arm): ROBOT2's certificate may not command it,
    the cell controller may; the refusal is in R1's journal."""

    async def ask(name: str) -> tuple[str, str]:
        async with Client(name, cell=secure_cell.name,
                          transport=secure_cell.transport(name)) as client:
            assert await client.wait_for("R1", 10)
            call = await client.create_process("R1", "ARM_JNTP", timeout=10)
            final = call.final or await asyncio.wait_for(call.result(), 10)
            return final.state.value, final.reason

    state, reason = run(ask("ROBOT2"))
    assert (state, reason) == ("Failed", "access denied: ROBOT2 may not run ARM_JNTP on R1 "
                                         "(no rule allows it)")
    assert any(p["recipient"] == "R1" and p["reason"] == reason for p in _journal(secure_cell))
    assert run(ask("CONTROLLER")) == ("Completed", "")


def test_the_publication_door_is_bound_to_the_certificate(secure_cell: SecureCell) -> None:
    """A certified peer publishing a request under another name's key never reaches
    the tracker (the Zenoh ACL drops it); under its own name it does (and is judged)."""
    from plugcell.framework import codec
    from plugcell.framework.keys import KeySpace
    from plugcell.framework.messages import Command, Process, Tag
    from plugcell.framework.transport import open_session

    keys = KeySpace(secure_cell.name)

    def request(sender: str, identifier: int) -> bytes:
        body = Process(command=Command(name="Set Base"), tag=Tag(sender, "TRACKER"),
                       identifier=identifier)
        return codec.encode(sender, "raw", body)

    def rows() -> list[dict]:
        return [p for p in _journal(secure_cell) if p.get("identifier") in (71, 72)]

    session = open_session(secure_cell.transport("ROBOT2"))
    try:
        time.sleep(1.0)  # the link and the tracker's subscriber are known
        session.put(keys.request("TRACKER", "ROBOT1"), request("ROBOT1", 71),
                    attachment=codec.attach_identifier(71))
        session.put(keys.request("TRACKER", "ROBOT2"), request("ROBOT2", 72),
                    attachment=codec.attach_identifier(72))
        deadline = time.monotonic() + 10
        while not rows() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)
    finally:
        session.close()
    seen = rows()
    assert [p["identifier"] for p in seen] == [72]  # ROBOT1's forged request never arrived
    assert seen[0]["state"] == "Failed" and seen[0]["reason"].startswith("access denied")
