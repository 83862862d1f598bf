// A tracked path's result (issue 38): the file of `plugcell path run … --out result.json`.
// The API (/api/tracked-path) checks it and gives each path's deviation from the commanded
// one over time — corrected (the loop's correction), actual (the TCP's true deviation) and
// measured (the tracker's samples) — which this draws as an SVG plot, with the windows
// without tracking shaded and the accuracy table of the run.  Its "Live" mode follows a
// robot's tracked move as it goes (tracked_live.js).
import { clear, h } from "./dom.js";
import { post } from "./api.js";
import { SERIES, mm, plot } from "./deviation_plot.js";
import { renderLive } from "./tracked_live.js";

let shown = null;   // the last answer (kept across sub-tab switches)
let ui = null;
let mode = "file";  // "file": a run's result; "live": a robot's tracked move as it goes

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

/** The "Tracked path" sub-tab of the metrology panel: a run's result file, or live. */
export function renderTracked(box) {
  const modes = h("div", { class: "subtabs", role: "tablist" },
    ...[["file", "Result file"], ["live", "Live"]].map(([m, label]) => h("button", {
      type: "button", class: m === mode ? "active" : undefined, dataset: { mode: m }, text: label,
      onclick: () => { mode = m; renderTracked(clear(box)); } })));
  box.append(modes);
  if (mode === "live") { renderLive(box); return; }
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
