"""Fixtures of the web UI tests: a cell with real services, the controller app, a browser."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "cell"))

from cell_testlib import unique_cell
from childproc import Launcher


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


@pytest.fixture(scope="module")
def module_cell() -> str:
    return unique_cell("u")


@pytest.fixture(scope="module")
def launcher(ui_home: Path) -> Iterator[Any]:
    launch = Launcher(ui_home)
    yield launch
    launch.stop()
