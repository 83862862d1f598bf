"""Fixtures of the web UI tests: a cell with real services, the controller app, a browser."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "cell"))

from cell_testlib import Proc, plugcell_argv, unique_cell


@pytest.fixture(scope="module")
def ui_home(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    path = tmp_path_factory.mktemp("home")
    old = os.environ.get("PLUGCELL_HOME")
    os.environ["PLUGCELL_HOME"] = str(path)
    yield path
    if old is None:
        os.environ.pop("PLUGCELL_HOME", None)
    else:
        os.environ["PLUGCELL_HOME"] = old


class Launcher:
    """Child processes of a test module, all stopped at its end."""

    def __init__(self, home: Path) -> None:
        self.env = {**os.environ, "PLUGCELL_HOME": str(home), "PYTHONUNBUFFERED": "1"}
        self.started: list[Proc] = []

    def start(self, argv: list[str]) -> Proc:
        proc = Proc(argv, self.env)
        self.started.append(proc)
        return proc

    def serve(self, kind: str, cell: str, *extra: str, name: str | None = None) -> Proc:
        argv = plugcell_argv("serve", kind, "--cell", cell, *extra)
        if name:
            argv += ["--name", name]
        proc = self.start(argv)
        proc.wait_line(lambda line: "serving in cell" in line, 30.0)
        return proc

    def stop(self) -> None:
        for proc in self.started:
            proc.stop()


@pytest.fixture(scope="module")
def module_cell() -> str:
    return unique_cell("u")


@pytest.fixture(scope="module")
def launcher(ui_home: Path) -> Iterator[Any]:
    launch = Launcher(ui_home)
    yield launch
    launch.stop()
