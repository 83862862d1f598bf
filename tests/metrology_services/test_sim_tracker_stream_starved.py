"""The simulated tracker's stream when its process was starved of CPU (a loaded machine):
it catches up on the samples the instrument took meanwhile — all of them, in order — a
few at a time between turns of the event loop, so the service it runs in (its Stop
Measurement, the other requests, the requester in the same process) is never blocked
while it does.  Before, the whole backlog was computed in one go: on a machine too slow
to make one sample per millisecond each catch-up took longer than the last, and the
stream never let the loop run again (tests/metrology_services/test_tracked_move_feed.py
timed out at load 20)."""

from __future__ import annotations

import asyncio
import itertools
import time

import numpy as np
import pytest
from metrology_testlib import run, unique_cell

from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.sim.drivers import tracker as sim_tracker
from plugcell.sim.world import ReflectorPublisher

pytestmark = pytest.mark.timeout(60)

TMAC = np.eye(4)
TMAC[:3, 3] = [2.0, 0.5, 0.3]  # the reflector in the tracker's frame (m)


class _StarvedClock:
    """The driver's ``time``: the real clocks plus a jump (``starve``): as if the
    process had been given no CPU for that long."""

    def __init__(self) -> None:
        self.lost = 0.0

    def starve(self, seconds: float) -> None:
        self.lost += seconds

    def monotonic(self) -> float:
        return time.monotonic() + self.lost

    def time(self) -> float:
        return time.time() + self.lost


def test_a_starved_stream_catches_up_between_turns_of_the_event_loop(world_session,
                                                                     monkeypatch):
    clock = _StarvedClock()
    monkeypatch.setattr(sim_tracker, "time", clock)
    cell = unique_cell()

    async def body():
        bus = Bus(world_session, KeySpace(cell))
        tmac = ReflectorPublisher(bus, "TMAC", "tmac")
        tmac.publish(TMAC)
        turns = 0

        async def count_turns():
            nonlocal turns
            while True:
                turns += 1
                await asyncio.sleep(0)

        counter = asyncio.create_task(count_turns())
        try:
            driver = sim_tracker.SimulatedTrackerDriver(bus, seed=3)
            await driver.connect()
            await driver.point(TMAC[:3, 3])
            samples = driver.stream(1000)
            seen, seqs = [], []
            async for sample in samples:
                seen.append(turns)
                seqs.append(sample.seq)
                if len(seen) == 1:
                    clock.starve(2.0)  # 2000 samples taken while the process waited
                if len(seen) == 1500:
                    break
            await samples.aclose()
        finally:
            counter.cancel()
            tmac.close()
        assert seqs == list(range(1500))  # every sample, in order: none lost
        longest = max(len(list(run)) for _, run in itertools.groupby(seen))
        assert longest <= sim_tracker.STREAM_SAMPLES_PER_TURN, longest

    run(body())
