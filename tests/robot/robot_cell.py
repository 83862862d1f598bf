"""The robot tests' cell of real service processes: launcher and client façade."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from childproc import Launcher as ChildLauncher
from robot_testlib import Proc, group_alive, until

from plugcell.framework import BlockingClient, ProcessStates, from_data

HERE = Path(__file__).resolve().parent
#: The twin's taught points of the EXAMPLE (thesis 4.1.3.2): in the working volume.
PNT0001 = "1500,0,1300,0,90,0"
PNT0002 = "1500,200,1000,0,90,0"


class Launcher(ChildLauncher):
    """Starts child processes in one cell and home (this folder importable in them); all
    stopped (and checked gone) after."""

    def __init__(self, home: Path, cell: str) -> None:
        super().__init__(home, {"PYTHONPATH": os.pathsep.join(
            [str(HERE), *filter(None, [os.environ.get("PYTHONPATH")])])})
        self.home = home
        self.cell = cell

    def serve(self, kind: str, *extra: str, name: str | None = None) -> Proc:  # type: ignore[override]
        """``plugcell serve KIND`` in this cell (not waited for: see :meth:`ready`)."""
        return super().serve(kind, self.cell, *extra, name=name, wait=False)

    @staticmethod
    def ready(*procs: Proc, timeout: float = 30.0) -> None:
        for proc in procs:
            proc.wait_line(lambda line: "serving in cell" in line, timeout)

    def stop_all(self) -> None:
        self.stop()
        for proc in self.started:  # the simulated controllers went with their services
            until(lambda p=proc: not group_alive(p.pid), 10.0, f"end of {proc.argv[3:5]}")


class RobotCell:
    """CAMERA, TOOL, PROBE and a simulated ROBOT wired to them, and a client."""

    def __init__(self, launcher: Launcher, client: BlockingClient) -> None:
        self.launcher = launcher
        self.client = client
        self.cell = launcher.cell
        self.home = launcher.home

    def activate(self, program: str | Path, *values: str, wait: bool = True,
                 robot: str = "ROBOT", timeout: float = 60.0) -> Any:
        """ACTIVATE a program (option Wait: until it ends); the final update."""
        call = self.client.create_process(robot, "ACTIVATE", "Wait" if wait else "",
                                          [str(program), *values], timeout=timeout)
        return call.result()

    def status(self, robot: str = "ROBOT") -> list[str]:
        """PROGRAM_STATUS: [program, state, simulated s, message, console lines…]."""
        final = self.client.create_process(robot, "PROGRAM_STATUS").result()
        assert final.state is ProcessStates.Completed, final.reason
        return [str(s) for s in from_data(final.data).reshape(-1)]

    def console(self, robot: str = "ROBOT") -> list[str]:
        return self.status(robot)[4:]
