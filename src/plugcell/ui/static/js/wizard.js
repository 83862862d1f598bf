// The BASE and PROBE wizards of appendix D (Figures D-3, D-5) and a best-fit tool (thesis 7.5):
// points come from the tracker service (one reading, or a stream while a robot program runs)
// or are typed/pasted; fits and frames are computed by plugcell.metrology (/api/fit, /api/wizard/*).
import { $, clear, h } from "./dom.js";
import { firstError, post } from "./api.js";
import { liveServices, on, state } from "./store.js";
import { runTask, stopTask } from "./tasks.js";
import { setFits } from "./view3d.js";
import { renderResiduals } from "./residuals.js";

const WIZARDS = {
  probe: {
    title: "PROBE: the T-MAC frame in the flange frame (D.1, eqs. D.2–D.3)",
    steps: [
      { key: "circle", kind: "circle", min: 3, title: "Circle of the flange",
        text: "SMR in a dowel hole of the flange; turn the last joint a full round in its positive direction and measure along the way (≥ 3 points, more is better)." },
      { key: "holes", kind: "line", min: 2, title: "Dowel holes → y axis",
        text: "SMR in the two dowel holes defining y of the flange: the hole at −y first, then the one at +y." },
    ],
    pose: { key: "tmac", title: "T-MAC pose", text: "Without moving the robot, mount the T-MAC and take one 6-D reading (x, y, z mm; roll, pitch, yaw deg in the tracker frame)." },
    send: "Set Probe",
  },
  base: {
    title: "BASE: the robot base frame in the tracker frame (D.2, eq. D.6)",
    steps: [
      { key: "circle", kind: "circle", min: 3, title: "Circle of joint 1",
        text: "SMR on the outer surface of joint 1; turn joint 1 in its positive direction and measure along the way." },
      { key: "plane", kind: "plane", min: 3, title: "Base plane (z = 0)",
        text: "SMR on the base surface of the robot: measure a few well-spread positions." },
      { key: "line", kind: "line", min: 2, title: "Move along x₀",
        text: "Move the robot along its x axis and measure the T-MAC positions, in the order of the move." },
    ],
    send: "Set Base",
  },
};

let current = "probe";
const stepState = {};       // wizard → key → {textarea, error, info, fit}
let streaming = null;       // {id, textarea}

function trackerName() { return $("#wiz-tracker").value; }
function robotName() { return $("#wiz-robot").value; }

