"""The gateway's reliance on asyncua internals fails loudly and closed (docs/opcua.md,
"Limits"): no start on an asyncua without them, no call sent as the gateway when the
caller's user is unknown and anonymous sessions are off."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

import pytest

from plugcell.devices.opcua.gateway import CellGateway
from plugcell.devices.opcua.sessions import caller_name, capture_session_users
from plugcell.devices.opcua.users import UserBook


async def _nothing(session: int) -> None:
    return None


def test_an_asyncua_without_the_session_internals_stops_the_gateway_at_start():
    stand_in = SimpleNamespace(iserver=SimpleNamespace())  # no create_session
    with pytest.raises(RuntimeError, match=r"asyncua .* changed the internals the gateway "
                       r"relies on to know who calls"):
        capture_session_users(stand_in, _nothing)  # type: ignore[arg-type]


def test_a_call_of_an_unknown_user_is_refused_when_anonymous_is_off():
    async def caller_of(gateway: CellGateway) -> object:
        return await gateway.calls.caller()

    assert caller_name() is None  # outside any session's call
    closed = CellGateway(cell="sessions-test", users=UserBook({}), allow_anonymous=False)
    with pytest.raises(ValueError, match="the OPC UA user of this call is unknown"):
        asyncio.run(caller_of(closed))
    open_ = CellGateway(cell="sessions-test", users=None, allow_anonymous=True)
    assert asyncio.run(caller_of(open_)) is open_.watcher  # anonymous: as the gateway
