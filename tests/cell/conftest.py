"""Fixtures of the cell controller tests: unique cells and homes, child processes stopped after."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from cell_testlib import unique_cell
from childproc import Launcher


@pytest.fixture
def cell() -> str:
    return unique_cell("c")


@pytest.fixture
def home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    path = tmp_path / "home"
    path.mkdir()
    monkeypatch.setenv("PLUGCELL_HOME", str(path))
    return path


@pytest.fixture
def procs(home: Path) -> Iterator[Launcher]:
    """Start child processes (``procs.serve(...)``, ``procs.start(argv)``); all stopped after."""
    launcher = Launcher(home)
    yield launcher
    launcher.stop()
