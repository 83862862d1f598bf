"""The web UI of the cell controller: one FastAPI app, one page, one websocket (thesis 7.6).

:func:`create_app` serves

* ``/`` — the page (``static/index.html``; CSS and JavaScript written for it,
  served from ``/static``; nothing from the Internet);
* ``/api/…`` — the actions (:mod:`plugcell.apps.ui.api`);
* ``/ws`` — live events: a snapshot, then ``cell``, ``processes``, ``run``,
  ``task`` and ``log`` events as they happen, each robot's joint state (``robot``) and
  tracked move as it goes (``tracking``) (:meth:`CellController.listen`);
* ``/reports/…`` — the calibration report and the reproduced thesis figures.

The controller service runs in the app's event loop: started by the app's
lifespan unless it is already running.  Only local use is accepted (``guard.py``).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request, WebSocket, WebSocketDisconnect
from fastapi.responses import FileResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.middleware.base import BaseHTTPMiddleware, RequestResponseEndpoint

from plugcell.apps.ui.api import make_router
from plugcell.apps.ui.guard import BadRequestError, check_connection, error_response
from plugcell.apps.ui.metrology import FitInputError
from plugcell.apps.ui.reports import SUFFIXES, ReportFiles
from plugcell.devices.cell.service import CellController

STATIC = Path(__file__).resolve().parent / "static"
#: Seconds between keep-alive pings on an idle websocket.
PING_PERIOD = 15.0

__all__ = ["STATIC", "create_app"]


def create_app(
    controller: CellController,
    *,
    reports: ReportFiles | None = None,
    manage: bool = True,
    allowed_hosts: set[str] | None = None,
) -> FastAPI:
    """The UI app for ``controller`` (started and closed by the app if ``manage``)."""
    files = reports or ReportFiles()
    hosts = frozenset(allowed_hosts or ())

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        if manage:
            await controller.host.start()
        try:
            yield
        finally:
            if manage:
                await controller.host.close()

    app = FastAPI(title="plugcell cell controller", lifespan=lifespan, docs_url=None,
                  redoc_url=None, openapi_url=None)

    app.add_middleware(_Guard, hosts=hosts)

    @app.exception_handler(BadRequestError)
    async def bad_request(request: Request, exc: BadRequestError) -> JSONResponse:
        return error_response(exc.errors, exc.status)

    @app.exception_handler(FitInputError)
    async def refused_input(request: Request, exc: FitInputError) -> JSONResponse:
        """Points, poses or matrices the metrology endpoints cannot use: field errors
        (200, ``ok: false``, as :class:`RefusedError`)."""
        return error_response(exc.errors, 200)

    app.include_router(make_router(controller))
    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/")
    async def index() -> FileResponse:
        return FileResponse(STATIC / "index.html", media_type="text/html")

    @app.get("/favicon.ico")
    async def favicon() -> FileResponse:
        return FileResponse(STATIC / "favicon.svg", media_type="image/svg+xml")

    _add_report_routes(app, files)

    @app.websocket("/ws")
    async def events(ws: WebSocket) -> None:
        if check_connection(ws, hosts):
            await ws.close(code=1008)
            return
        await ws.accept()
        queue = controller.listen()
        try:
            await ws.send_json(controller.snapshot())
            await _pump(ws, queue, controller)
        except (WebSocketDisconnect, RuntimeError):
            pass
        finally:
            controller.unlisten(queue)

    return app


class _Guard(BaseHTTPMiddleware):
    """Every request: refused (403) unless its host and origin are this UI's
    (:func:`check_connection`); every answer: not cached, not sniffed, and allowed to load
    only this server's own scripts, styles and images (Content-Security-Policy)."""

    def __init__(self, app: Any, hosts: frozenset[str]) -> None:
        super().__init__(app)
        self.hosts = hosts

    async def dispatch(self, request: Request, call_next: RequestResponseEndpoint
                       ) -> Response:
        reason = check_connection(request, self.hosts)
        if reason:
            return error_response({"_": reason}, 403)
        response = await call_next(request)
        response.headers.setdefault("Cache-Control", "no-store")
        response.headers["X-Content-Type-Options"] = "nosniff"
        response.headers.setdefault("Content-Security-Policy", (
            "default-src 'self'; img-src 'self' data:; style-src 'self'; "
            "script-src 'self'; connect-src 'self'; frame-ancestors 'self'"
        ))
        return response


def _add_report_routes(app: FastAPI, files: ReportFiles) -> None:
    """The reports' list and files: the results pages of docs/results and the
    calibration reports given (``--report``)."""

    @app.get("/api/reports")
    async def report_list() -> JSONResponse:
        return JSONResponse({"reports": files.listing()})

    @app.get("/reports/results/{name}")
    async def result_file(name: str) -> Response:
        path = files.result(name)
        if path is None:
            return error_response({"name": f"no result {name!r}"}, 404)
        return _file(path)

    @app.get("/reports/calibration/{index}")
    async def calibration_file(index: int) -> Response:
        path = files.calibration(index)
        if path is None:
            return error_response({"index": "no such calibration report"}, 404)
        return _file(path)


async def _pump(ws: WebSocket, queue: asyncio.Queue[dict[str, Any]],
                controller: CellController) -> None:
    """Events to the websocket until it closes; a listener that fell behind is re-synced."""
    receiver = asyncio.ensure_future(ws.receive_text())
    try:
        while True:
            getter = asyncio.ensure_future(queue.get())
            done, _ = await asyncio.wait({getter, receiver}, timeout=PING_PERIOD,
                                         return_when=asyncio.FIRST_COMPLETED)
            if receiver in done:
                getter.cancel()
                receiver.result()  # raises WebSocketDisconnect when the page went away
                receiver = asyncio.ensure_future(ws.receive_text())
                continue
            if getter not in done:
                getter.cancel()
                await ws.send_json({"type": "ping"})
                continue
            event = getter.result()
            if event.get("type") == "resync":
                event = controller.snapshot()
            await ws.send_json(event)
    finally:
        receiver.cancel()


def _file(path: Path) -> Response:
    media = SUFFIXES.get(path.suffix, "application/octet-stream")
    response = FileResponse(path, media_type=media)
    if path.suffix == ".html":  # a self-contained report: no scripts, its own styles
        response.headers["Content-Security-Policy"] = (
            "default-src 'none'; img-src data: 'self'; style-src 'unsafe-inline'"
        )
    return response
