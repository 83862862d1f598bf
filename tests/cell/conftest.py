"""Fixtures of the cell controller tests: unique cells and homes, child processes stopped after."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from cell_testlib import Proc, plugcell_argv, unique_cell


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
def procs(home: Path) -> Iterator[Any]:
    """Start child processes (``procs.serve(...)``, ``procs.start(argv)``); all stopped after."""
    started: list[Proc] = []

    class Launcher:
        def __init__(self) -> None:
            self.env = {**os.environ, "PLUGCELL_HOME": str(home), "PYTHONUNBUFFERED": "1"}

        def start(self, argv: list[str]) -> Proc:
            proc = Proc(argv, self.env)
            started.append(proc)
            return proc

        def serve(self, kind: str, cell: str, *extra: str, name: str | None = None) -> Proc:
            argv = plugcell_argv("serve", kind, "--cell", cell, *extra)
            if name:
                argv += ["--name", name]
            proc = self.start(argv)
            proc.wait_line(lambda line: "serving in cell" in line, 30.0)
            return proc

    yield Launcher()
    for proc in started:
        proc.stop()
