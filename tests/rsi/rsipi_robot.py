"""rsipi's simulated KUKA controller (``RSIPI.rsi_echo_server.EchoServer``, PyPI ``rsipi``
0.3.0, Apache-2.0) as a robot in a process of its own, for test_rsi_rsipi.py.

    python rsipi_robot.py CONFIG.xml MODE TIMEOUT WORKDIR

The EchoServer reads the ethernet configuration plugcell writes for the controller
(``plugcell_rsi_ethernet.xml``), sends ``<Rob>`` to its IP_NUMBER:PORT every cycle,
owns the IPOC clock, rejects late or wrong answers (counted in ``<Delay>``), breaks off
past ``Timeout`` and applies AKorr/RKorr relative or absolute.  Two things are changed,
both outside its protocol: it binds ("0.0.0.0", 50000) hard-coded, which would collide
between parallel tests, so its socket binds an ephemeral loopback port instead; and it
runs in WORKDIR, where it writes ``logs/echo_server.log`` at import.

Stdout: rsipi's own prints, then, after a line on stdin (or its end), one line
``RESULT {json}`` with its faulty-packet count, whether it still runs, and its state.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import types


class _LoopbackSocket(socket.socket):
    """A UDP socket whose bind goes to an ephemeral loopback port."""

    def bind(self, address) -> None:  # the address asked for is replaced
        super().bind(("127.0.0.1", 0))


def main(argv: list[str]) -> int:
    config, mode, timeout, workdir = argv
    os.chdir(workdir)
    from RSIPI import rsi_echo_server

    rsi_echo_server.socket = types.SimpleNamespace(
        socket=_LoopbackSocket, AF_INET=socket.AF_INET, SOCK_DGRAM=socket.SOCK_DGRAM,
        timeout=socket.timeout)
    server = rsi_echo_server.EchoServer(config_file=config, delay_ms=4, mode=mode,
                                        timeout_packets=int(timeout))
    server.start()
    print("READY", flush=True)
    sys.stdin.readline()
    running = server.running
    server.stop()
    state = {k: v for k, v in server.state.items() if isinstance(v, (dict, int, float, str))}
    print("RESULT " + json.dumps({"faulty_packets": server.faulty_packets,
                                  "running": running, "state": state}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
