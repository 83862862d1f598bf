// The live process monitor (Figure 7-11): timeline per service, queues of shared devices, table.
import { $, clear, clock, h, s, seconds, stateBadge } from "./dom.js";
import { on, state } from "./store.js";

const MAX_ROWS = 400;
let scheduled = false;
let visible = false;

function rows() {
  const filter = $("#proc-filter").value.trim().toLowerCase();
  let list = [...state.processes.values()];
  if (filter) {
    list = list.filter((p) => `${p.sender} ${p.recipient} ${p.command} ${p.option} ${p.state} ${p.reason}`.toLowerCase().includes(filter));
  }
  list.sort((a, b) => (b.receivedNs || b.startedNs) - (a.receivedNs || a.startedNs));
  return list.slice(0, MAX_ROWS);
}

function durationOf(p) {
  if (p.endedNs || !(p.receivedNs || p.startedNs)) return p.duration;
  return (Date.now() * 1e6 - (p.receivedNs || p.startedNs)) / 1e9;
}

function renderTable() {
  const body = clear($("#proc-table tbody"));
  for (const p of rows()) {
    body.append(h("tr", { class: p.state, dataset: { id: p.id, command: p.command, state: p.state } },
      h("td", { text: clock(p.receivedNs || p.startedNs) }),
      h("td", { text: p.sender }),
      h("td", { class: "muted", text: "→" }),
      h("td", { text: p.recipient }),
      h("td", { text: p.command || "?" }),
      h("td", { text: p.option }),
      h("td", {}, stateBadge(p.state)),
      h("td", { text: seconds(durationOf(p)) }),
      h("td", { class: "reason", title: p.reason || p.dataText, text: p.reason || (p.frames > 1 ? `${p.frames} frames · ${p.dataText}` : p.dataText) })));
  }
  if (!body.children.length) body.append(h("tr", {}, h("td", { colspan: 9, class: "hint", text: "No processes yet: assign a task or run a program." })));
}

function renderQueues() {
  const box = clear($("#queues"));
  const names = [...state.services.values()].filter((x) => !x.controller).map((x) => x.name).sort();
  const longest = Math.max(1, ...Object.values(state.queues).map((q) => q.length + q.running.length));
  for (const name of names) {
    const q = state.queues[name] || { running: [], queued: [], length: 0 };
    const svc = state.services.get(name);
    const run = h("div", { class: "qrun" }); const wait = h("div", { class: "qwait" });
    run.style.width = `${(100 * q.running.length) / longest}%`;
    wait.style.width = `${(100 * q.length) / longest}%`;
    const detail = [...q.running.map((x) => `▶ ${x.sender}:${x.command}`), ...q.queued.map((x) => `⏸ ${x.sender}:${x.command}`)].join("  ");
    box.append(h("div", { class: `queue${svc && !svc.alive ? " dead" : ""}`, dataset: { service: name, length: q.length } },
      h("span", { class: "qname", text: name }), h("div", { class: "qbar" }, run, wait), h("span", { class: "qlen", text: q.length }),
      detail ? h("div", { class: "qdetail", text: detail }) : null));
  }
  $("#journal-hint").textContent = state.journals
    ? "Queued processes are read from the services' journals on this host."
    : "Journals are not read (--no-journals): only running processes are shown.";
}

function renderTimeline() {
  const svg = $("#timeline");
  const width = svg.clientWidth || 800; const height = svg.clientHeight || 260;
  svg.setAttribute("viewBox", `0 0 ${width} ${height}`);
  clear(svg);
  const span = Number($("#timeline-window").value) * 1e9;
  const now = Date.now() * 1e6;
  const t0 = now - span;
  const left = 96; const right = 8;
  const x = (t) => left + ((t - t0) / span) * (width - left - right);
  const list = [...state.processes.values()].filter((p) => (p.endedNs || now) >= t0);
  const lanes = [...new Set(list.map((p) => p.recipient))].sort();
  const laneH = Math.min(36, (height - 22) / Math.max(lanes.length, 1));
  for (let i = 0; i <= 6; i++) {
    const t = t0 + (span * i) / 6;
    svg.append(s("line", { class: "grid", x1: x(t), x2: x(t), y1: 0, y2: height - 16 }),
      s("text", { class: "tick", x: x(t), y: height - 4, "text-anchor": i === 6 ? "end" : "middle", text: i === 6 ? "now" : `-${Math.round((span * (6 - i)) / 6 / 1e9)} s` }));
  }
  lanes.forEach((name, i) => {
    const y = 4 + i * laneH;
    svg.append(s("rect", { class: "lane", x: left, y, width: width - left - right, height: laneH - 4 }),
      s("text", { class: "lane-label", x: 6, y: y + laneH / 2 + 2, text: name }));
  });
  for (const p of list) {
    const lane = lanes.indexOf(p.recipient);
    const y = 4 + lane * laneH + 3; const bh = Math.max(4, laneH - 10);
    const rec = p.receivedNs || p.startedNs; const start = p.startedNs || (p.state === "Queued" ? now : rec);
    const end = p.endedNs || now;
    const title = `${p.sender} → ${p.recipient} ${p.command} ${p.state} ${seconds(durationOf(p))}${p.reason ? ` — ${p.reason}` : ""}`;
    if (rec && start > rec) svg.append(s("rect", { class: "bar-queued", x: Math.max(left, x(rec)), y: y + bh / 4, width: Math.max(1, x(start) - Math.max(left, x(rec))), height: bh / 2 }, s("title", { text: `${title} (queued)` })));
    if (p.state !== "Queued") svg.append(s("rect", { class: `bar-${p.state}`, x: Math.max(left, x(start)), y, width: Math.max(2, x(end) - Math.max(left, x(start))), height: bh, rx: 2 }, s("title", { text: title })));
  }
  if (!lanes.length) svg.append(s("text", { class: "tick", x: width / 2, y: height / 2, "text-anchor": "middle", text: "no processes in this window" }));
}

function renderAll() {
  scheduled = false;
  renderQueues();
  if (!visible) return;
  renderTable();
  renderTimeline();
}

function schedule() {
  if (!scheduled) { scheduled = true; requestAnimationFrame(renderAll); }
}

export function initMonitor() {
  on("processes", schedule);
  on("cell", schedule);
  on("tab", (t) => { visible = t === "processes"; schedule(); });
  $("#proc-filter").addEventListener("input", schedule);
  $("#timeline-window").addEventListener("change", schedule);
  setInterval(() => { if (visible) renderTimeline(); }, 1000);
}
