"""The BASE/PROBE wizards measuring live: the robot moves, the tracker measures (appendix D).

Appendix D has the operator turn a joint (a circle), move the robot along x₀ (a
line) or hold it still (the dowel holes, the T-MAC) while the tracker measures.  A
*live* step of the wizard has the robot do it: the controller runs the shipped robot
program ``frame_points`` (``pdl/programs/frame_points.pdl``) on the robot service
— the program moves, catches the beam, has the tracker measure the reflector raw (the
tracker frame: identity BASE and PROBE) and routes every measurement into a matrix of
the compute service (thesis 9.3) — then reads that matrix (``Get Matrix pts;
for=ROBOT``) and gives its points to the wizard, which fits them as before
(:mod:`plugcell.apps.ui.metrology`).  The program does the moving and measuring; the UI
fits.  A new sensor would change the program, not the UI.

``POST /api/wizard/live`` (mm, degrees; orientations roll-pitch-yaw as in the wizards)::

    {"robot": "H4", "tracker": "TRACKER", "compute": "COMPUTE",
     "sweep": {"joint": 6, "from": -150, "to": 150, "count": 13}   # a joint turned, or
     "line": {"axis": "x", "length": 700, "count": 8},             # a move along x₀, or
                                                                    # neither: hold still
     "reflectors": [[0, 50, 6.35]],          # in the flange frame: one, or one a point
     "base_est": [x, y, z, roll, pitch, yaw],  # the robot base in the tracker frame
     "joints": [q1, …],                      # the reference pose (default: where it is)
     "duration_ms": 100, "matrix": "pts", "timeout": 300}

answers ``{"ok": true, "points": [[x, y, z, roll, pitch, yaw], …], "joints", "configs",
"run"}`` (points in the tracker frame) or ``{"ok": false, "errors": {field: why}}``.
The estimates only aim the beam (within the tracker's 10 mm capture radius); the
robot ends at the reference pose, so the steps of one wizard share it (D.1: "without
moving the robot, mount the T-MAC").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from plugcell.apps.ui.metrology import FitInputError
from plugcell.devices.cell.runs import RunError
from plugcell.devices.compute.workspace import NAME as MATRIX_NAME
from plugcell.devices.robot.value_text import numbers_text, rows_text
from plugcell.framework.data import from_data
from plugcell.io.units import UnitsError, pose_from_robot, robot_from_pose

#: The robot program that moves and measures (src/plugcell/pdl/programs).
PROGRAM = "frame_points"
#: Most points of one live step (the program's ARRAY[100]).
MAX_POINTS = 100
#: Largest joint angle, move and coordinate accepted (deg, mm).
MAX_ANGLE = 3600.0
MAX_MM = 100_000.0
#: Seconds each query of the robot or the compute service may take.
QUERY_TIMEOUT = 30.0
DEFAULT_TIMEOUT = 300.0
MAX_TIMEOUT = 3600.0
#: Largest joint step between two neighbouring points of a line (deg): more is another
#: branch of the inverse kinematics, not a straight move.
MAX_LINE_STEP = 45.0
AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}

__all__ = ["PROGRAM", "LiveStep", "measure_live", "parse_live"]


def _number(v: Any) -> bool:
    return not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v)


def _vector(value: Any, field: str, sizes: tuple[int, ...], limit: float, what: str
            ) -> list[float]:
    if not (isinstance(value, list) and len(value) in sizes and all(_number(v) for v in value)
            and all(abs(v) <= limit for v in value)):
        raise FitInputError({field: what})
    return [float(v) for v in value]


def _zyz(vector: list[float], field: str) -> np.ndarray:
    """[x, y, z mm(, roll, pitch, yaw deg)] → the robot's x, y, z, a, b, c (ZYZ deg)."""
    v = np.r_[vector, [0.0] * (6 - len(vector))]
    try:
        return robot_from_pose(pose_from_robot(v, "rpy"), "zyz")
    except UnitsError as exc:
        raise FitInputError({field: str(exc)}) from None


