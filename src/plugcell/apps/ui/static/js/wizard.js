// The BASE and PROBE wizards of appendix D (Figures D-3, D-5) and a best-fit tool (thesis 7.5):
// points come from the tracker service (one reading, or a stream while a robot program runs),
// are measured live (the robot program frame_points turns a joint, moves along x0 or holds still
// while the tracker measures: /api/wizard/live), read from a compute service, or typed/pasted;
// fits and frames are computed by plugcell.metrology (/api/fit, /api/wizard/*).
import { $, clear, h } from "./dom.js";
import { firstError, post } from "./api.js";
import { liveServices, on, state } from "./store.js";
import { runTask, stopTask } from "./tasks.js";
import { setFits } from "./view3d.js";
import { renderResiduals } from "./residuals.js";
import { renderTracked } from "./tracked.js";

const WIZARDS = {
  probe: {
    title: "PROBE: the T-MAC frame in the flange frame (D.1, eqs. D.2–D.3)",
    steps: [
      { key: "circle", kind: "circle", min: 3, title: "Circle of the flange",
        text: "SMR in a dowel hole of the flange; turn the last joint a full round in its positive direction and measure along the way (≥ 3 points, more is better).",
        live: { kind: "sweep", joint: 6, from: -150, to: 150, count: 13, reflector: "hole" } },
      { key: "holes", kind: "line", min: 2, title: "Dowel holes → y axis",
        text: "SMR in the two dowel holes defining y of the flange: the hole at −y first, then the one at +y.",
        live: { kind: "holes" } },
    ],
    pose: { key: "tmac", title: "T-MAC pose", text: "Without moving the robot, mount the T-MAC and take one 6-D reading (x, y, z mm; roll, pitch, yaw deg in the tracker frame).",
      live: { kind: "tmac" } },
    send: "Set Probe",
  },
  base: {
    title: "BASE: the robot base frame in the tracker frame (D.2, eq. D.6)",
    steps: [
      { key: "circle", kind: "circle", min: 3, title: "Circle of joint 1",
        text: "A reflector on joint 1 (its outer surface, or the T-MAC on the flange); turn joint 1 in its positive direction and measure along the way.",
        live: { kind: "sweep", joint: 1, from: -60, to: 60, count: 13, reflector: "tmac" } },
      { key: "plane", kind: "plane", min: 3, title: "Base plane (z = 0)",
        text: "SMR on the base surface of the robot: measure a few well-spread positions (by hand: Measure point)." },
      { key: "line", kind: "line", min: 2, title: "Move along x₀",
        text: "Move the robot along its x axis and measure the T-MAC positions, in the order of the move.",
        live: { kind: "line", axis: "x", length: 700, count: 8, reflector: "tmac" } },
    ],
    send: "Set Base",
  },
};

let current = "probe";
const stepState = {};       // wizard → key → {textarea, error, info, fit}
let streaming = null;       // {id, textarea}
// the settings of live measurements, kept across re-renders
const live = { compute: "", base: "", tmac: "", hole: "50", smr: "6.35", joints: "" };

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

function fill(sel, names, empty) {
  if (!sel) return;
  const keep = sel.value;
  clear(sel).append(h("option", { value: "", text: names.length ? "—" : empty }), ...names.map((n) => h("option", { value: n, text: n })));
  sel.value = names.includes(keep) ? keep : (names[0] || "");
}

function computeNames() { return liveServices((s) => s.commands.some((c) => c.name === "Get Matrix")).map((s) => s.name).sort(); }

function sources() {
  fill($("#wiz-tracker"), liveServices((s) => s.commands.some((c) => c.name === "Single Measurement")).map((s) => s.name).sort(), "no tracker service");
  fill($("#wiz-robot"), liveServices((s) => s.commands.some((c) => c.name.toUpperCase() === "ACTIVATE")).map((s) => s.name).sort(), "no robot service");
  for (const sel of document.querySelectorAll("select.compute-service")) fill(sel, computeNames(), "no compute service");
}

