// The wiring graph (Figures 7-3, 7-9): services as boxes, partners as arrows A → B.
// Drag from a service to another to wire them; click an arrow to select it for Unwire.
import { $, clear, h, s } from "./dom.js";
import { post, firstError } from "./api.js";
import { emit, on, state } from "./store.js";

const W = 136; const H = 40;
let selectedEdge = null;
let drag = null;
const flashing = new Map();
let positions = new Map();

function layout(width, height) {
  // The controller on top (it is subscribed to everyone), the services on an ellipse below:
  // robots (they ask) on the left half, their peripherals on the right.
  const nodes = [...state.services.values()];
  const ctrl = nodes.filter((n) => n.controller);
  const others = nodes.filter((n) => !n.controller);
  const asks = (n) => (n.kind === "robot" || n.partners.length ? 0 : 1);
  others.sort((a, b) => asks(a) - asks(b) || a.name.localeCompare(b.name));
  const pos = new Map();
  const top = ctrl.length ? H + 16 : 0;
  const cx = width / 2; const cy = top + (height - top) / 2;
  const rx = Math.max(W, width / 2 - W / 2 - 14); const ry = Math.max(H, (height - top) / 2 - H / 2 - 12);
  const n = others.length;
  others.forEach((node, i) => {
    const a = Math.PI / 2 + (2 * Math.PI * (i + 0.5)) / n;   // bottom → left → top → right
    pos.set(node.name, { x: cx + rx * Math.cos(a), y: cy + ry * Math.sin(a) });
  });
  ctrl.forEach((node, i) => pos.set(node.name, { x: cx + i * (W + 12), y: H / 2 + 8 }));
  return pos;
}

function edgePath(a, b) {
  const dx = b.x - a.x; const dy = b.y - a.y;
  const len = Math.hypot(dx, dy) || 1;
  // leave and enter the boxes at their border
  const exit = (p, ux, uy) => {
    const tx = Math.abs(ux) > 1e-6 ? (W / 2) / Math.abs(ux) : Infinity;
    const ty = Math.abs(uy) > 1e-6 ? (H / 2) / Math.abs(uy) : Infinity;
    const t = Math.min(tx, ty) + 3;
    return { x: p.x + ux * t, y: p.y + uy * t };
  };
  const ux = dx / len; const uy = dy / len;
  const p1 = exit(a, ux, uy); const p2 = exit(b, -ux, -uy);
  const bend = 0.12 * len;
  const mx = (p1.x + p2.x) / 2 - uy * bend; const my = (p1.y + p2.y) / 2 + ux * bend;
  return `M${p1.x.toFixed(1)},${p1.y.toFixed(1)} Q${mx.toFixed(1)},${my.toFixed(1)} ${p2.x.toFixed(1)},${p2.y.toFixed(1)}`;
}

function defs() {
  const marker = (id, color) => s("marker", { id, viewBox: "0 0 10 10", refX: "9", refY: "5", markerWidth: "7", markerHeight: "7", orient: "auto-start-reverse" },
    s("path", { d: "M0,0 L10,5 L0,10 z", fill: color }));
  return s("defs", {}, marker("arrow", "#7f93ad"), marker("arrow-wanted", "#e0a54a"));
}

