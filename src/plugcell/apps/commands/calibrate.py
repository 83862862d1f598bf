"""``plugcell calibrate``: identify a robot's error model from a measurement file.

    plugcell calibrate --robot NAME|FILE --model 1..5|NAME --data CAL.csv
                       [--validate VAL.csv] [--rot rpy|zyz|xyz] [--payload-kg M]
                       [--out PARAMS.json] [--json] [--report REPORT.html]
                       [--residuals RES.json] [--prior EARLIER.json [--prior-scale TAU]
                       [--prior-stage learned|none] [--prior-cv kfold|cells]
                       [--prior-se K] [--prior-stage-se K]
                       [--prior-stage-weights W[,W…]]]

A file of joint readings and tracker measurements is all it needs: BASE and
PROBE are estimated from the data unless given (``--base``/``--probe``, e.g. from
the appendix-D procedures).  ``--residuals`` writes the residual of every pose
(measured position, error before/after in mm; calibration and validation poses) for
the 3-D view of the controller UI.  Progress goes to stderr; ``--json`` prints the
PARAMS.json object to stdout.  Bad files, unknown robots, too few poses for the
model and a diverging fit end with a clear message and exit code 2.

``--prior EARLIER.json``: the robot was calibrated before (another set-up) and moved; a
short campaign here identifies BASE and PROBE freely and the earlier calibration's other
parameters with regularisation toward it (MAP, :mod:`plugcell.calibration.prior`; τ = 0
among the CV's candidates: BASE and PROBE only), the earlier learned layer kept as an
offset, and the campaign's own learned stage on top when its grouped CV adopts it
(:mod:`plugcell.calibration.campaign_stage`; ``--prior-stage none``: never).  The
choice among the candidates is cross-validated over a seeded random 10-fold of the
campaign's poses (``--prior-cv cells``: grouped over its workspace cells instead) and
adopts a candidate other than the two baselines (the earlier model moved, the campaign
alone) only when it beats the better baseline by more than ``--prior-se K`` standard
errors of the paired CV difference (default 1; docs/calibration.md).  The campaign
stage is adopted when its grouped CV beats the fit without it by more than
``--prior-stage-se K`` standard errors of their paired difference (the same rule; default
0, the plain comparison: with at most 5 grouped folds the SE is noisy and k = 1 refused
stages that helped, docs/results/short-campaign-bounds.md), its correction weighted by
the value ``w̃`` of ``--prior-stage-weights`` whose grouped CV error
``m(w) = mean_i ‖e_i − w ê_i‖`` is least (``ê``: the stage's out-of-fold predictions; the
rule judges the weighted stage; default ``1``: the stage whole or not at all;
``0,0.25,0.5,0.75,1`` the grid measured on the IPA UR10, better at ≤ 100 poses and worse
at 200–400 there; ``0``: no stage).
``--residual-prior`` is a different thing (a new learned layer on top of the earlier
layer's arm-shape stage, ≥ 200 poses): kept as it is.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # numpy is imported where it is used: `--help` does not load it
    import numpy as np

from plugcell.apps.cli import CommandError
from plugcell.apps.commands.files import write_text
from plugcell.apps.commands.robotargs import add_robot_args


def configure(p: argparse.ArgumentParser) -> None:
    """Add the ``calibrate`` options to its parser (declared in :mod:`plugcell.apps.cli`)."""
    p.description = (
        "Identify the error parameters of one of the thesis's five models "
        "(1 serial, 2 loop, 3 serial+gravity, 4 loop+gravity, 5 full) from a "
        "measurement file (joint readings + tracker measurements, "
        "docs/measurement-files.md)."
    )
    add_robot_args(p, required=True)
    p.add_argument("--model", required=True,
                   help="1-5 or serial, loop, serial+gravity, loop+gravity, full")
    p.add_argument("--data", type=Path, required=True, help="calibration measurement file")
    p.add_argument("--validate", type=Path, help="independent validation measurement file")
    p.add_argument("--validate-refit", choices=("none", "base", "base+probe"), default="none",
                   help="the validation poses were measured with the tracker (and target) "
                        "elsewhere: re-identify BASE (and PROBE) on them, geometry kept; "
                        "orientation rows weighed by --rotation-weight")
    p.add_argument("--refit-positions-only", action="store_true",
                   help="with --validate-refit and 6-DOF files: re-identify on the measured "
                        "positions alone (orientations still evaluated)")
    p.add_argument("--rot", choices=("rpy", "zyz", "xyz"), default="rpy",
                   help="orientation convention of rx, ry, rz in the files (default rpy)")
    p.add_argument("--payload-kg", type=float, metavar="M",
                   help="payload carried in every pose (overrides a payload_kg column)")
    p.add_argument("--out", type=Path,
                   help="PARAMS.json to write (optional: --json prints it instead)")
    p.add_argument("--report", type=Path, help="self-contained HTML report to write")
    p.add_argument("--residuals", type=Path, metavar="RES.json",
                   help="write every pose's residual (measured position, error before and "
                        "after calibration, mm) for the UI's 3-D view")
    p.add_argument("--json", action="store_true", help="print the PARAMS.json object to stdout")
    p.add_argument("--base", help="initial BASE: JSON file (4x4 'matrix' or 'xyz_mm'+'rpy_deg') "
                                  "or 'x,y,z,roll,pitch,yaw' in mm and degrees")
    p.add_argument("--probe", help="initial PROBE, same forms as --base")
    p.add_argument("--method", choices=("gauss-newton", "lm", "least-squares"),
                   default="gauss-newton",
                   help="iteration (default gauss-newton, thesis Fig. 6-9; least-squares: "
                        "SciPy's trust-region solver, same minimum, slower)")
    p.add_argument("--loss", choices=("linear", "huber", "cauchy"), default="linear",
                   help="robust loss for outliers (default linear)")
    p.add_argument("--loss-scale", type=float, metavar="S",
                   help="threshold of the huber/cauchy loss: S × the median pose residual "
                        "(default 3); a pose beyond it is down-weighted")
    p.add_argument("--max-iterations", type=int, default=50)
    p.add_argument("--rotation-weight", type=float, default=1.0,
                   help="weight of orientation rows, m per rad, in the fit and the "
                        "--validate-refit (default 1, as the thesis)")
    p.add_argument("--condition-limit", type=float,
                   help="apply the condition-number rule (4.10) with this limit, e.g. 100")
    p.add_argument("--harmonics", type=int, choices=(0, 1, 2), default=0,
                   help="add joint-angle harmonics Δθ_j = Σ s sin(k q_j) + c cos(k q_j), "
                        "k ≤ this order, to the physical model (transmission error)")
    p.add_argument("--thermal", action="store_true",
                   help="identify a thermal expansion κT of the robot's lengths (1/K) about "
                        "the data's mean temperature (needs a temperature_c column)")
    p.add_argument("--residual-model", choices=("none", "learned"), default="none",
                   help="after the physical identification, learn the remaining error from "
                        "the joint readings (gradient boosting, grouped cross-validation; "
                        "written next to --out as PARAMS.residual.skops)")
    p.add_argument("--residual-cell-m", type=float, default=0.4, metavar="M",
                   help="workspace cell edge grouping poses for the residual model's "
                        "cross-validation (default 0.4 m)")
    p.add_argument("--residual-trees", type=int, default=300, metavar="N",
                   help="boosting iterations of each residual regressor (default 300)")
    p.add_argument("--residual-prior", type=Path, metavar="PARAMS.json",
                   help="learn the layer on top of the arm-shape stage of another "
                        "calibration of this robot with a learned layer (its PARAMS.json "
                        "and side file), e.g. one made in another set-up: a short campaign "
                        "here then adds to what that one taught (docs/calibration.md)")
    _add_prior_args(p)
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=_run)


def _add_prior_args(p: argparse.ArgumentParser) -> None:
    """The options of a short campaign with an earlier calibration as prior (--prior…)."""
    p.add_argument("--prior", type=Path, metavar="EARLIER.json",
                   help="the robot moved to a new set-up: identify this (short) campaign with "
                        "an earlier calibration of it (its PARAMS.json, with its learned layer "
                        "if it has one) as a prior — BASE and PROBE free, the other parameters "
                        "pulled toward the earlier values by their σ (docs/calibration.md)")
    p.add_argument("--prior-scale", type=float, metavar="TAU",
                   help="with --prior: inflate the earlier σ by TAU ≥ 1, or 0: BASE and PROBE "
                        "only (default: chosen by grouped cross-validation over the "
                        "campaign's poses, 0 among the candidates)")
    p.add_argument("--prior-stage", choices=("learned", "none"), default=None,
                   help="with --prior: learn the campaign's own stage on what the fit leaves "
                        "and keep it when its grouped CV over the campaign's cells beats the "
                        "fit without it (learned, the default), or never (none)")
    p.add_argument("--prior-cv", choices=("kfold", "cells"), default=None,
                   help="with --prior: the splits of the cross-validation that chooses among "
                        "the candidates — a seeded random 10-fold over the campaign's poses "
                        "(kfold, the default) or grouped over its workspace cells (cells: "
                        "biased against the weakly regularised candidates on I-optimal "
                        "campaigns, docs/results/short-campaign-bounds.md)")
    p.add_argument("--prior-se", type=float, metavar="K", default=None,
                   help="with --prior: adopt a candidate other than the baselines (the "
                        "earlier model moved, the campaign alone) only when its CV error is "
                        "below the better baseline's by more than K standard errors of the "
                        "paired difference (default 1: the one-standard-error rule; 0: any "
                        "gain)")
    p.add_argument("--prior-stage-se", type=float, metavar="K", default=None,
                   help="with --prior: adopt the campaign stage only when its grouped CV "
                        "beats the fit without it by more than K standard errors of the "
                        "paired difference (default 0: any gain; the same rule as --prior-se)")
    p.add_argument("--prior-stage-weights", metavar="W[,W…]", default=None,
                   help="with --prior: the weights in [0, 1] the campaign stage's grouped CV "
                        "chooses among for its correction, m(w) = mean ‖e − w ê‖ least "
                        "(default 1: the stage whole or not at all; 0,0.25,0.5,0.75,1: the "
                        "grid measured, docs/calibration.md; 0: no stage)")


def _frame(text: str, what: str) -> np.ndarray:
    """A 4x4 transform from a JSON file or an inline 'x,y,z,r,p,y' (mm, degrees)."""
    import numpy as np

    from plugcell.kinematics.rotations import rpy_to_matrix

    def from_xyz_rpy(xyz: Any, rpy: Any) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = rpy_to_matrix(*np.radians(np.asarray(rpy, float)))
        T[:3, 3] = np.asarray(xyz, float) / 1e3
        return T

    path = Path(text)
    if path.suffix.lower() == ".json" or path.is_file():
        try:
            obj = json.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise CommandError(f"--{what} {path}: cannot read: {exc.strerror}") from None
        except json.JSONDecodeError as exc:
            raise CommandError(f"--{what} {path}: invalid JSON: {exc}") from None
        try:
            if isinstance(obj, dict) and "matrix" in obj:
                T = np.asarray(obj["matrix"], float)
            elif isinstance(obj, dict) and "xyz_mm" in obj:
                T = from_xyz_rpy(obj["xyz_mm"], obj.get("rpy_deg", [0, 0, 0]))
            else:
                T = np.asarray(obj, float)
        except (TypeError, ValueError) as exc:
            raise CommandError(f"--{what} {path}: {exc}") from None
    else:
        try:
            vals = [float(x) for x in text.split(",")]
        except ValueError:
            raise CommandError(f"--{what}: expected a JSON file or 'x,y,z,roll,pitch,yaw', "
                               f"got {text!r}") from None
        if len(vals) != 6:
            raise CommandError(f"--{what}: expected 6 numbers x,y,z (mm),roll,pitch,yaw (deg)")
        T = from_xyz_rpy(vals[:3], vals[3:])
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise CommandError(f"--{what}: expected a finite 4x4 transform, got shape {T.shape}")
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise CommandError(f"--{what}: the rotation part is not a rotation matrix")
    return T


def _positive(value: float, option: str, unit: str) -> None:
    """Refuse a ``value`` of ``option`` that is not a finite number > 0."""
    if not (math.isfinite(value) and value > 0):
        raise CommandError(f"{option} must be a finite number > 0 ({unit}), got {value}")


def _read(path: Path, rot: str, n: int, payload: float | None, scale: Any = None):
    from dataclasses import replace

    import numpy as np

    from plugcell.calibration import CalibrationData
    from plugcell.io.measurements import MeasurementFileError, read_measurements

    try:
        m = read_measurements(path, rotation=rot, n_joints=n, joint_scale=scale)
    except MeasurementFileError as exc:
        raise CommandError(str(exc)) from None
    if payload is not None:
        m = replace(m, payload_kg=np.full(len(m), float(payload)))
    return CalibrationData.from_measurements(m)


class _Progress:
    def __init__(self, quiet: bool) -> None:
        self.quiet = quiet

    def __call__(self, stage: str, i: int, n: int, message: str) -> None:
        if not self.quiet:
            print(f"calibrate [{stage}] {message}", file=sys.stderr, flush=True)


def _counted(d: dict[str, Any]) -> str:
    """``50 of its 72 parameters identified (13 stand for others, 9 not identifiable)``:
    the model's parameters are the identified, the dependent ones (identified through
    another, ``dependent``) and those these data cannot determine (``unidentifiable``)."""
    n, dep, zero = (len(d.get(k) or []) for k in ("parameters", "dependent", "unidentifiable"))
    if not dep and not zero:
        return f"{n} parameters identified"
    parts = [f"{dep} stand for others" if dep else "",
             f"{zero} not identifiable from these data" if zero else ""]
    return (f"{n} of its {n + dep + zero} parameters identified "
            f"({', '.join(p for p in parts if p)})")


def _summary(d: dict[str, Any]) -> str:
    m = d["model"]
    lines = [f"robot {d['robot']}, model {m['number']} ({m['name']}): "
             f"{_counted(d)} from {d['data']['poses']} poses, "
             f"{d['iterations']} iterations, κ = {d['condition_number']:.1f}"]
    for key in ("calibration", "validation"):
        s = d.get(key)
        if not s:
            continue
        b = s.get("before", {})
        line = (f"  {key:11s} mean {b.get('mean_mm', math.nan):7.3f} -> {s['mean_mm']:7.3f} mm, "
                f"max {b.get('max_mm', math.nan):7.3f} -> {s['max_mm']:7.3f} mm")
        if "orientation" in s:
            line += (f", orientation {b.get('orientation', {}).get('mean_deg', math.nan):.4f} -> "
                     f"{s['orientation']['mean_deg']:.4f}°")
        lines.append(line)
    rm, hv = d.get("residual_model"), d.get("validation_hybrid")
    if rm:
        cv = rm["cross_validation"]
        lines.append(f"  residual model: grouped {cv['folds']}-fold CV over {cv['cells']} cells of "
                     f"{cv['cell_size_m']:g} m: {cv['physical_mm']:.3f} -> {cv['hybrid_mm']:.3f} mm"
                     + ("" if rm["useful"] else " (no gain: not applied)"))
        pr = rm.get("prior_stage")
        if pr:
            lines.append(f"  on top of a prior arm-shape stage ({', '.join(pr['features'])}; "
                         f"its own set-up {pr['physical_mm']:.3f} -> {pr['cv_mm']:.3f} mm): the "
                         "CV's first figure is the physical model with it")
        sh = rm.get("shape_stage")
        if sh:
            lines.append(f"  arm-shape stage (joint-1 frame, {', '.join(sh['features'])}): "
                         f"{sh['physical_mm']:.3f} -> {sh['cv_mm']:.3f} mm, applied where the "
                         "first stage is not")
    pri = d.get("settings", {}).get("prior")
    if pri:
        choice = pri.get("choice", "map")
        how = ("grouped CV over the campaign's cells" if pri["scale_chosen_by"] == "grouped CV"
               else pri["scale_chosen_by"])
        held = (f"its other parameters held (τ = 0, {pri['scale_chosen_by']})"
                if pri["scale"] == 0 else
                f"{len(pri['regularised'])} parameters pulled toward it with its σ × τ = "
                f"{pri['scale']:g} ({pri['scale_chosen_by']})")
        if choice == "alone":
            lines.append(f"  prior: the earlier calibration of {pri['robot']} not used: the "
                         f"{how} preferred the campaign alone")
        else:
            lines.append(f"  prior: the earlier calibration of {pri['robot']}, BASE + PROBE "
                         f"re-identified ('before' above), {held}"
                         + ("; its learned layer kept (its correction an offset of the fit)"
                            if pri["layer_offset"] else
                            "; its learned layer left out (the CV preferred the model "
                            "without it)" if pri.get("earlier_layer", True) and (
                                choice == "moved" or choice.endswith("/physical"))
                            else ""))
        if pri.get("cv_mm"):
            lines.append(f"  {how} (mm): " + ", ".join(
                f"{'τ = ' + k if k[0].isdigit() else k} {v:.3f}"
                for k, v in pri["cv_mm"].items()) + (
                f"; a candidate other than moved and alone only when more than "
                f"{pri['se_k']:g} standard error{'' if pri['se_k'] == 1 else 's'} of the "
                "paired CV difference below the better of them"
                if pri.get("se_k") is not None else ""))
        st = pri.get("stage")
        if st:
            w = st.get("weight", 1.0)
            lines.append("  campaign stage: " + (
                f"adopted (grouped CV over {st['cells']} cells: {st['physical_mm']:.3f} -> "
                f"{(st.get('cv_by_weight_mm') or {}).get(f'{w:g}', st['hybrid_mm']):.3f} mm"
                + ("" if w == 1 else f" at weight {w:g}") + (
                    f", gain {-st['gain_mm']:.3f} mm " + (
                        f"> {st['se_k']:g} × its standard error {st['se_mm']:.3f} mm"
                        if st["se_k"] else f"(standard error {st['se_mm']:.3f} mm)")
                    if st.get("gain_mm") is not None else "") + ")"
                if st["adopted"] else f"not used: {st['reason']}"))
    if hv:
        lines.append(f"  validation  physical {hv['physical']['mean_mm']:7.3f} mm, hybrid "
                     f"{hv['hybrid']['mean_mm']:7.3f} mm ({hv['fallbacks']} of {hv['poses']} "
                     "poses outside the trained region: physical model used)")
    lines += [f"  warning: {w}" for w in d["warnings"]]
    return "\n".join(lines)


def _prior_stage(path: Path, args: argparse.Namespace) -> Any:
    """The arm-shape stage of the learned layer of calibration ``path`` (--residual-prior),
    read with this command's robot: a calibration of another robot is refused."""
    from plugcell.apps.commands.files import read_calibration
    from plugcell.io.residual_models import ResidualFileError, load_residual

    d, result = read_calibration(path, args)
    entry = d.get("residual_model")
    if not entry:
        raise CommandError(f"--residual-prior {path}: that calibration has no learned "
                           "residual layer (calibrate it with --residual-model learned)")
    try:
        layer = load_residual(entry, path, robot=result.robot, model=result.model)
    except ResidualFileError as exc:
        raise CommandError(f"--residual-prior: {exc}") from None
    if layer.shape is None:
        raise CommandError(f"--residual-prior {path}: its layer has no arm-shape stage (none "
                           "beat the physical model on its held-out cells)")
    return layer.shape


