// A robot's tracked move as it goes (issue 38 §2): the controller relays each robot
// service's batches as `tracking` events (and the moves so far in its snapshot); this keeps
// each robot's latest move and draws it live in Metrology → Tracked path → Live: the
// deviations of the corrected command and of the tracker's measurement from the commanded
// path over the path's time (mm; the measured line breaks where no fresh sample came: a
// beam break; the stretches the loop held on the model alone shaded as they come),
// "move N of program P, running / ended", and the robot to follow.
import { clear, h } from "./dom.js";
import { on } from "./store.js";
import { SERIES, mm, plot } from "./deviation_plot.js";

const MAX_POINTS = 8000;      // points of one move kept at most (then halved by pairs)
const moves = new Map();      // service → {identity, points: [[t_s, corr_m, meas_m|null, holding]], end, running, batches}
let ui = null;                // the live pane while it is shown
let chosen = "";              // the robot followed
let drawing = false;

function sameMove(a, b) {
  return a && b && a.start_ns === b.start_ns && a.move === b.move;
}

/** Half the points, each pair's last time and largest deviations (null: neither had one),
 * holding if either held. */
function halve(points) {
  const out = [];
  for (let i = 0; i < points.length; i += 2) {
    const a = points[i], b = points[i + 1] || a;
    const m = [a[2], b[2]].filter((v) => v !== null);
    out.push([b[0], Math.max(a[1], b[1]), m.length ? Math.max(...m) : null, Boolean(a[3] || b[3])]);
  }
  return out;
}

function onTracking(ev) {
  let move = moves.get(ev.service);
  if (ev.whole || !move || !sameMove(move.identity, ev.identity)) {
    move = { identity: ev.identity, points: [], end: null, running: true, batches: 0 };
    moves.set(ev.service, move);
  }
  for (const p of ev.points) move.points.push(p);
  if (move.points.length > MAX_POINTS) move.points = halve(move.points);
  move.end = ev.end;
  move.running = ev.running;
  move.batches += 1;
  if (!chosen) chosen = ev.service;
  schedule();
}
on("tracking", onTracking);

function schedule() {
  if (!ui || drawing) return;
  drawing = true;
  requestAnimationFrame(() => { drawing = false; draw(); });
}

/** The words of a move: "move N of program P (run R) on TRACKER — running / ended". */
function status(move) {
  const id = move.identity;
  const prog = id.program ? `program ${id.program.split("/").pop()} (run ${id.run})` : "no program";
  let state = move.running ? "running" : "ended";
  if (!move.running && move.end && move.end.failure) state = `ended: ${move.end.failure}`;
  return `move ${id.number} of ${prog} with ${id.tracker}, started ${new Date(id.start_ns / 1e6).toLocaleTimeString()} — ${state}`;
}

/** While the move runs: its stretches on the model alone so far (the loop held). */
function holdingRuns(pts) {
  const out = [];
  let start = null;
  pts.forEach((p) => {
    if (p[3] && start === null) start = p[0];
    if (!p[3] && start !== null) { out.push({ start_s: start, end_s: p[0], reason: "holding" }); start = null; }
  });
  if (start !== null) out.push({ start_s: start, end_s: null, reason: "holding" });
  return out;
}

/** The plot's view of a move (m → mm here, the one place they are shown). */
function view(move) {
  const pts = move.points;
  const corrected = pts.map((p) => [p[0], p[1] * 1e3]);
  const measured = pts.map((p) => [p[0], p[2] === null ? null : p[2] * 1e3]);
  const top = (s) => Math.max(0, ...s.filter((p) => p[1] !== null).map((p) => p[1]));
  const t0 = pts.length ? pts[0][0] : 0, t1 = pts.length ? pts[pts.length - 1][0] : 1;
  const windows = move.end ? move.end.windows.map(([start_s, end_s, reason]) => ({ start_s, end_s, reason }))
    : holdingRuns(pts);
  return { span_s: [t0, Math.max(t1, t0 + 1e-3)], max_mm: { corrected: top(corrected), measured: top(measured) },
    windows, series: { corrected, measured } };
}

function draw() {
  if (!ui || !ui.out.isConnected) { ui = null; return; }
  const names = [...moves.keys()].sort();
  if (names.join() !== [...ui.robot.options].map((o) => o.value).join()) {
    clear(ui.robot).append(...names.map((n) => h("option", { value: n, text: n })));
  }
  ui.robot.value = chosen;
  const move = moves.get(chosen);
  if (!move) {
    clear(ui.out).append(h("p", { class: "muted", text: "No tracked move yet: a robot program's MOVE LINEAR TO p WITH TRACKING shows here as it goes." }));
    return;
  }
  const v = view(move);
  const gaps = v.series.measured.filter((p) => p[1] === null).length;
  const legend = h("div", { class: "legend" }, ...SERIES.filter(([n]) => n !== "actual").map(([name, , label]) =>
    h("span", { dataset: { legend: name } }, h("span", { text: "━ ", class: `sw-${name}` }),
      `${label}: max ${mm(v.max_mm[name])} mm  `)));
  const windows = v.windows.map((w) => h("div", { class: "muted", dataset: { window: w.reason },
    text: `without tracking: ${w.start_s.toFixed(3)} s – ${w.end_s === null ? "end" : `${w.end_s.toFixed(3)} s`} (${w.reason})` }));
  const end = move.end ? h("div", { class: "muted", dataset: { end: "" },
    text: `tracker term on ${move.end.tracking_cycles} of ${move.end.cycles} cycles; ${move.end.model}` }) : null;
  clear(ui.out).append(h("div", { class: "result", dataset: { result: "tracked-live", running: String(move.running), service: chosen } },
    h("b", { class: "live-status", text: status(move) }),
    move.end && move.end.failure ? h("div", { class: "field-error", text: move.end.failure }) : null,
    plot(v), legend,
    h("div", { class: "muted", dataset: { gaps: String(gaps) }, text: `${v.series.corrected.length} points; ${gaps} without a fresh tracker sample (the measured line breaks there)` }),
    ...windows, end,
    h("div", { class: "muted", text: "deviation from the commanded path in mm over the path's time in s (negative: the robot stands at the start while the correction blends in)" })));
}

/** The "Live" pane of the Tracked path sub-tab. */
export function renderLive(box) {
  const robot = h("select", { class: "tracked-robot", "aria-label": "robot" });
  robot.addEventListener("change", () => { chosen = robot.value; draw(); });
  const out = h("div", { id: "tracked-live" });
  ui = { robot, out };
  box.append(
    h("p", { class: "hint", text: "A robot's tracked move as it goes: the corrected command's and the tracker's deviation from the commanded path, appended as the robot service publishes them (≤ 10 times a second)." }),
    h("div", { class: "toolbar" }, h("label", {}, "robot ", robot)),
    out);
  draw();
}

// for the browser tests: what is kept of a robot's move
window.plugcellTracking = {
  robots: () => [...moves.keys()].sort(),
  points: (service) => (moves.get(service) || { points: [] }).points.length,
  lastT: (service) => { const p = (moves.get(service) || { points: [] }).points; return p.length ? p[p.length - 1][0] : null; },
  batches: (service) => (moves.get(service) || { batches: 0 }).batches,
  running: (service) => (moves.get(service) || {}).running,
};
