"""Calibration residuals for the UI's 3-D view (the visualisation service of thesis 7.5).

The residual of a pose is measured − predicted target position, in the tracker frame
(docs/calibration.md).  The view takes it from one of three sources and gets one
answer (:func:`residual_view`):

* ``{"document": …}`` — the file of ``plugcell calibrate --residuals`` (every
  calibration and validation pose, before and after calibration);
* ``{"matrix": [[x, y, z, dx, dy, dz], …]}`` — mm, what the compute service's
  ``residuals(params, mJ, mT)`` gives (pasted);
* ``{"service": COMPUTE, "name": "res", "workspace": "R1"}`` — the same matrix,
  read by the controller with the compute service's ``Get Matrix`` (``for=R1``: from
  the workspace of robot R1, where its calibration program computed it).

Every bad input raises :class:`~plugcell.apps.ui.metrology.FitInputError` with the field
it concerns (``document``, ``matrix``, ``service``, ``name``, ``workspace`` or ``_``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from plugcell.apps.ui.metrology import MAX_POINTS, FitInputError
from plugcell.devices.compute.workspace import NAME as MATRIX_NAME
from plugcell.framework.data import from_data
from plugcell.framework.keys import check_name

SETS = ("calibration", "validation")
#: Largest coordinate accepted (mm): 1000 km, far beyond any cell.
MAX_MM = 1e9
#: Seconds each wait of a Get Matrix may take.
FETCH_TIMEOUT = 10.0

__all__ = ["SETS", "fetch_matrix", "fetch_residuals", "residual_view",
           "residuals_from_document", "residuals_from_matrix"]


def _number(v: Any) -> bool:
    """A JSON number of at most :data:`MAX_MM` in size (so norms and means stay finite)."""
    return (not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v)
            and abs(v) <= MAX_MM)


def _xyz(value: Any) -> list[float] | None:
    if isinstance(value, list) and len(value) == 3 and all(_number(v) for v in value):
        return [float(v) for v in value]
    return None


def _count(value: Any, field: str, what: str) -> list[Any]:
    if not isinstance(value, list) or not value:
        raise FitInputError({field: f"no {what}: a non-empty list expected"})
    if len(value) > MAX_POINTS:
        raise FitInputError({field: f"at most {MAX_POINTS} {what}, got {len(value)}"})
    return value


def residuals_from_document(doc: Any) -> dict[str, Any]:
    """The view of a residual file (``plugcell calibrate --residuals``)."""
    # here, not at the top: io.params loads the calibration package (SciPy), which the UI
    # server needs only when a residual file is shown
    from plugcell.io.params import RESIDUALS_FORMAT, RESIDUALS_FORMAT_VERSION

    field = "document"
    if not isinstance(doc, dict) or doc.get("format") != RESIDUALS_FORMAT:
        raise FitInputError({field: f"not a residual file (format {RESIDUALS_FORMAT!r}): write "
                                    "one with plugcell calibrate … --residuals RES.json"})
    version = doc.get("format_version")
    if not (isinstance(version, int) and not isinstance(version, bool)
            and 1 <= version <= RESIDUALS_FORMAT_VERSION):
        raise FitInputError({field: f"format_version {version!r}: this plugcell reads "
                                    f"1…{RESIDUALS_FORMAT_VERSION}"})
    poses = []
    for i, p in enumerate(_count(doc.get("poses"), field, "poses")):
        where = f"pose {i + 1}"
        if not isinstance(p, dict):
            raise FitInputError({field: f"{where}: an object expected"})
        if p.get("set") not in SETS:
            raise FitInputError({field: f"{where}: set must be one of {', '.join(SETS)}"})
        measured, after = _xyz(p.get("measured_mm")), _xyz(p.get("after_mm"))
        before = _xyz(p.get("before_mm"))
        for key, value in (("measured_mm", measured), ("after_mm", after),
                           ("before_mm", before)):
            if value is None and (key != "before_mm" or p.get(key) is not None):
                raise FitInputError({field: f"{where}: {key} must be [x, y, z] in mm"})
        index = p.get("index")
        poses.append({"set": p["set"], "index": index if _number(index) else i + 1,
                      "measured": measured, "after": after, "before": before})
    model = doc.get("model")
    label = ""
    if isinstance(model, dict) and _number(model.get("number")) \
            and isinstance(model.get("name"), str):
        label = f"model {model['number']:g} ({model['name'][:40]})"
    robot = doc.get("robot")
    return residual_view(poses, source="document",
                         title=" · ".join(x for x in ((robot[:64] if isinstance(robot, str)
                                                       else ""), label) if x))


def residuals_from_matrix(value: Any, field: str = "matrix", title: str = "") -> dict[str, Any]:
    """The view of an N×6 ``[x, y, z, dx, dy, dz]`` mm matrix (calibration poses, after)."""
    poses = []
    for i, row in enumerate(_count(value, field, "rows")):
        if not (isinstance(row, list) and len(row) == 6 and all(_number(v) for v in row)):
            raise FitInputError({field: f"row {i + 1}: 6 numbers x, y, z, dx, dy, dz (mm) "
                                        "expected — the matrix of residuals(params, mJ, mT)"})
        poses.append({"set": "calibration", "index": i + 1, "measured": [float(v) for v in row[:3]],
                      "after": [float(v) for v in row[3:]], "before": None})
    return residual_view(poses, source=field, title=title)


def residual_view(poses: list[dict[str, Any]], *, source: str, title: str = "") -> dict[str, Any]:
    """The answer of ``/api/residuals``: the poses with their norms and, per set, the
    mean/rms/max of |Δp| after (and the mean before) calibration, in mm."""
    for p in poses:
        p["after_norm"] = math.hypot(*p["after"])
        p["before_norm"] = None if p["before"] is None else math.hypot(*p["before"])
    sets = {}
    for name in SETS:
        mine = [p for p in poses if p["set"] == name]
        if not mine:
            continue
        after = np.array([p["after_norm"] for p in mine])
        before = [p["before_norm"] for p in mine if p["before_norm"] is not None]
        sets[name] = {"poses": len(mine), "mean_mm": float(after.mean()),
                      "rms_mm": float(np.sqrt(np.mean(after**2))), "max_mm": float(after.max()),
                      "before_mean_mm": float(np.mean(before)) if len(before) == len(mine)
                      else None}
    return {"source": source, "title": title, "poses": poses, "sets": sets,
            "max_mm": max(p["after_norm"] for p in poses),
            "max_before_mm": max((p["before_norm"] or 0.0) for p in poses)}


async def fetch_matrix(controller: Any, body: dict[str, Any]) -> tuple[np.ndarray, str]:
    """The matrix ``name`` of a compute service (``Get Matrix``; from the workspace of
    ``workspace`` when given, else the controller's own) as a 2-D array of numbers, and
    where it came from (``COMPUTE: mT of H4``)."""
    service, name, owner = body.get("service"), body.get("name"), body.get("workspace")
    device = controller.device_of(service) if isinstance(service, str) else None
    if device is None or not any(c.name == "Get Matrix" for c in device.commands):
        raise FitInputError({"service": "a live compute service (one with Get Matrix)"})
    if not isinstance(name, str) or not MATRIX_NAME.fullmatch(name):
        raise FitInputError({"name": "a matrix name: a letter, then letters, digits or '_'"})
    option = name
    if owner not in (None, ""):
        try:
            option += f"; for={check_name(owner, 'workspace')}"
        except (TypeError, ValueError) as exc:
            raise FitInputError({"workspace": str(exc)}) from None
    final, data = await controller.fetch(service, "Get Matrix", option, timeout=FETCH_TIMEOUT)
    if final.state.value != "Completed":
        raise FitInputError({"name": f"{service} Get Matrix {option}: {final.reason}"})
    arr = from_data(data)
    try:
        arr = None if arr is None else np.atleast_2d(np.asarray(arr, dtype=float))
    except (TypeError, ValueError):
        arr = None
    if arr is None or arr.ndim != 2 or not np.all(np.isfinite(arr)):
        raise FitInputError({"name": f"{name} is not a matrix of numbers"})
    return arr, f"{service}: {name}" + (f" of {owner}" if owner else "")


async def fetch_residuals(controller: Any, body: dict[str, Any]) -> dict[str, Any]:
    """The residual matrix ``name`` of a compute service (:func:`fetch_matrix`)."""
    arr, where = await fetch_matrix(controller, body)
    if arr.shape[1] != 6:
        shape = "×".join(str(n) for n in arr.shape)
        raise FitInputError({"name": f"{body['name']} is {shape}: an N×6 residual matrix "
                                     "expected (residuals(params, mJ, mT))"})
    return residuals_from_matrix(arr.tolist(), "name", title=where)
