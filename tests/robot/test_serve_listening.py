"""``plugcell serve robot --rsi/--egm`` says when its link listens: the moment to start
the controller's program, whose own timeout (EGM's ``\\CommTimeout``, RSI's ``Timeout``)
runs from its first packet — before that line the service is still joining its cell."""

from __future__ import annotations

import asyncio
import contextlib

import pytest
from robot_testlib import unique_cell

from plugcell.apps.commands.serve import _say_when_listening
from plugcell.apps.kinds import build
from plugcell.sim.ports import free_port

pytestmark = pytest.mark.timeout(60)


@pytest.mark.parametrize("vendor", ["rsi", "egm"])
def test_the_line_comes_once_the_link_listens_before_any_stream(vendor, capsys) -> None:
    port = free_port("udp")

    async def body() -> None:
        service = build("robot", None, {vendor: f"127.0.0.1:{port}", "stream_process": False},
                        cell=unique_cell(), journal=False)
        starting = asyncio.ensure_future(service.start())  # waits for a stream: none comes
        try:
            await asyncio.wait_for(_say_when_listening(service), 30)
            assert not starting.done()
        finally:
            starting.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await starting

    asyncio.run(body())
    assert capsys.readouterr().out == (
        f"plugcell: ROBOT (robot) listening on 127.0.0.1:{port} for the {vendor.upper()} "
        "stream of the controller at 127.0.0.1\n")


def test_a_service_without_a_stream_says_nothing(capsys) -> None:
    tracker = build("tracker", None, {}, cell=unique_cell(), journal=False)
    asyncio.run(asyncio.wait_for(_say_when_listening(tracker), 5))
    assert capsys.readouterr().out == ""
