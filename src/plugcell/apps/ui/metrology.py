"""Best-fit geometry and the BASE/PROBE wizards for the web UI (thesis 7.5, appendix D).

The laser tracker visualisation service of 7.5 "contains built-in functions for
calculating best-fit geometries (e.g. lines, circles, planes ...) of the
measurements, based on which initial estimates of the BASE and PROBE
transformations ... can be determined" (wizards of Figures D-3 and D-5).  Here the
fits are those of :mod:`plugcell.metrology`; this module only converts between the
tracker's units (points in **mm**, as the tracker service reports them) and the
metrology package's (m), and turns results into JSON with each point's residual
so the 3-D view can colour them.  Every bad input raises :class:`FitInputError`
with the field it concerns.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from plugcell.io.units import UnitsError, pose_from_robot, robot_from_pose

MM = 1e-3
MAX_POINTS = 100_000
#: Largest coordinate a fit takes (mm): 1 000 km, far beyond any tracker; the squares
#: of much larger ones overflow the fits.
MAX_MM = 1e9
KINDS = ("circle", "line", "plane")

__all__ = ["KINDS", "FitInputError", "fit_json", "points_mm", "wizard_base", "wizard_probe"]


class FitInputError(ValueError):
    """Points or poses that cannot be used: ``errors`` maps the field to why."""

    def __init__(self, errors: dict[str, str]) -> None:
        super().__init__("; ".join(f"{k}: {v}" for k, v in errors.items()))
        self.errors = errors


def points_mm(value: Any, field: str, minimum: int) -> np.ndarray:
    """``[[x, y, z(, …)], …]`` in mm as an (N, 3) array in m (extra columns ignored)."""
    if not isinstance(value, list):
        raise FitInputError({field: "a list of points [x, y, z] in mm"})
    if len(value) < minimum:
        raise FitInputError({field: f"at least {minimum} points, got {len(value)}"})
    if len(value) > MAX_POINTS:
        raise FitInputError({field: f"at most {MAX_POINTS} points"})
    out = np.empty((len(value), 3))
    for i, p in enumerate(value):
        if not isinstance(p, list) or len(p) < 3:
            raise FitInputError({field: f"point {i + 1}: expected [x, y, z]"})
        for j in range(3):
            v = p[j]
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise FitInputError({field: f"point {i + 1}: coordinate {j + 1} is not a number"})
            if abs(v) > MAX_MM:
                raise FitInputError({field: f"point {i + 1}: coordinate {j + 1} is beyond "
                                            f"±{MAX_MM:g} mm"})
            out[i, j] = float(v)
    return out * MM


def _mm(v: np.ndarray) -> list[float]:
    return [float(x) for x in np.asarray(v, dtype=float).reshape(-1) / MM]


def _transform_json(T: np.ndarray) -> dict[str, Any]:
    """A 4×4 (m) as the matrix (translation mm) and the tracker's rpy 6-vector (mm, deg)."""
    M = np.array(T, dtype=float)
    vector = [float(x) for x in robot_from_pose(M, "rpy")]
    return {
        "matrix": [[float(M[i, j]) if j < 3 else float(M[i, j] / MM) for j in range(4)]
                   for i in range(4)],
        "xyz_mm": vector[:3],
        "rpy_deg": vector[3:],
        "vector": vector,
    }


def _finite(result: dict[str, Any], field: str) -> dict[str, Any]:
    """``result`` if all its numbers are finite (JSON has no NaN or infinity)."""
    stack: list[Any] = [result]
    while stack:
        node = stack.pop()
        if isinstance(node, dict):
            stack.extend(node.values())
        elif isinstance(node, list):
            stack.extend(node)
        elif isinstance(node, float) and not math.isfinite(node):
            raise FitInputError({field: "no finite result: numbers too large or too small "
                                        "for the fit"})
    return result


def fit_json(kind: Any, points: Any) -> dict[str, Any]:
    """Fit a circle, line or plane through points in mm; JSON in mm with residuals."""
    return _finite(_fit(kind, points), "points")


def _fit(kind: Any, points: Any) -> dict[str, Any]:
    # here, not at the top: the UI server starts without the fits' SciPy
    from plugcell.metrology import MetrologyError, fit_circle, fit_line, fit_plane

    if kind not in KINDS:
        raise FitInputError({"kind": f"one of {', '.join(KINDS)}"})
    p = points_mm(points, "points", {"circle": 3, "line": 2, "plane": 3}[kind])
    try:
        if kind == "circle":
            c = fit_circle(p)
            return {
                "kind": kind, "centre": _mm(c.centre), "normal": [float(x) for x in c.normal],
                "radius": c.radius / MM, "rms": c.rms / MM,
                "residuals": _mm(c.distances), "sweep_deg": math.degrees(c.sweep),
                "oriented": c.oriented,
            }
        if kind == "line":
            line = fit_line(p)
            return {
                "kind": kind, "point": _mm(line.point),
                "direction": [float(x) for x in line.direction],
                "rms": line.rms / MM, "residuals": _mm(line.residuals),
                "extent": [float(np.min(line.parameters(p)) / MM),
                           float(np.max(line.parameters(p)) / MM)],
            }
        plane = fit_plane(p)
        return {
            "kind": kind, "centroid": _mm(plane.centroid),
            "normal": [float(x) for x in plane.normal],
            "rms": plane.rms / MM, "residuals": _mm(np.abs(plane.residuals)),
            "flatness": plane.flatness / MM,
        }
    except MetrologyError as exc:
        raise FitInputError({"points": str(exc)}) from None


