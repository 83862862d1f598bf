"""Fixtures of the fault-injection tests: real service processes in a fresh cell."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "framework"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from faults_testlib import FaultCell
from framework_testlib import unique_cell


@pytest.fixture
def fault_cell(tmp_path: Path) -> Iterator[FaultCell]:
    cell = FaultCell(unique_cell("f"), tmp_path / "home")
    try:
        yield cell
    finally:
        cell.stop()
