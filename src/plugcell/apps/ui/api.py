"""The web API of the cell controller (thesis 7.6): every action of the UI, as JSON.

==========================  =====================================================
``GET  /api/snapshot``      services (alive and dead), wiring, processes, queues, runs
``POST /api/wire``          ``{service, partner}`` — service subscribes to partner
``POST /api/unwire``        ``{service, partner}``
``POST /api/tasks``         ``{service, command, option, data, timeout}`` → ack
``POST /api/tasks/check``   the same, only checked (inline form errors)
``POST /api/tasks/stop``    ``{id}`` — StopData of a MultipleData task
``POST /api/runs``          ``{items: [{robot, program, values}], mode}`` (values:
                            the program's ``["name=value", …]``)
``GET  /api/programs``      the robot program library; ``/api/programs/{name}`` its text
``GET  /api/wiring``        the wiring file of the cell (download)
``POST /api/wiring/save``   ``{path}``;  ``POST /api/wiring/load`` ``{path}`` or ``{document}``
``POST /api/fit``           ``{kind: circle|line|plane, points}`` (mm)
``POST /api/wizard/probe``  appendix D.1;  ``POST /api/wizard/base`` appendix D.2
``POST /api/wizard/live``   a wizard step measured live: the robot moves, the tracker
                            measures (program ``frame_points``; ``wizard_live.py``)
``POST /api/residuals``     calibration residuals for the 3-D view: ``{document}`` (a
                            ``plugcell calibrate --residuals`` file), ``{matrix}`` (N×6
                            mm) or ``{service, name, workspace}`` (Get Matrix)
``POST /api/matrix``        a compute service's matrix: ``{service, name, workspace}``
``POST /api/tracked-path``  a tracked path's result (``plugcell path run --out``):
                            ``{document}`` → deviations from the commanded path
==========================  =====================================================

Refused input (a field that does not fit, a wire a service refuses) is answered
``200`` with ``{"ok": false, "errors": {field: why}}``; a body that is not a JSON
object is a ``400``, an unknown thing a ``404``, a request from elsewhere a ``403``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse, PlainTextResponse, Response

from plugcell.apps.ui.guard import BadRequestError, RefusedError, error_response, json_body
from plugcell.apps.ui.metrology import fit_json, wizard_base, wizard_probe
from plugcell.apps.ui.residuals import (
    fetch_matrix,
    fetch_residuals,
    residuals_from_document,
    residuals_from_matrix,
)
from plugcell.apps.ui.tracked import tracked_path_view
from plugcell.apps.ui.wizard_live import measure_live
from plugcell.devices.cell.runs import RunError, list_programs
from plugcell.devices.cell.service import CellController
from plugcell.devices.cell.tasks import TaskInputError, check_task
from plugcell.devices.cell.wiring import WiringError, dump_wiring

__all__ = ["make_router"]


def _names(body: dict[str, Any]) -> tuple[str, str]:
    errors = {}
    for key in ("service", "partner"):
        if not isinstance(body.get(key), str) or not body[key]:
            errors[key] = f"choose a {key}"
    if errors:
        raise RefusedError(errors)
    return body["service"], body["partner"]


def _file(path: str) -> Path:
    """The file a form names (RefusedError for what the OS would refuse otherwise than
    with an OSError: a NUL character, ``~user`` of an unknown user, ``.``)."""
    if "\0" in path:
        raise RefusedError({"path": "a file name cannot hold a NUL character"})
    try:
        file = Path(path.strip()).expanduser()
    except RuntimeError as exc:
        raise RefusedError({"path": f"{path.strip()}: {exc}"}) from None
    if not file.name:
        raise RefusedError({"path": f"{path.strip()!r} is a folder, not a file name"})
    return file


def make_router(controller: CellController) -> APIRouter:
    """The API routes, bound to ``controller``: the cell and its wiring, tasks and runs,
    the metrology tools."""
    router = APIRouter(prefix="/api")
    _cell_routes(router, controller)
    _task_routes(router, controller)
    _metrology_routes(router, controller)
    return router


def _cell_routes(router: APIRouter, controller: CellController) -> None:
    """The cell's snapshot, wire and unwire, the wiring file (download, save, load)."""

    @router.get("/snapshot")
    async def snapshot() -> JSONResponse:
        return JSONResponse(controller.snapshot())

    @router.post("/wire")
    async def wire(request: Request) -> JSONResponse:
        service, partner = _names(await json_body(request))
        result = await controller.wire(service, partner)
        return _result(result, "partner")

    @router.post("/unwire")
    async def unwire(request: Request) -> JSONResponse:
        service, partner = _names(await json_body(request))
        return _result(await controller.unwire(service, partner), "partner")

    @router.get("/wiring")
    async def wiring() -> Response:
        doc = dump_wiring(controller.wiring_document(), controller.host.cell)
        return Response(
            json.dumps(doc, indent=2) + "\n", media_type="application/json",
            headers={"Content-Disposition":
                     f'attachment; filename="{controller.host.cell}-wiring.json"'},
        )

    @router.post("/wiring/save")
    async def wiring_save(request: Request) -> JSONResponse:
        body = await json_body(request)
        path = body.get("path")
        if not isinstance(path, str) or not path.strip():
            raise RefusedError({"path": "a file name, e.g. cell-wiring.json"})
        try:
            doc = controller.save(_file(path))
        except WiringError as exc:
            raise RefusedError({"path": str(exc)}) from None
        return JSONResponse({"ok": True, "path": path.strip(), "document": doc})

    @router.post("/wiring/load")
    async def wiring_load(request: Request) -> JSONResponse:
        body = await json_body(request)
        try:
            if isinstance(body.get("document"), dict):
                wires = controller.load(body["document"])
            elif isinstance(body.get("path"), str) and body["path"].strip():
                wires = controller.load(_file(body["path"]))
            else:
                raise RefusedError({"path": "a wiring file to load"})
        except WiringError as exc:
            raise RefusedError({"path": str(exc)}) from None
        await controller.refresh()
        return JSONResponse({"ok": True, "wires": [w.to_json() for w in wires],
                             "wiring": controller.cell_json()["wiring"]})