/** Parse "x y z" / "x, y, z" lines (extra columns ignored); returns [points, error]. */
export function parsePoints(text) {
  const pts = [];
  for (const [i, raw] of text.split("\n").entries()) {
    const line = raw.replace(/#.*/, "").trim();
    if (!line) continue;
    const parts = line.split(/[,;\s]+/).filter(Boolean);
    if (parts.length < 3) return [null, `line ${i + 1}: expected x y z`];
    const xyz = parts.slice(0, 3).map(Number);
    if (xyz.some((v, j) => !Number.isFinite(v) || !/^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$/.test(parts[j]))) return [null, `line ${i + 1}: not a number`];
    pts.push(xyz);
  }
  return [pts, ""];
}

function fmt(v, d = 3) { return v.map((x) => x.toFixed(d)).join(", "); }

function append(textarea, xyz) {
  textarea.value += `${textarea.value && !textarea.value.endsWith("\n") ? "\n" : ""}${fmt(xyz)}\n`;
  textarea.dispatchEvent(new Event("input"));
}

function sources() {
  const fill = (sel, names, empty) => {
    const keep = sel.value;
    clear(sel).append(h("option", { value: "", text: names.length ? "—" : empty }), ...names.map((n) => h("option", { value: n, text: n })));
    sel.value = names.includes(keep) ? keep : (names[0] || "");
  };
  fill($("#wiz-tracker"), liveServices((s) => s.commands.some((c) => c.name === "Single Measurement")).map((s) => s.name).sort(), "no tracker service");
  fill($("#wiz-robot"), liveServices((s) => s.commands.some((c) => c.name.toUpperCase() === "ACTIVATE")).map((s) => s.name).sort(), "no robot service");
}

async function measureOnce(onPoint, error) {
  const tracker = trackerName();
  if (!tracker) { error.textContent = "no tracker service in the cell: type or paste the points"; return null; }
  const duration = Number($("#wiz-duration").value);
  if (!Number.isInteger(duration) || duration < 1 || duration > 60000) { $("#wiz-duration").classList.add("invalid"); error.textContent = "reading ms: 1…60000"; return null; }
  $("#wiz-duration").classList.remove("invalid");
  const r = await runTask({ service: tracker, command: "Single Measurement", option: "tr2rpy", data: [duration] });
  if (!r.ok) { error.textContent = `measurement failed: ${r.reason}`; return null; }
  const v = r.data && r.data.value;
  if (!Array.isArray(v)) { error.textContent = "the tracker returned no pose"; return null; }
  onPoint(v);
  return v;
}

async function lockOn(error) {
  const tracker = trackerName(); const robot = robotName();
  if (!tracker || !robot) { error.textContent = "needs a tracker and a robot service"; return; }
  const pos = await runTask({ service: robot, command: "ARM_POS" });
  if (!pos.ok) { error.textContent = `${robot} ARM_POS: ${pos.reason}`; return; }
  const move = await runTask({ service: tracker, command: "Move", data: pos.data.value });
  error.textContent = move.ok ? "" : `${tracker} Move: ${move.reason}`;
}

async function toggleStream(textarea, button, error, programInput) {
  if (streaming) {
    const s = streaming; streaming = null;
    button.textContent = "Stream";
    await stopTask(s.id);
    return;
  }
  const tracker = trackerName();
  if (!tracker) { error.textContent = "no tracker service in the cell"; return; }
  const interval = Math.max(1, Number($("#wiz-duration").value) || 100);
  button.textContent = "Stop";
  const run = runTask({ service: tracker, command: "Continuous Measurement", option: "tr2rpy", data: [interval] }, {
    timeoutMs: 3600000,
    onStarted: (id) => { streaming = { id, textarea }; },
    onData: (d) => { if (Array.isArray(d.value)) append(textarea, d.value); },
  });
  const program = programInput.value.trim();
  if (program) {
    const robot = robotName();
    if (!robot) error.textContent = "no robot service to run the program";
    else {
      const res = await post("/api/runs", { items: [{ robot, program }], mode: "sequential" });
      if (!res.ok) error.textContent = firstError(res);
      else waitRun(res.run.id, () => { if (streaming) toggleStream(textarea, button, error, programInput); });
    }
  }
  const r = await run;
  button.textContent = "Stream";
  streaming = null;
  if (!r.ok && !/stopped/.test(r.reason || "")) error.textContent = `stream: ${r.reason}`;
}

function waitRun(id, done) {
  const check = () => {
    const run = state.runs.get(id);
    if (run && run.state !== "Running") { done(run); return true; }
    return false;
  };
  if (check()) return;
  const timer = setInterval(() => { if (check()) clearInterval(timer); }, 250);
  setTimeout(() => clearInterval(timer), 3600000);
}

function stepBox(n, step, slot) {
  const textarea = h("textarea", { name: `points-${step.key}`, placeholder: "x y z (mm), one point per line — or measure", spellcheck: "false" });
  const error = h("span", { class: "field-error", dataset: { for: step.key } });
  const info = h("div", { class: "pts" });
  const fitline = h("div", { class: "fitline" });
  const program = h("input", { type: "text", list: "program-names", placeholder: "robot program (optional)", "aria-label": "program to run while streaming" });
  const streamBtn = h("button", { type: "button", text: "Stream" });
  streamBtn.addEventListener("click", () => toggleStream(textarea, streamBtn, error, program));
  slot[step.key] = { textarea, error, info, fitline, step };
  textarea.addEventListener("input", () => { error.textContent = ""; textarea.classList.remove("invalid"); previewStep(slot[step.key]); });
  return h("div", { class: "step", dataset: { step: step.key } },
    h("h3", {}, h("span", { class: "n", text: n }), step.title),
    h("p", { text: step.text }),
    h("div", { class: "toolbar" },
      h("button", { type: "button", text: "Measure point", onclick: () => measureOnce((v) => append(textarea, v), error) }),
      streamBtn, program,
      h("button", { type: "button", text: "Lock on robot", title: "ARM_POS of the robot, then the tracker's Move to it (eq. 7.1)", onclick: () => lockOn(error) }),
      h("button", { type: "button", text: "Clear", onclick: () => { textarea.value = ""; textarea.dispatchEvent(new Event("input")); } })),
    textarea, info, fitline, error);
}

let previewTimer = null;
function previewStep(slot) {
  const [pts, err] = parsePoints(slot.textarea.value);
  if (err) { slot.error.textContent = err; slot.textarea.classList.add("invalid"); slot.info.textContent = ""; return; }
  slot.info.textContent = `${pts.length} point${pts.length === 1 ? "" : "s"}${pts.length < slot.step.min ? ` — at least ${slot.step.min} needed` : ""}`;
  slot.fitline.textContent = "";
  clearTimeout(previewTimer);
  previewTimer = setTimeout(() => showPreview(), 250);
}

async function showPreview() {
  const slots = stepState[current] || {};
  const layers = [];
  for (const slot of Object.values(slots)) {
    if (!slot.step) continue;
    const [pts, err] = parsePoints(slot.textarea.value);
    if (err || pts.length < slot.step.min) { if (pts && pts.length) layers.push({ name: slot.step.key, points: pts }); continue; }
    const res = await post("/api/fit", { kind: slot.step.kind, points: pts });
    if (!res.ok) { slot.error.textContent = firstError(res); layers.push({ name: slot.step.key, points: pts }); continue; }
    slot.fitline.textContent = fitText(res);
    const spread = Math.max(...[0, 1, 2].map((i) => Math.max(...pts.map((p) => p[i])) - Math.min(...pts.map((p) => p[i]))));
    layers.push({ name: slot.step.key, points: pts, residuals: res.residuals, geometry: { ...res, size: spread / 1.6 } });
  }
  setFits(layers);
}

function fitText(r) {
  if (r.kind === "circle") return `circle: centre ${fmt(r.centre)} mm, radius ${r.radius.toFixed(3)} mm, normal ${fmt(r.normal, 4)}, rms ${r.rms.toFixed(4)} mm, sweep ${r.sweep_deg.toFixed(1)}°`;
  if (r.kind === "line") return `line: through ${fmt(r.point)} mm, direction ${fmt(r.direction, 4)}, rms ${r.rms.toFixed(4)} mm`;
  return `plane: centroid ${fmt(r.centroid)} mm, normal ${fmt(r.normal, 4)}, rms ${r.rms.toFixed(4)} mm, flatness ${r.flatness.toFixed(4)} mm`;
}

function matrixTable(m) {
  return h("table", {}, ...m.map((row) => h("tr", {}, ...row.map((x, j) => h("td", { text: j < 3 ? x.toFixed(6) : x.toFixed(3) })))));
}

function render() {
  const box = clear($("#wizard"));
  const slot = stepState[current] = {};
  $("#wizard-panel .source-row").style.display = current === "residuals" ? "none" : "";
  if (current === "fit") { renderFit(box, slot); return; }
  if (current === "residuals") { renderResiduals(box); return; }
  const wiz = WIZARDS[current];
  box.append(h("p", { class: "hint", text: wiz.title }));
  wiz.steps.forEach((step, i) => box.append(stepBox(i + 1, step, slot)));
  const out = h("div", { id: "wizard-result" });
  let poseInputs = [];
  if (wiz.pose) {
    poseInputs = ["x", "y", "z", "roll", "pitch", "yaw"].map((l) => h("input", { type: "text", inputmode: "decimal", placeholder: l, "aria-label": `T-MAC ${l}`, class: "cell-in" }));
    const err = h("span", { class: "field-error", dataset: { for: wiz.pose.key } });
    slot.pose = { inputs: poseInputs, error: err };
    box.append(h("div", { class: "step", dataset: { step: wiz.pose.key } },
      h("h3", {}, h("span", { class: "n", text: wiz.steps.length + 1 }), wiz.pose.title),
      h("p", { text: wiz.pose.text }),
      h("div", { class: "toolbar" }, h("button", { type: "button", text: "Measure T-MAC", onclick: () => measureOnce((v) => v.forEach((x, i) => { poseInputs[i].value = x.toFixed(4); }), err) })),
      h("div", { class: "toolbar" }, ...poseInputs), err));
  }
  const compute = h("button", { class: "primary", type: "button", text: `Compute ${current.toUpperCase()}` });
  const err = h("span", { class: "field-error", dataset: { for: "_" } });
  compute.addEventListener("click", () => computeWizard(slot, out, err));
  box.append(h("div", { class: "toolbar" }, compute, err), out);
}

async function computeWizard(slot, out, err) {
  err.textContent = ""; clear(out);
  const body = {};
  let bad = false;
  for (const [key, s] of Object.entries(slot)) {
    if (!s.step) continue;
    const [pts, e] = parsePoints(s.textarea.value);
    if (e || pts.length < s.step.min) { s.error.textContent = e || `at least ${s.step.min} points`; s.textarea.classList.add("invalid"); bad = true; continue; }
    body[key] = pts;
  }
  if (slot.pose) {
    const vals = slot.pose.inputs.map((i) => i.value.trim());
    const nums = vals.map(Number);
    slot.pose.inputs.forEach((inp, i) => inp.classList.toggle("invalid", vals[i] === "" || !Number.isFinite(nums[i])));
    if (vals.some((v, i) => v === "" || !Number.isFinite(nums[i]))) { slot.pose.error.textContent = "six numbers: x, y, z mm, roll, pitch, yaw deg"; bad = true; }
    else slot.pose.error.textContent = "";
    body.tmac = nums;
  }
  if (bad) { err.textContent = "fix the marked fields first"; return; }
  const res = await post(`/api/wizard/${current}`, body);
  if (!res.ok) {
    for (const [k, msg] of Object.entries(res.errors || {})) {
      const target = slot[k] ? slot[k].error : (k === "tmac" && slot.pose ? slot.pose.error : err);
      target.textContent = msg;
    }
    return;
  }
  const frame = current === "probe" ? res.probe : res.base;
  const wiz = WIZARDS[current];
  const send = h("button", { type: "button", text: `${wiz.send} on ${trackerName() || "tracker"}`, disabled: !trackerName() });
  const sent = h("span", { class: "ok-text" });
  send.addEventListener("click", async () => {
    const r = await runTask({ service: trackerName(), command: wiz.send, option: "rpy2tr", data: frame.vector });
    sent.textContent = r.ok ? `${wiz.send} completed` : ""; if (!r.ok) err.textContent = r.reason;
  });
  out.append(h("div", { class: "result", dataset: { result: current } },
    h("b", { text: current === "probe" ? "PROBE = (T_n^LT)⁻¹ · T_TMAC^LT" : "BASE = F₀ in the tracker frame" }),
    matrixTable(frame.matrix),
    h("div", { class: "vector", text: `rpy2tr vector: ${fmt(frame.vector, 4)}` }),
    res.parameters ? h("div", { class: "vector", text: `eq. D.6: ${Object.entries(res.parameters).map(([k, v]) => `${k} ${v.toFixed(4)}`).join(", ")}` }) : null,
    h("div", { class: "muted", text: current === "probe"
      ? `circle rms ${res.circle.rms.toFixed(4)} mm · hole line tilt ${res.hole_line_tilt_deg.toFixed(3)}°`
      : `circle rms ${res.circle.rms.toFixed(4)} mm · plane rms ${res.plane.rms.toFixed(4)} mm · axis ⟂ plane ${res.axis_plane_angle_deg.toFixed(3)}° · line tilt ${res.line_tilt_deg.toFixed(3)}°` }),
    h("div", { class: "toolbar" }, send, sent)));
}

function renderFit(box, slot) {
  const kind = h("select", { "aria-label": "geometry" }, ...["circle", "line", "plane"].map((k) => h("option", { value: k, text: k })));
  const step = { key: "fit", kind: "circle", min: 3, title: "Points", text: "Measure, stream or paste points; the best-fit geometry and each point's residual show in the 3-D view." };
  box.append(h("div", { class: "toolbar" }, h("label", {}, "geometry ", kind)), stepBox(1, step, slot));
  kind.addEventListener("change", () => { step.kind = kind.value; step.min = kind.value === "line" ? 2 : 3; previewStep(slot.fit); });
}

export function initWizard() {
  for (const b of document.querySelectorAll("#wizard-tabs button")) {
    b.addEventListener("click", () => {
      current = b.dataset.wizard;
      for (const x of document.querySelectorAll("#wizard-tabs button")) x.classList.toggle("active", x === b);
      render(); showPreview();
    });
  }
  on("cell", sources);
  render();
}