function render() {
  const svg = $("#graph");
  const width = svg.clientWidth || 640; const height = svg.clientHeight || 420;
  svg.setAttribute("viewBox", `0 0 ${width} ${height}`);
  positions = layout(width, height);
  clear(svg).append(defs());
  if (!state.services.size) {
    svg.append(s("text", { x: width / 2, y: height / 2, class: "empty", text: "No services discovered yet" }));
    renderSelects();
    return;
  }
  const edges = s("g", { class: "edges" });
  const nodes = s("g", { class: "nodes" });
  svg.append(edges, nodes);
  const inPlace = new Set();
  for (const a of state.services.values()) {
    if (!a.alive) continue;
    for (const b of a.partners) {
      const pa = positions.get(a.name); const pb = positions.get(b);
      if (!pa || !pb) continue;
      if (a.controller) {
        edges.append(s("path", { class: "edge ctrl", d: edgePath(pa, pb) }));
        continue;
      }
      inPlace.add(`${a.name}>${b}`);
      addEdge(edges, a.name, b, pa, pb, "");
    }
  }
  for (const w of state.wiring) {
    const key = `${w.service}>${w.partner}`;
    if (inPlace.has(key)) continue;
    const pa = positions.get(w.service); const pb = positions.get(w.partner);
    if (pa && pb) addEdge(edges, w.service, w.partner, pa, pb, " wanted", `${w.state}: ${w.reason || "not in place"}`);
  }
  for (const n of state.services.values()) {
    const p = positions.get(n.name);
    const cls = ["node", n.alive ? "alive" : "dead"];
    if (n.controller) cls.push("controller");
    if (n.alive && n.state === "Busy") cls.push("busy");
    if (n.alive && (n.state === "Error" || n.connection === "Error")) cls.push("error");
    if (state.selected.service === n.name) cls.push("selected");
    const g = s("g", { class: cls.join(" "), transform: `translate(${p.x - W / 2},${p.y - H / 2})`, dataset: { name: n.name } },
      s("title", { text: `${n.name} (${n.kind || "?"}) ${n.alive ? `${n.state}, ${n.connection}` : "gone"}` }),
      s("rect", { width: W, height: H, rx: 6 }),
      s("text", { x: W / 2, y: 17, text: n.name }),
      s("text", { x: W / 2, y: 31, class: "sub", text: n.alive ? `${n.kind || "?"} · ${n.state}` : `${n.kind || "?"} · gone` }));
    g.addEventListener("pointerdown", (ev) => startDrag(ev, n));
    nodes.append(g);
  }
  renderSelects();
}

function addEdge(layer, a, b, pa, pb, extra, title) {
  const key = `${a}>${b}`;
  const cls = `edge${extra}${selectedEdge === key ? " selected" : ""}${flashing.has(key) ? " flash" : ""}`;
  const d = edgePath(pa, pb);
  const g = s("g", { class: "edge-group", dataset: { wire: key } },
    s("title", { text: title || `${a} → ${b} (click to select for Unwire)` }),
    s("path", { class: cls, d }),
    s("path", { class: "edge-hit", d }));
  g.addEventListener("click", () => {
    selectedEdge = selectedEdge === key ? null : key;
    $("#wire-service").value = a; $("#wire-partner").value = b;
    render();
  });
  layer.append(g);
}

function svgPoint(ev) {
  const svg = $("#graph");
  const pt = svg.createSVGPoint(); pt.x = ev.clientX; pt.y = ev.clientY;
  return pt.matrixTransform(svg.getScreenCTM().inverse());
}

function nodeAt(ev) {
  const el = document.elementFromPoint(ev.clientX, ev.clientY);
  const g = el && el.closest ? el.closest("g.node") : null;
  return g ? g.dataset.name : null;
}

function startDrag(ev, n) {
  if (!n.alive || n.controller) return;
  ev.preventDefault();
  const svg = $("#graph");
  const from = positions.get(n.name);
  const line = s("line", { class: "drag-line", x1: from.x, y1: from.y, x2: from.x, y2: from.y });
  svg.append(line);
  drag = { from: n.name, line, moved: false };
  svg.setPointerCapture(ev.pointerId);
}

function moveDrag(ev) {
  if (!drag) return;
  const p = svgPoint(ev);
  drag.moved = true;
  drag.line.setAttribute("x2", p.x); drag.line.setAttribute("y2", p.y);
  const over = nodeAt(ev);
  for (const g of $("#graph").querySelectorAll("g.node")) g.classList.toggle("drop", g.dataset.name === over && over !== drag.from);
}

async function endDrag(ev) {
  if (!drag) return;
  const { from, line, moved } = drag;
  drag = null;
  line.remove();
  const to = nodeAt(ev);
  for (const g of $("#graph").querySelectorAll("g.node")) g.classList.remove("drop");
  if (!moved || !to || to === from) {
    if (!moved) { state.selected = { service: from, command: null }; emit("select"); }
    return;
  }
  $("#wire-service").value = from; $("#wire-partner").value = to;
  await act("/api/wire");
}

