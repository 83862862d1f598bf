"""Fixtures of the OPC UA tests: a cell (camera, tracker) as OS processes and its gateway."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest
from opcua_testlib import UaCell, ensure_node_harness, unique_cell


@pytest.fixture(scope="session")
def node_harness() -> None:
    ensure_node_harness()


@pytest.fixture(scope="session")
def cell_certs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The cell's OPC UA authority and certificates (OPCUA, HMI, SECURE_GRIPPER), and a
    rogue authority's HMI certificate (the same name, another CA) — made once (RSA)."""
    from plugcell.devices.opcua.certificates import issue_application_certificate

    root = tmp_path_factory.mktemp("opcua-certs")
    certs, rogue = root / "certs", root / "rogue"
    for name in ("OPCUA", "HMI", "SECURE_GRIPPER"):
        issue_application_certificate(certs, name)
    issue_application_certificate(rogue, "HMI")
    return certs, rogue


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
