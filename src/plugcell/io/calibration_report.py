"""A self-contained, offline HTML report of a calibration (thesis Fig. 8-8 and more).

:func:`render_report` returns one HTML string: plots are PNGs embedded as base64
(matplotlib's Agg backend, imported lazily — without matplotlib the report has
the tables only), no scripts, no CDN.  It shows:

* the accuracy before/after on the calibration and validation poses (8.1–8.2);
* per-component error histograms before and after calibration (Fig. 8-8);
* the identified parameters with σ (8.5), units and what each stands for;
* the residual of every pose; a 3-D view of the poses coloured by their error;
* the convergence history; the warnings (ill-conditioning, outliers, few equations);
* the calibrated region: joint ranges covered against the limits, the distance
  threshold, and the validation poses outside it (docs/planning.md).

Writing the file is the caller's business (``plugcell calibrate --report``).
"""

from __future__ import annotations

import base64
import html
import io
import math
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from plugcell.calibration.data import CalibrationData
from plugcell.calibration.result import CalibrationResult
from plugcell.calibration.statistics import PoseResiduals

Array = NDArray[np.float64]

__all__ = ["display_value", "render_report"]

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:2em;
color:#222;max-width:1100px}
h1{font-size:1.5em}h2{font-size:1.2em;margin-top:2em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;margin:.5em 0;font-size:.9em}
td,th{border:1px solid #ccc;padding:.25em .6em;text-align:right}
th{background:#f3f3f3}td.l,th.l{text-align:left}
.warn{background:#fff4e0;border-left:4px solid #e69500;padding:.4em .8em;margin:.3em 0}
.ok{background:#eaf7ea;border-left:4px solid #3a3;padding:.4em .8em}
img{max-width:100%}.small{color:#666;font-size:.85em}
"""


def display_value(value: float, unit: str) -> tuple[float, str]:
    """A parameter value in reading units: m → mm for lengths, rad → degrees for angles.

    Parameters
    ----------
    value : float
        The value in SI, unit ``unit``.
    unit : str
        Its unit as a parameter space states it (``"m"``, ``"rad"``, ``"rad/(N·m)"``…).

    Returns
    -------
    value : float
        ``value · 10³`` for ``"m"``, ``value · 180/π`` for ``"rad"``, else unchanged.
    unit : str
        ``"mm"``, ``"°"``, or ``unit`` unchanged (compound units are not converted).
    """
    if unit == "m":
        return value * 1e3, "mm"
    if unit == "rad":
        return math.degrees(value), "°"
    return value, unit


def _png(fig: Any) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return ('<img alt="plot" src="data:image/png;base64,'
            + base64.b64encode(buf.getvalue()).decode("ascii") + '">')


def _residuals(stored: PoseResiduals | None, result: CalibrationResult,
               data: CalibrationData) -> PoseResiduals:
    """The residuals the result carries for ``data`` (so a validation with a re-fitted
    BASE shows what its statistics are of), else computed."""
    if stored is not None and len(stored) == len(data) and np.array_equal(stored.positions,
                                                                        data.positions):
        return stored
    return result.evaluate_poses(data)


def _errors(res: PoseResiduals, which: Literal["before", "after"]
            ) -> tuple[Array, Array | None]:
    """Position errors (mm) and orientation errors (deg, or None), before or after."""
    dp, dphi = res.errors(which)
    return dp * 1e3, None if dphi is None else np.degrees(dphi)


def _stats_rows(label: str, before: Any, after: Any) -> str:
    def cells(st: Any) -> str:
        if st is None:
            return "<td></td>" * 5
        p = st.position.norm
        o = st.orientation.norm if st.orientation is not None else None
        ori = "" if o is None else f"{math.degrees(o.mean):.4f}"
        return (f"<td>{p.mean * 1e3:.3f}</td><td>{p.std * 1e3:.3f}</td>"
                f"<td>{p.max * 1e3:.3f}</td><td>{p.rms * 1e3:.3f}</td><td>{ori}</td>")

    return (f'<tr><td class="l">{label}, nominal</td>{cells(before)}</tr>'
            f'<tr><td class="l">{label}, calibrated</td>{cells(after)}</tr>')


def _coverage_table(result: CalibrationResult) -> list[str]:
    """The calibrated region (docs/planning.md): per joint the range covered against the
    limits, the threshold, payloads, the Cartesian box, validation poses outside."""
    region = result.validity
    if region is None:
        return []
    desc = result.model.structure.source
    lim = np.degrees(desc.joint_limits)
    lo, hi = np.degrees(region.joint_lower), np.degrees(region.joint_upper)
    out = ["<h2>Calibrated region (where the model may be trusted)</h2>",
           "<table><tr><th class='l'>joint</th><th>calibrated from (°)</th><th>to (°)</th>"
           "<th>limits (°)</th><th>covered</th><th>lever arm (mm/°)</th></tr>"]
    for j, name in enumerate(desc.actuated):
        span = max(lim[j, 1] - lim[j, 0], 1e-9)
        out.append(f"<tr><td class='l'>{html.escape(name)}</td><td>{lo[j]:.1f}</td>"
                   f"<td>{hi[j]:.1f}</td><td>{lim[j, 0]:.0f} … {lim[j, 1]:.0f}</td>"
                   f"<td>{100 * (hi[j] - lo[j]) / span:.0f} %</td>"
                   f"<td>{region.lever_m[j] * 1e3 * math.pi / 180:.2f}</td></tr>")
    tl, tu = region.target_lower * 1e3, region.target_upper * 1e3
    out.append("</table>")
    val = ""
    if result.validation_region is not None:
        v = result.validation_region
        val = (f" Validation: {v.count} of {len(v)} poses outside"
               + (f" (largest distance {v.distance_m.max() * 1e3:.0f} mm)." if v.count else "."))
    out.append(
        f"<p>{region.n_poses} calibration poses; a pose farther than "
        f"<b>{region.threshold_m * 1e3:.0f} mm</b> (joint-space distance scaled by the lever "
        "arms, mm of target motion) from every calibration pose, or beyond a joint's range, "
        f"is outside. Payloads {region.payload_kg[0]:g}–{region.payload_kg[1]:g} kg; targets "
        f"(robot base frame) x {tl[0]:.0f}…{tu[0]:.0f}, y {tl[1]:.0f}…{tu[1]:.0f}, "
        f"z {tl[2]:.0f}…{tu[2]:.0f} mm.{html.escape(val)}</p>")
    return out


def _coverage_figure(plt: Any, result: CalibrationResult, calibration: CalibrationData,
                     validation: CalibrationData | None) -> Any:
    """Per joint: limits (grey), calibration poses (blue), validation poses (green inside,
    red outside the region)."""
    region = result.validity
    assert region is not None
    desc = result.model.structure.source
    n = desc.n_actuated
    lim = np.degrees(desc.joint_limits)
    fig, ax = plt.subplots(figsize=(8, 0.45 * n + 1.2))
    for j in range(n):
        y = n - 1 - j
        ax.plot(lim[j], [y, y], color="0.85", lw=8, solid_capstyle="butt")
        ax.plot(np.degrees(calibration.q[:, j]), np.full(len(calibration), y + 0.12), "|",
                color="tab:blue", ms=7)
        if validation is not None:
            out = result.check_region(validation.q, validation.payload_kg)
            flag = np.zeros(len(validation), bool) if out is None else out.outside
            qv = np.degrees(validation.q[:, j])
            ax.plot(qv[~flag], np.full(int((~flag).sum()), y - 0.15), "|", color="tab:green",
                    ms=6)
            ax.plot(qv[flag], np.full(int(flag.sum()), y - 0.15), "|", color="tab:red", ms=6)
    ax.set_yticks(range(n))
    ax.set_yticklabels([f"joint {a}" for a in reversed(desc.actuated)])
    ax.set_xlabel("joint reading (°); grey: limits, blue: calibration poses, "
                  "green/red: validation poses inside/outside the region")
    ax.tick_params(labelsize=8)
    fig.tight_layout()
    return fig


def _hybrid_section(result: CalibrationResult) -> list[str]:
    """Physical vs hybrid on the validation poses and the layer's grouped CV."""
    layer = result.residual_model
    if layer is None:
        return []
    cv = layer.cv
    out = ["<h2>Learned residual layer (hybrid model)</h2>",
           f"<p>Gradient-boosted trees on {', '.join(layer.summary()['features'])}; residual in "
           f"the robot base frame; grouped {cv.folds}-fold cross-validation over {cv.cells} "
           f"workspace cells of {cv.cell_size_m:g} m: held-out mean position error "
           f"{cv.physical_mm:.3f} mm (physical) → {cv.hybrid_mm:.3f} mm (hybrid)"
           + ("" if layer.useful else " — <b>no gain: this stage is not applied</b>")
           + ("" if layer.weight == 1 else
              f"; its correction applied with weight {layer.weight:g}, the value its grouped "
              "cross-validation chose (a campaign stage, <code>--prior</code>)")
           + ("" if layer.shape is None else
              f"; arm-shape stage (joint-1 frame, sin/cos of "
              f"{', '.join(f'q{j + 1}' for j in layer.shape.joints)}): "
              f"{layer.shape.physical_mm:.3f} → {layer.shape.cv_mm:.3f} mm, applied where the "
              "first stage is not")
           + ("" if layer.prior is None else
              "; learned on top of a prior arm-shape stage from another calibration "
              "(sin/cos of " + ", ".join(f"q{j + 1}" for j in layer.prior.joints)
              + "), which every prediction adds and the “physical” figure includes")
           + ".</p>"]
    h = result.hybrid_validation_residuals
    if h is None:
        out.append("<p class='small'>No validation set: the hybrid model was not validated "
                   "on independent poses (it is never evaluated on its training poses).</p>")
        return out
    out.append("<table><tr><th class='l'>validation</th><th>mean Δp (mm)</th><th>σ (mm)</th>"
               "<th>max (mm)</th><th>rms (mm)</th><th>mean Δφ (°)</th></tr>")
    rows = _stats_rows("validation", h.accuracy("before"), h.accuracy("after"))
    rows = rows.replace(", nominal<", ", physical<").replace(", calibrated<", ", hybrid<")
    out.append(rows + "</table>")
    out.append(f"<p class='small'>{result.hybrid_fallbacks} of {len(h)} validation poses lie "
               "outside the layer's trained region: the physical model is used for them.</p>")
    return out


def render_report(
    result: CalibrationResult,
    calibration: CalibrationData,
    validation: CalibrationData | None = None,
    *,
    title: str | None = None,
) -> str:
    """The HTML report of a calibration on its calibration (and validation) data.

    One self-contained page (module docstring): summary, warnings, accuracy table
    (mm, degrees), joint-range coverage, hybrid-layer section, then — when matplotlib
    is installed, whose backend is switched to Agg here — error histograms, residual
    per pose, a 3-D view of the poses, coverage and convergence plots as embedded
    PNGs; last the identified parameters (mm and degrees, :func:`display_value`) and
    BASE/PROBE (x, y, z mm; roll, pitch, yaw degrees).  SI values of ``result`` are
    converted for display only here.

    Parameters
    ----------
    result : CalibrationResult
        The calibration (statistics, parameters, history, validity).
    calibration : CalibrationData
        The N calibration poses ``result`` was fitted on (positions (N, 3) m); their
        residuals are recomputed unless ``result`` stores them for these poses.
    validation : CalibrationData, optional
        M validation poses, plotted after the calibration poses in the residual plot.
        (The accuracy table's validation row comes from ``result.validation``.)
    title : str, optional
        The page title; default ``"Calibration of ROBOT — model K (NAME)"``.

    Returns
    -------
    str
        The HTML document (UTF-8 text, no scripts, no external resources).
    """
    cfg = result.config
    title = title or f"Calibration of {result.robot} — model {cfg.number} ({cfg.name})"
    parts: list[str] = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        f"<title>{_esc(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{_esc(title)}</h1>",
        _summary(result),
        *_warnings_section(result),
        *_accuracy_section(result),
        *_coverage_table(result),
        *_hybrid_section(result),
        *_plots(result, calibration, validation),
        *_parameter_section(result),
        *_frames_section(result),
        "<p class='small'>generated by plugcell calibrate</p></body></html>",
    ]
    return "\n".join(parts)


def _esc(text: str) -> str:
    return html.escape(text, quote=False)


def _summary(result: CalibrationResult) -> str:
    """One paragraph: the model, the poses, the parameters, convergence, κ and σ."""
    st = result.statistics
    kappa = "" if st is None else (
        f"; condition number κ = {st.condition_number:.1f}; σ = "
        f"{math.sqrt(st.sigma2) * 1e3:.4f} (mm | mrad, eq. 8.3)")
    val = f", {result.n_validation} validation poses" if result.n_validation else ""
    kind = "poses (6-DOF)" if result.six_dof else "positions (3-DOF)"
    conv = "converged" if result.converged else "NOT converged"
    return (
        f"<p>{_esc(result.config.title)}. {result.n_poses} calibration {kind}{val}; "
        f"{len(result.keys)} parameters identified in {result.iterations} iterations "
        f"({conv}){kappa}; {result.elapsed_s:.2f} s.</p>")


def _warnings_section(result: CalibrationResult) -> list[str]:
    parts = ["<h2>Warnings</h2>"]
    if result.warnings:
        parts += [f'<div class="warn">{_esc(w)}</div>' for w in result.warnings]
    else:
        parts.append('<div class="ok">none</div>')
    return parts


def _accuracy_section(result: CalibrationResult) -> list[str]:
    """The accuracy table of eqs. 8.1–8.2, nominal against calibrated, per data set."""
    parts = ["<h2>Accuracy (eqs. 8.1–8.2)</h2><table><tr><th class='l'>set</th>"
             "<th>mean Δp (mm)</th><th>σ (mm)</th><th>max (mm)</th><th>rms (mm)</th>"
             "<th>mean Δφ (°)</th></tr>",
             _stats_rows("calibration", result.calibration_before, result.calibration)]
    if result.validation is not None:
        parts.append(_stats_rows("validation", result.validation_before, result.validation))
    parts.append("</table><p class='small'>nominal: the robot's nominal geometry with BASE "
                 "and PROBE fitted; Δφ: angle of the rotation between measured and "
                 "predicted orientation.</p>")
    return parts


def _plots(result: CalibrationResult, calibration: CalibrationData,
           validation: CalibrationData | None) -> list[str]:
    """Every figure as an embedded PNG (matplotlib's Agg backend), or a note without it."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover - matplotlib is an optional dependency
        return ["<p class='warn'>matplotlib is not installed: no plots.</p>"]
    res_cal = _residuals(result.calibration_residuals, result, calibration)
    parts = ["<h2>Error distributions before and after (cf. Fig. 8-8)</h2>",
             _png(_histograms(plt, res_cal)),
             "<h2>Residual per pose</h2>",
             _png(_residual_per_pose(plt, result, res_cal, validation)),
             "<h2>Poses in the measurement frame, coloured by the calibrated error</h2>",
             _png(_pose_cloud(plt, calibration, _errors(res_cal, "after")[0]))]
    if result.validity is not None:
        parts.append("<h2>Coverage of the joint ranges</h2>")
        parts.append(_png(_coverage_figure(plt, result, calibration, validation)))
    if result.history:
        parts.append("<h2>Convergence (Fig. 6-9)</h2>")
        parts.append(_png(_convergence(plt, result)))
    return parts


def _histograms(plt: Any, res_cal: PoseResiduals) -> Any:
    """Histograms of each error component, nominal (top row) and calibrated (bottom)."""
    eb, ob = _errors(res_cal, "before")
    ea, oa = _errors(res_cal, "after")
    ncol = 6 if ob is not None else 3
    fig, axes = plt.subplots(2, ncol, figsize=(2.2 * ncol, 4.2), squeeze=False)
    labels = ["Δx (mm)", "Δy (mm)", "Δz (mm)", "Δφx (°)", "Δφy (°)", "Δφz (°)"]
    for c in range(ncol):
        for r, (e, o, name, color) in enumerate(((eb, ob, "nominal", "tab:red"),
                                                 (ea, oa, "calibrated", "tab:blue"))):
            x = e[:, c] if c < 3 else o[:, c - 3]  # type: ignore[index]
            ax = axes[r, c]
            ax.hist(x, bins=20, color=color, alpha=0.8)
            ax.set_title(f"{name}: mean {x.mean():.3g}, σ {x.std(ddof=1):.2g}", fontsize=7)
            ax.set_xlabel(labels[c], fontsize=8)
            ax.tick_params(labelsize=7)
    fig.tight_layout()
    return fig


def _residual_per_pose(plt: Any, result: CalibrationResult, res_cal: PoseResiduals,
                       validation: CalibrationData | None) -> Any:
    """|Δp| of every calibration pose, then of every validation pose, nominal and
    calibrated (log scale)."""
    eb, ea = _errors(res_cal, "before")[0], _errors(res_cal, "after")[0]
    fig, ax = plt.subplots(figsize=(10, 2.8))
    n = len(eb)
    ax.plot(np.arange(1, n + 1), np.linalg.norm(eb, axis=1), ".", color="tab:red",
            label="calibration, nominal")
    ax.plot(np.arange(1, n + 1), np.linalg.norm(ea, axis=1), ".", color="tab:blue",
            label="calibration, calibrated")
    if validation is not None:
        res_val = _residuals(result.validation_residuals, result, validation)
        vb, va = _errors(res_val, "before")[0], _errors(res_val, "after")[0]
        x = np.arange(n + 1, n + len(validation) + 1)
        ax.plot(x, np.linalg.norm(vb, axis=1), "x", color="tab:orange",
                label="validation, nominal")
        ax.plot(x, np.linalg.norm(va, axis=1), "x", color="tab:green",
                label="validation, calibrated")
    ax.set_yscale("log")
    ax.set_xlabel("pose #")
    ax.set_ylabel("|Δp| (mm)")
    ax.legend(fontsize=7, ncol=4)
    fig.tight_layout()
    return fig


def _pose_cloud(plt: Any, calibration: CalibrationData, after_mm: Array) -> Any:
    """The measured positions in 3-D, coloured by their calibrated |Δp| (mm)."""
    fig = plt.figure(figsize=(6.5, 5))
    ax3 = fig.add_subplot(projection="3d")
    p = calibration.positions
    sc = ax3.scatter(p[:, 0], p[:, 1], p[:, 2], c=np.linalg.norm(after_mm, axis=1),
                     cmap="viridis")
    fig.colorbar(sc, ax=ax3, shrink=0.7, label="|Δp| after calibration (mm)")
    ax3.set_xlabel("x (m)")
    ax3.set_ylabel("y (m)")
    ax3.set_zlabel("z (m)")
    fig.tight_layout()
    return fig


def _convergence(plt: Any, result: CalibrationResult) -> Any:
    """Mean |Δp| before each step and the step's norm per iteration (Fig. 6-9)."""
    fig, ax = plt.subplots(figsize=(5.5, 3))
    it = [h.iteration for h in result.history]
    ax.semilogy(it, [h.mean_position_mm for h in result.history], "o-",
                label="mean |Δp| before the step (mm)")
    ax.semilogy(it, [max(h.step_norm, 1e-16) for h in result.history], "s--",
                label="‖Δg‖")
    ax.axhline(result.settings.get("tol", 1e-6), color="gray", ls=":")
    ax.set_xlabel("iteration")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _parameter_section(result: CalibrationResult) -> list[str]:
    """The identified parameters (mm and degrees) with σ (eq. 8.5), and which were
    identified through others or have no effect."""
    parts = ["<h2>Identified parameters (σ: eq. 8.5)</h2><table><tr><th class='l'>"
             "parameter</th><th>value</th><th>σ</th><th class='l'>unit</th>"
             "<th class='l'>stands for</th></tr>"]
    for row in result.parameter_table():
        v, unit = display_value(row["value"], row["unit"])
        s, _ = display_value(row["sigma"], row["unit"])
        fmt = ".5g" if unit in ("mm", "°") else ".4g"
        parts.append(f"<tr><td class='l'>{_esc(row['name'])}</td><td>{v:{fmt}}</td>"
                     f"<td>{s:.2g}</td><td class='l'>{_esc(unit)}</td>"
                     f"<td class='l'>{_esc(row['stands_for'])}</td></tr>")
    parts.append("</table>")
    ident = result.identifiability
    if ident is not None and (ident.dropped or ident.zero):
        names = dict(zip(result.model.space.keys, result.model.space.names, strict=True))
        dep = ", ".join(f"{names[k]} (via {', '.join(names[v] for v in ident.via.get(k, ()))})"
                        for k in ident.dropped)
        parts.append(f"<p class='small'>Identified through others: {_esc(dep)}.<br>"
                     "No effect on the measurements: "
                     f"{_esc(', '.join(names[k] for k in ident.zero)) or 'none'}.</p>")
    return parts


def _frames_section(result: CalibrationResult) -> list[str]:
    """BASE and PROBE: x, y, z (mm) and roll, pitch, yaw (degrees)."""
    from plugcell.kinematics.rotations import matrix_to_rpy

    parts = ["<h2>BASE and PROBE</h2><table><tr><th class='l'>frame</th><th>x (mm)</th>"
             "<th>y (mm)</th><th>z (mm)</th><th>roll (°)</th><th>pitch (°)</th>"
             "<th>yaw (°)</th></tr>"]
    for name, T in (("BASE (robot in tracker frame)", result.model.base()),
                    ("PROBE (target in flange frame)", result.model.probe())):
        xyz = T[:3, 3] * 1e3
        rpy = np.degrees(matrix_to_rpy(T[:3, :3]))
        parts.append(f"<tr><td class='l'>{name}</td>"
                     + "".join(f"<td>{x:.3f}</td>" for x in xyz)
                     + "".join(f"<td>{x:.4f}</td>" for x in rpy) + "</tr>")
    parts.append("</table>")
    return parts
