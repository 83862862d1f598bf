// The 3-D view (the visualisation service of thesis 7.5, Figure 7-8), drawn by three.js (bundled
// under /static/vendor, nothing from the Internet): every robot of the cell as the kinematic
// skeleton of its description — a cylinder per joint axis, the DH path of every link (the Smart
// H4's parallelogram loop included), the flange triad — following its joint state live (the
// robot service's `robot` events, ≥ 20 Hz); tracker measurements as they arrive, wizard points
// coloured by their fit residual, fitted geometry, and the residual of every calibration pose as
// an arrow from its measured position.  Scene units: mm, tracker (world) frame, z up.
import * as THREE from "../vendor/three.bundle.js";
import { $ } from "./dom.js";
import { on, state } from "./store.js";

const live = [];          // [x, y, z] mm
const MAX_LIVE = 5000;
const shownFrames = new Map();   // process id → data frames already drawn (a record comes again on every change)
let fits = [];            // [{name, points, residuals, geometry}]
let residuals = null;     // the answer of /api/residuals: {poses: [{set, measured, after, before, …}], max_mm, …}
const resOpts = { set: "all", before: false };
const robots = new Map(); // robot service → {msg, group, received, rate: [t…]}
const MM = 1000;          // scene mm per metre of a joint state

let renderer = null; let scene; let camera; let controls; let canvas; let pending = false;
let layers = {};          // three groups: points, fits, residuals, robots, axes

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

function shownResiduals() {
  if (!residuals || !$("#show-residuals").checked) return [];
  return residuals.poses.filter((p) => resOpts.set === "all" || p.set === resOpts.set);
}

function robotPoints() {
  const pts = [];
  for (const r of robots.values()) if (r.group.visible) for (const o of r.origins) pts.push(o);
  return pts;
}

function allPoints() {
  const pts = [];
  if ($("#show-live").checked) pts.push(...live);
  if ($("#show-fits").checked) for (const f of fits) pts.push(...f.points);
  pts.push(...shownResiduals().map((p) => p.measured));
  if (!pts.length) pts.push(...robotPoints());
  return pts;
}

/** Aim the camera at everything shown (the robots when nothing else is). */
export function resetView() {
  if (!renderer) return;
  const pts = allPoints();
  let target = new THREE.Vector3(0, 0, 0); let size = 1500;
  if (pts.length) {
    const box = new THREE.Box3().setFromPoints(pts.map((p) => new THREE.Vector3(...p)));
    box.getCenter(target);
    size = Math.max(50, ...box.getSize(new THREE.Vector3()).toArray());
  }
  const dist = size * 2.2;
  controls.target.copy(target);
  camera.position.copy(target).add(new THREE.Vector3(0.6, -0.55, 0.5).normalize().multiplyScalar(dist));
  camera.near = dist / 1000; camera.far = dist * 50; camera.updateProjectionMatrix();
  controls.update();
  rebuild();
}

/** Show the points and fits of a wizard (replacing the previous ones). */
export function setFits(list) { fits = list; resetView(); }

/** Show calibration residuals (an answer of /api/residuals; null removes them). */
export function setResiduals(view) { residuals = view; $("#show-residuals").checked = true; resetView(); }

/** {set: "all" | "calibration" | "validation", before: show the arrows before calibration}. */
export function setResidualOptions(options) {
  const moved = options.set !== undefined && options.set !== resOpts.set;
  Object.assign(resOpts, options);
  if (moved && residuals) resetView(); else rebuild();
}

function colour(r, max) {
  const t = max > 0 ? Math.min(1, r / max) : 0;
  return new THREE.Color().setHSL((140 - 140 * t) / 360, 0.75, 0.55);
}

function clearGroup(g) {
  for (const child of [...g.children]) {
    g.remove(child);
    child.traverse((o) => { if (o.geometry) o.geometry.dispose(); if (o.material && !o.material.shared) o.material.dispose(); });
  }
}

function lineMesh(points, color, opacity = 1) {
  const geom = new THREE.BufferGeometry().setFromPoints(points.map((p) => new THREE.Vector3(...p)));
  return new THREE.Line(geom, new THREE.LineBasicMaterial({ color, transparent: opacity < 1, opacity }));
}

function pointCloud(items, size) {
  const pos = new Float32Array(items.length * 3); const col = new Float32Array(items.length * 3);
  items.forEach((it, i) => { pos.set(it.p, 3 * i); const c = new THREE.Color(it.c); col.set([c.r, c.g, c.b], 3 * i); });
  const geom = new THREE.BufferGeometry();
  geom.setAttribute("position", new THREE.BufferAttribute(pos, 3));
  geom.setAttribute("color", new THREE.BufferAttribute(col, 3));
  return new THREE.Points(geom, new THREE.PointsMaterial({ size, vertexColors: true, sizeAttenuation: false }));
}

