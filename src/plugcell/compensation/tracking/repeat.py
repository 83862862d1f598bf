"""Runs of a repeated path with iterative learning: when to learn, when to stop.

:class:`~.learning.IterativeLearning` is the law; this is what a cell integrator needs
around it when a path is run ``N`` times (``plugcell path run --learn N``):

* **what a run is judged by** — only the tracker's view: the measured error
  ``e_k(t) = p_meas(t) − p_cmd(t)`` on the learning's grid (:func:`~.learning.path_error`),
  over the motion's cycles that had a good sample; its rms and max
  (``r_k = sqrt(mean ‖e_k‖²)``, ``m_k = max ‖e_k‖``) and the share ``c_k`` of the
  motion's cycles measured.  The twin's truth never enters;
* **a run the tracker hardly saw is not learned from**: ``c_k < c_min`` (a beam broken
  over most of the path) leaves ``u`` as it was;
* **divergence guard**: ``r_k > (1 + g) · min_{j<k} r_j`` — the error grew beyond the
  best run so far — stops the runs and **rolls ``u`` back** to the offset the best run
  used (the one a later run can trust);
* **converged**: the run improved the best error by less than a share ``h``,
  ``r_k > (1 − h) · min_{j<k} r_j``, or the update changed ``u`` by less than
  ``Δu_min`` (``max |u_{k+1} − u_k|``): more runs would not pay; ``u`` is set to the
  offset the best run used (``argmin_j r_j``, measured), not the last update's (never
  run);
* **the identifying run** of the inverse law (it carried the known excitation,
  :class:`~.learning.IterativeLearning`) is learned from (the plant is identified from
  it) but not judged: its error holds the excitation, so it neither sets the best run
  nor ends the runs;
* **what was never measured**: the motion's cycles no learned run measured (a beam
  break at the same place in every run), as windows of the path's time — there ``u``
  is only what ``Q`` and ``W`` spread into them, not learned.

Pure math: numpy, SI units (m, s), no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from plugcell.compensation.tracking.learning import (
    IterativeLearning,
    LearnedOffset,
    LearningSettings,
    path_error,
)

Array = NDArray[np.float64]

__all__ = ["LEARNING", "RepeatedLearning", "RunRecord", "StopRule"]

#: The learning on the twin (benchmarks/dynamic_correction.py's, docs/dynamic-correction.md):
#: Q 6 Hz order 4 below the arm's first mode (9 Hz), L = 0.8 falling as 1/(1 + 0.5 k),
#: δ = 8 ms (the RSI twin's lead).  The window ends with its fade 0.15 s after the motion:
#: the correction source blends the whole offset out from the path's end
#: (:class:`~plugcell.devices.robot.rsi.tracking.TrackingSource`), so what the tracker
#: sees after it is that blend, not a repeatable error to learn.
LEARNING = LearningSettings(gain=0.8, cutoff_hz=6.0, order=4, gain_decay=0.5, post_s=0.15)


@dataclass(frozen=True)
class StopRule:
    """When the runs of a repeated path stop (module docstring).

    Attributes
    ----------
    converged_rel : float
        ``h`` in [0, 1): a run that lowers the best measured rms by less than this share
        ends the runs as converged.
    diverged_rel : float
        ``g`` > 0: a measured rms above ``(1 + g)`` times the best ends them as diverging.
    min_measured : float
        ``c_min`` in [0, 1]: the share of the motion's cycles a run must have measured to
        be learned from.
    min_change_m : float
        ``Δu_min`` ≥ 0 (m): an update that moves ``u`` by less ends the runs as converged.
    """

    converged_rel: float = 0.05
    diverged_rel: float = 0.25
    min_measured: float = 0.5
    min_change_m: float = 1e-6

    def __post_init__(self) -> None:
        checks = (("converged_rel", 0.0 <= self.converged_rel < 1.0, "in [0, 1)"),
                  ("diverged_rel", self.diverged_rel > 0.0, "> 0"),
                  ("min_measured", 0.0 <= self.min_measured <= 1.0, "in [0, 1]"),
                  ("min_change_m", self.min_change_m >= 0.0, "≥ 0"))
        for name, ok, want in checks:
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and ok):
                raise ValueError(f"StopRule.{name} must be a finite number {want}, "
                                 f"got {value!r}")


@dataclass(frozen=True)
class RunRecord:
    """One run of the repeated path as the tracker saw it.

    Attributes
    ----------
    run : int
        1 for the first run of this session.
    rms_m, max_m : float
        ``r_k``, ``m_k`` of the measured error over the motion's measured cycles (m; NaN
        when none was measured).
    measured : float
        ``c_k``, the share of the motion's cycles measured.
    change_m : float
        ``max |u_{k+1} − u_k|`` of the update this run gave (m; NaN: not learned from).
    verdict : str
        ``learned``, ``converged``, ``diverged`` or ``not learned``.
    reason : str
        Why the runs stop (or why this run was not learned from); ``""`` otherwise.
    law : str
        The law of the update this run gave (``"p"``, ``"inverse"``; ``""``: no update).
    """

    run: int
    rms_m: float
    max_m: float
    measured: float
    change_m: float
    verdict: str
    reason: str = ""
    law: str = ""

    @property
    def stop(self) -> bool:
        """The runs end here."""
        return self.verdict in ("converged", "diverged")


@dataclass
class RepeatedLearning:
    """The runs of one repeated path with its learning (module docstring).

    Parameters
    ----------
    learning : IterativeLearning
        The law and its state (a fresh one, or one continued from a file).
    rule : StopRule

    Attributes
    ----------
    records : list of RunRecord
        One per :meth:`learn`.

    API note: ``feedforward(start_s)`` before a run, ``learn(…)`` after it; stop when
    the returned record's ``stop`` is true.
    """

    learning: IterativeLearning
    rule: StopRule = field(default_factory=StopRule)
    records: list[RunRecord] = field(init=False, default_factory=list)

    def __post_init__(self) -> None:
        self._best: tuple[float, Array, int] | None = None  # (r, u it ran with, steps)
        self._seen = np.zeros(self.learning.grid.size, dtype=bool)

    @property
    def best(self) -> tuple[float, Array, int] | None:
        """The best judged run so far: its measured rms ``r`` (m), the offset ``u`` it ran
        with (G, 3) (m) and the learning's steps then; None before one."""
        return self._best

    def resume(self, best: tuple[float, Array, int] | None) -> None:
        """Go on from an earlier session's :attr:`best` (the stop rule then judges this
        session's runs against it: a learning that runs once a session, as a robot
        program's tracked move does)."""
        if best is None:
            self._best = None
            return
        rms, u, steps = best
        u = np.asarray(u, dtype=float)
        if u.shape != self.learning.u.shape or not (math.isfinite(rms) and rms >= 0):
            raise ValueError(f"RepeatedLearning.resume: a best run of rms ≥ 0 and an offset "
                             f"{self.learning.u.shape}, got {rms!r} and {u.shape}")
        self._best = (float(rms), u.copy(), int(steps))

    def feedforward(self, start_s: float) -> LearnedOffset:
        """The next run's learned offset, its motion starting at robot time ``start_s``."""
        return self.learning.feedforward(start_s)

    @property
    def motion(self) -> NDArray[np.bool_]:
        """The grid's cycles of the motion (path time 0 … duration)."""
        g = self.learning.grid
        return (g >= 0.0) & (g <= self.learning.duration_s)

    def learn(self, sample_t: ArrayLike, sample_p: ArrayLike, path_t: ArrayLike,
              path_p: ArrayLike, start_s: float) -> RunRecord:
        """Judge a run by its tracker samples and learn from it (module docstring).

        Parameters
        ----------
        sample_t : (m,) array_like
            The good tracker samples' acquisition times (s, robot clock).
        sample_p : (m, 3) array_like
            Their TCP positions (m, F0).
        path_t : (N,) array_like
            Times of the commanded path (s, robot clock, increasing).
        path_p : (N, 3) array_like
            The commanded path's positions (m, F0).
        start_s : float
            Robot time the run's motion started.

        Returns
        -------
        RunRecord
        """
        lr, rule = self.learning, self.rule
        if np.size(sample_t) == 0:  # nothing to judge the run by
            return self._record(len(self.records) + 1, math.nan, math.nan, 0.0, math.nan,
                                "not learned", "the tracker measured 0 % of the motion")
        e, measured = path_error(sample_t, sample_p, path_t, path_p, lr.grid + float(start_s),
                                 lr.settings.cycle_s)
        motion = self.motion
        seen = motion & measured
        mag = np.linalg.norm(e[seen], axis=1)
        rms = float(np.sqrt(np.mean(mag ** 2))) if mag.size else math.nan
        peak = float(mag.max()) if mag.size else math.nan
        share = float(seen.sum() / max(motion.sum(), 1))
        run = len(self.records) + 1
        if share < rule.min_measured:
            return self._record(run, rms, peak, share, math.nan, "not learned",
                                f"the tracker measured {100 * share:.0f} % of the motion "
                                f"(less than {100 * rule.min_measured:.0f} %)")
        if lr.identifying_next:  # the run carried the excitation
            before = lr.u.copy()
            lr.update(sample_t, sample_p, path_t, path_p, start_s)
            self._seen |= seen
            return self._record(run, rms, peak, share, float(np.abs(lr.u - before).max()),
                                "learned", "the identifying run (excitation): not judged",
                                str(lr.history[-1]["law"]))
        best = self._best
        if best is not None and rms > (1.0 + rule.diverged_rel) * best[0]:
            lr.u, lr.steps = best[1].copy(), best[2]
            return self._record(run, rms, peak, share, math.nan, "diverged",
                                f"the measured error grew to {rms * 1e3:.4f} mm rms, more than "
                                f"{100 * rule.diverged_rel:g} % above the best run's "
                                f"{best[0] * 1e3:.4f} mm: the learned offset is rolled back "
                                "to the one that run used")
        if best is None or rms < best[0]:
            self._best = (rms, lr.u.copy(), lr.steps)
        before = lr.u.copy()
        lr.update(sample_t, sample_p, path_t, path_p, start_s)
        self._seen |= seen
        change = float(np.abs(lr.u - before).max())
        law = str(lr.history[-1]["law"])
        if best is not None and rms > (1.0 - rule.converged_rel) * best[0]:
            return self._converged(run, rms, peak, share, change,
                                   f"the measured error {rms * 1e3:.4f} mm rms is less than "
                                   f"{100 * rule.converged_rel:g} % below the best run's "
                                   f"{best[0] * 1e3:.4f} mm", law)
        if change < rule.min_change_m:
            return self._converged(run, rms, peak, share, change,
                                   f"the learned offset changed by {change * 1e3:.4f} mm "
                                   f"(less than {rule.min_change_m * 1e3:g} mm)", law)
        return self._record(run, rms, peak, share, change, "learned", "", law)

    def _converged(self, run: int, rms: float, peak: float, share: float, change: float,
                   reason: str, law: str) -> RunRecord:
        """End the runs as converged, ``u`` back to the offset the best run used."""
        assert self._best is not None
        self.learning.u, self.learning.steps = self._best[1].copy(), self._best[2]
        return self._record(run, rms, peak, share, change, "converged",
                            reason + "; the offset kept is the one the best run "
                            f"({self._best[0] * 1e3:.4f} mm rms) used", law)

    def _record(self, *args: object) -> RunRecord:
        rec = RunRecord(*args)  # type: ignore[arg-type]
        self.records.append(rec)
        return rec

    def never_measured(self) -> list[tuple[float, float]]:
        """Windows of the path's time (s, from the motion's start) whose cycles no learned
        run measured (each cycle ``t_i`` standing for ``[t_i − T/2, t_i + T/2)``); empty
        before any run was learned from."""
        if not any(r.verdict in ("learned", "converged") for r in self.records):
            return []
        g, T = self.learning.grid, self.learning.settings.cycle_s
        hole = self.motion & ~self._seen
        edges = np.flatnonzero(np.diff(np.concatenate([[0], hole.astype(int), [0]])))
        return [(float(g[a] - T / 2), float(g[b - 1] + T / 2))
                for a, b in zip(edges[::2], edges[1::2], strict=True)]
