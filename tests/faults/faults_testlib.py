"""Helpers of the fault-injection tests: a cell of service processes."""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "framework"))

from framework_testlib import Proc, plugcell_argv


@dataclass
class FaultCell:
    """A cell whose services run as OS processes (all stopped after the test)."""

    name: str
    home: Path
    env: dict[str, str]
    procs: list[Proc] = field(default_factory=list)

    def start(self, *args: str) -> Proc:
        proc = Proc(plugcell_argv(*args), self.env)
        self.procs.append(proc)
        return proc

    def serve(self, kind: str, *extra: str) -> Proc:
        proc = self.start("serve", kind, "--cell", self.name, *extra)
        proc.wait_line(lambda line: "serving in cell" in line, 30.0)
        return proc

    def cli(self, *args: str, timeout: float = 30.0) -> Proc:
        """Run a ``plugcell`` command to its end (bounded)."""
        proc = self.start(*args, "--cell", self.name)
        proc.popen.wait(timeout)
        return proc