def _prior(path: Path, args: argparse.Namespace) -> Any:
    """The earlier calibration ``path`` (--prior) as a :class:`~plugcell.calibration.prior.Prior`,
    read with this command's robot: another robot, another model, a file without the
    earlier σ or a layer that does not load are refused, naming the mismatch."""
    import numpy as np

    from plugcell.apps.commands.files import read_calibration
    from plugcell.calibration import CalibrationError, model_config
    from plugcell.calibration.prior import Prior
    from plugcell.io.residual_models import ResidualFileError, load_residual

    d, result = read_calibration(path, args)
    try:
        cfg = model_config(args.model)
    except ValueError as exc:
        raise CommandError(str(exc)) from None
    if cfg.number != result.config.number:
        raise CommandError(f"--prior {path}: a calibration with model {result.config.number} "
                           f"({result.config.name}), not model {cfg.number} ({cfg.name}); give "
                           f"--model {result.config.number}")
    rows = {r.get("key"): r for r in d.get("parameters", []) if isinstance(r, dict)}
    try:
        sigma = np.array([float(rows[k]["sigma"]) for k in result.keys])
        sigma2 = float(d["sigma2"])
    except (KeyError, TypeError, ValueError) as exc:
        raise CommandError(f"--prior {path}: the earlier σ are missing ({exc}); calibrate "
                           "it again with this plugcell") from None
    layer = None
    entry = d.get("residual_model")
    if entry:
        try:
            layer = load_residual(entry, path, robot=result.robot, model=result.model)
        except ResidualFileError as exc:
            raise CommandError(f"--prior: {exc}") from None
    try:
        return Prior(result.robot, result.config, result.model, tuple(result.keys), sigma,
                     math.sqrt(sigma2) if sigma2 > 0 else math.nan, layer)
    except CalibrationError as exc:
        raise CommandError(f"--prior {path}: {exc}") from None


