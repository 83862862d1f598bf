"""Fixtures of the metrology-service tests: one tracker and one compute service as real
OS processes per module, a Zenoh session for the simulated world, child processes stopped."""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from metrology_testlib import Proc, plugcell_argv, unique_cell

from plugcell.framework.bus import Bus
from plugcell.framework.keys import KeySpace
from plugcell.framework.transport import TransportConfig, open_session
from plugcell.sim.world import ReflectorPublisher


@dataclass
class Cell:
    """A cell with its tracker and compute services running as OS processes."""

    name: str
    home: Path
    env: dict[str, str]
    procs: list[Proc]

    def start(self, *args: str) -> Proc:
        proc = Proc(plugcell_argv(*args), self.env)
        self.procs.append(proc)
        return proc

    def serve(self, kind: str, *extra: str) -> Proc:
        proc = self.start("serve", kind, "--cell", self.name, *extra)
        proc.wait_line(lambda line: "serving in cell" in line, 30.0)
        return proc


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Cell]:
    """TRACKER (simulated, seed 7) and COMPUTE (data in the module's home) as processes."""
    home = tmp_path_factory.mktemp("home")
    env = {**os.environ, "PLUGCELL_HOME": str(home), "PYTHONUNBUFFERED": "1"}
    c = Cell(unique_cell(), home, env, [])
    try:
        c.serve("tracker", "--param", "seed=7")
        c.serve("compute", "--param", f"data_dir={home / 'compute'}")
        yield c
    finally:
        for proc in c.procs:
            proc.stop()


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
