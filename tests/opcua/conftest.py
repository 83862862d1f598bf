"""Fixtures of the OPC UA tests: a cell (camera, tracker) as OS processes and its gateway."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest
from opcua_testlib import UaCell, ensure_node_harness, unique_cell


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
