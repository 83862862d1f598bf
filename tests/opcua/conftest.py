"""Fixtures of the OPC UA tests: a cell (camera, tracker) as OS processes and its gateway."""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from opcua_testlib import Proc, ensure_node_harness, free_port, plugcell_argv, unique_cell


@dataclass
class UaCell:
    """A cell of services run as processes, and ``plugcell opcua serve`` for it."""

    name: str
    home: Path
    env: dict[str, str]
    procs: list[Proc] = field(default_factory=list)
    url: str = ""

    def start(self, *args: str, env: dict[str, str] | None = None) -> Proc:
        proc = Proc(plugcell_argv(*args), {**self.env, **(env or {})})
        self.procs.append(proc)
        return proc

    def serve(self, kind: str, *extra: str, env: dict[str, str] | None = None) -> Proc:
        proc = self.start("serve", kind, "--cell", self.name, *extra, env=env)
        proc.wait_line(lambda line: "serving in cell" in line, 30.0)
        return proc

    def gateway(self, *extra: str, env: dict[str, str] | None = None) -> tuple[Proc, str]:
        port = free_port()
        proc = self.start("opcua", "serve", "--cell", self.name, "--port", str(port), *extra,
                          env=env)
        line = proc.wait_line(lambda line: "OPC UA gateway" in line, 30.0)
        return proc, line.split(" at ")[1].split()[0]

    def stop(self) -> None:
        for proc in reversed(self.procs):
            proc.stop()


@pytest.fixture(scope="session")
def node_harness() -> None:
    ensure_node_harness()


@pytest.fixture(scope="module")
def ua_cell(tmp_path_factory: pytest.TempPathFactory, node_harness: None) -> Iterator[UaCell]:
    """CAMERA and TRACKER (simulated) and an anonymous gateway, as processes."""
    home = tmp_path_factory.mktemp("home")
    env = {**os.environ, "PLUGCELL_HOME": str(home), "PYTHONUNBUFFERED": "1"}
    cell = UaCell(unique_cell(), home, env)
    try:
        cell.serve("camera", "--param", "time_scale=0.01")
        cell.serve("tracker", "--param", "seed=7")
        _, cell.url = cell.gateway("--allow-anonymous")
        yield cell
    finally:
        cell.stop()
