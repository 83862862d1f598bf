"""A tracked path's result for the web UI (issue 38): commanded, measured and corrected.

The file of ``plugcell path run … --out result.json`` (docs/tracked-paths.md) holds the
traces every 4 ms: the commanded TCP (the path's nominal pose), the corrected one (with
the offset the controller applied), the twin's true TCP, and each tracker sample.  At
path scale (hundreds of millimetres) their differences (tenths of a millimetre) do not
show, so the view is each one's deviation from the commanded path, in mm, over time:

* ``corrected``: ``|p_corrected − p_commanded|`` — the correction the loop applied;
* ``actual``: ``|p_actual − p_commanded|`` — how far the TCP truly was from the path;
* ``measured``: ``|p_measured − p_commanded(t_s)|`` — what the tracker saw (the commanded
  path interpolated at the sample's time);

decimated to at most :data:`MAX_POINTS` points each, with the windows without tracking
and the accuracy table of the result.  Every problem of the file is a
:class:`~plugcell.apps.ui.metrology.FitInputError` naming the field.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from plugcell.apps.ui.metrology import FitInputError

__all__ = ["MAX_POINTS", "TRACKED_FORMAT", "tracked_path_view"]

TRACKED_FORMAT = "plugcell-tracked-path"
#: Points of each plotted series at most (the browser draws polylines of them).
MAX_POINTS = 1500
#: Cycles a result may hold (an hour at 4 ms).
MAX_CYCLES = 900_000

_FIELD = "document"


def _refuse(why: str) -> FitInputError:
    return FitInputError({_FIELD: why})


def _rows(value: Any, name: str, width: int, n: int | None = None) -> np.ndarray:
    """A finite (N, width) array of a list of rows (``n``: the rows it must have)."""
    if not isinstance(value, list) or not value or len(value) > MAX_CYCLES:
        raise _refuse(f"traces.{name}: a list of 1…{MAX_CYCLES} rows expected")
    if n is not None and len(value) != n:
        raise _refuse(f"traces.{name}: {len(value)} rows, t_s has {n}")
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise _refuse(f"traces.{name}: rows of {width} numbers expected") from None
    if arr.ndim == 1 and width == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[1] != width or not np.all(np.isfinite(arr)):
        raise _refuse(f"traces.{name}: rows of {width} finite numbers expected")
    return arr


def _stride(n: int) -> int:
    return max(1, math.ceil(n / MAX_POINTS))


def _windows(value: Any) -> list[dict[str, Any]]:
    out = []
    for w in value if isinstance(value, list) else []:
        if not isinstance(w, dict):
            continue
        start, end = w.get("start_s"), w.get("end_s")
        if not isinstance(start, int | float) or isinstance(start, bool):
            continue
        out.append({"start_s": float(start),
                    "end_s": float(end) if isinstance(end, int | float)
                    and not isinstance(end, bool) else None,
                    "reason": str(w.get("reason", ""))[:80]})
    return out


def _accuracy(value: Any) -> list[dict[str, Any]]:
    keys = ("segment", "state", "cycles", "perpendicular_max_mm", "perpendicular_3sigma_mm",
            "along_max_mm")
    out = []
    for r in value if isinstance(value, list) else []:
        if isinstance(r, dict) and all(k in r for k in keys):
            row = {k: r[k] for k in keys}
            if not isinstance(row["state"], str) or not all(
                    isinstance(row[k], int | float) and not isinstance(row[k], bool)
                    for k in keys if k != "state"):
                continue
            row["state"] = row["state"][:20]
            out.append(row)
    return out


def tracked_path_view(doc: Any) -> dict[str, Any]:
    """The plot and table of a tracked path's result file (module docstring).

    Parameters
    ----------
    doc : object
        The JSON document of ``plugcell path run --out``.

    Returns
    -------
    dict
        ``title``, ``ended``, ``accuracy`` (rows as in the file), ``windows``
        (``start_s``, ``end_s`` or None, ``reason``), ``series``: ``corrected``,
        ``actual``, ``measured`` as ``[[t_s, deviation_mm], …]`` (at most
        :data:`MAX_POINTS` each), ``max_mm`` of each.

    Raises
    ------
    FitInputError
        Not such a file, or traces that do not fit (the field and why).
    """
    if not isinstance(doc, dict) or doc.get("format") != TRACKED_FORMAT:
        raise _refuse(f"not a tracked path's result (format {TRACKED_FORMAT!r}): write one "
                      "with plugcell path run … --out result.json")
    version = doc.get("format_version")
    if version != 1 or isinstance(version, bool):
        raise _refuse(f"format_version {version!r}: this plugcell reads 1")
    traces = doc.get("traces")
    if not isinstance(traces, dict):
        raise _refuse("traces: missing (the file of path run --out has them)")
    t = _rows(traces.get("t_s"), "t_s", 1)[:, 0]
    if len(t) > 1 and not np.all(np.diff(t) > 0):
        raise _refuse("traces.t_s: times must increase")
    n = len(t)
    commanded = _rows(traces.get("commanded_mm"), "commanded_mm", 3, n)
    corrected = _rows(traces.get("corrected_mm"), "corrected_mm", 3, n)
    actual = _rows(traces.get("actual_mm"), "actual_mm", 3, n)
    measured_raw = traces.get("measured_mm", [])
    measured = _rows(measured_raw, "measured_mm", 4) if measured_raw else np.zeros((0, 4))
    k = slice(None, None, _stride(n))
    series: dict[str, list[list[float]]] = {}
    for name, p in (("corrected", corrected), ("actual", actual)):
        dev = np.linalg.norm(p - commanded, axis=1)
        series[name] = np.column_stack([t[k], dev[k]]).round(5).tolist()
    if len(measured):
        ts = measured[:, 0]
        at = np.column_stack([np.interp(ts, t, commanded[:, i]) for i in range(3)])
        dev = np.linalg.norm(measured[:, 1:] - at, axis=1)
        m = slice(None, None, _stride(len(ts)))
        series["measured"] = np.column_stack([ts[m], dev[m]]).round(5).tolist()
    else:
        series["measured"] = []
    path = doc.get("path")
    ended = doc.get("ended")
    return {"title": path[:80] if isinstance(path, str) else "tracked path",
            "ended": ended[:200] if isinstance(ended, str) else "",
            "accuracy": _accuracy(doc.get("accuracy")),
            "windows": _windows(doc.get("windows_without_tracking")),
            "series": series,
            "max_mm": {k: max((p[1] for p in v), default=0.0) for k, v in series.items()},
            "span_s": [float(t[0]), float(t[-1])]}
