// The plot of a tracked path's deviations from the commanded path over time (issue 38):
// an SVG of polylines (mm over s), the windows without tracking shaded.  Drawn for a run's
// result file (tracked.js) and for a robot's tracked move as it goes (tracked_live.js).
import { s } from "./dom.js";

const W = 760, H = 270, M = { l: 48, r: 16, t: 16, b: 36 };
export const SERIES = [
  ["measured", "#7fa7d9", "measured (tracker)"],
  ["corrected", "#e0b050", "corrected (command)"],
  ["actual", "#5fd39b", "actual (true TCP)"],
];

export function mm(x) { return typeof x === "number" ? x.toFixed(3) : "—"; }

/**
 * About n "nice" ticks in [lo, hi]: multiples of a step 1, 2 or 5 × 10^k, with the
 * decimals the step needs ({values, decimals}), so that labels neither repeat nor crowd.
 */
export function ticks(lo, hi, n) {
  const span = Math.max(hi - lo, 1e-9);
  const pow = 10 ** Math.floor(Math.log10(span / n));
  const at = (step) => {
    const values = [];
    for (let k = Math.ceil(lo / step - 1e-9); k * step <= hi + step * 1e-9; k++) values.push(k * step);
    return values;
  };
  // the step whose count of ticks is nearest n, among those that give two or more (the
  // finest, 10^k ≤ span/n, always does)
  const steps = [1, 2, 5, 10].map((m) => m * pow).filter((st) => at(st).length >= 2);
  const step = steps.reduce((a, b) => (Math.abs(at(b).length - 1 - n) < Math.abs(at(a).length - 1 - n) ? b : a));
  return { values: at(step), decimals: Math.max(0, -Math.floor(Math.log10(step) + 1e-9)) };
}

/** Runs of consecutive points with a value ([t, v] with v null: a gap between runs). */
function runs(pts) {
  const out = [];
  let cur = [];
  for (const p of pts) {
    if (p[1] === null) { if (cur.length) out.push(cur); cur = []; } else cur.push(p);
  }
  if (cur.length) out.push(cur);
  return out;
}

/**
 * The SVG plot of the deviations (mm) over time (s): view = {span_s: [t0, t1], max_mm:
 * {series: mm}, windows: [{start_s, end_s, reason}], series: {name: [[t, mm or null]]}} —
 * a null value is a gap (no sample), each run between gaps a polyline of its own.
 */
export function plot(view) {
  const [t0, t1] = view.span_s;
  const ymax = Math.max(1e-3, ...Object.values(view.max_mm)) * 1.08;
  const x = (t) => M.l + ((t - t0) / Math.max(t1 - t0, 1e-9)) * (W - M.l - M.r);
  const y = (v) => H - M.b - (v / ymax) * (H - M.t - M.b);
  const svg = s("svg", { viewBox: `0 0 ${W} ${H}`, class: "tracked-plot", role: "img",
    "aria-label": "deviation from the commanded path" });
  for (const w of view.windows) {
    const a = x(Math.max(w.start_s, t0)), b = x(w.end_s === null ? t1 : Math.min(w.end_s, t1));
    svg.append(s("rect", { x: a, y: M.t, width: Math.max(b - a, 1), height: H - M.t - M.b,
      fill: "#553333", "fill-opacity": 0.5, class: "window", dataset: { reason: w.reason } },
    s("title", { text: `without tracking: ${w.reason}` })));
  }
  const label = { fill: "#8aa", "font-size": 10, class: "tick" };
  const yt = ticks(0, ymax, 4);
  for (const v of yt.values) {
    svg.append(s("line", { x1: M.l, x2: W - M.r, y1: y(v), y2: y(v), stroke: "#2a3a3a" }),
      s("text", { ...label, x: M.l - 4, y: y(v) + 4, "text-anchor": "end", text: v.toFixed(yt.decimals) }));
  }
  const xt = ticks(t0, t1, 6);
  for (const t of xt.values) {
    svg.append(s("text", { ...label, x: x(t), y: H - M.b + 14, "text-anchor": "middle", text: t.toFixed(xt.decimals) }));
  }
  svg.append(s("text", { fill: "#8aa", "font-size": 10, x: 4, y: M.t - 5, text: "deviation (mm)" }),
    s("text", { fill: "#8aa", "font-size": 10, x: (M.l + W - M.r) / 2, y: H - 4, "text-anchor": "middle",
      text: "time on the path (s)" }));
  for (const [name, colour] of SERIES) {
    const pts = view.series[name];
    if (!pts || !pts.length) continue;
    for (const run of runs(pts)) {
      const d = run.map(([t, v]) => `${x(t).toFixed(1)},${y(v).toFixed(1)}`).join(" ");
      svg.append(s("polyline", { points: d, fill: "none", stroke: colour, "stroke-width": name === "measured" ? 1 : 1.6,
        class: "series", dataset: { series: name, points: run.length } }));
    }
  }
  return svg;
}
