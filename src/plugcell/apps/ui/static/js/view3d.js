// A small 3-D view on a 2-D canvas (the visualisation service of thesis 7.5, Figure 7-8):
// tracker measurements as they arrive, wizard points coloured by their fit residual, fitted geometry,
// and the residual of every calibration pose as an arrow from its measured position.
import { $ } from "./dom.js";
import { on, state } from "./store.js";

const live = [];          // [x, y, z] mm
const MAX_LIVE = 5000;
const shownFrames = new Map();   // process id → data frames already drawn (a record comes again on every change)
let fits = [];            // [{name, points, residuals, geometry}]
let residuals = null;     // the answer of /api/residuals: {poses: [{set, measured, after, before, …}], max_mm, …}
const resOpts = { set: "all", before: false };
const cam = { yaw: -0.8, pitch: 0.55, dist: 3000, target: [0, 0, 0] };
let canvas; let ctx; let dragging = null; let pending = false;

function trackers() {
  return new Set([...state.services.values()].filter((s) => s.kind === "tracker").map((s) => s.name));
}

function addLive(p) {
  const d = p.data;
  if (!d || d.type !== "Double" || !Array.isArray(d.value)) return;
  if (d.size.length === 1 && d.size[0] >= 3) live.push(d.value.slice(0, 3));
  else if (d.size.length === 2 && d.size[1] >= 3) for (const r of d.value) live.push(r.slice(0, 3));
  while (live.length > MAX_LIVE) live.shift();
}

function allPoints() {
  const pts = [];
  if ($("#show-live").checked) pts.push(...live);
  if ($("#show-fits").checked) for (const f of fits) pts.push(...f.points);
  pts.push(...shownResiduals().map((p) => p.measured));
  return pts;
}

function shownResiduals() {
  if (!residuals || !$("#show-residuals").checked) return [];
  return residuals.poses.filter((p) => resOpts.set === "all" || p.set === resOpts.set);
}

export function resetView() {
  const pts = allPoints();
  if (!pts.length) { cam.target = [0, 0, 0]; cam.dist = 3000; draw(); return; }
  const lo = [0, 1, 2].map((i) => Math.min(...pts.map((p) => p[i])));
  const hi = [0, 1, 2].map((i) => Math.max(...pts.map((p) => p[i])));
  cam.target = lo.map((v, i) => (v + hi[i]) / 2);
  const size = Math.max(50, ...hi.map((v, i) => v - lo[i]));
  cam.dist = size * 2.2;
  draw();
}

/** Show the points and fits of a wizard (replacing the previous ones). */
export function setFits(layers) { fits = layers; resetView(); }

/** Show calibration residuals (an answer of /api/residuals; null removes them). */
export function setResiduals(view) { residuals = view; $("#show-residuals").checked = true; resetView(); }

/** {set: "all" | "calibration" | "validation", before: show the arrows before calibration}. */
export function setResidualOptions(options) {
  const moved = options.set !== undefined && options.set !== resOpts.set;
  Object.assign(resOpts, options);
  if (moved && residuals) resetView(); else redraw();
}

function project(p) {
  const [tx, ty, tz] = cam.target;
  let x = p[0] - tx; let y = p[1] - ty; const z = p[2] - tz;
  const cy = Math.cos(cam.yaw); const sy = Math.sin(cam.yaw);
  [x, y] = [cy * x - sy * y, sy * x + cy * y];
  const cp = Math.cos(cam.pitch); const sp = Math.sin(cam.pitch);
  const depth = y * cp + z * sp;         // towards the viewer: -y rotated
  const up = -y * sp + z * cp;
  const d = cam.dist + depth;
  const f = (canvas.height * 0.9) / (2 * Math.tan(0.45)) / Math.max(d, 1e-3);
  return { x: canvas.width / 2 + x * f, y: canvas.height / 2 - up * f, d };
}

function colour(r, max) {
  const t = max > 0 ? Math.min(1, r / max) : 0;
  const hue = 140 - 140 * t;
  return `hsl(${hue}, 75%, 55%)`;
}

function line3(a, b, style, width = 1) {
  const p = project(a); const q = project(b);
  ctx.strokeStyle = style; ctx.lineWidth = width;
  ctx.beginPath(); ctx.moveTo(p.x, p.y); ctx.lineTo(q.x, q.y); ctx.stroke();
}

function polyline(points, style, width = 1.5) {
  ctx.strokeStyle = style; ctx.lineWidth = width; ctx.beginPath();
  points.forEach((pt, i) => { const p = project(pt); if (i) ctx.lineTo(p.x, p.y); else ctx.moveTo(p.x, p.y); });
  ctx.stroke();
}

