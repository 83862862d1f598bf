"""Fixtures of the security tests: a cell CA, certificates, a TLS tracker process."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "framework"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from framework_testlib import Proc, plugcell_argv, unique_cell
from sec_testlib import NAMES, POLICY, SecureCell, issue_cell_certificates

from plugcell.sim.ports import free_port


@pytest.fixture(scope="module")
def secure_cell(tmp_path_factory: pytest.TempPathFactory) -> Iterator[SecureCell]:
    base = tmp_path_factory.mktemp("secure")
    certs, rogue, home = issue_cell_certificates(base, "secure")
    (base / "policy.toml").write_text(POLICY)
    endpoint = f"tls/127.0.0.1:{free_port()}"
    env = {
        **os.environ,
        "PLUGCELL_HOME": str(home),
        "PYTHONUNBUFFERED": "1",
        "PLUGCELL_TLS_DIR": str(certs),
        "PLUGCELL_ACL": str(base / "policy.toml"),
        "PLUGCELL_MULTICAST": "0",
        "PLUGCELL_LISTEN": endpoint,
        "PLUGCELL_CELL_NAMES": ",".join(NAMES),
    }
    cell = unique_cell("sec")
    tracker = Proc(plugcell_argv("serve", "tracker", "--cell", cell, "--param", "seed=7"), env)
    robot: Proc | None = None
    try:
        tracker.wait_line(lambda line: "serving in cell" in line, 30.0)
        robot_env = {**env, "PLUGCELL_LISTEN": "tls/127.0.0.1:0",
                     "PLUGCELL_CONNECT": endpoint,
                     # the robot's simulated controller (a child process) opens its own
                     # session: it uses the robot's certificate
                     "PLUGCELL_TLS_CERT": str(certs / "R1.pem"),
                     "PLUGCELL_TLS_KEY": str(certs / "R1.key")}
        robot = Proc(plugcell_argv("serve", "robot", "--cell", cell, "--name", "R1",
                                   "--param", "sim=true"), robot_env)
        robot.wait_line(lambda line: "serving in cell" in line, 30.0)
        yield SecureCell(cell, certs, rogue, home, endpoint, tracker, robot)
    finally:
        for proc in (robot, tracker):
            if proc is not None:
                proc.stop()
