"""Iterative learning of a robot program's repeated tracked moves (``--param
learned_dir=DIR`` of a streamed robot service; docs/tracked-paths.md, "Learning a
program's repeated tracked moves").

A program that runs the same ``MOVE LINEAR TO p WITH TRACKING`` on every part repeats
the move's error: what ``plugcell path run --learn`` learns across the runs of a path
file (:mod:`plugcell.compensation.tracking.repeat`), the robot service learns across the
runs of a program, one run of each tracked move per program run:

* **the key** — each tracked move of a program run is numbered in the order it runs:
  the ``n``-th tracked move of program ``P`` is ``P.n``, its learned correction the file
  ``DIR/P.n.json`` (:mod:`plugcell.io.learned_paths`, the format of ``path run
  --learned-out``: the same file, the same checks);
* **before the robot moves** the file, when there is one, is read and checked against
  the move (:meth:`~plugcell.io.learned_paths.LearnedContext.mismatch`): the move's
  geometry (its start and end poses, to 0.1 mm and 0.1 mrad: start a learned move from a
  taught position), its mean speed, the robot, its tool, the payload, the calibration
  (``nominal`` or the SHA-256 of its PARAMS.json), the loop and the reflector, the
  motion's duration — a file learned for anything else fails the move with the first
  difference, and the program stops at that line; a file that cannot be read fails it
  with the cause.  A new file starts the service's law (``--param learning_law``):
  ``p``, the P-type law (:data:`~plugcell.compensation.tracking.repeat.LEARNING` at the
  link's cycle; the default), or ``inverse``, the model-inverting law with its defaults
  (:class:`~plugcell.compensation.tracking.learning.InverseSettings`: the first program
  run's update adds the identifying excitation, the second run carries it — its error
  is larger than the model's, the price of the identification — and from the third run
  on the plant is inverted; the file keeps the run before the identifying one, so the
  identification happens in the next program run); a file
  continues by its own law (an inverse-law file with its plant and — format version 3 —
  the weighting's state and the re-identification's runs, so that it goes on as an
  uninterrupted learning would; :meth:`~plugcell.io.learned_paths.LearnedFile.continued`),
  and after the move the file is written with that state grown by the run;
* **during the move** its learned offset is the loop's feed-forward (``TrackingLoop``'s
  ``learned``), on the path's time from the motion's start;
* **after the move** the tracker's good samples of the motion judge the run and update
  the offset (:meth:`RepeatedLearning.learn`), with the stop rule's best run carried in
  the file from program run to program run: *converged* (less than 5 % better than the
  best run, or an update under 1 µm) and *diverged* (25 % above the best) end the
  learning with the offset the best run used; from then on the move feeds that offset
  forward without learning (delete the file to learn anew).  A move that failed (the
  tracker lost) is not learned from.  The verdict is a line of the program's console
  (PROGRAM_STATUS, the process's result).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.compensation.tracking.learning import (
    InverseSettings,
    IterativeLearning,
    LearnedOffset,
)
from plugcell.compensation.tracking.repeat import LEARNING, RepeatedLearning, StopRule
from plugcell.io.learned_paths import (
    LAWS,
    LearnedContext,
    LearnedFile,
    LearnedFileError,
    load_learned,
    path_sha256,
    run_entries,
    save_learned,
)
from plugcell.io.path_files import PathFile
from plugcell.io.units import MM_PER_M, robot_from_pose
from plugcell.pdl.interfaces import MotionError

Array = NDArray[np.float64]

__all__ = ["MoveLearning", "MoveSession"]

log = logging.getLogger("plugcell.devices.robot.move_learning")

#: The grid the move's start and end are compared on (m, rad): a start that differs by
#: less is the same move (the robot stands where the previous move's correction left it).
GEOMETRY_STEP = 1e-4
#: The verdicts that end a learning (the file's offset is then fed forward only).
ENDED = ("converged", "diverged")


def move_path(start: Array, end: Array, duration_s: float) -> PathFile:
    """The move as a one-segment path (its geometry on :data:`GEOMETRY_STEP`, its mean
    speed), for :func:`~plugcell.io.learned_paths.path_sha256` and the context.

    Parameters
    ----------
    start, end : (4, 4) array
        The TCP's planned poses at the move's start and end (m, robot base frame).
    duration_s : float
        The motion's duration (s).

    Returns
    -------
    PathFile
    """
    poses = np.stack([np.asarray(start, float), np.asarray(end, float)])
    snapped = np.round(poses / GEOMETRY_STEP) * GEOMETRY_STEP
    length = float(np.linalg.norm(poses[1, :3, 3] - poses[0, :3, 3]))
    return PathFile(snapped, np.array([length / duration_s]), np.array([True]),
                    np.array([0, 0]), True)


@dataclass
class MoveSession:
    """One tracked move's learning (module docstring): built by :meth:`MoveLearning.begin`.

    Attributes
    ----------
    file : Path
        The learned correction.
    context : LearnedContext
        This move's.
    repeated : RepeatedLearning
        The learning and its stop rule (resumed from the file's best run).
    before : list of dict
        The runs the file recorded.
    learning : bool
        False: the learning ended (converged or diverged): the offset is fed forward only.
    """

    file: Path
    context: LearnedContext
    repeated: RepeatedLearning
    before: list[dict[str, Any]] = field(default_factory=list)
    learning: bool = True

    @property
    def run(self) -> int:
        """This run's number in the file."""
        return len(self.before) + 1

    def feedforward(self, start_s: float) -> LearnedOffset:
        """The learned offset of the move whose motion starts at robot time ``start_s``."""
        return self.repeated.feedforward(start_s)

    def finish(self, sample_t: ArrayLike, sample_p: ArrayLike, path_t: ArrayLike,
               path_p: ArrayLike, start_s: float) -> str:
        """Judge the run by its tracker samples, learn, save; the console's line.

        Parameters
        ----------
        sample_t : (m,) array_like
            The good samples' robot times (s).
        sample_p : (m, 3) array_like
            Their TCP positions (m, F0).
        path_t : (N,) array_like
            The planned path's robot times (s).
        path_p : (N, 3) array_like
            Its TCP positions (m, F0).
        start_s : float
            The robot time the motion started.

        Returns
        -------
        str
            ``LEARNED <file>: run k, …`` — the run's measured rms, the verdict and why.
        """
        name = self.file.name
        if not self.learning:
            last = self.before[-1] if self.before else {}
            return (f"LEARNED {name}: fed forward, not learning (the learning ended at run "
                    f"{last.get('run', '?')}: {last.get('verdict', '?')})")
        t = np.asarray(sample_t, dtype=float).reshape(-1)
        p = np.asarray(sample_p, dtype=float).reshape(-1, 3)
        motion = t <= start_s + self.repeated.learning.duration_s
        rec = self.repeated.learn(t[motion], p[motion], path_t, path_p, start_s)
        best = self.repeated.best
        save_learned(self.file, LearnedFile(self.context, self.repeated.learning,
                                            run_entries([rec], self.before), best=best))
        rms = "–" if not np.isfinite(rec.rms_m) else f"{rec.rms_m * MM_PER_M:.4f} mm"
        line = (f"LEARNED {name}: run {self.run}, tracker rms {rms}"
                + ("" if best is None else f" (best {best[0] * MM_PER_M:.4f} mm)")
                + f", {rec.verdict}" + (f": {rec.reason}" if rec.reason else ""))
        log.info(line)
        return line


class MoveLearning:
    """The learned corrections of a robot service's tracked moves (module docstring).

    Parameters
    ----------
    folder : str or Path
        Where the learned corrections are (created when missing).
    robot : str
        The robot's name (the context's).
    calibration : str
        ``nominal`` or ``sha256:<hex>`` of the calibration file the loop's model is from.
    residual_layer : bool
        The calibration's learned residual layer is part of the loop's model.
    rule : StopRule, optional
        When the learning ends (``path run``'s defaults).
    law : {"p", "inverse"}
        The law of a new file (module docstring); a file goes on by its own.

    Raises
    ------
    ValueError
        An unknown law.
    """

    def __init__(self, folder: str | Path, robot: str, calibration: str = "nominal",
                 residual_layer: bool = False, rule: StopRule | None = None,
                 law: str = "p") -> None:
        if law not in LAWS:
            raise ValueError(f"learning_law must be one of {', '.join(LAWS)}, got {law!r}")
        self.law = law
        self.folder = Path(folder)
        self.robot, self.calibration, self.residual_layer = robot, calibration, residual_layer
        self.rule = rule or StopRule()
        self._run: tuple[str, int] | None = None
        self._count = 0

    def key(self, program: str, run: int) -> str:
        """``P.n``: the ``n``-th tracked move of the run ``run`` of program ``P``."""
        if self._run != (program, run):
            self._run, self._count = (program, run), 0
        self._count += 1
        return f"{Path(program).stem}.{self._count}"

    def context(self, key: str, start: Array, end: Array, duration_s: float, tool: Array,
                payload_kg: float) -> LearnedContext:
        """The move's context (module docstring); poses (4, 4) m, ``tool`` the TCP in the
        flange frame (4, 4)."""
        path = move_path(start, end, duration_s)
        return LearnedContext(
            key, path_sha256(path), (float(path.speeds[0]) * MM_PER_M,), self.robot,
            tuple(round(float(v), 6) for v in robot_from_pose(tool)), float(payload_kg),
            self.calibration, bool(self.residual_layer), "tracking", "6dof",
            float(duration_s))

    def begin(self, key: str, start: Array, end: Array, duration_s: float, tool: Array,
              payload_kg: float, cycle_s: float) -> MoveSession:
        """The learning of the move ``key`` (before it moves: MotionError with the reason
        when its file cannot be used).

        Parameters
        ----------
        key : str
            :meth:`key`'s.
        start, end : (4, 4) array
            The planned TCP poses at the motion's start and end (m).
        duration_s : float
            The motion's duration (s).
        tool : (4, 4) array
            The TCP in the flange frame (m).
        payload_kg : float
        cycle_s : float
            The link's cycle (s): a new learning's grid.

        Returns
        -------
        MoveSession

        Raises
        ------
        MotionError
            ``<file>: <cause>``: unreadable or corrupt, learned for another move (the first
            difference), or a law that cannot go on.
        """
        ctx = self.context(key, start, end, duration_s, tool, payload_kg)
        file = self.folder / f"{key}.json"
        if not file.exists():
            self.folder.mkdir(parents=True, exist_ok=True)
            settings = dataclasses.replace(
                LEARNING, cycle_s=cycle_s,
                inverse=InverseSettings() if self.law == "inverse" else None)
            return MoveSession(file, ctx, RepeatedLearning(
                IterativeLearning(duration_s, settings), self.rule))
        try:
            saved = load_learned(file)
        except LearnedFileError as exc:
            raise MotionError(f"learned correction {exc}") from None
        why = saved.context.mismatch(ctx)
        if why is not None:
            raise MotionError(f"learned correction {file}: cannot be used for this move: "
                              f"{why}")
        try:
            learning = saved.continued()
        except ValueError as exc:
            raise MotionError(f"learned correction {file}: cannot be continued: {exc}"
                              ) from None
        repeated = RepeatedLearning(learning, self.rule)
        repeated.resume(saved.best)
        ended = bool(saved.runs) and saved.runs[-1].get("verdict") in ENDED
        return MoveSession(file, ctx, repeated, list(saved.runs), not ended)


def program_of(controller: Any) -> Callable[[], tuple[str, int] | None]:
    """``() → (program, run)`` of the current run of ``controller.runner`` (a
    :class:`~.runner.ProgramRunner`, looked up at the call; None: no program runs)."""

    def current() -> tuple[str, int] | None:
        cur = controller.runner.current
        return None if cur is None else (cur.program, cur.run)

    return current