function basis(n) {
  const a = Math.abs(n[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0];
  const cross = (u, v) => [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
  const norm = (v) => { const l = Math.hypot(...v) || 1; return v.map((x) => x / l); };
  const u = norm(cross(n, a)); const v = cross(n, u);
  return [u, v];
}

function drawGeometry(g) {
  if (!g) return;
  const add = (p, v, t) => p.map((x, i) => x + v[i] * t);
  if (g.kind === "circle") {
    const [u, v] = basis(g.normal);
    const pts = [];
    for (let i = 0; i <= 96; i++) { const a = (2 * Math.PI * i) / 96; pts.push(add(add(g.centre, u, g.radius * Math.cos(a)), v, g.radius * Math.sin(a))); }
    polyline(pts, "rgba(108,158,248,.9)");
    line3(g.centre, add(g.centre, g.normal, g.radius * 0.6), "rgba(108,158,248,.9)", 2);
  } else if (g.kind === "line") {
    const [a, b] = g.extent;
    line3(add(g.point, g.direction, a - 0.1 * (b - a)), add(g.point, g.direction, b + 0.1 * (b - a)), "rgba(108,158,248,.9)", 2);
  } else if (g.kind === "plane") {
    const [u, v] = basis(g.normal); const r = g.size || 100;
    const c = g.centroid;
    const corners = [[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]].map(([i, j]) => add(add(c, u, i * r), v, j * r));
    polyline(corners, "rgba(108,158,248,.7)");
    for (let k = -1; k <= 1; k += 0.5) { line3(add(add(c, u, k * r), v, -r), add(add(c, u, k * r), v, r), "rgba(108,158,248,.25)"); }
  }
}

function arrow(a, b, style) {
  const p = project(a); const q = project(b);
  const dx = q.x - p.x; const dy = q.y - p.y; const len = Math.hypot(dx, dy);
  ctx.strokeStyle = style; ctx.lineWidth = 1.5;
  ctx.beginPath(); ctx.moveTo(p.x, p.y); ctx.lineTo(q.x, q.y);
  if (len > 4) {
    const head = Math.min(7, len / 3); const ux = dx / len; const uy = dy / len;
    ctx.moveTo(q.x, q.y); ctx.lineTo(q.x - head * (ux - 0.5 * uy), q.y - head * (uy + 0.5 * ux));
    ctx.moveTo(q.x, q.y); ctx.lineTo(q.x - head * (ux + 0.5 * uy), q.y - head * (uy - 0.5 * ux));
  }
  ctx.stroke();
}

/** Arrows ×scale (the longest 15 % of the scene), points coloured by |Δp| after. Returns the legend. */
function drawResiduals(items) {
  const poses = shownResiduals();
  if (!poses.length) return "";
  const lo = [0, 1, 2].map((i) => Math.min(...poses.map((p) => p.measured[i])));
  const hi = [0, 1, 2].map((i) => Math.max(...poses.map((p) => p.measured[i])));
  const extent = Math.max(50, ...hi.map((v, i) => v - lo[i]));
  const maxAfter = Math.max(0.001, ...poses.map((p) => p.after_norm));
  const longest = Math.max(maxAfter, ...(resOpts.before ? poses.map((p) => p.before_norm || 0) : []));
  const scale = (0.15 * extent) / longest;
  const tip = (p, d) => p.measured.map((x, i) => x + d[i] * scale);
  for (const p of poses) {
    if (resOpts.before && p.before) arrow(p.measured, tip(p, p.before), "rgba(170,180,195,.55)");
    const c = colour(p.after_norm, maxAfter);
    arrow(p.measured, tip(p, p.after), c);
    items.push({ p: p.measured, c, r: p.set === "validation" ? 2.5 : 3.5, square: p.set === "validation" });
  }
  const s = scale >= 10 ? scale.toFixed(0) : scale.toPrecision(2);
  return `calibration residual after: green 0 → red ${maxAfter.toFixed(3)} mm · arrows ×${s}${resOpts.before ? " (grey: before)" : ""} · ● calibration ■ validation`;
}

function drawAxes() {
  const [tx, ty, tz] = cam.target;
  const size = cam.dist * 0.12;
  const o = [tx, ty, tz];
  const grid = cam.dist * 0.5; const step = grid / 5;
  ctx.lineWidth = 1;
  for (let i = -5; i <= 5; i++) {
    line3([tx - grid, ty + i * step, tz], [tx + grid, ty + i * step, tz], "rgba(80,100,125,.18)");
    line3([tx + i * step, ty - grid, tz], [tx + i * step, ty + grid, tz], "rgba(80,100,125,.18)");
  }
  const axes = [[[size, 0, 0], "#ef6a6a", "x"], [[0, size, 0], "#4cc38a", "y"], [[0, 0, size], "#6c9ef8", "z"]];
  for (const [d, c, label] of axes) {
    const end = o.map((v, i) => v + d[i]);
    line3(o, end, c, 2);
    const p = project(end); ctx.fillStyle = c; ctx.font = "12px monospace"; ctx.fillText(label, p.x + 3, p.y - 3);
  }
}

function draw() {
  pending = false;
  if (!canvas) return;
  const w = canvas.clientWidth; const hgt = canvas.clientHeight;
  if (w && (canvas.width !== w || canvas.height !== hgt)) { canvas.width = w; canvas.height = hgt; }
  ctx.fillStyle = "#0a0f15"; ctx.fillRect(0, 0, canvas.width, canvas.height);
  drawAxes();
  const items = [];
  if ($("#show-live").checked) for (const p of live) items.push({ p, c: "rgba(224,165,74,.85)", r: 2.5 });
  let maxRes = 0;
  if ($("#show-fits").checked) {
    for (const f of fits) for (const r of f.residuals || []) maxRes = Math.max(maxRes, r);
    maxRes = Math.max(maxRes, 0.01);   // below 10 µm every point is green
    for (const f of fits) {
      drawGeometry(f.geometry);
      f.points.forEach((p, i) => items.push({ p, c: f.residuals ? colour(f.residuals[i], maxRes) : "#c8d3e0", r: 3.5 }));
    }
  }
  const resLegend = drawResiduals(items);
  items.map((it) => ({ ...it, q: project(it.p) })).sort((a, b) => b.q.d - a.q.d).forEach((it) => {
    ctx.fillStyle = it.c; ctx.beginPath();
    if (it.square) ctx.rect(it.q.x - it.r, it.q.y - it.r, 2 * it.r, 2 * it.r);
    else ctx.arc(it.q.x, it.q.y, it.r, 0, 2 * Math.PI);
    ctx.fill();
  });
  ctx.fillStyle = "#8393a7"; ctx.font = "11px monospace";
  const nres = shownResiduals().length;
  ctx.fillText(`${live.length} live · ${fits.reduce((n, f) => n + f.points.length, 0)} fitted points${nres ? ` · ${nres} calibration residuals` : ""}`, 8, canvas.height - 8);
  const legend = [];
  if (fits.some((f) => f.residuals)) legend.push(`residual colour: green 0 → red ${maxRes.toFixed(3)} mm`);
  if (resLegend) legend.push(resLegend);
  $("#legend").textContent = legend.join(" · ");
}

export function redraw() { if (!pending) { pending = true; requestAnimationFrame(draw); } }

export function initView3d() {
  canvas = $("#view3d"); ctx = canvas.getContext("2d");
  canvas.addEventListener("pointerdown", (ev) => { dragging = { x: ev.clientX, y: ev.clientY }; canvas.setPointerCapture(ev.pointerId); });
  canvas.addEventListener("pointermove", (ev) => {
    if (!dragging) return;
    cam.yaw += (ev.clientX - dragging.x) * 0.01;
    cam.pitch = Math.max(-1.5, Math.min(1.5, cam.pitch + (ev.clientY - dragging.y) * 0.01));
    dragging = { x: ev.clientX, y: ev.clientY }; redraw();
  });
  canvas.addEventListener("pointerup", () => { dragging = null; });
  canvas.addEventListener("wheel", (ev) => { ev.preventDefault(); cam.dist *= Math.exp(ev.deltaY * 0.001); redraw(); }, { passive: false });
  $("#view-reset").addEventListener("click", resetView);
  $("#view-clear").addEventListener("click", () => { live.length = 0; redraw(); });
  for (const id of ["#show-live", "#show-fits", "#show-residuals"]) $(id).addEventListener("change", redraw);
  on("processes", (list) => {
    const t = trackers();
    let added = false;
    for (const p of list || []) {
      if (!t.has(p.recipient) || !p.data || p.sender === state.controller) continue;
      const frames = p.frames || 1;
      if ((shownFrames.get(p.id) || 0) >= frames) continue;
      shownFrames.set(p.id, frames);
      if (shownFrames.size > 20000) shownFrames.delete(shownFrames.keys().next().value);
      addLive(p); added = true;
    }
    if (added) redraw();
  });
  on("task", (msg) => { if (msg.data && trackers().has(msg.id.split("/")[0])) { addLive(msg); redraw(); } });
  on("tab", (tab) => { if (tab === "metrology") { if (live.length || fits.length || residuals) resetView(); else redraw(); } });
  window.addEventListener("resize", redraw);
  redraw();
}
