"""Fixtures of the framework tests: unique cells, homes, child processes stopped after."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from childproc import Launcher
from framework_testlib import unique_cell


@pytest.fixture
def cell() -> str:
    return unique_cell()


@pytest.fixture
def home(tmp_path: Path) -> Path:
    path = tmp_path / "home"
    path.mkdir()
    return path


@pytest.fixture
def procs(home: Path) -> Iterator[Launcher]:
    """Start child processes (``procs.serve(...)``, ``procs.start(argv)``); all stopped after."""
    launcher = Launcher(home)
    yield launcher
    launcher.stop()