/** "x, y, z, …" → numbers (commas, semicolons or blanks); null if not `n` numbers. */
function numbers(text, counts) {
  const parts = text.split(/[,;\s]+/).filter(Boolean);
  const v = parts.map(Number);
  if (!counts.includes(v.length) || v.some((x, i) => !Number.isFinite(x) || !/^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$/.test(parts[i]))) return null;
  return v;
}

// -- live: the robot program frame_points moves the robot, the tracker measures (/api/wizard/live)

function liveSettings() {
  const input = (key, label, cls, placeholder) => {
    const el = h("input", { type: "text", class: cls, value: live[key], placeholder, "aria-label": label, id: `live-${key}` });
    el.addEventListener("input", () => { live[key] = el.value; el.classList.remove("invalid"); });
    return el;
  };
  const compute = h("select", { class: "compute-service", id: "wiz-compute", "aria-label": "compute service" });
  compute.addEventListener("change", () => { live.compute = compute.value; });
  const box = h("details", { class: "live", open: true },
    h("summary", { text: "Measure live: the robot moves, the tracker measures (robot program frame_points), the points come back through the compute service" }),
    h("div", { class: "toolbar" },
      h("label", {}, "compute ", compute),
      h("label", {}, "BASE estimate ", input("base", "BASE estimate", "vec", "x, y, z, roll, pitch, yaw (tracker frame)")),
      h("label", {}, "T-MAC estimate ", input("tmac", "T-MAC estimate", "vec", "x, y, z, roll, pitch, yaw (flange frame)"))),
    h("div", { class: "toolbar" },
      h("label", {}, "dowel holes at y = ± ", input("hole", "dowel hole y", "num", "mm"), " mm"),
      h("label", {}, "SMR centre above the face ", input("smr", "SMR height", "num", "mm"), " mm"),
      h("label", {}, "reference pose ", input("joints", "reference joints", "vec", "where the robot is (or q1, …, q6 deg)"))),
    h("p", { class: "hint", text: "The estimates only aim the beam (10 mm capture radius); points are raw, in the tracker frame. The robot ends at the reference pose. Wire the robot to the tracker and the compute service first." }));
  fill(compute, computeNames(), "no compute service");
  if (live.compute && [...compute.options].some((o) => o.value === live.compute)) compute.value = live.compute;
  return box;
}

function liveError(slot, errors) {
  const fields = { robot: "#wiz-robot", tracker: "#wiz-tracker", compute: "#wiz-compute", base_est: "#live-base", joints: "#live-joints", duration_ms: "#wiz-duration" };
  const [field, msg] = Object.entries(errors || { _: "refused" })[0];
  if (fields[field]) { const el = $(fields[field]); if (el) el.classList.add("invalid"); }
  if (field === "reflectors") for (const id of ["#live-tmac", "#live-hole", "#live-smr"]) { const el = $(id); if (el) el.classList.add("invalid"); }
  if ((field === "sweep" || field === "line") && slot.liveInputs) for (const el of Object.values(slot.liveInputs)) el.classList.add("invalid");
  slot.error.textContent = field === "_" ? msg : `${field}: ${msg}`;
}