def _task_routes(router: APIRouter, controller: CellController) -> None:
    """Tasks (one command at one service), runs of robot programs, the program library."""

    def _check(body: dict[str, Any]) -> Any:
        service = body.get("service")
        device = controller.device_of(service) if isinstance(service, str) else None
        try:
            return check_task(device, service, body.get("command"), body.get("option", ""),
                              body.get("data"), body.get("timeout"))
        except TaskInputError as exc:
            raise RefusedError(exc.errors) from None

    @router.post("/tasks/check")
    async def task_check(request: Request) -> JSONResponse:
        _check(await json_body(request))
        return JSONResponse({"ok": True})

    @router.post("/tasks")
    async def task(request: Request) -> JSONResponse:
        checked = _check(await json_body(request))
        result = await controller.assign(checked)
        if result["state"] == "Failed":
            return JSONResponse({**result, "ok": False, "errors": {"_": result["reason"]}})
        return JSONResponse({**result, "ok": True})

    @router.post("/tasks/stop")
    async def task_stop(request: Request) -> JSONResponse:
        body = await json_body(request)
        if not isinstance(body.get("id"), str):
            raise RefusedError({"id": "the task id"})
        return _result(await controller.stop_task(body["id"]), "_")

    @router.post("/runs")
    async def runs(request: Request) -> JSONResponse:
        body = await json_body(request)
        try:
            run = controller.start_run(body.get("items"), body.get("mode", "sequential"))
        except RunError as exc:
            raise RefusedError({"items": str(exc)}) from None
        return JSONResponse({"ok": True, "run": run.to_json()})

    @router.get("/programs")
    async def programs() -> JSONResponse:
        return JSONResponse({"programs": list_programs()})

    @router.get("/programs/{name}")
    async def program(name: str) -> Response:
        for p in list_programs():
            if p["name"] == name:
                return PlainTextResponse(Path(p["path"]).read_text(encoding="utf-8"))
        return error_response({"name": f"no program {name!r} in the library"}, 404)


def _metrology_routes(router: APIRouter, controller: CellController) -> None:
    """Fits, the BASE/PROBE wizards, residual and matrix views."""

    @router.post("/fit")
    async def fit(request: Request) -> JSONResponse:
        body = await json_body(request)
        return JSONResponse({"ok": True, **fit_json(body.get("kind"), body.get("points"))})

    @router.post("/wizard/live")
    async def wizard_live(request: Request) -> JSONResponse:
        body = await json_body(request)
        return JSONResponse({"ok": True, **await measure_live(controller, body)})

    @router.post("/wizard/{which}")
    async def wizard(which: str, request: Request) -> JSONResponse:
        body = await json_body(request)
        if which not in ("probe", "base"):
            raise BadRequestError({"_": f"no wizard {which!r} (probe, base)"}, 404)
        result = wizard_probe(body) if which == "probe" else wizard_base(body)
        return JSONResponse({"ok": True, **result})

    @router.post("/residuals")
    async def residuals(request: Request) -> JSONResponse:
        body = await json_body(request)
        if "document" in body:
            view = residuals_from_document(body["document"])
        elif "matrix" in body:
            view = residuals_from_matrix(body["matrix"])
        elif "service" in body:
            view = await fetch_residuals(controller, body)
        else:
            raise RefusedError({"_": "a residual file (document), an N×6 matrix or a "
                                     "compute service's matrix (service, name)"})
        return JSONResponse({"ok": True, **view})

    @router.post("/tracked-path")
    async def tracked_path(request: Request) -> JSONResponse:
        body = await json_body(request)
        return JSONResponse({"ok": True, **tracked_path_view(body.get("document"))})

    @router.post("/matrix")
    async def matrix(request: Request) -> JSONResponse:
        body = await json_body(request)
        arr, title = await fetch_matrix(controller, body)
        return JSONResponse({"ok": True, "title": title, "shape": list(arr.shape),
                             "rows": arr.tolist()})


def _result(result: dict[str, Any], field: str) -> JSONResponse:
    if result.get("ok"):
        return JSONResponse(result)
    return error_response({field: result.get("reason") or "failed"}, 200)
