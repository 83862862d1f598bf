// Calibration residuals in the 3-D view (the visualisation service of thesis 7.5): the file of
// `plugcell calibrate --residuals`, a pasted N×6 matrix (x y z dx dy dz mm, the compute service's
// residuals(params, mJ, mT)), or that matrix read from a compute service (Get Matrix).
// The API (/api/residuals) checks and summarises them; view3d.js draws them.
import { $, clear, h } from "./dom.js";
import { post } from "./api.js";
import { liveServices, on } from "./store.js";
import { setResidualOptions, setResiduals } from "./view3d.js";

let shown = null;    // the last answer of /api/residuals (kept across sub-tab switches)
let ui = null;       // the elements of the rendered sub-tab

const NUMBER = /^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$/;

/** Rows of 6 numbers ("x y z dx dy dz", commas or spaces; # comments); returns [rows, error]. */
export function parseMatrix(text) {
  const rows = [];
  for (const [i, raw] of text.split("\n").entries()) {
    const line = raw.replace(/#.*/, "").trim();
    if (!line) continue;
    const parts = line.split(/[,;\s]+/).filter(Boolean);
    if (parts.length !== 6) return [null, `line ${i + 1}: expected 6 numbers x y z dx dy dz (mm)`];
    if (!parts.every((p) => NUMBER.test(p))) return [null, `line ${i + 1}: not a number`];
    rows.push(parts.map(Number));
  }
  if (!rows.length) return [null, "paste a residual file or rows x y z dx dy dz (mm)"];
  return [rows, ""];
}

function computeServices() {
  return liveServices((s) => s.commands.some((c) => c.name === "Get Matrix")).map((s) => s.name).sort();
}

function fillServices() {
  if (!ui || !ui.service.isConnected) return;
  const names = computeServices();
  const keep = ui.service.value;
  clear(ui.service).append(...(names.length ? names.map((n) => h("option", { value: n, text: n }))
    : [h("option", { value: "", text: "no compute service" })]));
  ui.service.value = names.includes(keep) ? keep : (names[0] || "");
}

function mm(x) { return x === null || x === undefined ? "—" : x.toFixed(3); }

function summary(view) {
  const rows = Object.entries(view.sets).map(([name, s]) => h("tr", { dataset: { set: name } },
    h("td", { class: "l", text: name }), h("td", { text: s.poses }), h("td", { text: mm(s.before_mean_mm) }),
    h("td", { text: mm(s.mean_mm) }), h("td", { text: mm(s.rms_mm) }), h("td", { text: mm(s.max_mm) })));
  return h("div", { class: "result", dataset: { result: "residuals" } },
    h("b", { text: view.title || (view.source === "document" ? "residual file" : "residual matrix") }),
    h("table", {}, h("tr", {}, ...["set", "poses", "mean before", "mean after", "rms after", "max after"].map((t, i) => h("th", { text: t, class: i ? undefined : "l" }))), ...rows),
    h("div", { class: "muted", text: "|Δp| in mm, measured − model, tracker frame; before: nominal robot with BASE/PROBE fitted" }));
}

function show(view) {
  shown = view;
  setResiduals(view);
  if (ui) clear(ui.out).append(summary(view));
}

function setError(el, input, text) {
  el.textContent = text;
  if (input) input.classList.toggle("invalid", Boolean(text));
}

async function submitText() {
  const text = ui.text.value.trim();
  setError(ui.fileError, ui.text, "");
  let body;
  if (text.startsWith("{")) {
    try { body = { document: JSON.parse(text) }; } catch (exc) { setError(ui.fileError, ui.text, `not JSON: ${exc.message}`); return; }
  } else {
    const [rows, err] = parseMatrix(text);
    if (err) { setError(ui.fileError, ui.text, err); return; }
    body = { matrix: rows };
  }
  const res = await post("/api/residuals", body);
  if (!res.ok) { setError(ui.fileError, ui.text, Object.values(res.errors || {})[0] || "refused"); return; }
  show(res);
}

async function fetchMatrix() {
  for (const el of [ui.service, ui.name, ui.owner]) el.classList.remove("invalid");
  ui.computeError.textContent = "";
  if (!ui.service.value) { setError(ui.computeError, ui.service, "no compute service in the cell"); return; }
  ui.fetch.disabled = true;
  const res = await post("/api/residuals", { service: ui.service.value, name: ui.name.value.trim(), workspace: ui.owner.value.trim() });
  ui.fetch.disabled = false;
  if (!res.ok) {
    const [field, msg] = Object.entries(res.errors || { _: "refused" })[0];
    setError(ui.computeError, { service: ui.service, name: ui.name, workspace: ui.owner }[field], msg);
    return;
  }
  show(res);
}

/** The "Residuals" sub-tab of the metrology panel. */
export function renderResiduals(box) {
  const file = h("input", { type: "file", accept: ".json,application/json", "aria-label": "residual file" });
  const text = h("textarea", { name: "residual-text", spellcheck: "false", placeholder: "a residual file (JSON) — or rows x y z dx dy dz (mm), one pose per line" });
  const fileError = h("span", { class: "field-error", dataset: { for: "residuals" } });
  const service = h("select", { "aria-label": "compute service" });
  const name = h("input", { type: "text", value: "res", "aria-label": "matrix name", class: "cell-in" });
  const owner = h("input", { type: "text", placeholder: "workspace of (robot)", "aria-label": "workspace of" });
  const fetch = h("button", { type: "button", text: "Get Matrix" });
  const computeError = h("span", { class: "field-error", dataset: { for: "compute" } });
  const set = h("select", { "aria-label": "poses shown" }, ...["all", "calibration", "validation"].map((v) => h("option", { value: v, text: v })));
  const before = h("input", { type: "checkbox", "aria-label": "arrows before calibration" });
  const out = h("div", { id: "residual-result" });
  ui = { text, fileError, service, name, owner, fetch, computeError, out };

  file.addEventListener("change", async () => {
    const f = file.files && file.files[0];
    if (!f) return;
    text.value = await f.text();
    submitText();
  });
  text.addEventListener("input", () => setError(fileError, text, ""));
  fetch.addEventListener("click", fetchMatrix);
  set.addEventListener("change", () => setResidualOptions({ set: set.value }));
  before.addEventListener("change", () => setResidualOptions({ before: before.checked }));
  setResidualOptions({ set: "all", before: false });

  box.append(
    h("p", { class: "hint", text: "Calibration residuals: every pose's measured position with its error (measured − model) as an arrow, coloured by |Δp| after calibration." }),
    h("div", { class: "step", dataset: { step: "residual-file" } },
      h("h3", {}, h("span", { class: "n", text: "1" }), "Residual file or matrix"),
      h("p", { text: "The file of plugcell calibrate … --residuals RES.json (calibration and validation poses, before and after), or the N×6 matrix of the compute service's residuals(params, mJ, mT) pasted as rows x y z dx dy dz (mm)." }),
      h("div", { class: "toolbar" }, file, h("button", { type: "button", class: "primary", text: "Show", onclick: submitText })),
      text, fileError),
    h("div", { class: "step", dataset: { step: "residual-compute" } },
      h("h3", {}, h("span", { class: "n", text: "2" }), "From a compute service"),
      h("p", { text: "A robot program computes res = residuals(params, mJ, mT) in its workspace; Get Matrix reads it (workspace of: the robot's name)." }),
      h("div", { class: "toolbar" }, service, name, owner, fetch), computeError),
    h("div", { class: "toolbar" }, h("label", {}, "show ", set), h("label", { class: "check" }, before, " arrows before calibration (grey)")),
    out);
  fillServices();
  if (shown) out.append(summary(shown));
}

export function initResiduals() { on("cell", fillServices); }