def _prior_conflicts(args: argparse.Namespace) -> None:
    """Refuse options that mean nothing with --prior (the earlier model decides them)."""
    if args.prior is None:
        if args.prior_scale is not None:
            raise CommandError("--prior-scale needs --prior EARLIER.json")
        if args.prior_stage is not None:
            raise CommandError("--prior-stage needs --prior EARLIER.json")
        if args.prior_cv is not None:
            raise CommandError("--prior-cv needs --prior EARLIER.json")
        if args.prior_se is not None:
            raise CommandError("--prior-se needs --prior EARLIER.json")
        if args.prior_stage_se is not None:
            raise CommandError("--prior-stage-se needs --prior EARLIER.json")
        if args.prior_stage_weights is not None:
            raise CommandError("--prior-stage-weights needs --prior EARLIER.json")
        return
    given = [o for o, on in (("--residual-model learned", args.residual_model != "none"),
                             ("--residual-prior", args.residual_prior is not None),
                             ("--base", args.base is not None),
                             ("--probe", args.probe is not None),
                             ("--harmonics", args.harmonics != 0),
                             ("--thermal", args.thermal),
                             ("--loss", args.loss != "linear"),
                             ("--method", args.method != "gauss-newton")) if on]
    if given:
        raise CommandError(f"--prior: {', '.join(given)} cannot be combined with it (the "
                           "earlier calibration decides the model and keeps its layer; "
                           "BASE and PROBE are re-identified from the campaign)")
    if args.prior_scale is not None and not (args.prior_scale == 0 or (
            math.isfinite(args.prior_scale) and args.prior_scale >= 1)):
        raise CommandError(f"--prior-scale must be 0 (BASE + PROBE only) or a number ≥ 1, "
                           f"got {args.prior_scale}")
    for opt, k in (("--prior-se", args.prior_se), ("--prior-stage-se", args.prior_stage_se)):
        if k is not None and not (math.isfinite(k) and k >= 0):
            raise CommandError(f"{opt} must be a number ≥ 0 (standard errors), got {k}")
    if args.prior_stage_weights is not None:
        stage_weights(args.prior_stage_weights)


