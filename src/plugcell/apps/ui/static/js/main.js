// The page: websocket to the controller, tabs, header, activity log; the views do the rest.
import { $, $$, clear, clock, h } from "./dom.js";
import { applyCell, applyProcesses, applySnapshot, emit, on, state } from "./store.js";
import { initServices } from "./services.js";
import { initGraph } from "./graph.js";
import { initTaskForm } from "./taskform.js";
import { initPrograms } from "./programs.js";
import { initMonitor } from "./monitor.js";
import { initView3d } from "./view3d.js";
import { initWizard } from "./wizard.js";
import { initReports } from "./reports.js";
import { initResiduals } from "./residuals.js";

let retry = 500;

function connect() {
  const conn = $("#conn");
  const proto = location.protocol === "https:" ? "wss" : "ws";
  const ws = new WebSocket(`${proto}://${location.host}/ws`);
  ws.addEventListener("open", () => {
    retry = 500;
    conn.dataset.state = "open";
    $("#conn-text").textContent = "live";
  });
  ws.addEventListener("message", (ev) => {
    const msg = JSON.parse(ev.data);
    switch (msg.type) {
      case "snapshot":
        applySnapshot(msg);
        for (const r of msg.robots || []) emit("robot", r);
        for (const t of msg.tracking || []) emit("tracking", t);
        break;
      case "robot": emit("robot", msg); break;
      case "tracking": emit("tracking", msg); break;
      case "cell": applyCell(msg); break;
      case "processes": applyProcesses(msg.processes, msg.queues); break;
      case "run": state.runs.set(msg.run.id, msg.run); emit("runs", msg.run); break;
      case "task": emit("task", msg); break;
      case "log": state.log.push(msg.line); if (state.log.length > 300) state.log.shift(); emit("log", msg.line); break;
      default: break;
    }
  });
  ws.addEventListener("close", () => {
    conn.dataset.state = "closed";
    $("#conn-text").textContent = "reconnecting…";
    setTimeout(connect, retry);
    retry = Math.min(retry * 2, 5000);
  });
}

function initTabs() {
  for (const b of $$(".tabs button")) {
    b.addEventListener("click", () => {
      for (const x of $$(".tabs button")) x.classList.toggle("active", x === b);
      for (const t of $$(".tab")) t.classList.toggle("active", t.id === `tab-${b.dataset.tab}`);
      emit("tab", b.dataset.tab);
    });
  }
}

function renderHeader() {
  $("#cell-name").textContent = state.cell || "…";
  $("#controller-name").textContent = state.controller || "…";
  const all = [...state.services.values()].filter((s) => !s.controller);
  const live = all.filter((s) => s.alive).length;
  let running = 0; let queued = 0; let failed = 0;
  for (const p of state.processes.values()) {
    if (p.state === "Running") running++;
    else if (p.state === "Queued") queued++;
    else if (p.state === "Failed") failed++;
  }
  const stat = (label, value, id) => h("span", { class: "stat", id }, `${label} `, h("b", { text: value }));
  clear($("#stats")).append(
    stat("services", `${live}/${all.length}`, "stat-services"),
    stat("running", running, "stat-running"),
    stat("queued", queued, "stat-queued"),
    stat("failed", failed, "stat-failed"),
  );
  $("#tab-running").textContent = running ? String(running) : "";
}

function renderLog(line) {
  const list = $("#activity");
  const item = (l) => h("li", { class: l.level }, h("time", { text: clock(l.t) }), l.text);
  if (line === null) {
    clear(list);
    for (const l of state.log.slice(-150)) list.append(item(l));
  } else {
    list.append(item(line));
    while (list.children.length > 150) list.removeChild(list.firstChild);
  }
  list.scrollTop = list.scrollHeight;
  const last = state.log[state.log.length - 1];
  $("#activity-last").textContent = last ? `${state.log.length} events` : "";
}

function init() {
  initTabs();
  on("cell", renderHeader);
  on("processes", renderHeader);
  on("log", renderLog);
  initServices();
  initGraph();
  initTaskForm();
  initPrograms();
  initMonitor();
  initView3d();
  initWizard();
  initResiduals();
  initReports();
  connect();
}

init();