function basis(n) {
  const v = new THREE.Vector3(...n).normalize();
  const a = Math.abs(v.x) < 0.9 ? new THREE.Vector3(1, 0, 0) : new THREE.Vector3(0, 1, 0);
  const u = new THREE.Vector3().crossVectors(v, a).normalize();
  return [u, new THREE.Vector3().crossVectors(v, u)];
}

function geometryLines(g) {
  const blue = 0x6c9ef8; const out = [];
  const at = (c, u, v, i, j) => new THREE.Vector3(...c).addScaledVector(u, i).addScaledVector(v, j).toArray();
  if (g.kind === "circle") {
    const [u, v] = basis(g.normal); const pts = [];
    for (let i = 0; i <= 96; i++) { const a = (2 * Math.PI * i) / 96; pts.push(at(g.centre, u, v, g.radius * Math.cos(a), g.radius * Math.sin(a))); }
    out.push(lineMesh(pts, blue));
    out.push(lineMesh([g.centre, new THREE.Vector3(...g.centre).addScaledVector(new THREE.Vector3(...g.normal), g.radius * 0.6).toArray()], blue));
  } else if (g.kind === "line") {
    const [a, b] = g.extent; const d = new THREE.Vector3(...g.direction);
    const p = (t) => new THREE.Vector3(...g.point).addScaledVector(d, t).toArray();
    out.push(lineMesh([p(a - 0.1 * (b - a)), p(b + 0.1 * (b - a))], blue));
  } else if (g.kind === "plane") {
    const [u, v] = basis(g.normal); const r = g.size || 100;
    out.push(lineMesh([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]].map(([i, j]) => at(g.centroid, u, v, i * r, j * r)), blue, 0.7));
    for (let k = -1; k <= 1; k += 0.5) out.push(lineMesh([at(g.centroid, u, v, k * r, -r), at(g.centroid, u, v, k * r, r)], blue, 0.25));
  }
  return out;
}

/** Arrows ×scale (the longest 15 % of the scene), points coloured by |Δp| after. Returns the legend. */
function buildResiduals(group, items) {
  const poses = shownResiduals();
  if (!poses.length) return "";
  const box = new THREE.Box3().setFromPoints(poses.map((p) => new THREE.Vector3(...p.measured)));
  const extent = Math.max(50, ...box.getSize(new THREE.Vector3()).toArray());
  const maxAfter = Math.max(0.001, ...poses.map((p) => p.after_norm));
  const longest = Math.max(maxAfter, ...(resOpts.before ? poses.map((p) => p.before_norm || 0) : []));
  const scale = (0.15 * extent) / longest;
  const arrow = (p, d, c) => {
    const dir = new THREE.Vector3(...d); const len = dir.length() * scale;
    if (len <= 0) return;
    group.add(new THREE.ArrowHelper(dir.normalize(), new THREE.Vector3(...p), len, c, Math.min(0.25 * len, extent * 0.02), Math.min(0.12 * len, extent * 0.01)));
  };
  for (const p of poses) {
    if (resOpts.before && p.before) arrow(p.measured, p.before, 0x9aa4b2);
    const c = colour(p.after_norm, maxAfter);
    arrow(p.measured, p.after, c);
    items.push({ p: p.measured, c, size: p.set === "validation" ? 5 : 7 });
  }
  const s = scale >= 10 ? scale.toFixed(0) : scale.toPrecision(2);
  return `calibration residual after: green 0 → red ${maxAfter.toFixed(3)} mm · arrows ×${s}${resOpts.before ? " (grey: before)" : ""} · ● calibration ■ validation`;
}

function buildAxes() {
  const g = layers.axes; clearGroup(g);
  const size = camera.position.distanceTo(controls.target) * 0.12;
  const grid = new THREE.GridHelper(10 * size, 10, 0x2a3646, 0x1b2430);
  grid.rotation.x = Math.PI / 2; g.add(grid);
  [[0xef6a6a, [1, 0, 0]], [0x4cc38a, [0, 1, 0]], [0x6c9ef8, [0, 0, 1]]].forEach(([c, d]) => g.add(lineMesh([[0, 0, 0], d.map((x) => x * size)], c)));
}