def stage_weights(text: str) -> tuple[float, ...]:
    """The grid of ``--prior-stage-weights W[,W…]``, checked
    (:func:`~plugcell.calibration.campaign_stage.check_weights`).

    Parameters
    ----------
    text : str
        Comma-separated weights, e.g. ``"0,0.5,1"``.

    Returns
    -------
    tuple of float
        The weights, sorted.

    Raises
    ------
    CommandError
        A part that is not a number, or a grid :func:`check_weights` refuses (empty, a
        weight outside [0, 1] or not finite, a weight twice), naming the option.
    """
    from plugcell.calibration import CalibrationError
    from plugcell.calibration.campaign_stage import check_weights

    values = []
    for part in (x.strip() for x in text.split(",")) if text.strip() else ():
        try:
            values.append(float(part))
        except ValueError:
            raise CommandError(f"--prior-stage-weights: {part!r} is not a number (W[,W…], "
                               "each in [0, 1])") from None
    try:
        return check_weights(values)
    except CalibrationError as exc:
        raise CommandError(f"--prior-stage-weights: {str(exc).removeprefix('prior: ')}"
                           ) from None


def _run(args: argparse.Namespace) -> int:
    from plugcell.apps.commands.robotargs import load_robot_of
    from plugcell.calibration import CalibrationError
    from plugcell.calibration.residual_model import ResidualModelError

    desc = load_robot_of(args)
    if args.payload_kg is not None and not (math.isfinite(args.payload_kg)
                                            and args.payload_kg >= 0):
        raise CommandError(f"--payload-kg must be a mass ≥ 0, got {args.payload_kg}")
    if args.max_iterations < 1:
        raise CommandError("--max-iterations must be at least 1")
    _positive(args.rotation_weight, "--rotation-weight", "m per rad")
    if args.loss_scale is not None:
        if args.loss == "linear":
            raise CommandError("--loss-scale sets the threshold of --loss huber or cauchy; "
                               "the linear loss has none")
        _positive(args.loss_scale, "--loss-scale", "× the median pose residual")
    if args.validate_refit != "none" and args.validate is None:
        raise CommandError("--validate-refit needs a --validate file")
    if args.refit_positions_only and args.validate_refit == "none":
        raise CommandError("--refit-positions-only needs --validate-refit base or base+probe")
    if not (math.isfinite(args.residual_cell_m) and args.residual_cell_m > 0):
        raise CommandError(f"--residual-cell-m must be > 0, got {args.residual_cell_m}")
    if args.residual_prior is not None and args.residual_model != "learned":
        raise CommandError("--residual-prior needs --residual-model learned")
    _prior_conflicts(args)
    if args.residual_model == "learned" and args.out is None:
        raise CommandError("--residual-model learned needs --out PARAMS.json: the layer is "
                           "saved beside it (PARAMS.residual.skops)")
    scale = desc.reading_scale()  # degrees, mm for a prismatic joint
    data = _read(args.data, args.rot, desc.n_readings, args.payload_kg, scale)
    val = None
    if args.validate is not None:
        val = _read(args.validate, args.rot, desc.n_readings, args.payload_kg, scale)
        if val.six_dof != data.six_dof:
            raise CommandError("--validate: the validation file must measure the same (6-DOF "
                               "or positions) as the calibration file")
        if args.refit_positions_only and not val.six_dof:
            raise CommandError(f"--refit-positions-only: {args.validate} measures positions "
                               "only; the refit uses them without the option")
    progress = _Progress(args.quiet)
    learner = None
    if args.residual_model == "learned":  # refused before the identification, not after
        from plugcell.calibration.residual_model import ResidualLearner

        learner = ResidualLearner(cell_size_m=args.residual_cell_m, trees=args.residual_trees,
                                  progress=lambda t: progress("residual", 0, 0, t))
        try:
            learner.check_poses(len(data))
        except ResidualModelError as exc:
            raise CommandError(f"--residual-model learned: {exc}") from None
    prior = None if args.residual_prior is None else _prior_stage(args.residual_prior, args)
    earlier = None if args.prior is None else _prior(args.prior, args)
    if earlier is not None and (earlier.layer is not None or args.prior_stage != "none") \
            and args.out is None:
        raise CommandError("--prior needs --out PARAMS.json: the learned layer (the earlier "
                           "one, or the campaign's own stage) is saved beside it "
                           "(PARAMS.residual.skops); --prior-stage none with an earlier "
                           "calibration without a layer writes none")
    base = None if args.base is None else _frame(args.base, "base")
    probe = None if args.probe is None else _frame(args.probe, "probe")
    try:
        if earlier is not None:
            result = _fit_prior(args, earlier, data, progress)
        else:
            result = _fit(args, desc, data, base, probe, prior, learner, progress)
        if val is not None:
            result = result.with_validation(
                val, refit_base=args.validate_refit != "none",
                refit_probe=args.validate_refit == "base+probe",
                rotation_weight=args.rotation_weight,
                refit_positions_only=args.refit_positions_only)
    except (CalibrationError, ResidualModelError) as exc:
        raise CommandError(str(exc)) from None
    return _write(args, desc, data, val, result)


