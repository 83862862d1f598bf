"""SIGTERM ends the OPC UA processes promptly (issue 39 §5): a device service still
connecting to a server that never answers, and the gateway's server without waiting out
asyncua's status clock.  How long they take is measured by benchmarks/stop_latency.py."""

from __future__ import annotations

import asyncio
import os
import signal
import socket
import subprocess
import threading
from pathlib import Path

import pytest
from opcua_testlib import plugcell_argv, unique_cell

from plugcell.devices.opcua.gateway import CellGateway
from plugcell.framework import eventloop
from plugcell.sim.ports import free_port

pytestmark = pytest.mark.slow

MAP = Path(__file__).resolve().parent / "gripper.toml"


def test_sigterm_while_connecting_to_a_silent_server_ends_the_device_service(tmp_path):
    """Before: the signal was only heeded once started, i.e. after the connection's
    timeout (200 s here, with watch_s=100)."""
    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen()
        held: list[socket.socket] = []
        accepting = threading.Thread(target=lambda: held.append(silent.accept()[0]),
                                     daemon=True)
        accepting.start()
        endpoint = f"opc.tcp://127.0.0.1:{silent.getsockname()[1]}/silent"
        proc = subprocess.Popen(
            plugcell_argv("serve", "opcua-device", "--cell", unique_cell("stop"), "--endpoint",
                          endpoint, "--map", str(MAP), "--param", "watch_s=100",
                          "--insecure-accept-any", "--log-level", "INFO"),
            env={**os.environ, "PLUGCELL_HOME": str(tmp_path), "PYTHONUNBUFFERED": "1"},
            stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
            start_new_session=True)
        try:
            assert proc.stderr is not None
            for line in proc.stderr:  # its log: it is connecting now
                if f"connecting to {endpoint}" in line:
                    break
            else:
                pytest.fail(f"no 'connecting to' line; exit code {proc.wait()}")
            accepting.join(30)
            assert held, "the service never opened its connection"
            proc.send_signal(signal.SIGTERM)
            try:
                code = proc.wait(60)  # a third of the connection's timeout
            except subprocess.TimeoutExpired:
                pytest.fail("SIGTERM ignored while the service was connecting")
            assert code == 0
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
            for conn in held:
                conn.close()


def test_closing_the_gateway_does_not_wait_out_the_status_clock():
    """asyncua's Server.stop awaits its 1 s ServerStatus clock loop; the gateway cancels
    it first (before: the loop ran on until its next wake-up and ended by itself)."""
    async def body() -> None:
        gateway = CellGateway(cell=unique_cell("clock"), port=free_port(), allow_anonymous=True,
                              robot_poll=0)
        await gateway.start()
        clock = gateway.server.iserver.time_task
        assert clock is not None and not clock.done()
        await asyncio.sleep(0.1)
        await gateway.close()
        assert clock.cancelled()

    eventloop.run(body())
