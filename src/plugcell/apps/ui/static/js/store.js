// What the page knows about the cell, fed by the websocket; views subscribe to topics.
export const state = {
  cell: "", controller: "", services: new Map(), clients: [], wiring: [], wiringFile: "",
  processes: new Map(), queues: {}, runs: new Map(), log: [], journals: false,
  selected: { service: null, command: null },
};

const topics = new Map();

export function on(topic, fn) {
  if (!topics.has(topic)) topics.set(topic, new Set());
  topics.get(topic).add(fn);
}

export function emit(topic, detail) {
  for (const fn of topics.get(topic) || []) {
    try { fn(detail); } catch (exc) { console.warn(`view ${topic} failed`, exc); }
  }
}

export function liveServices(predicate = () => true) {
  return [...state.services.values()].filter((s) => s.alive && !s.controller && predicate(s));
}

export function applyCell(msg) {
  state.cell = msg.cell; state.controller = msg.controller;
  state.services = new Map(msg.services.map((s) => [s.name, s]));
  state.clients = msg.clients || []; state.wiring = msg.wiring || [];
  state.wiringFile = msg.wiringFile || "";
  emit("cell");
}

const MAX_PROCESSES = 3000;

export function applyProcesses(list, queues) {
  for (const p of list) state.processes.set(p.id, p);
  if (state.processes.size > MAX_PROCESSES) {
    const drop = state.processes.size - MAX_PROCESSES;
    let i = 0;
    for (const k of state.processes.keys()) { if (i++ >= drop) break; state.processes.delete(k); }
  }
  if (queues) state.queues = queues;
  emit("processes", list);
}

export function applySnapshot(msg) {
  state.journals = Boolean(msg.journals);
  applyCell(msg);
  state.processes.clear();
  for (const p of msg.processes || []) state.processes.set(p.id, p);
  state.queues = msg.queues || {};
  emit("processes", null);
  state.runs = new Map((msg.runs || []).map((r) => [r.id, r]));
  emit("runs");
  state.log = msg.log || [];
  emit("log", null);
}
