"""Serving the controller UI with uvicorn until SIGINT/SIGTERM (``plugcell controller``).

The cell controller service and the web server share one event loop; the first
stdout line says where the page is (``plugcell: controller UI on http://…/``),
with the real port when ``--port 0`` let the OS choose one.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
import socket

import uvicorn

from plugcell.apps.ui.app import create_app
from plugcell.apps.ui.reports import ReportFiles
from plugcell.devices.cell.service import CellController

__all__ = ["serve"]


async def serve(
    controller: CellController,
    *,
    host: str = "127.0.0.1",
    port: int = 8765,
    reports: ReportFiles | None = None,
    log_level: str = "warning",
) -> None:
    """Start the controller, serve the UI, stop both cleanly on a signal.

    The port is bound first (OSError if it is taken), before the controller joins the cell.
    """
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
    except OSError:
        sock.close()
        raise
    await controller.host.start()
    app = create_app(controller, reports=reports, manage=False,
                     allowed_hosts={host} if host not in ("0.0.0.0", "::") else None)
    config = uvicorn.Config(app, host=host, port=port, log_level=log_level, lifespan="off",
                            ws="auto", ws_ping_interval=None)
    server = uvicorn.Server(config)
    server.install_signal_handlers = lambda: None  # type: ignore[method-assign]
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, lambda: setattr(server, "should_exit", True))
    task = asyncio.create_task(server.serve(sockets=[sock]))
    try:
        while not server.started:
            if task.done():
                task.result()  # the port was taken …: raise its error
                raise OSError(f"cannot serve on {host}:{port}")
            await asyncio.sleep(0.02)
        bound = int(sock.getsockname()[1])
        shown = "127.0.0.1" if host in ("0.0.0.0", "::") else host
        print(f"plugcell: controller UI on http://{shown}:{bound}/ "
              f"(service {controller.host.name} in cell {controller.host.cell!r})", flush=True)
        await task
    finally:
        server.should_exit = True
        with contextlib.suppress(BaseException):
            await asyncio.wait_for(task, 10.0)
        await controller.host.close()