/** The body of /api/wizard/live for a step, or an error text. */
function liveBody(spec, inputs) {
  const robot = robotName(); const tracker = trackerName(); const compute = $("#wiz-compute") ? $("#wiz-compute").value : "";
  if (!robot || !tracker || !compute) return [null, "needs a robot, a tracker and a compute service"];
  const base = numbers(live.base, [6]);
  if (!base) { $("#live-base").classList.add("invalid"); return [null, "BASE estimate: six numbers x, y, z mm, roll, pitch, yaw deg (it aims the beam)"]; }
  const hole = Number(live.hole); const smr = Number(live.smr);
  const body = { robot, tracker, compute, base_est: base, duration_ms: Number($("#wiz-duration").value), matrix: "pts" };
  if (live.joints.trim()) {
    const q = numbers(live.joints, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]);
    if (!q) { $("#live-joints").classList.add("invalid"); return [null, "reference pose: joint angles in degrees, or empty for where the robot is"]; }
    body.joints = q;
  }
  let reflector;
  if (spec.kind === "holes" || spec.reflector === "hole") {
    if (!Number.isFinite(hole) || !Number.isFinite(smr) || !live.hole.trim() || !live.smr.trim()) { $("#live-hole").classList.add("invalid"); return [null, "dowel hole y and SMR height: numbers of mm"]; }
    reflector = [0, hole, smr];
  } else {
    reflector = numbers(live.tmac, [6]);
    if (!reflector) { $("#live-tmac").classList.add("invalid"); return [null, "T-MAC estimate: six numbers x, y, z mm, roll, pitch, yaw deg in the flange frame (it aims the beam)"]; }
  }
  const val = (k) => Number(inputs[k].value);
  if (spec.kind === "sweep") body.sweep = { joint: val("joint"), from: val("from"), to: val("to"), count: val("count") };
  else if (spec.kind === "line") body.line = { axis: inputs.axis.value, length: val("length"), count: val("count") };
  body.reflectors = spec.kind === "holes" ? [[0, -hole, smr], [0, hole, smr]] : [reflector];
  return [body, ""];
}

async function measureLive(spec, slot, button, onPoints) {
  slot.error.textContent = "";
  for (const el of document.querySelectorAll("#wizard-panel .invalid")) el.classList.remove("invalid");
  const [body, err] = liveBody(spec, slot.liveInputs || {});
  if (!body) { slot.error.textContent = err; return; }
  const label = button.textContent;
  button.disabled = true; button.textContent = "measuring…";
  const res = await post("/api/wizard/live", body);
  button.disabled = false; button.textContent = label;
  if (!res.ok) { liveError(slot, res.errors); return; }
  onPoints(res.points);
}

function liveRow(step, slot) {
  const spec = step.live;
  const num = (k, label, v) => h("input", { type: "text", inputmode: "decimal", value: v, "aria-label": label });
  const inputs = {};
  const parts = [];
  if (spec.kind === "sweep") {
    Object.assign(inputs, { joint: num("joint", "joint", spec.joint), from: num("from", "from deg", spec.from), to: num("to", "to deg", spec.to), count: num("count", "points", spec.count) });
    parts.push("joint ", inputs.joint, " from ", inputs.from, " to ", inputs.to, "° in ", inputs.count, " points");
  } else if (spec.kind === "line") {
    inputs.axis = h("select", { "aria-label": "axis" }, ...["x", "y", "z"].map((a) => h("option", { value: a, text: `${a}₀` })));
    Object.assign(inputs, { length: num("length", "move mm", spec.length), count: num("count", "points", spec.count) });
    parts.push("along ", inputs.axis, " by ", inputs.length, " mm in ", inputs.count, " points");
  } else parts.push("an SMR in each dowel hole (−y, then +y), robot still");
  slot.liveInputs = inputs;
  for (const el of Object.values(inputs)) el.addEventListener("input", () => el.classList.remove("invalid"));
  const button = h("button", { type: "button", class: "live-btn", text: "Measure live" });
  button.addEventListener("click", () => measureLive(spec, slot, button, (points) => {
    slot.textarea.value = points.map((p) => fmt(p.slice(0, 3), 4)).join("\n") + "\n";
    slot.textarea.dispatchEvent(new Event("input"));
  }));
  return h("div", { class: "live-row", dataset: { live: spec.kind } }, ...parts, button);
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
    step.live ? liveRow(step, slot[step.key]) : null,
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
  if (r.kind === "circle") return `circle: centre ${fmt(r.centre)} mm, radius ${r.radius.toFixed(3)} mm, normal ${fmt(r.normal, 4)}, rms ${r.rms.toFixed(4)} mm, sweep ${r.sweep_deg.toFixed(1)}°${r.oriented ? "" : " (the normal's sign is arbitrary: the points go back and forth)"}`;
  if (r.kind === "line") return `line: through ${fmt(r.point)} mm, direction ${fmt(r.direction, 4)}, rms ${r.rms.toFixed(4)} mm`;
  return `plane: centroid ${fmt(r.centroid)} mm, normal ${fmt(r.normal, 4)}, rms ${r.rms.toFixed(4)} mm, flatness ${r.flatness.toFixed(4)} mm`;
}

