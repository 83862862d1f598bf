"""A small version of ``benchmarks/load.py``: 3 robots × 50 processes against one
tracker process — no process lost, per-sender order kept, no deadlock (bounded)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from load import print_report, run_load

pytestmark = [pytest.mark.slow, pytest.mark.timeout(90)]


def test_three_robots_fifty_processes_each(tmp_path: Path) -> None:
    rep = run_load(robots=3, per_robot=50, window=4, timeout=60.0, home=str(tmp_path))
    print_report(rep)
    assert rep["ok"], rep["problems"]
    assert rep["processes"] == 150
    assert [r["completed"] for r in rep["robots"]] == [50, 50, 50]
    assert 0.0 < rep["tracker_utilisation"] <= 1.0
