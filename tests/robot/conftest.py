"""Fixtures of the robot tests: a cell of real service processes, stopped after."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from metrology_cell import MetrologyCell
from robot_cell import HERE, Launcher, RobotCell
from robot_testlib import unique_cell

from plugcell.framework import BlockingClient


@pytest.fixture(scope="module")
def launcher(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Launcher]:
    home = tmp_path_factory.mktemp("home")
    started = Launcher(home, unique_cell())
    try:
        yield started
    finally:
        started.stop_all()


@pytest.fixture(scope="module")
def robot_cell(launcher: Launcher) -> Iterator[RobotCell]:
    procs = [
        launcher.serve("camera", "--param", "time_scale=0.001"),
        launcher.serve("drill", "--param", "time_scale=0.001"),
        launcher.serve("robot_devices:ProbeService"),
        launcher.serve("robot", "--param", "sim=true", "--param", "speed=1000",
                       "--param", "seed=3", "--param", f"library={HERE / 'programs'}"),
    ]
    launcher.ready(*procs)
    with BlockingClient("tester", cell=launcher.cell) as client:
        for name in ("ROBOT", "CAMERA", "TOOL", "PROBE"):
            assert client.wait_for(name, 10.0), f"{name} not seen"
        for partner in ("CAMERA", "TOOL", "PROBE"):
            response = client.ask_subscribe("ROBOT", partner)
            assert response.ok, response.reason
        yield RobotCell(launcher, client)


@pytest.fixture(scope="module")
def metrology_cell(launcher: Launcher) -> Iterator[MetrologyCell]:
    launcher.ready(*MetrologyCell.start(launcher), timeout=60.0)
    with BlockingClient("tester", cell=launcher.cell) as client:
        cell = MetrologyCell(launcher, client)
        cell.wire()
        yield cell