function matrixTable(m) {
  return h("table", {}, ...m.map((row) => h("tr", {}, ...row.map((x, j) => h("td", { text: j < 3 ? x.toFixed(6) : x.toFixed(3) })))));
}

function render() {
  const box = clear($("#wizard"));
  const slot = stepState[current] = {};
  $("#wizard-panel .source-row").style.display = ["residuals", "tracked"].includes(current) ? "none" : "";
  if (current === "fit") { renderFit(box, slot); return; }
  if (current === "residuals") { renderResiduals(box); return; }
  if (current === "tracked") { renderTracked(box); return; }
  const wiz = WIZARDS[current];
  box.append(h("p", { class: "hint", text: wiz.title }), liveSettings());
  wiz.steps.forEach((step, i) => box.append(stepBox(i + 1, step, slot)));
  const out = h("div", { id: "wizard-result" });
  let poseInputs = [];
  if (wiz.pose) {
    poseInputs = ["x", "y", "z", "roll", "pitch", "yaw"].map((l) => h("input", { type: "text", inputmode: "decimal", placeholder: l, "aria-label": `T-MAC ${l}`, class: "cell-in" }));
    const err = h("span", { class: "field-error", dataset: { for: wiz.pose.key } });
    slot.pose = { inputs: poseInputs, error: err };
    const liveBtn = h("button", { type: "button", class: "live-btn", text: "Measure T-MAC live", title: "the robot program catches the beam on the T-MAC (its estimate) and measures it, raw" });
    liveBtn.addEventListener("click", () => measureLive(wiz.pose.live, slot.pose, liveBtn, (points) => {
      points[0].forEach((x, i) => { poseInputs[i].value = x.toFixed(4); });
    }));
    box.append(h("div", { class: "step", dataset: { step: wiz.pose.key } },
      h("h3", {}, h("span", { class: "n", text: wiz.steps.length + 1 }), wiz.pose.title),
      h("p", { text: wiz.pose.text }),
      h("div", { class: "toolbar" }, h("button", { type: "button", text: "Measure T-MAC", onclick: () => measureOnce((v) => v.forEach((x, i) => { poseInputs[i].value = x.toFixed(4); }), err) }), liveBtn),
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
  const smr = Number(live.smr);
  if (live.smr.trim() && Number.isFinite(smr)) body.smr_offset = smr;
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
  const step = { key: "fit", kind: "circle", min: 3, title: "Points", text: "Measure, stream, paste or read points from a compute service; the best-fit geometry and each point's residual show in the 3-D view." };
  const service = h("select", { class: "compute-service", "aria-label": "compute service of the points" });
  const name = h("input", { type: "text", value: "mT", class: "cell-in", "aria-label": "points matrix" });
  const owner = h("input", { type: "text", placeholder: "workspace of (robot)", "aria-label": "points workspace of" });
  const get = h("button", { type: "button", text: "Get Matrix" });
  box.append(h("div", { class: "toolbar" }, h("label", {}, "geometry ", kind)), stepBox(1, step, slot),
    h("div", { class: "toolbar", dataset: { step: "fit-compute" } }, h("span", { class: "muted", text: "points from " }), service, name, owner, get));
  fill(service, computeNames(), "no compute service");
  get.addEventListener("click", async () => {
    const s = slot.fit;
    s.error.textContent = "";
    if (!service.value) { s.error.textContent = "no compute service in the cell"; return; }
    get.disabled = true;
    const res = await post("/api/matrix", { service: service.value, name: name.value.trim(), workspace: owner.value.trim() });
    get.disabled = false;
    if (!res.ok) { s.error.textContent = firstError(res); return; }
    if (res.shape[1] < 3) { s.error.textContent = `${res.title} is ${res.shape.join("×")}: x y z columns expected`; return; }
    s.textarea.value = res.rows.map((r) => fmt(r.slice(0, 3), 4)).join("\n") + "\n";
    s.textarea.dispatchEvent(new Event("input"));
  });
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