/** Points, fits and residuals again (they change seldom; robots move on their own). */
function rebuild() {
  if (!renderer) return;
  for (const k of ["points", "fits", "residuals"]) clearGroup(layers[k]);
  buildAxes();
  const items = [];
  if ($("#show-live").checked) for (const p of live) items.push({ p, c: 0xe0a54a, size: 5 });
  let maxRes = 0;
  if ($("#show-fits").checked) {
    for (const f of fits) for (const r of f.residuals || []) maxRes = Math.max(maxRes, r);
    maxRes = Math.max(maxRes, 0.01);   // below 10 µm every point is green
    for (const f of fits) {
      if (f.geometry) for (const m of geometryLines(f.geometry)) layers.fits.add(m);
      f.points.forEach((p, i) => items.push({ p, c: f.residuals ? colour(f.residuals[i], maxRes) : 0xc8d3e0, size: 7 }));
    }
  }
  const resLegend = buildResiduals(layers.residuals, items);
  if (items.length) layers.points.add(pointCloud(items, 6));
  const nres = shownResiduals().length;
  const nrob = [...robots.values()].filter((r) => r.group.visible).length;
  $("#view-stats").textContent = `${live.length} live · ${fits.reduce((n, f) => n + f.points.length, 0)} fitted points${nres ? ` · ${nres} calibration residuals` : ""}${nrob ? ` · ${nrob} robot${nrob > 1 ? "s" : ""}` : ""}`;
  const legend = [];
  if (fits.some((f) => f.residuals)) legend.push(`residual colour: green 0 → red ${maxRes.toFixed(3)} mm`);
  if (resLegend) legend.push(resLegend);
  $("#legend").textContent = legend.join(" · ");
  redraw();
}

// -- robots: the skeleton of the description at the joint state ----------------------------------

const robotMaterials = {
  link: new THREE.MeshStandardMaterial({ color: 0xd9822b, metalness: 0.2, roughness: 0.6 }),
  loop: new THREE.MeshStandardMaterial({ color: 0xb9c3cf, metalness: 0.2, roughness: 0.6 }),
  actuated: new THREE.MeshStandardMaterial({ color: 0x3d6fb6, metalness: 0.3, roughness: 0.5 }),
  passive: new THREE.MeshStandardMaterial({ color: 0x7f8a99, metalness: 0.3, roughness: 0.5 }),
};
for (const m of Object.values(robotMaterials)) m.shared = true;
const UNIT_CYLINDER = new THREE.CylinderGeometry(1, 1, 1, 20);   // along y, height 1

/** A cylinder of radius r from a to b (THREE.Vector3, mm) into mesh m. */
function placeCylinder(m, a, b, r) {
  const d = new THREE.Vector3().subVectors(b, a); const len = d.length();
  m.visible = len > 1e-6;
  if (!m.visible) return;
  m.position.copy(a).addScaledVector(d, 0.5);
  m.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), d.divideScalar(len));
  m.scale.set(r, len, r);
}

function matrixOf(rowMajor, base) {
  const m = new THREE.Matrix4().set(...rowMajor);
  m.elements[12] *= MM; m.elements[13] *= MM; m.elements[14] *= MM;   // column-major: translation
  return base ? base.clone().multiply(m) : m;
}

/** The meshes of one robot (made once per link tree): per link a joint cylinder and two segments. */
function robotGroup(msg) {
  const group = new THREE.Group(); group.name = msg.service;
  const loop = new Set();
  const parts = msg.links.map(([name, , joint]) => {
    const seg = [new THREE.Mesh(UNIT_CYLINDER, robotMaterials.link), new THREE.Mesh(UNIT_CYLINDER, robotMaterials.link)];
    const axis = joint === "fixed" ? null : new THREE.Mesh(UNIT_CYLINDER, joint === "passive" ? robotMaterials.passive : robotMaterials.actuated);
    if (joint === "passive") loop.add(name);
    for (const m of [...seg, axis]) if (m) group.add(m);
    return { name, seg, axis };
  });
  for (const p of parts) if (loop.has(p.name)) for (const s of p.seg) s.material = robotMaterials.loop;
  const triad = new THREE.AxesHelper(1); group.add(triad);
  const pedestal = new THREE.Mesh(UNIT_CYLINDER, robotMaterials.passive); group.add(pedestal);
  return { group, parts, triad, pedestal, key: msg.links.map((l) => l.join(":")).join("|") };
}

/** Put the robot's meshes at its joint state (frames of the robot base, m; BASE → world). */
function poseRobot(r, msg) {
  const base = matrixOf(msg.base);
  const frames = new Map([["base", base]]);
  msg.links.forEach(([name], i) => { if (msg.frames[i]) frames.set(name, matrixOf(msg.frames[i], base)); });
  const reach = Math.max(200, ...msg.links.map(([, , , d]) => Math.abs(d) * MM));
  const radius = reach * 0.06;
  const origin = (m) => new THREE.Vector3().setFromMatrixPosition(m);
  const zAxis = (m) => new THREE.Vector3().setFromMatrixColumn(m, 2).normalize();
  r.origins = [];
  r.group.visible = msg.frames.length > 0;
  if (!r.group.visible) return;
  msg.links.forEach(([name, parent, , d], i) => {
    const p = r.parts[i]; const F = frames.get(name); const P = frames.get(parent);
    const a = origin(P); const corner = a.clone().addScaledVector(zAxis(P), d * MM); const b = origin(F);
    placeCylinder(p.seg[0], a, corner, radius * 0.55);
    placeCylinder(p.seg[1], corner, b, radius * 0.55);
    if (p.axis) {   // the joint's axis: z of the parent frame, through its origin
      const h = radius * 1.6; const z = zAxis(P);
      placeCylinder(p.axis, a.clone().addScaledVector(z, -h), a.clone().addScaledVector(z, h), radius);
    }
    r.origins.push(b.toArray());
  });
  const flange = frames.get(msg.flange);
  r.triad.matrix.copy(flange).multiply(new THREE.Matrix4().makeScale(reach * 0.15, reach * 0.15, reach * 0.15));
  r.triad.matrixAutoUpdate = false;
  const o = origin(base); const zb = zAxis(base);
  placeCylinder(r.pedestal, o.clone().addScaledVector(zb, -radius * 0.4), o, radius * 2.2);
  r.origins.push(o.toArray());
}

