// Tasks whose result a view waits for (measurements of the wizards), through /api/tasks.
import { firstError, post } from "./api.js";
import { on } from "./store.js";

const waiting = new Map();   // id → {resolve, frames, onData}
const early = new Map();     // finals that arrived before their POST answered

on("task", (msg) => {
  const w = waiting.get(msg.id);
  if (!w) {
    if (msg.state === "Completed" || msg.state === "Failed") {
      early.set(msg.id, msg);
      if (early.size > 50) early.delete(early.keys().next().value);
    }
    return;
  }
  if (msg.data && w.onData) w.onData(msg.data);
  if (msg.state === "Completed" || msg.state === "Failed") {
    waiting.delete(msg.id);
    clearTimeout(w.timer);
    w.resolve({ ok: msg.state === "Completed", state: msg.state, reason: msg.reason, data: msg.data });
  }
});

/** Create a process and wait (bounded) for its end; onData gets every data update. */
export async function runTask(body, { onData = null, timeoutMs = 120000, onStarted = null } = {}) {
  const ack = await post("/api/tasks", body);
  if (!ack.ok) return { ok: false, state: "Failed", reason: firstError(ack) };
  if (onStarted) onStarted(ack.id);
  const done = early.get(ack.id);
  if (done) { early.delete(ack.id); return { ok: done.state === "Completed", state: done.state, reason: done.reason, data: done.data }; }
  return new Promise((resolve) => {
    const timer = setTimeout(() => { waiting.delete(ack.id); resolve({ ok: false, state: "Failed", reason: `no answer within ${timeoutMs / 1000} s` }); }, timeoutMs);
    waiting.set(ack.id, { resolve, onData, timer });
  });
}

export async function stopTask(id) { return post("/api/tasks/stop", { id }); }
