"""A robot moved to a new set-up: a short campaign with the earlier calibration as a prior
(issue 36 part 2; IPA UR10 robot-accuracy data set, series A as the earlier set-up).

Earlier set-up: series A, all 11 911 poses — thesis model 3 (serial + joint compliance from
the published link masses) with its learned residual layer (``plugcell calibrate
--residual-model learned``).  New set-ups: series B, D (the goal) and C (never worse).

Protocol, for each of B, C, D: grouped 5-fold over the series' 0.4 m workspace cells
(target position in the robot base frame).  In each fold a campaign of n poses is chosen
among the training cells' poses — as ``plugcell plan --from`` chooses among poses already
measured (I-optimal for model 3, :class:`~plugcell.calibration.planning.PosePlanner`), or
by default a seeded random draw (``--selection planned``: I-optimal, written to
short-campaign-ur10-planned.md) — and three methods identify on it:

(i)   **alone**: model 3 calibrated on the campaign alone (``plugcell calibrate``);
(ii)  **A moved**: A's physical model with BASE + PROBE re-identified on the campaign
      (and, for the record, A's hybrid model moved the same way);
(iii) **prior**: ``plugcell calibrate --prior A.json``
      (:class:`~plugcell.calibration.prior.PriorCalibrator`: MAP toward A with A's layer's
      correction as an offset; a seeded random 10-fold CV over the campaign's poses chooses
      among τ — 0 = BASE + PROBE only included —, the same MAP without A's layer
      (``τ/physical``: the CV decides whether A's layer helps) and the baselines (ii) and (i)
      themselves, another candidate than these only when it beats the better of them by
      more than k standard errors of the paired CV difference, never one whose CV error
      exceeds theirs (:func:`~plugcell.calibration.prior.pick_significant`); then the
      campaign's own stage when its CV adopts it, :mod:`plugcell.calibration.campaign_stage`);
      and the same choice without the stage.

With ``--draws K`` (random selection) K campaigns are drawn per fold and size (seeded; draw 0
is the single draw of earlier runs): each figure is the mean over the draws of the mean
held-out error, the table adds their sample sd.

Each is scored on the held-out cells (never a campaign pose nor a neighbour in its cell):
mean position error, mm.  Nothing is tuned on the held-out cells.

    .venv/bin/python benchmarks/short_campaign_ur10.py [--data DIR] [--sizes 25,50,...]
        [--series B,C,D] [--selection random|planned] [--draws K] [--quick]
        [--prior-cv kfold|cells] [--prior-se K] [--prior-stage-se K]
        [--prior-stage-weights W,…]
        [--out docs/results/short-campaign-ur10.md]

``--prior-cv cells``: the choice's CV grouped over the campaign's 0.4 m cells instead of the
default seeded random 10-fold of its poses (``PriorCalibrator(cv_split=…)``); ``--prior-se
K``: the k of the choice's k-standard-error rule (default 1); ``--prior-stage-se K``: the
k of the same rule on the campaign stage's grouped CV (default 0, the plain comparison);
``--prior-stage-weights W,…``: the grid of the stage's CV-chosen weight (default ``1``:
the stage whole or not at all; ``0,0.25,0.5,0.75,1`` the grid measured) —
all measured in docs/results/short-campaign-bounds.md; write such a run elsewhere with
``--out``.

Single-threaded (threadpoolctl).  Without the data folder it says so and exits 0.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calibration_ur10 import ur10_toml
from plugcell.calibration import CalibrationData, CalibrationError, Calibrator
from plugcell.calibration.campaign_stage import (
    STAGE_SE_K,
    STAGE_WEIGHT_GRID,
    STAGE_WEIGHTS,
    check_weights,
)
from plugcell.calibration.identify import refit_base
from plugcell.calibration.planning import (
    PosePlanner,
    filter_candidates,
    planning_keys,
)
from plugcell.calibration.prior import CV_SPLITS, SE_RULE_K, Prior, PriorCalibrator
from plugcell.calibration.residual_model import (
    DEFAULT_GRID,
    ResidualLearner,
    calibration_fingerprint,
    workspace_cells,
)
from plugcell.io.robots import load_robot
from residual_ur10 import _without_temperature, find_data, load_sets

ROOT = Path(__file__).resolve().parents[1]
SIZES = (25, 50, 100, 200, 400)
MODEL = "serial+gravity"
METHODS = ("alone", "moved", "moved_hybrid", "prior_map", "prior")
LABELS = {"alone": "(i) model 3 on the campaign alone",
          "moved": "(ii) A's model, BASE + PROBE re-identified",
          "moved_hybrid": "A's hybrid model, BASE + PROBE re-identified",
          "prior_map": "--prior A --prior-stage none (the CV's choice, no campaign stage)",
          "prior": "(iii) --prior A (the CV's choice + campaign stage)"}


def _errors(d: CalibrationData, P: np.ndarray) -> np.ndarray:
    return np.linalg.norm(d.positions - P[:, :3, 3], axis=1)


def choose(model: Any, d: CalibrationData, pool: np.ndarray, n: int, selection: str,
           rng: np.random.Generator) -> np.ndarray:
    """``n`` of the poses ``pool`` of ``d``: as ``plan --from`` (I-optimal for model 3 at
    A's geometry re-registered on the pool) or a seeded random draw."""
    if n >= len(pool):
        return pool
    if selection == "random":
        return rng.choice(pool, size=n, replace=False)
    cands = filter_candidates(model, d.q[pool])
    keys = planning_keys(model, np.unique(cands.payload_kg))
    plan = PosePlanner(model, keys, criterion="I").plan(cands, n)
    return pool[cands.source[plan.index]]


def outer_folds(model: Any, d: CalibrationData, folds: int = 5
                ) -> tuple[Any, np.ndarray, list[tuple[np.ndarray, np.ndarray, Any]]]:
    """The benchmark's outer folds of a series ``d``: grouped ``folds``-fold over its 0.4 m
    workspace cells (the TCP positions of A's ``model`` with BASE and PROBE re-identified
    on all of ``d``, in its base frame).  Returns that re-identified model, the cells
    ``(len(d),)`` and per fold ``(train, test, planner)``: the pose indices and the model a
    campaign is drawn or planned with (A's, BASE and PROBE refitted on the training cells,
    BASE = I)."""
    from sklearn.model_selection import GroupKFold

    moved_all = refit_base(model, d, probe=True)
    targets = (np.linalg.inv(moved_all.base()) @ moved_all.predict(d.q))[:, :3, 3]
    cells = workspace_cells(targets, 0.4)
    split = GroupKFold(n_splits=folds).split(targets, groups=cells)
    return moved_all, cells, [
        (tr, te, refit_base(model, d.subset(tr), probe=True).with_references(base=np.eye(4)))
        for tr, te in split]


def ur10_and_sets(data: Path) -> tuple[Any, dict[str, CalibrationData]]:
    """The UR10 with its link masses (``calibration_ur10.ur10_toml``, loaded from a
    temporary file of its own: runs side by side) and the IPA series A–D of ``data``
    without their temperature columns."""
    with tempfile.TemporaryDirectory() as work:
        (Path(work) / "ur10_masses.toml").write_text(ur10_toml(masses=True), encoding="utf-8")
        desc = load_robot(Path(work) / "ur10_masses.toml")
    return desc, {k: _without_temperature(v) for k, v in load_sets(data).items()}


#: ``--quick``: set-up A is every QUICK_A_STRIDE-th pose of series A (2 978 of 11 911),
#: its layer one hyper-parameter candidate of 100 trees — the scripts' paths, not their
#: figures, in a quarter of the time
QUICK_A_STRIDE = 4


def set_up_a(A: CalibrationData, quick: bool) -> tuple[CalibrationData, ResidualLearner]:
    """Set-up A's poses and the learner of its layer: all of A and two hyper-parameter
    candidates of 200 trees, or with ``quick`` (the tests' runs) every
    :data:`QUICK_A_STRIDE`-th pose and one candidate of 100 trees."""
    if quick:
        return (A.subset(np.arange(0, len(A), QUICK_A_STRIDE)),
                ResidualLearner(grid=DEFAULT_GRID[1:2], trees=100))
    return A, ResidualLearner(grid=(DEFAULT_GRID[1], DEFAULT_GRID[2]), trees=200)


def earlier(desc: Any, A: CalibrationData, learner: ResidualLearner,
            cache: Path | None) -> Any:
    """Set-up A: model 3 and its learned layer fitted on ``A`` — or, with ``cache``,
    read from the pickle an earlier run of this script (or of the scripts that share
    its set-up A) wrote there with the same model, poses and learner (runs side by side,
    one per series, then fit A once); a cache of other poses or another learner is
    fitted again and overwritten."""
    import hashlib
    import pickle

    key = (MODEL, hashlib.sha256(np.ascontiguousarray(A.q).tobytes()).hexdigest(),
           repr(sorted((k, v) for k, v in vars(learner).items() if k != "progress")))
    if cache is not None and cache.is_file():
        with cache.open("rb") as f:
            kept = pickle.load(f)  # these scripts' own file
        if isinstance(kept, dict) and kept.get("key") == key:
            return kept["result"]
        print(f"{cache}: set-up A of another model or learner: fitted again", flush=True)
    resA = Calibrator(desc, MODEL).fit(A)
    resA = resA.with_residual_model(learner.fit(resA.model, A, robot=desc.name))
    if cache is not None:
        with cache.open("wb") as f:
            pickle.dump({"key": key, "result": resA}, f)
    return resA


def run(desc: Any, sets: dict[str, CalibrationData], series: str, sizes: tuple[int, ...],
        selection: str, learner: ResidualLearner, folds: int = 5,
        cache: Path | None = None, draws: int = 1, cv_split: str = "kfold",
        se_k: float = SE_RULE_K, stage_se_k: float = STAGE_SE_K,
        stage_weights: tuple[float, ...] = STAGE_WEIGHTS) -> dict[str, Any]:
    t0 = time.perf_counter()
    A = sets["A"]
    resA = earlier(desc, A, learner, cache)
    layer = resA.residual_model
    prior = Prior.from_result(resA)
    print(f"A: model 3 {resA.calibration.position.norm.mean * 1e3:.3f} mm on its "
          f"{len(A)} poses; layer CV {layer.cv.physical_mm:.3f} -> {layer.cv.hybrid_mm:.3f} mm "
          f"({time.perf_counter() - t0:.0f} s)", flush=True)
    out: dict[str, Any] = {"A": {"poses": len(A), "physical_mm": resA.calibration.position.norm
                                 .mean * 1e3, "layer_cv_mm": [layer.cv.physical_mm,
                                                              layer.cv.hybrid_mm]},
                           "series": {}}
    for s_no, key in enumerate(series):
        d = sets[key]
        moved_all, groups, split = outer_folds(resA.model, d, folds)
        draws_k = 1 if selection == "planned" else draws  # a plan is one draw
        err = {m: {(n, k): np.full(len(d), np.nan) for n in sizes for k in range(draws_k)}
               for m in METHODS}
        taus: dict[int, list[str]] = {n: [] for n in sizes}
        stages: dict[int, list[bool]] = {n: [] for n in sizes}
        weights: dict[int, list[float]] = {n: [] for n in sizes}
        for f_no, (tr, te, rng_model) in enumerate(split):
            test = d.subset(te)
            for n, k in ((n, k) for n in sizes for k in range(draws_k)):
                t1 = time.perf_counter()
                # draw 0: the seed of the single-draw runs before --draws
                rng = np.random.default_rng([s_no, f_no, n] + ([k] if k else []))
                pick = choose(rng_model, d, tr, n, selection, rng)
                camp = d.subset(pick)
                e = {m: err[m][n, k] for m in METHODS}
                try:
                    alone = Calibrator(desc, MODEL).fit(camp)
                    e["alone"][te] = _errors(test, alone.predict(test.q))
                except CalibrationError as exc:
                    print(f"    alone, n = {n}: {exc}", flush=True)
                moved = refit_base(resA.model, camp, probe=True)
                e["moved"][te] = _errors(test, moved.predict(test.q))
                # A's hybrid moved: BASE + PROBE re-identified on the campaign with the
                # layer's correction taken out, the layer's correction on the test poses
                e["moved_hybrid"][te] = _hybrid_moved(resA, camp, test)
                res = PriorCalibrator(prior, cv_split=cv_split, se_k=se_k,
                                      stage_se_k=stage_se_k,
                                      stage_weights=stage_weights).fit(camp)
                pri = res.settings["prior"]
                taus[n].append(pri["choice"] if pri["choice"] != "map" else f"{pri['scale']:g}")
                stages[n].append(bool(pri["stage"]["adopted"]))
                weights[n].append(float(pri["stage"]["weight"]))
                P, _ = res.predict_hybrid(test.q)
                e["prior"][te] = _errors(test, P)
                # the same choice without the campaign stage (--prior-stage none): no second
                # fit — A's layer on the MAP, no layer on a baseline the CV chose
                P, _ = (res.with_residual_model(replace(
                    prior.layer, fingerprint=calibration_fingerprint(res.model)))
                    if pri["choice"] == "map" else replace(res, residual_model=None)
                ).predict_hybrid(test.q)
                e["prior_map"][te] = _errors(test, P)
                print(f"  {key} fold {f_no + 1}, n = {n}, draw {k}: " + ", ".join(
                    f"{m} {np.nanmean(e[m][te]) * 1e3:.3f}" for m in METHODS)
                    + f" mm (CV chose {taus[n][-1]}, stage {stages[n][-1]}, weight "
                    f"{weights[n][-1]:g}; "
                    f"{time.perf_counter() - t1:.0f} s)",
                    flush=True)
        # per draw: the mean over all held-out poses (mm); the figure: their mean
        per_draw = {m: {str(n): [float(np.nanmean(err[m][n, k]) * 1e3)
                                 for k in range(draws_k)] for n in sizes} for m in METHODS}
        row = {m: {str(n): float(np.mean(v)) for n, v in per_draw[m].items()}
               for m in METHODS}
        row["draws"] = per_draw
        row["tau"] = {str(n): taus[n] for n in sizes}
        row["stage"] = {str(n): stages[n] for n in sizes}
        row["stage_weight"] = {str(n): weights[n] for n in sizes}
        row["cells"] = int(groups.max()) + 1
        row["poses"] = len(d)
        row["physical_all_mm"] = float(_errors(d, moved_all.predict(d.q)).mean() * 1e3)
        out["series"][key] = row
    out["elapsed_s"] = time.perf_counter() - t0
    return out


def _hybrid_moved(resA: Any, camp: CalibrationData, test: CalibrationData) -> np.ndarray:
    """A's hybrid model with BASE + PROBE re-identified on the campaign (with the layer's
    correction taken out, as :func:`hybrid_residuals`): its position errors on ``test``."""
    from plugcell.calibration.residual_model import _remove_correction, hybrid_poses

    layer = resA.residual_model
    pred_c = layer.predict(camp.q)
    phys = refit_base(resA.model, camp, probe=True)
    hyb = refit_base(resA.model, _remove_correction(camp, phys.base()[:3, :3],
                                                     pred_c.correction), probe=True)
    pred = layer.predict(test.q)
    return _errors(test, hybrid_poses(hyb.predict(test.q), hyb.base()[:3, :3],
                                      pred.correction))


def _spread(row: dict[str, Any], m: str, n: int) -> str:
    """" ± sd" of method ``m``'s figure over the campaign draws (sample sd), "" for one."""
    v = row.get("draws", {}).get(m, {}).get(str(n), [])
    return f" ± {np.std(v, ddof=1):.3f}" if len(v) > 1 else ""


def table(d: dict[str, Any]) -> str:
    sizes = d["sizes"]
    lines = ["| series | method | " + " | ".join(f"n = {n}" for n in sizes) + " |",
             "|---|---|" + "---|" * len(sizes)]
    for key, row in d["result"]["series"].items():
        for m in METHODS:
            cells = []
            for n in sizes:
                v = row[m][str(n)]
                if m in ("prior", "prior_map"):
                    best = min(row["alone"][str(n)], row["moved"][str(n)])
                    cells.append(f"**{v:.3f}**{_spread(row, m, n)} "
                                 f"({(v / best - 1) * 100:+.0f}%)")
                else:
                    cells.append(f"{v:.3f}{_spread(row, m, n)}")
            lines.append(f"| {key} | {LABELS[m]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def goal(d: dict[str, Any]) -> list[str]:
    out = []
    for key, row in d["result"]["series"].items():
        for n in d["sizes"]:
            if n > 100:
                continue
            p, a, m = (row[x][str(n)] for x in ("prior", "alone", "moved"))
            out.append(f"{key}, n = {n}: prior {p:.3f} mm, {(1 - p / a) * 100:.0f}% lower than "
                       f"(i) {a:.3f}, {(1 - p / m) * 100:.0f}% lower than (ii) {m:.3f}")
    return out


def verdict(d: dict[str, Any]) -> str:
    """The goal, judged from the table: met where (iii) is ≥ 20 % below both (i) and (ii)
    at some n ≤ 100 on B and D, and never above the better of them on C."""
    rows = d["result"]["series"]
    small = [n for n in d["sizes"] if n <= 100]
    parts = []
    for key in ("B", "D"):
        if key in rows:
            r = rows[key]
            ok = [n for n in small if r["prior"][str(n)]
                  <= 0.8 * min(r["alone"][str(n)], r["moved"][str(n)])]
            parts.append(f"{key}: " + (f"met at n = {', '.join(map(str, ok))}" if ok
                                       else "not met at any n ≤ 100"))
    if "C" in rows:
        r = rows["C"]
        worse = [n for n in d["sizes"] if r["prior"][str(n)]
                 > min(r["alone"][str(n)], r["moved"][str(n)])]
        parts.append("C: " + ("never worse than (i) or (ii)" if not worse else
                              "worse than the better of (i) and (ii) at n = "
                              + ", ".join(map(str, worse))))
    return "; ".join(parts) + "."


def plot(d: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series = list(d["result"]["series"])
    fig, axes = plt.subplots(1, len(series), figsize=(4.2 * len(series), 4.2), squeeze=False)
    for ax, key in zip(axes[0], series, strict=True):
        row = d["result"]["series"][key]
        for m, style in (("alone", "s--"), ("moved", "o:"), ("moved_hybrid", "x:"),
                         ("prior_map", "v-."), ("prior", "D-")):
            sd = [np.std(v, ddof=1) if len(v := row.get("draws", {}).get(m, {})
                                             .get(str(n), [])) > 1 else 0.0
                  for n in d["sizes"]]
            ax.errorbar(d["sizes"], [row[m][str(n)] for n in d["sizes"]], yerr=sd, fmt=style,
                        capsize=2, label=LABELS[m])
        ax.set_xscale("log")
        ax.set_xticks(d["sizes"], [str(n) for n in d["sizes"]])
        ax.minorticks_off()
        ax.set_title(f"series {key} (held-out cells)")
        ax.set_xlabel("new poses n")
        ax.set_ylabel("mean position error (mm)")
        ax.grid(alpha=0.3)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=7)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _commands(argv: list[str]) -> str:
    """The command line(s) of a run (without ``--out``), merged runs joined."""
    runs: list[list[str]] = [[]]
    for a in argv:
        if a == "+":
            runs.append([])
        else:
            runs[-1].append(a)
    cmds = []
    for r in runs:
        keep = [a for i, a in enumerate(r) if a != "--out" and (i == 0 or r[i - 1] != "--out")]
        cmds.append("`" + " ".join(["benchmarks/short_campaign_ur10.py", *keep]) + "`")
    if len(cmds) == 1:
        return cmds[0]
    return (", ".join(cmds) + " side by side, merged with `--from-json` "
            "(each run's JSON in turn)")


def _per_fold(r: dict[str, Any], what: str) -> dict[str, Any]:
    return {k: v.get(what) for k, v in r["series"].items()}


def _cpu() -> str:
    """This machine's processor and core count, as /proc/cpuinfo names them."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
        name = next(x.split(":", 1)[1].strip() for x in lines if x.startswith("model name"))
    except (OSError, StopIteration):
        name = "an unknown processor"
    return f"{os.cpu_count()} cores of {name}"


def _draws_note(d: dict[str, Any]) -> str:
    """" Campaigns drawn per fold: …" when the runs merged drew different numbers per size
    (figures: the mean over the draws, ± their sd), "" when every size had one draw."""
    counts = {n: max((len(row.get("draws", {}).get("prior", {}).get(str(n), [None]))
                      for row in d["result"]["series"].values()), default=1)
              for n in d["sizes"]}
    if all(c == 1 for c in counts.values()):
        return ""
    return (" Campaigns drawn per fold and size: " + ", ".join(
        f"{c} at n = {n}" for n, c in counts.items()) + " (seeded; a figure is the mean over "
        "the draws of the mean held-out error, ± their sample sd).")


def _cv_text(d: dict[str, Any]) -> str:
    """The choice's CV split as the page names it (runs before ``prior_cv`` was recorded:
    the grouped split, then the default)."""
    return ("a seeded random 10-fold CV" if d.get("prior_cv", "cells") == "kfold"
            else "the grouped CV over the campaign's 0.4 m cells")


def _rule_text(d: dict[str, Any]) -> str:
    """The choice's k-standard-error rule as the page names it ("" for runs before it)."""
    k = d.get("prior_se")
    if k is None:
        return ""
    return (f"a candidate other than the baselines only when it beats the better of them by "
            f"more than {k:g} standard error{'s' if k != 1 else ''} of the paired CV "
            "difference (clustered by fold), and among those and the baselines ")


def _stage_rule_text(d: dict[str, Any]) -> str:
    """The campaign stage's k-standard-error rule as the page names it ("" for k = 0 and
    for runs before it)."""
    k = d.get("prior_stage_se") or 0.0
    w = d.get("prior_stage_weights") or [1.0]
    return ((f" by more than {k:g} standard error{'s' if k != 1 else ''} of the paired "
             "difference (clustered by fold, `--prior-stage-se`)" if k else "")
            + ("" if w == [1.0] else ", its correction weighted by w, the value of "
               f"{{{', '.join(f'{x:g}' for x in w)}}} (`--prior-stage-weights`) whose grouped "
               "CV error is least (the weighted stage judged against the fit)"))


def write_page(d: dict[str, Any], path: Path, image: str | None) -> None:
    r = d["result"]
    text = f"""# A robot moved to a new set-up: a short campaign with a prior (UR10, IPA data)

Generated by {_commands(d['argv'])} (do not edit by hand);
{d['machine']}, {d.get('cpu') or _cpu()}, single-threaded, {r['elapsed_s']:.0f} s{
    ' (summed over the runs)' if '+' in d['argv'] else ''}.{
    chr(10) + chr(10) + d['note'] if d.get('note') else ''}

Earlier set-up: series A ({r['A']['poses']} poses), model 3 (serial + joint compliance from the
published link masses): {r['A']['physical_mm']:.3f} mm on its own poses; its learned layer
(grouped CV on A: {r['A']['layer_cv_mm'][0]:.3f} → {r['A']['layer_cv_mm'][1]:.3f} mm).
New set-ups: series {', '.join(r['series'])}.

## Protocol

Grouped 5-fold over each series' 0.4 m workspace cells. In each fold a campaign of n poses is
chosen among the training cells' poses ({d['selection_text'] if not _draws_note(d)
                                          else 'seeded random draws'}); the three methods identify
on it and the held-out cells are predicted (never a campaign pose, never a pose in a
campaign's cell). Mean position error over all held-out poses, mm.{_draws_note(d)}

* (i) model 3 calibrated on the campaign alone (`plugcell calibrate --model 3`);
* (ii) A's model with BASE + PROBE re-identified on the campaign (and A's hybrid model,
  moved the same way, for the record);
* (iii) `plugcell calibrate --prior A.json` (its default): BASE and PROBE free, A's other
  parameters pulled toward A by λ_k = σ̂_A / (τ σ_k) (MAP, docs/calibration.md), A's learned
  layer's correction taken out of the campaign before the fit; {_cv_text(d)} over the
  campaign's own poses (never the held-out cells) chooses among τ ∈ {{0 (BASE + PROBE
  only, with A's layer), 1, 3, 10, …, 1000}}, the same MAP without A's layer for
  τ ∈ {{1, 3, 10, 30, 100}} (*τ/physical*: whether A's layer helps in the new set-up is the
  CV's choice too) and the two baselines themselves, *moved*
  ((ii): A's physical model, BASE + PROBE re-identified, no layer) and *alone* ((i)):
  {_rule_text(d)}the first within 1 % of the best CV score that is no worse than either
  baseline's — so the choice's CV error is never above (i)'s or (ii)'s by construction; then the
  campaign's own stage (trees on sin/cos q of what the fit leaves, on top of A's
  arm-shape stage when A's layer is kept) adopted only when its grouped CV over the
  campaign's cells beats the fit without it{_stage_rule_text(d)}. The row
  *--prior-stage none* is the same choice without the campaign stage. In brackets: the
  change against the better of (i) and (ii).

{table(d)}

{'![error against the number of new poses](' + image + ')' if image else ''}

The CV's choice per fold (τ; 0: BASE + PROBE only with A's layer; τ/physical: the MAP
without A's layer; moved: (ii); alone: (i)){
    ', fold by fold, the draws of a fold in turn' if any(len(v) > 1 for row in r['series'].values()
                               for v in row.get('draws', {}).get('prior', {}).values())
    else ''}: {json.dumps(_per_fold(r, 'tau'))}

Campaign stage adopted per fold: {json.dumps(_per_fold(r, 'stage'))}{
    chr(10) + chr(10) + 'Campaign stage weight per fold (0: not adopted): '
    + json.dumps(_per_fold(r, 'stage_weight')) if any('stage_weight' in row
                                                      for row in r['series'].values())
    else ''}

## The goal (≥ 20 % lower than (i) and (ii) with ≤ 100 new poses on B and D; never worse on C)

""" + "\n".join(f"* {g}" for g in goal(d)) + f"\n\n**Verdict**: {verdict(d)}\n"
    path.write_text(text, encoding="utf-8")


def merge(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """One record of several runs of one selection (e.g. one per series or per group of
    sizes, run side by side): series in order, each size's figures from the run that
    computed it, the elapsed times summed, the command lines joined."""
    d = json.loads(json.dumps(runs[0]))
    for r in runs[1:]:
        if r["selection"] != d["selection"]:
            raise SystemExit("--from-json: runs of different selections")
        for key, row in r["result"]["series"].items():
            into = d["result"]["series"].setdefault(key, {})
            for k, v in row.items():
                if k == "draws":
                    for m, per_n in v.items():
                        into.setdefault(k, {}).setdefault(m, {}).update(per_n)
                elif isinstance(v, dict):
                    into.setdefault(k, {}).update(v)
                else:
                    into[k] = v
        d["sizes"] = sorted(set(d["sizes"]) | set(r["sizes"]))
        d["result"]["elapsed_s"] += r["result"]["elapsed_s"]
        d["argv"] = d["argv"] + ["+"] + r["argv"]
        if r.get("cpu") and r.get("cpu") != d.get("cpu"):
            d["cpu"] = " / ".join(x for x in (d.get("cpu"), r["cpu"]) if x)
        for k in ("prior_cv", "prior_se", "prior_stage_se",
                  "prior_stage_weights"):  # the last run's choice
            if k in r:
                d[k] = r[k]
    return d


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--sizes", default=",".join(str(n) for n in SIZES))
    ap.add_argument("--series", default="BCD")
    ap.add_argument("--selection", choices=("planned", "random"), default="random",
                    help="how the campaign is chosen among the training cells' poses "
                         "(default random; planned writes short-campaign-ur10-planned.md)")
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--cache", type=Path, metavar="FILE",
                    help="pickle of set-up A's fit: read if present, else written (for runs "
                         "side by side; delete it when the code or the data change)")
    ap.add_argument("--draws", type=int, default=1,
                    help="random campaigns drawn per fold and size (seeded); the figures are "
                         "the mean over the draws, the table adds their sd (random only)")
    ap.add_argument("--prior-cv", choices=CV_SPLITS, default="kfold",
                    help="the CV splits of --prior's choice (PriorCalibrator cv_split; "
                         "default kfold: a seeded random 10-fold over the campaign's poses)")
    ap.add_argument("--prior-se", type=float, default=SE_RULE_K, metavar="K",
                    help="the choice's k-standard-error rule (PriorCalibrator se_k; default "
                         f"{SE_RULE_K:g})")
    ap.add_argument("--prior-stage-weights", default=None, metavar="W[,W…]",
                    help="the campaign stage's weight grid (PriorCalibrator stage_weights; "
                         f"default {','.join(f'{w:g}' for w in STAGE_WEIGHTS)}: the stage "
                         "whole or not at all; the grid measured: "
                         f"{','.join(f'{w:g}' for w in STAGE_WEIGHT_GRID)})")
    ap.add_argument("--prior-stage-se", type=float, default=STAGE_SE_K, metavar="K",
                    help="the campaign stage's k-standard-error rule (PriorCalibrator "
                         f"stage_se_k; default {STAGE_SE_K:g})")
    ap.add_argument("--quick", action="store_true",
                    help=f"set-up A: every {QUICK_A_STRIDE}th pose of series A, its layer one "
                         "hyper-parameter candidate of 100 trees (the paths, not the figures)")
    ap.add_argument("--out", type=Path, default=None,
                    help="page to write (default docs/results/short-campaign-ur10.md, "
                         "-planned.md with --selection planned)")
    ap.add_argument("--from-json", metavar="FILE[,FILE…]",
                    help="re-render the page from the JSON previous runs wrote (no "
                         "computation; the plot is redrawn); several files (e.g. one run "
                         "per --series, run side by side) are merged in order")
    ap.add_argument("--note", default=None,
                    help="with --from-json: a paragraph printed under the page's header (e.g. "
                         "which merged runs ran which version of the code)")
    args = ap.parse_args()
    if args.out is None:
        args.out = ROOT / "docs" / "results" / ("short-campaign-ur10.md" if args.selection
                                                == "random" else
                                                "short-campaign-ur10-planned.md")
    if args.from_json is not None:
        d = merge([json.loads(Path(f).read_text(encoding="utf-8"))
                   for f in args.from_json.split(",")])
        if args.note:
            d["note"] = args.note
        args.out.with_suffix(".json").write_text(json.dumps(d, indent=1), encoding="utf-8")
        plot(d, args.out.with_suffix(".png"))
        write_page(d, args.out, args.out.with_suffix(".png").name)
        print(table(d))
        print(verdict(d))
        return 0
    data = args.data or find_data()
    if data is None or not data.is_dir():
        print("IPA robot-accuracy data not found (../shared/data/ipa-robot-accuracy): skipped")
        return 0
    import scipy.linalg  # noqa: F401
    import sklearn.ensemble  # noqa: F401
    from threadpoolctl import threadpool_limits

    sizes = tuple(int(x) for x in args.sizes.split(","))
    weights = (STAGE_WEIGHTS if args.prior_stage_weights is None
               else check_weights([float(x) for x in args.prior_stage_weights.split(",")]))
    series = [s for s in args.series.replace(",", "") if s in "BCD"]
    desc, sets = ur10_and_sets(data)
    sets["A"], learner = set_up_a(sets["A"], args.quick)
    with threadpool_limits(1):
        result = run(desc, sets, "".join(series), sizes, args.selection,
                     learner, folds=args.folds, cache=args.cache,
                     draws=args.draws, cv_split=args.prior_cv, se_k=args.prior_se,
                     stage_se_k=args.prior_stage_se, stage_weights=weights)
    d = {"argv": sys.argv[1:], "sizes": list(sizes), "selection": args.selection,
         "selection_text": "I-optimal for model 3, as `plugcell plan --from` chooses among "
                           "poses already measured" if args.selection == "planned"
                           else "a seeded random draw" if args.draws == 1 else
                           f"{args.draws} seeded random draws: each figure the mean over the "
                           "draws of the mean held-out error, ± their sd",
         "machine": f"{platform.machine()}, Python {platform.python_version()}",
         "cpu": _cpu(),  # where it ran (a page re-rendered elsewhere says this one)
         "prior_cv": args.prior_cv, "prior_se": args.prior_se,
         "prior_stage_se": args.prior_stage_se, "prior_stage_weights": list(weights),
         "result": result}
    print(table(d))
    print("\n".join(goal(d)))
    print(verdict(d))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    image = args.out.with_suffix(".png")
    plot(d, image)
    write_page(d, args.out, image.name)
    args.out.with_suffix(".json").write_text(json.dumps(d, indent=1), encoding="utf-8")
    print(f"wrote {args.out}, {image.name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