def _fit_prior(args: argparse.Namespace, earlier: Any, data: Any, progress: Any) -> Any:
    """The short campaign with the earlier calibration as prior (--prior)."""
    from plugcell.calibration.campaign_stage import STAGE_SE_K, STAGE_WEIGHTS
    from plugcell.calibration.prior import SE_RULE_K, PriorCalibrator

    return PriorCalibrator(earlier, scale=args.prior_scale, stage=args.prior_stage != "none",
                           rotation_weight=args.rotation_weight,
                           max_iterations=args.max_iterations, cell_size_m=args.residual_cell_m,
                           cv_split=args.prior_cv or "kfold",
                           se_k=SE_RULE_K if args.prior_se is None else args.prior_se,
                           stage_se_k=STAGE_SE_K if args.prior_stage_se is None
                           else args.prior_stage_se,
                           stage_weights=STAGE_WEIGHTS if args.prior_stage_weights is None
                           else stage_weights(args.prior_stage_weights),
                           progress=progress).fit(data)


def _fit(args: argparse.Namespace, desc: Any, data: Any, base: Any, probe: Any, prior: Any,
         learner: Any, progress: Any) -> Any:
    """The plain calibration (no --prior): the physical fit and, with ``learner`` (checked
    against the poses before), its learned layer."""
    from plugcell.calibration import Calibrator

    cal = Calibrator(desc, args.model, base=base, probe=probe, method=args.method,
                     loss=args.loss, max_iterations=args.max_iterations,
                     **({} if args.loss_scale is None else {"loss_scale": args.loss_scale}),
                     rotation_weight=args.rotation_weight,
                     condition_limit=args.condition_limit, progress=progress,
                     harmonics=args.harmonics, thermal=args.thermal)
    result = cal.fit(data)
    if learner is not None:
        result = result.with_residual_model(learner.fit(result.model, data,
                                                        robot=result.robot, prior=prior))
    return result


