"""The learned correction of a repeated path (``plugcell path run --learned-out FILE``).

A JSON document (strict: no NaN) that holds the learning's state — the offset ``u(t)``
the next run adds to its target, on the path's time grid — and **what it was learned
for**, so that a later run refuses it, before moving the robot, when anything it depends
on differs::

    {"format": "plugcell-learned-path", "format_version": 3,
     "context": {"path": "line.csv", "path_sha256": "…", "speeds_mm_s": [100.0],
                 "robot": "smart_h4", "tool_mm_deg": [x, y, z, a, b, c],
                 "payload_kg": 36.0, "calibration": "nominal" | "sha256:…",
                 "residual_layer": false, "loop": "tracking" | "model",
                 "reflector": "6dof" | "3dof", "duration_s": 1.144},
     "law": "p" | "inverse",                            # the learning law
     "inverse": {"settings": …, "plant": …, …},         # the inverse law's (version 2;
                                                        # 3: "weighting", "state")
     "settings": {"gain": 0.8, "lead_s": 0.008, …},   # LearningSettings, SI
     "steps": 4,                                        # updates so far (the gain's k)
     "runs": [{"run": 1, "measured_rms_mm": …, "measured_max_mm": …,
               "measured_share": …, "change_max_mm": …, "verdict": "learned",
               "law": "p"}, …],
     "offset": {"t0_s": -0.3, "cycle_s": 0.004, "u_mm": [[x, y, z], …]},
     "best": {"measured_rms_mm": …, "steps": 2, "t0_s": …, "cycle_s": …,
              "u_mm": […]}}                             # version 2, optional

* ``path_sha256`` — SHA-256 of the path's geometry as read (the poses in µm and µrad,
  the tracking flags, whether it is oriented): the same path in another file, with
  other comments or column order, is the same path; ``speeds_mm_s`` — each segment's
  speed, compared on its own so that a mismatch names the segment;
* ``tool_mm_deg`` — the TCP in the flange frame (mm, degrees, the robot's convention);
* ``calibration`` — ``nominal`` or the SHA-256 of the PARAMS.json the loop's model came
  from, and whether its residual layer was used;
* ``loop``, ``reflector`` — the loop the offset was learned on top of (the learned
  offset compensates what *that* loop left);
* ``law`` — ``p`` (the P-type law) or ``inverse`` (the norm-optimal inverse of an
  identified plant, ``LearningSettings.inverse``; a file without the key is ``p``);
* ``inverse`` (version 2, only with the inverse law) — the law's settings, its updates
  so far, ``β``'s scale and the **identified plant** (:mod:`plugcell.io.learned_plant`),
  so that the learning goes on by the inverse law (:meth:`LearnedFile.continued`);
  version 3 adds the weighting's settings and state and the re-identification's runs
  (:mod:`plugcell.io.learned_state`): a file continued goes on exactly as the learning
  saved would have — also one saved after its first update, before the identifying run
  (``state.identifying``: the run before it).  A version-2 file of the inverse law is
  read with no weighting (its law learned all of the error) and goes on without
  re-identifying.  A version-1 file (or a version-2 one saved before the plant was
  identified) keeps no plant: its offset can be fed forward and continued by the P-type
  law, not by the inverse law;
* ``best`` (version 2, optional) — the stop rule's best run so far: its measured rms and
  the offset it ran with (:attr:`~plugcell.compensation.tracking.repeat.RepeatedLearning.best`),
  so that a learning run once a session (a robot program's tracked move) judges its next
  run against it and rolls back to it;
* ``u_mm`` — millimetres in the cell's frame F0, one row per robot cycle from
  ``t0_s`` (s from the motion's start); its length is the learning's grid for
  ``duration_s`` and the settings (version 3: at full precision; versions 1 and 2
  rounded to 1 nm).

Every fault is a :class:`LearnedFileError` naming the file and the cause; SI inside,
millimetres only in the document.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from plugcell.compensation.tracking.learning import IterativeLearning, LearningSettings
from plugcell.compensation.tracking.repeat import RunRecord
from plugcell.io.json_fields import (
    DocumentError,
    at,
    finite,
    flag,
    integer,
    number,
    numbers,
    strict,
    string,
    typename,
)
from plugcell.io.learned_plant import inverse_document, read_inverse, read_plant
from plugcell.io.learned_state import read_state, read_weighting
from plugcell.io.path_files import PathFile
from plugcell.io.text_files import read_text
from plugcell.io.units import M_PER_MM, MM_PER_M

Array = NDArray[np.float64]

__all__ = ["FORMAT", "FORMAT_VERSION", "LearnedContext", "LearnedFile", "LearnedFileError",
           "load_learned", "path_sha256", "save_learned"]

FORMAT = "plugcell-learned-path"
FORMAT_VERSION = 3
#: The versions this plugcell reads (1: without the inverse law's state; 2: without the
#: weighting and the re-identification's runs).
READ_VERSIONS = (1, 2, 3)
#: The learning laws a file may record.
LAWS = ("p", "inverse")
#: Tolerances of the context's comparison: speeds (relative), tool (mm, deg), payload
#: (kg), duration (s).
SPEED_REL, TOOL_TOL, PAYLOAD_TOL = 1e-9, 1e-3, 1e-6


class LearnedFileError(ValueError):
    """A learned-correction file that cannot be read or used; the message says why."""


def path_sha256(path: PathFile) -> str:
    """SHA-256 (hex) of a path's geometry: poses rounded to 1 µm / 1 µrad, the tracking
    flags and whether it is oriented (not its speeds, not the file's text).

    Parameters
    ----------
    path : PathFile
        The path as read (:mod:`plugcell.io.path_files`).

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    h = hashlib.sha256()
    h.update(np.round(np.asarray(path.poses, float) * 1e6).astype(np.int64).tobytes())
    h.update(np.asarray(path.tracking, bool).tobytes())
    h.update(b"oriented" if path.oriented else b"position")
    return h.hexdigest()


@dataclass(frozen=True)
class LearnedContext:
    """What a learned correction was learned for (module docstring).

    Attributes
    ----------
    path, path_sha256 : str
        The path file's name and the SHA-256 of its geometry (not of its text).
    speeds_mm_s : tuple of float
        Each segment's speed (mm/s).
    robot : str
        The robot (its name or description file).
    tool_mm_deg : tuple of float
        The TCP ``(x, y, z, a, b, c)`` (mm, degrees).
    payload_kg : float
        The payload (kg).
    calibration : str
        ``nominal`` or the SHA-256 of the PARAMS.json.
    residual_layer : bool
        Whether the calibration's learned residual layer was used.
    loop, reflector : str
        The tracking loop's kind and the tracker's reflector.
    duration_s : float
        The motion's duration (s).
    """

    path: str
    path_sha256: str
    speeds_mm_s: tuple[float, ...]
    robot: str
    tool_mm_deg: tuple[float, ...]
    payload_kg: float
    calibration: str
    residual_layer: bool
    loop: str
    reflector: str
    duration_s: float

    def mismatch(self, now: LearnedContext) -> str | None:
        """Why a correction learned for ``self`` does not fit a run in ``now`` (None: it
        fits); the first difference, precisely."""
        if self.path_sha256 != now.path_sha256:
            return (f"it was learned on the path {self.path!r} (sha256 "
                    f"{self.path_sha256[:12]}…), this run's path {now.path!r} is another "
                    f"(sha256 {now.path_sha256[:12]}…)")
        if len(self.speeds_mm_s) != len(now.speeds_mm_s):
            return (f"it was learned for {len(self.speeds_mm_s)} segments, the path has "
                    f"{len(now.speeds_mm_s)}")
        for i, (a, b) in enumerate(zip(self.speeds_mm_s, now.speeds_mm_s, strict=True)):
            if abs(a - b) > SPEED_REL * max(abs(a), abs(b)):
                return f"segment {i + 1} was learned at {a:g} mm/s, this run goes {b:g} mm/s"
        if self.robot != now.robot:
            return f"it was learned on the robot {self.robot!r}, this run is on {now.robot!r}"
        if np.max(np.abs(np.subtract(self.tool_mm_deg, now.tool_mm_deg))) > TOOL_TOL:
            return (f"it was learned with the tool {_six(self.tool_mm_deg)}, this run's is "
                    f"{_six(now.tool_mm_deg)} (mm, deg)")
        if abs(self.payload_kg - now.payload_kg) > PAYLOAD_TOL:
            return (f"it was learned with a payload of {self.payload_kg:g} kg, this run "
                    f"carries {now.payload_kg:g} kg")
        if (self.calibration, self.residual_layer) != (now.calibration, now.residual_layer):
            return (f"it was learned with the calibration {_cal(self)}, this run uses "
                    f"{_cal(now)}")
        for name, what in (("loop", "the loop"), ("reflector", "the reflector")):
            if getattr(self, name) != getattr(now, name):
                return (f"it was learned with {what} {getattr(self, name)!r}, this run's is "
                        f"{getattr(now, name)!r}")
        if abs(self.duration_s - now.duration_s) > 1e-6:
            return (f"it was learned on a motion of {self.duration_s:.4f} s, this run's "
                    f"takes {now.duration_s:.4f} s")
        return None


def _six(x: tuple[float, ...]) -> str:
    return "(" + ", ".join(f"{v:.3f}" for v in x) + ")"


def _cal(c: LearnedContext) -> str:
    if c.calibration == "nominal":
        return "nominal (no PARAMS.json)"
    return f"{c.calibration[:19]}… {'with' if c.residual_layer else 'without'} residual layer"


@dataclass
class LearnedFile:
    """A learned correction: its context, the learning's state, its runs so far and the
    law it was learned with.

    Parameters
    ----------
    context : LearnedContext
        What it was learned for.
    learning : IterativeLearning
        The learning's settings and state (``u``, the steps taken).
    runs : list of dict
        Each run's measured figures, as written.
    law : {"p", "inverse"}, optional
        None: the learning's own — ``inverse`` when its settings have ``inverse``, else
        ``p``.
    best : (float, (G, 3) array, int), optional
        The stop rule's best run: its measured rms (m), the offset it ran with (m), the
        learning's steps then (``RepeatedLearning.best``).
    """

    context: LearnedContext
    learning: IterativeLearning
    runs: list[dict[str, Any]]
    law: str | None = None
    best: tuple[float, Array, int] | None = None

    def __post_init__(self) -> None:
        if self.law is None:
            self.law = "p" if self.learning.settings.inverse is None else "inverse"
        if self.law not in LAWS:
            raise ValueError(f"law: expected one of {', '.join(LAWS)}, got {self.law!r}")

    def document(self) -> dict[str, Any]:
        """The JSON document (module docstring)."""
        lr = self.learning
        settings = dataclasses.asdict(lr.settings)
        del settings["inverse"], settings["weighting"]  # in "inverse", with the law's state
        inverse = inverse_document(lr)
        return {"format": FORMAT, "format_version": FORMAT_VERSION,
                "context": dataclasses.asdict(self.context), "law": self.law,
                **({} if inverse is None else {"inverse": inverse}),
                "settings": settings, "steps": int(lr.steps),
                "runs": self.runs,
                "offset": _offset_document(lr, lr.u),
                **({} if self.best is None else {"best": {
                    "measured_rms_mm": self.best[0] * MM_PER_M, "steps": int(self.best[2]),
                    **_offset_document(lr, self.best[1])}})}


    def continued(self, law: str | None = None) -> IterativeLearning:
        """The learning to go on with by ``law`` (None: the file's own).

        Parameters
        ----------
        law : {"p", "inverse"} or None
            ``p`` continues an inverse-law file by the P-type law (its offset and steps
            kept); ``inverse`` needs the file's identified plant.

        Returns
        -------
        IterativeLearning

        Raises
        ------
        ValueError
            The law cannot continue this file (why).
        """
        lr, want = self.learning, self.law if law is None else law
        if want not in LAWS:
            raise ValueError(f"law: expected one of {', '.join(LAWS)}, got {want!r}")
        if want == "p":
            if lr.settings.inverse is None:
                return lr
            out = IterativeLearning(lr.duration_s,
                                    dataclasses.replace(lr.settings, inverse=None))
            out.u, out.steps = lr.u.copy(), lr.steps
            return out
        if self.law == "p":
            raise ValueError("it was learned with the P-type law: the inverse law starts "
                             "with an identifying run of its own (start anew)")
        if lr.settings.inverse is None or (lr.plant is None and not lr.identifying_next):
            raise ValueError("it was learned with the inverse law but holds no identified "
                             "plant and no identifying run ahead (format version 1, or saved "
                             "by a plugcell that did not keep the run before the identifying "
                             "one): continue it by the P-type law or start anew")
        return lr


def _offset_document(lr: IterativeLearning, u: Array) -> dict[str, Any]:
    return {"t0_s": float(lr.grid[0]), "cycle_s": lr.settings.cycle_s,
            "u_mm": (np.asarray(u, float) * MM_PER_M).tolist()}


def run_entries(records: list[RunRecord], before: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The document's ``runs``: the earlier sessions' entries, then ``records`` numbered on."""
    out = list(before)
    for r in records:
        out.append({"run": len(out) + 1, "measured_rms_mm": r.rms_m * MM_PER_M,
                    "measured_max_mm": r.max_m * MM_PER_M, "measured_share": r.measured,
                    "change_max_mm": r.change_m * MM_PER_M, "verdict": r.verdict,
                    "law": r.law})
    return out


def save_learned(path: str | Path, learned: LearnedFile) -> None:
    """Write ``learned`` as JSON to ``path`` (whole or not at all: a temporary file then
    a rename).

    Parameters
    ----------
    path : str or Path
        The file.
    learned : LearnedFile
        What to write.
    """
    p = Path(path)
    text = json.dumps(strict(learned.document()), indent=1, allow_nan=False) + "\n"
    tmp = p.with_name(p.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(p)


def load_learned(path: str | Path) -> LearnedFile:
    """Read a learned correction (module docstring).

    Parameters
    ----------
    path : str or Path
        The file.

    Returns
    -------
    LearnedFile

    Raises
    ------
    LearnedFileError
        ``<file>: <cause>``: unreadable, not JSON, another format or version, a missing or
        wrong key (named), settings the law refuses, an offset whose length is not the
        learning's grid or beyond its bound.
    """
    name = str(path)
    text = read_text(path, LearnedFileError)
    try:
        doc = json.loads(text)
    except ValueError as exc:
        raise LearnedFileError(f"{name}: not a JSON document ({exc})") from None
    try:
        return _from_document(doc)
    except (DocumentError, ValueError) as exc:
        raise LearnedFileError(f"{name}: {exc}") from None


def _context(doc: dict[str, Any]) -> LearnedContext:
    c = "context"
    residual = flag(doc, c, "residual_layer")
    tool = numbers(doc, c, "tool_mm_deg")
    if len(tool) != 6:
        raise DocumentError(f"context.tool_mm_deg: expected 6 numbers, got {len(tool)}")
    speeds = numbers(doc, c, "speeds_mm_s")
    if not speeds or min(speeds) <= 0:
        raise DocumentError("context.speeds_mm_s: expected one speed > 0 per segment")
    ctx = LearnedContext(
        string(doc, c, "path"), string(doc, c, "path_sha256"), speeds,
        string(doc, c, "robot"), tool, number(doc, c, "payload_kg"),
        string(doc, c, "calibration"), residual, string(doc, c, "loop"),
        string(doc, c, "reflector"), number(doc, c, "duration_s"))
    if ctx.duration_s <= 0:
        raise DocumentError(f"context.duration_s must be > 0 s, got {ctx.duration_s!r}")
    return ctx


def _from_document(doc: Any) -> LearnedFile:
    if not isinstance(doc, dict):
        raise DocumentError(f"expected a JSON object, got {typename(doc)}")
    fmt = doc.get("format")
    if fmt != FORMAT:
        raise DocumentError(f"format {fmt!r}: not a learned correction (expected {FORMAT!r}, "
                            "the file of plugcell path run --learned-out)")
    version = integer(doc, "format_version")
    if version not in READ_VERSIONS:
        raise DocumentError(f"format_version {version}: this plugcell reads versions "
                            f"{', '.join(map(str, READ_VERSIONS))}")
    ctx = _context(doc)
    law = doc.get("law", "p")
    if law not in LAWS:
        raise DocumentError(f"law: expected one of {', '.join(LAWS)}, got {law!r}")
    values = {}
    for f in fields(LearningSettings):
        if f.name in ("inverse", "weighting"):  # the inverse law's: in "inverse"
            continue
        values[f.name] = integer(doc, "settings", f.name) if f.name == "order" else \
            number(doc, "settings", f.name)
    learning = _learning(doc, ctx, law, LearningSettings(**_checked_settings(values)),
                         version)
    steps = integer(doc, "steps")
    if steps < 0:
        raise DocumentError(f"steps must be ≥ 0, got {steps}")
    learning.steps = steps
    learning.u = _offset(doc, learning)
    runs = at(doc, "runs")
    if not isinstance(runs, list) or not all(isinstance(r, dict) for r in runs):
        raise DocumentError(f"runs: expected a list of objects, got {typename(runs)}")
    best = None
    if "best" in doc and version != 1:
        rms, best_steps = number(doc, "best", "measured_rms_mm"), integer(doc, "best", "steps")
        if rms < 0 or best_steps < 0:
            raise DocumentError(f"best: measured_rms_mm {rms!r} and steps {best_steps!r} must "
                                "be ≥ 0")
        best = (rms * M_PER_MM, _offset(doc, learning, "best"), best_steps)
    return LearnedFile(ctx, learning, runs, law, best)


def _checked_settings(values: dict[str, Any]) -> dict[str, Any]:
    """``values`` once LearningSettings accepts them (a DocumentError naming the cause)."""
    try:
        LearningSettings(**values)
    except ValueError as exc:
        raise DocumentError(f"settings: {exc}") from None
    return values


def _learning(doc: dict[str, Any], ctx: LearnedContext, law: str,
              settings: LearningSettings, version: int) -> IterativeLearning:
    """The learning of ``settings`` and, with ``inverse`` (version 2), the inverse law's
    settings, plant and state (version 3: its weighting and run-to-run state)."""
    plant = None
    if "inverse" in doc and version != 1:
        if law != "inverse":
            raise DocumentError(f"inverse: the state of the inverse law in a file learned with "
                                f"the law {law!r}")
        inv, steps, scale, raw = read_inverse(doc)
        weighting = None if version == 2 else \
            read_weighting(at(doc, "inverse", "weighting"), "inverse.weighting")
        try:
            settings = dataclasses.replace(settings, inverse=inv, weighting=weighting)
        except ValueError as exc:
            raise DocumentError(f"inverse.settings: {exc}") from None
        plant = None if raw is None else read_plant(raw, settings.cycle_s)
    try:
        learning = IterativeLearning(ctx.duration_s, settings, plant)
    except ValueError as exc:
        raise DocumentError(f"settings: {exc}") from None
    state = None if version < 3 or settings.inverse is None else \
        read_state(at(doc, "inverse", "state"), learning)
    if plant is not None or (state is not None and state.identifying is not None):
        try:
            learning.resume_inverse(steps, scale, state)
        except ValueError as exc:
            raise DocumentError(f"inverse: {exc}") from None
    return learning


def _offset(doc: dict[str, Any], learning: IterativeLearning, key: str = "offset") -> Array:
    """``doc[key]``'s offset on the learning's grid (m), checked."""
    s = learning.settings
    t0, cycle = number(doc, key, "t0_s"), number(doc, key, "cycle_s")
    if abs(t0 - learning.grid[0]) > 1e-9 or abs(cycle - s.cycle_s) > 1e-12:
        raise DocumentError(f"{key}: t0_s {t0!r} and cycle_s {cycle!r} are not the "
                            f"settings' grid ({learning.grid[0]:g} s, {s.cycle_s:g} s)")
    rows = at(doc, key, "u_mm")
    n = learning.grid.size
    if not isinstance(rows, list) or len(rows) != n:
        got = f"{len(rows)} rows" if isinstance(rows, list) else typename(rows)
        raise DocumentError(f"{key}.u_mm: expected {n} rows (the grid of a "
                            f"{learning.duration_s:g} s motion), got {got}")
    u = np.empty((n, 3))
    for i, row in enumerate(rows):
        if not (isinstance(row, list) and len(row) == 3):
            raise DocumentError(f"{key}.u_mm[{i}]: expected 3 numbers (x, y, z mm), got "
                                f"{typename(row)}")
        u[i] = [finite(v, f"{key}.u_mm[{i}][{j}]") for j, v in enumerate(row)]
    bound = s.max_offset_m * MM_PER_M
    over = (np.abs(u) > bound * (1 + 1e-9)).any(axis=1)
    if over.any():
        bad = int(np.argmax(over))
        raise DocumentError(f"{key}.u_mm[{bad}]: {rows[bad]!r} is beyond the settings' "
                            f"bound ±{bound:g} mm")
    return u * M_PER_MM