def _pose(value: Any, field: str) -> np.ndarray:
    """A T-MAC pose: a 4×4 matrix (translation mm) or [x, y, z mm, roll, pitch, yaw deg]."""
    arr = None
    if isinstance(value, list):
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            arr = None
    if arr is None or not np.all(np.isfinite(arr)):
        raise FitInputError({field: "a 6-vector [x, y, z mm, roll, pitch, yaw deg] or 4×4"})
    if arr.shape == (4, 4):
        T = arr.copy()
        T[:3, 3] *= MM
        return T
    if arr.shape == (6,):
        try:
            return pose_from_robot(arr, "rpy")
        except UnitsError as exc:
            raise FitInputError({field: str(exc)}) from None
    raise FitInputError({field: "a 6-vector [x, y, z mm, roll, pitch, yaw deg] or 4×4"})


def _offset(value: Any) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise FitInputError({"smr_offset": "a number of mm"})
    return float(value) * MM


def wizard_probe(body: dict[str, Any]) -> dict[str, Any]:
    """Appendix D.1: circle (joint n turning), dowel holes, T-MAC pose → PROBE."""
    return _finite(_probe(body), "_")


def _probe(body: dict[str, Any]) -> dict[str, Any]:
    from plugcell.metrology import MetrologyError, probe_from_flange_features

    circle = points_mm(body.get("circle"), "circle", 3)
    holes = points_mm(body.get("holes"), "holes", 2)
    tmac = _pose(body.get("tmac"), "tmac")
    offset = _offset(body.get("smr_offset"))
    kwargs = {} if offset is None else {"smr_offset": offset}
    try:
        est = probe_from_flange_features(circle, holes, tmac, **kwargs)
    except MetrologyError as exc:
        raise FitInputError({"circle": str(exc)}) from None
    return {
        "probe": _transform_json(est.probe),
        "flange": _transform_json(est.flange_pose),
        "circle": {"centre": _mm(est.circle.centre), "normal": list(map(float, est.circle.normal)),
                   "radius": est.circle.radius / MM, "rms": est.circle.rms / MM,
                   "residuals": _mm(est.circle.distances)},
        "holes": {"point": _mm(est.hole_line.point),
                  "direction": list(map(float, est.hole_line.direction)),
                  "rms": est.hole_line.rms / MM, "residuals": _mm(est.hole_line.residuals)},
        "hole_line_tilt_deg": math.degrees(est.hole_line_tilt),
    }


def wizard_base(body: dict[str, Any]) -> dict[str, Any]:
    """Appendix D.2: circle (joint 1 turning), base plane, x move → BASE and eq. D.6."""
    return _finite(_base(body), "_")


def _base(body: dict[str, Any]) -> dict[str, Any]:
    from plugcell.metrology import MetrologyError, base_from_features

    circle = points_mm(body.get("circle"), "circle", 3)
    plane = points_mm(body.get("plane"), "plane", 3)
    line = points_mm(body.get("line"), "line", 2)
    offset = _offset(body.get("smr_offset"))
    kwargs = {} if offset is None else {"smr_offset": offset}
    try:
        est = base_from_features(circle, plane, line, **kwargs)
    except MetrologyError as exc:
        field = str(exc).split(":", 1)[0]
        key = {"base_plane_points": "plane", "x_axis_line_points": "line"}.get(field, "circle")
        raise FitInputError({key: str(exc)}) from None
    params = est.parameters
    return {
        "base": _transform_json(est.base),
        "parameters": {k: (float(v) / MM if k in ("a0", "b0", "d0") else math.degrees(float(v)))
                       for k, v in _params(params).items()},
        "circle": {"centre": _mm(est.circle.centre), "normal": list(map(float, est.circle.normal)),
                   "radius": est.circle.radius / MM, "rms": est.circle.rms / MM,
                   "residuals": _mm(est.circle.distances)},
        "plane": {"centroid": _mm(est.plane.centroid), "normal": list(map(float, est.plane.normal)),
                  "rms": est.plane.rms / MM, "residuals": _mm(np.abs(est.plane.residuals))},
        "line": {"point": _mm(est.line.point), "direction": list(map(float, est.line.direction)),
                 "rms": est.line.rms / MM, "residuals": _mm(est.line.residuals)},
        "axis_plane_angle_deg": math.degrees(est.axis_plane_angle),
        "line_tilt_deg": math.degrees(est.line_tilt),
    }


def _params(params: Any) -> dict[str, float]:
    names = ("a0", "b0", "d0", "alpha0", "beta0", "theta0")
    return {n: getattr(params, n) for n in names if hasattr(params, n)}
