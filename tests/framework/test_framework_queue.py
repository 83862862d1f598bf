"""The process queue alone: FIFO and the re-scheduling of 5.2.3.5 (Figure 5-13)."""

from __future__ import annotations

import asyncio

import pytest

from plugcell.framework.messages import Command, CommandTypes, Process, Tag
from plugcell.framework.processqueue import Entry, ProcessQueue

pytestmark = pytest.mark.timeout(30)
_ids = iter(range(1, 10**6))


def entry(sender: str, kind: CommandTypes, name: str = "") -> Entry:
    command = Command(name=name or kind.value, type=kind)
    return Entry(
        Process(command=command, tag=Tag(sender, "CAMERA"), identifier=next(_ids)), command
    )


def test_fifo_when_free():
    q = ProcessQueue()
    entries = [entry(s, CommandTypes.NoData) for s in "ABCAB"]
    for e in entries:
        q.post(e)
    assert [q.take_next() for _ in entries] == entries
    assert q.take_next() is None


def test_stop_of_the_same_sender_overtakes_and_the_rest_keeps_order():
    """robotA's MovieShot runs; robotB/robotC requests wait; robotA's StopMovie goes first."""
    q = ProcessQueue()
    b1 = entry("robotB", CommandTypes.SingleData, "SnapShot")
    c_stop = entry("robotC", CommandTypes.StopData, "StopMovie")
    b2 = entry("robotB", CommandTypes.NoData, "Connect")
    a_stop = entry("robotA", CommandTypes.StopData, "StopMovie")
    a_next = entry("robotA", CommandTypes.SingleData, "SnapShot")
    for e in (b1, c_stop, b2, a_stop, a_next):
        q.post(e)
    assert q.take_stop_for("robotA") is a_stop
    assert q.take_stop_for("robotA") is None
    assert list(q) == [b1, c_stop, b2, a_next]  # re-queued, never dropped, same order


def test_remove_if_keeps_the_others_in_order():
    q = ProcessQueue()
    es = [entry(s, CommandTypes.NoData) for s in "ABAB"]
    for e in es:
        q.post(e)
    gone = q.remove_if(lambda e: e.sender == "A")
    assert gone == [es[0], es[2]] and list(q) == [es[1], es[3]]


def test_wait_returns_on_post_and_on_timeout():
    async def body():
        q = ProcessQueue()
        await q.wait(0.01)  # times out quietly
        waiter = asyncio.create_task(q.wait(30))
        await asyncio.sleep(0)
        q.post(entry("A", CommandTypes.NoData))
        await asyncio.wait_for(waiter, 5)

    asyncio.run(body())