function renderSelects() {
  const fill = (sel, names) => {
    const keep = sel.value;
    clear(sel).append(h("option", { value: "", text: "—" }), ...names.map((n) => h("option", { value: n, text: n })));
    if (names.includes(keep)) sel.value = keep;
  };
  const services = [...state.services.values()].filter((x) => !x.controller);
  fill($("#wire-service"), services.filter((x) => x.alive).map((x) => x.name).sort());
  fill($("#wire-partner"), services.map((x) => x.name).sort());
}

async function act(url) {
  const service = $("#wire-service").value; const partner = $("#wire-partner").value;
  const err = $("#wire-error");
  err.textContent = "";
  $("#wire-service").classList.toggle("invalid", !service);
  $("#wire-partner").classList.toggle("invalid", !partner);
  if (!service || !partner) { err.textContent = "choose a service and a partner"; return; }
  if (service === partner) { err.textContent = "a service cannot be its own partner"; $("#wire-partner").classList.add("invalid"); return; }
  for (const b of [$("#wire-btn"), $("#unwire-btn")]) b.disabled = true;
  const result = await post(url, { service, partner });
  for (const b of [$("#wire-btn"), $("#unwire-btn")]) b.disabled = false;
  if (!result.ok) err.textContent = firstError(result);
  else selectedEdge = null;
}

function flash(list) {
  const recent = Date.now() * 1e6 - 2e9;
  for (const p of list || []) {
    if (p.state !== "Running" && p.state !== "Completed") continue;
    if ((p.endedNs || p.startedNs || 0) < recent) continue;
    const key = `${p.sender}>${p.recipient}`;
    clearTimeout(flashing.get(key));
    flashing.set(key, setTimeout(() => { flashing.delete(key); const e = document.querySelector(`[data-wire="${CSS.escape(key)}"] .edge`); if (e) e.classList.remove("flash"); }, 700));
    const e = document.querySelector(`[data-wire="${CSS.escape(key)}"] .edge`);
    if (e) e.classList.add("flash");
  }
}

export function initGraph() {
  const svg = $("#graph");
  svg.addEventListener("pointermove", moveDrag);
  svg.addEventListener("pointerup", endDrag);
  svg.addEventListener("pointercancel", () => { if (drag) { drag.line.remove(); drag = null; } });
  $("#wire-btn").addEventListener("click", () => act("/api/wire"));
  $("#unwire-btn").addEventListener("click", () => act("/api/unwire"));
  for (const sel of [$("#wire-service"), $("#wire-partner")]) sel.addEventListener("change", () => { sel.classList.remove("invalid"); $("#wire-error").textContent = ""; });
  on("cell", render);
  on("select", render);
  on("processes", flash);
  on("tab", (t) => { if (t === "cell") render(); });
  window.addEventListener("resize", render);
  initFiles();
}

function initFiles() {
  const path = $("#wiring-path"); const err = $("#file-error"); const ok = $("#file-ok");
  const run = async (url) => {
    err.textContent = ""; ok.textContent = "";
    path.classList.remove("invalid");
    if (!path.value.trim()) { path.classList.add("invalid"); err.textContent = "type a file name, e.g. cell-wiring.json"; return; }
    const result = await post(url, { path: path.value.trim() });
    if (!result.ok) { path.classList.add("invalid"); err.textContent = firstError(result); return; }
    ok.textContent = url.endsWith("save") ? `saved ${result.document.wires.length} wires` : `loaded ${result.wires.length} wires`;
  };
  $("#save-btn").addEventListener("click", () => run("/api/wiring/save"));
  $("#load-btn").addEventListener("click", () => run("/api/wiring/load"));
  path.addEventListener("input", () => { path.classList.remove("invalid"); err.textContent = ""; });
  on("cell", () => {
    if (!path.value && state.wiringFile) path.value = state.wiringFile;
    const list = clear($("#wanted"));
    for (const w of state.wiring) {
      list.append(h("li", { dataset: { state: w.state }, title: w.reason || w.state, text: `${w.service} → ${w.partner} · ${w.state}` }));
    }
  });
}