function onRobot(msg) {
  const now = performance.now();
  let r = robots.get(msg.service);
  const key = msg.links.map((l) => l.join(":")).join("|");
  if (r && r.key !== key) { layers.robots.remove(r.group); clearGroup(r.group); r = null; }
  const first = !r;
  if (!r) { r = { ...robotGroup(msg), received: 0, times: [] }; robots.set(msg.service, r); layers.robots.add(r.group); }
  r.msg = msg; r.received += 1; r.times.push(now);
  while (r.times.length && now - r.times[0] > 2000) r.times.shift();
  poseRobot(r, msg);
  if (first) { if (!live.length && !fits.length && !residuals) resetView(); else rebuild(); } else redraw();
}

function dropDeadRobots() {
  for (const [name, r] of robots) {
    const s = state.services.get(name);
    if (s && !s.alive) { layers.robots.remove(r.group); clearGroup(r.group); robots.delete(name); }
  }
}

// -- rendering ------------------------------------------------------------------------------------

function draw() {
  pending = false;
  if (!renderer) return;
  const w = canvas.clientWidth; const hgt = canvas.clientHeight;
  const size = renderer.getSize(new THREE.Vector2());
  if (w && hgt && (size.x !== w || size.y !== hgt)) {
    renderer.setSize(w, hgt, false); camera.aspect = w / hgt; camera.updateProjectionMatrix();
  }
  renderer.render(scene, camera);
}

export function redraw() { if (!pending) { pending = true; requestAnimationFrame(draw); } }

/** Read-only, for tests and the curious: what the view holds. */
const debugHook = {
  robots: () => [...robots.keys()],
  received: (name) => (robots.get(name) || { received: 0 }).received,
  /** Joint states received in the last `ms` milliseconds (≤ 2000). */
  recent: (name, ms = 1000) => { const r = robots.get(name); const now = performance.now(); return r ? r.times.filter((t) => now - t <= ms).length : 0; },
  joints: (name) => { const r = robots.get(name); return r ? [...r.msg.q] : null; },
  /** The link origins drawn (mm, world frame). */
  linkOrigins: (name) => { const r = robots.get(name); return r ? r.origins.map((o) => [...o]) : null; },
  webgl: () => Boolean(renderer),
};

export function initView3d() {
  canvas = $("#view3d");
  window.plugcellView = Object.freeze(debugHook);
  try {
    renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
  } catch (exc) {
    $("#view-stats").textContent = `3-D view unavailable: this browser gives no WebGL (${exc.message})`;
    return;
  }
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setClearColor(0x0a0f15);
  scene = new THREE.Scene();
  camera = new THREE.PerspectiveCamera(50, 800 / 520, 1, 1e6);
  camera.up.set(0, 0, 1);
  controls = new THREE.OrbitControls(camera, canvas);
  controls.addEventListener("change", redraw);
  scene.add(new THREE.HemisphereLight(0xdfe8f5, 0x202830, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.8); sun.position.set(2, -3, 4); scene.add(sun);
  layers = Object.fromEntries(["axes", "points", "fits", "residuals", "robots"].map((k) => { const g = new THREE.Group(); g.name = k; scene.add(g); return [k, g]; }));
  $("#view-reset").addEventListener("click", resetView);
  $("#view-clear").addEventListener("click", () => { live.length = 0; rebuild(); });
  for (const id of ["#show-live", "#show-fits", "#show-residuals"]) $(id).addEventListener("change", rebuild);
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
    if (added) rebuild();
  });
  on("task", (msg) => { if (msg.data && trackers().has(msg.id.split("/")[0])) { addLive(msg); rebuild(); } });
  on("robot", onRobot);
  on("cell", dropDeadRobots);
  on("tab", (tab) => { if (tab === "metrology") resetView(); });
  window.addEventListener("resize", redraw);
  resetView();
}
