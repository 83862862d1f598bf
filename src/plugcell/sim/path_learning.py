"""A path run again and again on the twin, learning from each run (``path run --learn``).

Each run is :func:`~.path_run.run_path` — the twin's RSI controller, the link over UDP,
the tracker stream, the loop — with the learned offset of
:class:`~plugcell.compensation.tracking.repeat.RepeatedLearning` added to the loop's
target (``learned``); after the run the learning is judged and updated from **the
tracker's samples** of the run's motion (the run's ``measured`` trace: the good samples,
as the loop received them, in F0) against the commanded path — never from the twin's truth,
which only the printed accuracy uses.  Every run has the same robot and instrument and
fresh tracker noise (its own ``stream_seed``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from plugcell.compensation.tracking.learning import InverseSettings, LearningSettings
from plugcell.compensation.tracking.repeat import LEARNING, RepeatedLearning, RunRecord
from plugcell.compensation.tracking.smoothing import WeightingSettings
from plugcell.io.learned_paths import LAWS, LearnedContext, path_sha256
from plugcell.io.path_files import PathFile
from plugcell.io.robots import load_robot
from plugcell.io.units import MM_PER_M, robot_from_pose
from plugcell.kinematics import forward
from plugcell.sim.path_run import PathRun, PathRunOptions, plan_path, run_path

__all__ = ["LAWS", "LEARNING", "RepeatRun", "learned_context", "learning_settings", "repeat_path"]

#: Tracker noise seeds of successive runs: ``seed + SEED_STEP · (run − 1)``.
SEED_STEP = 1000


def learning_settings(options: PathRunOptions, gain: float | None = None,
                      cutoff_hz: float | None = None, law: str = "p",
                      reidentify: int | None = None, weighting: str | None = None,
                      kalman: WeightingSettings | None = None) -> LearningSettings:
    """:data:`LEARNING` at the link's cycle, bounded by the link's largest offset, with
    the law ``law``: ``p`` the P-type law (1) alone; ``inverse`` its first update with
    the identifying excitation, then the norm-optimal inverse (3) of the identified plant
    (:class:`InverseSettings`' defaults, docs/dynamic-correction.md "learning above the
    modes"): ``reidentify`` (None: the default, 1) its plant identified again after each
    run, ``weighting`` (None: the default, ``"kalman"``) each frequency learned by its
    Kalman gain — with ``kalman``'s settings (None: ``DEFAULT_WEIGHTING`` of
    :mod:`plugcell.compensation.tracking.learning`: gains per 1 s tile ``window_s``, the
    covariance matching ``detect`` 3 where the error fell) —,
    ``"none"`` all of the error."""
    if law not in LAWS:
        raise ValueError(f"the learning law must be one of {', '.join(LAWS)}, got {law!r}")
    if weighting not in (None, "kalman", "none"):
        raise ValueError(f"the weighting must be kalman or none, got {weighting!r}")
    if kalman is not None and weighting == "none":
        raise ValueError("the Kalman weighting's settings with the weighting none")
    inverse = InverseSettings() if reidentify is None else InverseSettings(reidentify=reidentify)
    return dataclasses.replace(
        LEARNING, inverse=inverse if law == "inverse" else None,
        weighting=None if weighting == "none" else kalman or LEARNING.weighting,
        cycle_s=0.004, max_offset_m=options.max_offset_mm / MM_PER_M,
        gain=LEARNING.gain if gain is None else gain,
        cutoff_hz=LEARNING.cutoff_hz if cutoff_hz is None else cutoff_hz)


def learned_context(path: PathFile, name: str, options: PathRunOptions, calibration: str,
                    residual_layer: bool) -> LearnedContext:
    """What a learned correction of ``path`` run with ``options`` depends on (planned on
    the robot's nominal model, as :func:`~.path_run.run_path` plans it).

    Parameters
    ----------
    path : PathFile
    name : str
        The path's file name (for messages).
    options : PathRunOptions
    calibration : str
        ``"nominal"`` or ``"sha256:<hex>"`` of the calibration file.
    residual_layer : bool
        The calibration's residual layer is used.

    Raises
    ------
    ValueError
        A path the planner refuses (its reason).
    """
    desc = load_robot(options.robot)
    _, trajectory = plan_path(desc, path)
    fk = forward(desc, None, np.asarray(desc.home, float), "nominal")
    tool = robot_from_pose(np.linalg.inv(fk.flange) @ fk.tcp)
    return LearnedContext(
        name, path_sha256(path), tuple(float(v) for v in np.asarray(path.speeds) * MM_PER_M),
        desc.name, tuple(round(float(v), 6) for v in tool), float(options.payload_kg),
        calibration, bool(residual_layer), "tracking" if options.tracking else "model",
        "6dof" if options.six_dof else "3dof", float(trajectory.duration))


@dataclass
class RepeatRun:
    """One run of :func:`repeat_path`: the run and how the learning judged it (None: the
    run ended early and was not learned from)."""

    run: PathRun
    record: RunRecord | None


def repeat_path(path: PathFile, options: PathRunOptions, repeated: RepeatedLearning,
                runs: int, *, first_seed_run: int = 1, calibration: object = None,
                on_run: Callable[[int, RepeatRun], None] | None = None,
                progress: Callable[[int, float], None] | None = None) -> list[RepeatRun]:
    """Run ``path`` up to ``runs`` times, learning after each (module docstring).

    Parameters
    ----------
    path : PathFile
    options : PathRunOptions
        Each run's; its ``stream_seed`` is replaced per run.
    repeated : RepeatedLearning
        The learning (its offset fed forward, updated from each run).
    runs : int
        ``N`` ≥ 1: the most runs; fewer when one ends early, converges or diverges.
    first_seed_run : int
        The number of the first run for its tracker seed (a continued learning goes on
        counting, so its noise is fresh).
    calibration : CalibrationResult, optional
        As :func:`~.path_run.run_path`'s.
    on_run : callable, optional
        ``on_run(k, RepeatRun)`` after run ``k`` (1-based).
    progress : callable, optional
        ``progress(k, fraction)`` during run ``k``.

    Returns
    -------
    list of RepeatRun
    """
    if runs < 1:
        raise ValueError(f"the runs of a learning must be ≥ 1, got {runs}")
    out: list[RepeatRun] = []
    for k in range(1, runs + 1):
        seed = options.seed + SEED_STEP * (first_seed_run + k - 2)
        o = dataclasses.replace(options, stream_seed=seed)
        step = None if progress is None else (lambda f, k=k: progress(k, f))
        run = run_path(path, o, step, calibration,  # type: ignore[arg-type]
                       learned=repeated.feedforward(o.settle_s))
        if abs(run.motion_s - repeated.learning.duration_s) > 1e-6:
            raise ValueError(f"the path's motion took {run.motion_s:.4f} s, the learning is "
                             f"for one of {repeated.learning.duration_s:.4f} s")
        record = None
        if not run.ended:
            m = run.traces["measured"]
            m = m[m[:, 0] <= run.motion_s]  # the motion's samples (LEARNING's docstring)
            record = repeated.learn(m[:, 0], m[:, 1:4], run.traces["t"],
                                    run.traces["commanded"], 0.0)
        out.append(RepeatRun(run, record))
        if on_run is not None:
            on_run(k, out[-1])
        if record is None or record.stop:
            break
    return out
