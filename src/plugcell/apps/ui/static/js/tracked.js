// A tracked path's result (issue 38): the file of `plugcell path run … --out result.json`.
// The API (/api/tracked-path) checks it and gives each path's deviation from the commanded
// one over time — corrected (the loop's correction), actual (the TCP's true deviation) and
// measured (the tracker's samples) — which this draws as an SVG plot, with the windows
// without tracking shaded and the accuracy table of the run.
import { clear, h, s } from "./dom.js";
import { post } from "./api.js";

let shown = null;   // the last answer (kept across sub-tab switches)
let ui = null;

const W = 760, H = 260, M = { l: 48, r: 12, t: 10, b: 28 };
const SERIES = [
  ["measured", "#7fa7d9", "measured (tracker)"],
  ["corrected", "#e0b050", "corrected (command)"],
  ["actual", "#5fd39b", "actual (true TCP)"],
];

function mm(x) { return typeof x === "number" ? x.toFixed(3) : "—"; }

function ticks(lo, hi, n) {
  const step = (hi - lo) / n;
  return Array.from({ length: n + 1 }, (_, i) => lo + i * step);
}

/** The SVG plot of the deviations (mm) over time (s). */
function plot(view) {
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
  for (const v of ticks(0, ymax, 4)) {
    svg.append(s("line", { x1: M.l, x2: W - M.r, y1: y(v), y2: y(v), stroke: "#2a3a3a" }),
      s("text", { x: M.l - 4, y: y(v) + 4, "text-anchor": "end", fill: "#8aa", "font-size": 10, text: v.toFixed(2) }));
  }
  for (const t of ticks(t0, t1, 6)) {
    svg.append(s("text", { x: x(t), y: H - 10, "text-anchor": "middle", fill: "#8aa", "font-size": 10, text: t.toFixed(2) }));
  }
  svg.append(s("text", { x: 4, y: M.t + 8, fill: "#8aa", "font-size": 10, text: "mm" }),
    s("text", { x: W - M.r, y: H - 10, "text-anchor": "end", fill: "#8aa", "font-size": 10, text: "s" }));
  for (const [name, colour] of SERIES) {
    const pts = view.series[name];
    if (!pts || !pts.length) continue;
    const d = pts.map(([t, v]) => `${x(t).toFixed(1)},${y(v).toFixed(1)}`).join(" ");
    svg.append(s("polyline", { points: d, fill: "none", stroke: colour, "stroke-width": name === "measured" ? 1 : 1.6,
      class: "series", dataset: { series: name, points: pts.length } }));
  }
  return svg;
}

function table(view) {
  const head = ["segment", "state", "cycles", "perp max", "perp 3σ", "along max"];
  const rows = view.accuracy.map((r) => h("tr", { dataset: { segment: r.segment, state: r.state } },
    h("td", { class: "l", text: r.segment < 0 ? "path" : String(r.segment + 1) }), h("td", { class: "l", text: r.state }),
    h("td", { text: r.cycles }), h("td", { text: mm(r.perpendicular_max_mm) }),
    h("td", { text: mm(r.perpendicular_3sigma_mm) }), h("td", { text: mm(r.along_max_mm) })));
  return h("table", {}, h("tr", {}, ...head.map((t, i) => h("th", { text: t, class: i < 2 ? "l" : undefined }))), ...rows);
}

function summary(view) {
  const legend = h("div", { class: "legend" }, ...SERIES.map(([name, , label]) =>
    h("span", { dataset: { legend: name } }, h("span", { text: "━ ", class: `sw-${name}` }),
      `${label}: max ${mm(view.max_mm[name])} mm  `)));
  const windows = view.windows.map((w) => h("div", { class: "muted", dataset: { window: w.reason },
    text: `without tracking: ${w.start_s.toFixed(3)} s – ${w.end_s === null ? "end" : `${w.end_s.toFixed(3)} s`} (${w.reason})` }));
  return h("div", { class: "result", dataset: { result: "tracked" } },
    h("b", { text: view.title }),
    view.ended ? h("div", { class: "field-error", text: `ended early: ${view.ended}` }) : null,
    plot(view), legend, ...windows, table(view),
    h("div", { class: "muted", text: "deviation from the commanded path |p − p_commanded| in mm; accuracy per segment in mm (perpendicular max and 3σ, along max), against the true TCP" }));
}

function show(view) {
  shown = view;
  if (ui) clear(ui.out).append(summary(view));
}

function setError(text) {
  ui.error.textContent = text;
  ui.text.classList.toggle("invalid", Boolean(text));
}

async function submit() {
  const text = ui.text.value.trim();
  setError("");
  let doc;
  try { doc = JSON.parse(text); } catch (exc) { setError(`not JSON: ${exc.message}`); return; }
  const res = await post("/api/tracked-path", { document: doc });
  if (!res.ok) { setError(Object.values(res.errors || {})[0] || "refused"); return; }
  show(res);
}

/** The "Tracked path" sub-tab of the metrology panel. */
export function renderTracked(box) {
  const file = h("input", { type: "file", accept: ".json,application/json", "aria-label": "tracked path result" });
  const text = h("textarea", { name: "tracked-text", spellcheck: "false", placeholder: "the result file of plugcell path run … --out result.json" });
  const error = h("span", { class: "field-error", dataset: { for: "tracked" } });
  const out = h("div", { id: "tracked-result" });
  ui = { text, error, out };
  file.addEventListener("change", async () => {
    const f = file.files && file.files[0];
    if (!f) return;
    text.value = await f.text();
    submit();
  });
  text.addEventListener("input", () => setError(""));
  box.append(
    h("p", { class: "hint", text: "A path run with the laser tracker in the loop: how far the commanded correction, the tracker's samples and the true TCP were from the commanded path, over time, with the windows without tracking shaded." }),
    h("div", { class: "step", dataset: { step: "tracked-file" } },
      h("h3", {}, h("span", { class: "n", text: "1" }), "Result file"),
      h("p", { text: "The file of plugcell path run --path PATH.csv (or --program FILE.pdl) --out result.json (docs/tracked-paths.md)." }),
      h("div", { class: "toolbar" }, file, h("button", { type: "button", class: "primary", text: "Show", onclick: submit })),
      text, error),
    out);
  if (shown) out.append(summary(shown));
}
