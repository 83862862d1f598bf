"""Fixtures of the metrology-service tests: one tracker and one compute service as real
OS processes per module, a Zenoh session for the simulated world, child processes stopped."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from childproc import CellProcesses
from metrology_testlib import unique_cell

from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.framework.transport import TransportConfig, open_session
from plugcell.sim.world import ReflectorPublisher


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[CellProcesses]:
    """TRACKER (simulated, seed 7) and COMPUTE (data in the module's home) as processes."""
    home = tmp_path_factory.mktemp("home")
    c = CellProcesses(unique_cell(), home)
    try:
        c.serve("tracker", "--param", "seed=7")
        c.serve("compute", "--param", f"data_dir={home / 'compute'}")
        yield c
    finally:
        c.stop()


@pytest.fixture(scope="module")
def world_session() -> Iterator[object]:
    session = open_session(TransportConfig.from_env())
    yield session
    session.close()


@pytest.fixture
def world(world_session: object) -> Iterator[object]:
    """``world(cell, name, kind)`` → a ReflectorPublisher, closed after the test."""
    made: list[ReflectorPublisher] = []

    def publisher(cell: str, name: str, kind: str = "tmac") -> ReflectorPublisher:
        pub = ReflectorPublisher(Bus(world_session, KeySpace(cell)), name, kind)  # type: ignore[arg-type]
        made.append(pub)
        return pub

    yield publisher
    for pub in made:
        pub.close()