def _write(args: argparse.Namespace, desc: Any, data: Any, val: Any, result: Any) -> int:
    """Write PARAMS.json, its layer, the report and the residuals; print the summary."""
    from plugcell.apps.commands.robotargs import robot_source_of
    from plugcell.io.params import params_json, residuals_json
    from plugcell.io.robot_schema import description_to_dict

    written = []
    side = None
    if result.residual_model is not None:
        from plugcell.io.residual_models import ResidualFileError, residual_path, save_residual

        try:
            side = save_residual(result.residual_model, residual_path(args.out))
        except ResidualFileError as exc:
            raise CommandError(str(exc)) from None
    d = json.loads(params_json(result, residual_file=side))
    # where the robot came from and what it was: export and compensate find it again
    d["robot_source"] = robot_source_of(args).absolute().to_dict()
    d["description"] = description_to_dict(desc)
    text = json.dumps(d, indent=2, allow_nan=False)
    if args.out is not None:
        write_text(args.out, text + "\n")
        written.append(args.out)
        if side is not None:
            written.append(residual_path(args.out))
    if args.report is not None:
        from plugcell.io.calibration_report import render_report

        write_text(args.report, render_report(result, data, val))
        written.append(args.report)
    if args.residuals is not None:
        write_text(args.residuals, residuals_json(result) + "\n")
        written.append(args.residuals)
    if args.json:
        print(text)
    else:
        print(_summary(d))
        if written:
            print("wrote " + ", ".join(str(w) for w in written[:-1])
                  + (" and " if len(written) > 1 else "") + str(written[-1]))
        if args.out is None:
            print("parameters not saved: give --out PARAMS.json (or --json to print them)",
                  file=sys.stderr)
    return 0