def _integer(value: Any, field: str, low: int, high: int, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise FitInputError({field: f"{what}: a whole number {low}…{high}"})
    return value


def _service(controller: Any, body: dict[str, Any], field: str, command: str, what: str
             ) -> str:
    name = body.get(field)
    device = controller.device_of(name) if isinstance(name, str) and name else None
    if device is None or device.command(command) is None:
        raise FitInputError({field: f"a live {what} service (one with {command})"})
    return str(name)


async def _fetch(controller: Any, service: str, command: str, option: str = "",
                 data: Any = None, field: str = "_") -> np.ndarray:
    final, out = await controller.fetch(service, command, option, data, timeout=QUERY_TIMEOUT)
    if final.state.value != "Completed":
        raise FitInputError({field: f"{service} {command}: {final.reason}"})
    arr = from_data(out)
    if arr is None:
        raise FitInputError({field: f"{service} {command} returned no data"})
    return np.asarray(arr, dtype=float)


@dataclass(frozen=True)
class LiveStep:
    """A live step as asked for, checked (what needs the robot comes later)."""

    reflectors: list[np.ndarray]
    base: np.ndarray
    duration_ms: int
    matrix: str
    timeout: float
    joints: np.ndarray | None
    sweep: tuple[int, float, float, int] | None
    line: tuple[str, float, int] | None


def parse_live(body: dict[str, Any]) -> LiveStep:
    """The input of a live step without the services (FitInputError with the field)."""
    refl = body.get("reflectors")
    if not (isinstance(refl, list) and 1 <= len(refl) <= MAX_POINTS):
        raise FitInputError({"reflectors": "where the reflector sits in the flange frame: "
                                           "[[x, y, z(, roll, pitch, yaw)]] (mm, deg)"})
    what = "x, y, z mm (and roll, pitch, yaw deg) in the flange frame"
    reflectors = [_zyz(_vector(r, "reflectors", (3, 6), MAX_MM, what), "reflectors")
                  for r in refl]
    base = _zyz(_vector(body.get("base_est"), "base_est", (6,), MAX_MM,
                        "the BASE estimate: x, y, z mm, roll, pitch, yaw deg"), "base_est")
    duration = _integer(body.get("duration_ms", 100), "duration_ms", 1, 60_000, "reading ms")
    matrix = body.get("matrix", "pts")
    if not isinstance(matrix, str) or not MATRIX_NAME.fullmatch(matrix):
        raise FitInputError({"matrix": "a matrix name: a letter, then letters, digits or '_'"})
    timeout = body.get("timeout", DEFAULT_TIMEOUT)
    if not (_number(timeout) and 0 < timeout <= MAX_TIMEOUT):
        raise FitInputError({"timeout": f"between 0 and {MAX_TIMEOUT:g} s"})
    joints = None
    if body.get("joints") not in (None, []):
        joints = np.array(_vector(body["joints"], "joints", tuple(range(1, 11)), MAX_ANGLE,
                                  "the reference pose: 1…10 joint angles (deg)"))
    sweep, line = body.get("sweep"), body.get("line")
    if sweep is not None and line is not None:
        raise FitInputError({"sweep": "a joint sweep or a line, not both"})
    swept = moved = None
    if sweep is not None:
        if not isinstance(sweep, dict):
            raise FitInputError({"sweep": "{joint, from, to, count}"})
        joint = _integer(sweep.get("joint"), "sweep", 1, 10, "joint")
        count = _integer(sweep.get("count"), "sweep", 3, MAX_POINTS, "count")
        ends = [sweep.get("from"), sweep.get("to")]
        if not all(_number(v) and abs(v) <= MAX_ANGLE for v in ends) or ends[0] == ends[1]:
            raise FitInputError({"sweep": "from and to: two different angles (deg)"})
        swept = (joint, float(ends[0]), float(ends[1]), count)
    if line is not None:
        if not isinstance(line, dict):
            raise FitInputError({"line": "{axis, length, count}"})
        axis = line.get("axis", "x")
        if not isinstance(axis, str) or axis not in AXES:
            raise FitInputError({"line": "axis: x, y or z of the robot base"})
        count = _integer(line.get("count"), "line", 2, MAX_POINTS, "count")
        length = line.get("length")
        if not (_number(length) and 0 < abs(length) <= MAX_MM):
            raise FitInputError({"line": f"length: a move of 0…{MAX_MM:g} mm"})
        moved = (axis, float(length), count)
    points = swept[3] if swept else moved[2] if moved else len(reflectors)
    if len(reflectors) not in (1, points):
        raise FitInputError({"reflectors": f"one reflector, or one for each of the "
                                           f"{points} points"})
    return LiveStep(reflectors, base, duration, matrix, float(timeout), joints, swept, moved)


async def _configs(controller: Any, robot: str, step: LiveStep, q0: np.ndarray) -> np.ndarray:
    """The joint configurations to measure at (deg)."""
    if step.sweep is not None:
        joint, start, end, count = step.sweep
        if joint > len(q0):
            raise FitInputError({"sweep": f"joint {joint}: {robot} has {len(q0)} joints"})
        configs = np.tile(q0, (count, 1))
        configs[:, joint - 1] = np.linspace(start, end, count)
        return configs
    if step.line is not None:
        axis, length, count = step.line
        start_pos = (await _fetch(controller, robot, "JNTP_TO_POS", data=q0.tolist(),
                                  field="line")).reshape(-1)
        configs = [q0]
        for t in np.linspace(0.0, length, count)[1:]:
            target = start_pos.copy()
            target[:3] += t * np.asarray(AXES[axis])
            q = (await _fetch(controller, robot, "POS_TO_JNTP", data=target.tolist(),
                              field="line")).reshape(-1)
            if q.shape != q0.shape or np.max(np.abs(q - configs[-1])) > MAX_LINE_STEP:
                to = numbers_text(target[:3])
                raise FitInputError({"line": f"no continuous move to {to} mm: choose a "
                                             "shorter move or another pose"})
            configs.append(q)
        return np.array(configs)
    return np.tile(q0, (len(step.reflectors), 1))


async def measure_live(controller: Any, body: dict[str, Any]) -> dict[str, Any]:
    """One live step (module docstring); FitInputError with the field for bad input or
    a program that did not finish."""
    step = parse_live(body)
    robot = _service(controller, body, "robot", "ACTIVATE", "robot")
    tracker = _service(controller, body, "tracker", "Single Measurement", "laser tracker")
    compute = _service(controller, body, "compute", "Get Matrix", "compute")
    record = controller.records.get(robot)
    missing = [p for p in (tracker, compute) if record is None or p not in record.partners]
    if missing:
        raise FitInputError({"robot": f"wire {robot} → {' and '.join(missing)} first: the "
                                      "program measures through them"})
    if step.joints is not None:
        q0 = step.joints
    else:
        q0 = (await _fetch(controller, robot, "ARM_JNTP", field="robot")).reshape(-1)
    configs = await _configs(controller, robot, step, q0)
    each = len(step.reflectors) > 1
    reflectors = step.reflectors if each else step.reflectors * len(configs)
    values = [
        f"configs={rows_text(configs)}", f"n_configs={len(configs)}",
        f"reflectors={rows_text(reflectors)}", f"catch_each={'TRUE' if each else 'FALSE'}",
        f"base_est={numbers_text(step.base)}", f"duration_ms={step.duration_ms}",
        f"tracker={tracker}", f"compute={compute}", f"matrix={step.matrix}",
        f"home={numbers_text(q0)}",
    ]
    try:
        run = controller.start_run([{"robot": robot, "program": PROGRAM, "values": values}])
    except RunError as exc:
        raise FitInputError({"_": str(exc)}) from None
    if not await controller.wait_run(run, step.timeout):
        raise FitInputError({"timeout": f"{run.id}: {robot} still measuring after "
                                        f"{step.timeout:g} s (see Robot programs)"})
    item = run.items[0]
    if item.state != "Completed" and not item.program_state:
        raise FitInputError({"_": f"{robot} {PROGRAM}: {item.reason or item.state}"})
    if item.program_state not in ("", "FINISHED"):
        said = [line for line in item.console if line.startswith(f"{PROGRAM}:")]
        why = item.message or (said[-1] if said else "")
        raise FitInputError({"_": f"{robot} {PROGRAM} {item.program_state.lower()}"
                                  + (f": {why}" if why else "")})
    points = await _fetch(controller, compute, "Get Matrix", f"{step.matrix}; for={robot}",
                          field="_")
    if points.ndim != 2 or points.shape != (len(configs), 6):
        shape = "×".join(str(n) for n in points.shape)
        raise FitInputError({"_": f"{compute} {step.matrix} of {robot} is {shape}, "
                                  f"{len(configs)}×6 expected"})
    return {"points": points.tolist(), "joints": q0.tolist(), "configs": configs.tolist(),
            "run": run.to_json()}
