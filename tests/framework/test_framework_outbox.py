"""The outbox on its own (framework/outbox.py), with its four seams replaced by recorders:
the journal commit comes before anything is sent; acknowledgements of queries are
replies, the others ride with their sender's updates; a Running update superseded in
the same flush is not sent."""

from __future__ import annotations

import asyncio

from plugcell.framework.messages import (
    Acknowledgement,
    Command,
    Process,
    ProcessStates,
    ProcessUpdateBatch,
    ProcessUpdateNotification,
    Tag,
)
from plugcell.framework.outbox import Outbox
from plugcell.framework.processqueue import Entry

R, C, Q = ProcessStates.Running, ProcessStates.Completed, ProcessStates.Queued


def _entry(sender: str, identifier: int) -> Entry:
    cmd = Command(name="Work")
    return Entry(process=Process(command=cmd, tag=Tag(sender, "DEV"), identifier=identifier),
                 command=cmd)


def _update(e: Entry, state: ProcessStates) -> ProcessUpdateNotification:
    e.seq += 1
    return ProcessUpdateNotification(tag=e.process.tag, identifier=e.identifier, state=state,
                                     seq=e.seq)


def _outbox(events: list):
    return Outbox("DEV", commit=lambda: events.append(("commit",)),
                  reply=lambda q, body: events.append(("reply", q, body)),
                  publish=lambda sender, body: events.append(("publish", sender, body)),
                  is_open=lambda: True)


def test_commit_first_replies_for_queries_and_one_sample_per_sender():
    events: list = []
    box = _outbox(events)
    a, b = _entry("A", 1), _entry("B", 2)
    box.acknowledge("A", Acknowledgement(identifier=1, state=Q))
    query = object()  # a Zenoh query (anything but a sender's name)
    box.acknowledge(query, Acknowledgement(identifier=2, state=Q))
    box._updates += [(a, _update(a, R)), (b, _update(b, R))]
    assert box
    box.flush()
    assert events[0] == ("commit",)
    assert events[1][0] == "reply" and events[1][1] is query
    published = {e[1]: e[2] for e in events if e[0] == "publish"}
    assert isinstance(published["A"], ProcessUpdateBatch)  # its ack and its update
    assert published["A"].acks[0].identifier == 1 and published["A"].updates[0].state is R
    assert isinstance(published["B"], ProcessUpdateNotification)
    assert not box


def test_a_final_update_flushes_at_once_and_supersedes_a_bare_running():
    events: list = []
    box = _outbox(events)
    e = _entry("A", 7)
    box._updates.append((e, _update(e, R)))  # journaled, not yet sent
    box.update(e, _update(e, C))  # final: flushed now
    sent = [ev[2] for ev in events if ev[0] == "publish"]
    assert len(sent) == 1 and isinstance(sent[0], ProcessUpdateNotification)
    assert (sent[0].state, sent[0].seq) == (C, 2)


def test_flush_soon_runs_once_per_turn():
    events: list = []
    box = _outbox(events)

    async def body() -> None:
        box.loop = asyncio.get_running_loop()
        e = _entry("A", 1)
        for _ in range(3):
            box.update(e, _update(e, R))
        assert events == []
        await asyncio.sleep(0)
        assert [ev[0] for ev in events] == ["commit", "publish"]

    asyncio.run(body())
