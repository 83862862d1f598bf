// Task forms generated from a command's declaration (Figure 7-10, appendix F.5), checked as you type.
import { $, clear, h, stateBadge } from "./dom.js";
import { post, firstError } from "./api.js";
import { on, state } from "./store.js";

const INT32 = [-2147483648, 2147483647];
const MAX_CELLS = 64;

/** Whether a declared size has a fixed shape small enough for one input per element. */
function cellsOf(size) {
  if (!size.length || size.some((d) => d < 0)) return 0;
  const n = size.reduce((a, b) => a * b, 1);
  return n <= MAX_CELLS ? n : 0;
}

/** Parse one element typed in a field; returns [value, error]. */
export function parseElement(text, type) {
  const t = text.trim();
  if (type === "String") return [text, ""];
  if (type === "Boolean") {
    const u = t.toUpperCase();
    if (u === "TRUE" || u === "1") return [true, ""];
    if (u === "FALSE" || u === "0") return [false, ""];
    return [null, "TRUE or FALSE"];
  }
  if (t === "") return [null, "required"];
  if (!/^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$/.test(t)) return [null, "not a number"];
  const x = Number(t);
  if (!Number.isFinite(x)) return [null, "out of range"];
  if (type === "Integer" || type === "Byte") {
    if (!Number.isInteger(x)) return [null, "a whole number"];
    const [lo, hi] = type === "Byte" ? [0, 255] : INT32;
    if (x < lo || x > hi) return [null, `${lo}…${hi}`];
  }
  return [x, ""];
}

function shapeOf(v) {
  const shape = [];
  let x = v;
  while (Array.isArray(x)) { shape.push(x.length); x = x[0]; }
  return shape;
}

function flat(v) { return Array.isArray(v) ? v.flatMap(flat) : [v]; }

function sizeText(size) { return size.length ? `[${size.map((d) => (d < 0 ? "*" : d)).join(", ")}]` : "[any]"; }

/** Parse free text (JSON, or rows split by ';'/newline and values by ','/blanks) for a declaration. */
export function parseFree(text, type, size) {
  const t = text.trim();
  if (!t) return [null, "required"];
  let value;
  if (type === "String") {
    if (t.startsWith("[")) {
      try { value = JSON.parse(t); } catch (e) { return [null, `not JSON: ${e.message}`]; }
    } else {
      const lines = text.split("\n").filter((l) => l.length);
      value = size.length === 1 || !size.length ? lines : lines;
    }
  } else if (t.startsWith("[")) {
    try { value = JSON.parse(t); } catch (e) { return [null, `not JSON: ${e.message}`]; }
  } else {
    const rows = t.split(/[;\n]+/).map((r) => r.trim()).filter(Boolean)
      .map((r) => r.split(/[,\s]+/).filter(Boolean));
    const parsed = [];
    for (const [i, r] of rows.entries()) {
      const row = [];
      for (const [j, cell] of r.entries()) {
        const [x, err] = parseElement(cell, type);
        if (err) return [null, `row ${i + 1}, value ${j + 1}: ${err}`];
        row.push(x);
      }
      parsed.push(row);
    }
    value = size.length === 1 || (parsed.length === 1 && size.length !== 2) ? parsed.flat() : parsed;
  }
  const shape = shapeOf(value);
  if (Array.isArray(value) && value.some((r) => Array.isArray(r) && r.length !== value[0].length)) return [null, "rows of different lengths"];
  for (const x of flat(value)) {
    const [, err] = type === "String" ? [x, typeof x === "string" ? "" : "strings expected"] : parseElement(String(x), type);
    if (err) return [null, err];
  }
  if (size.length && (shape.length !== size.length || shape.some((d, i) => size[i] >= 0 && d !== size[i]))) {
    return [null, `size ${sizeText(shape)} does not match the declared ${sizeText(size)}`];
  }
  return [value, ""];
}

function reshape(values, size) {
  if (size.length <= 1) return values;
  const [first, ...rest] = size;
  const step = rest.reduce((a, b) => a * b, 1);
  return Array.from({ length: first }, (_, i) => reshape(values.slice(i * step, (i + 1) * step), rest));
}

function optionsFromInfo(info) {
  const m = /option\s+([\w'.:-]+(?:\s*\|\s*[\w'.:-]+)+)/i.exec(info || "");
  return m ? m[1].split("|").map((x) => x.trim().replace(/'/g, "")).filter((x) => x && x !== "''") : [];
}

let current = null;

function render() {
  const form = clear($("#task-form"));
  const svc = state.services.get(state.selected.service);
  const cmd = svc && svc.commands.find((c) => c.name === state.selected.command);
  current = null;
  if (!svc || !cmd) {
    $("#task-title").textContent = "choose a command";
    form.append(h("p", { class: "hint", text: "Select a service (list or graph), then one of its commands: a form for its option and input data appears here, checked against the command's declared type and size." }));
    return;
  }
  $("#task-title").textContent = `${svc.name} · ${cmd.name}`;
  const input = cmd.input;
  const fields = { option: null, cells: [], free: null, timeout: null };
  const errOf = (k) => h("span", { class: "field-error", dataset: { for: k } });
  if (cmd.info) form.append(h("div", { class: "info", text: cmd.info }));
  form.append(h("div", { class: "info" }, `${cmd.type} · output ${cmd.output.text} · success code '${cmd.successCode}'`));
  const opts = optionsFromInfo(cmd.info);
  fields.option = h("input", { name: "option", type: "text", list: opts.length ? "option-list" : null, placeholder: opts.length ? opts.join(" | ") : "(none)" });
  form.append(h("div", { class: "row" }, h("label", { text: "Option" }), fields.option,
    opts.length ? h("datalist", { id: "option-list" }, ...opts.map((o) => h("option", { value: o }))) : null, errOf("option")));
  if (input.size.length === 1 && input.size[0] === 0) {
    form.append(h("div", { class: "row" }, h("label", { text: "Input data" }), h("span", { class: "hint", text: "no input data" })));
  } else {
    const n = cellsOf(input.size);
    const row = h("div", { class: "row" }, h("label", {}, "Input data ", h("span", { class: "decl", text: input.text })));
    if (n && input.type !== "String") {
      const cols = input.size.length === 2 ? input.size[1] : Math.min(n, 6);
      const grid = h("div", { class: input.size.length === 2 ? "matrix" : "vector" });
      if (input.size.length === 2) grid.style.gridTemplateColumns = `repeat(${cols}, minmax(60px, 1fr))`;
      for (let i = 0; i < n; i++) {
        const el = h("input", { class: "cell-in", type: "text", inputmode: "decimal", name: `data-${i}`, "aria-label": `value ${i + 1}`, placeholder: input.type === "Boolean" ? "TRUE/FALSE" : `[${i}]` });
        fields.cells.push(el);
        grid.append(el);
      }
      row.append(grid);
    } else if (n === 1 && input.type === "String") {
      const el = h("input", { class: "cell-in", type: "text", name: "data-0", "aria-label": "text" });
      fields.cells.push(el); row.append(el);
    } else {
      fields.free = h("textarea", { name: "data", placeholder: input.type === "String" ? "one string per line, or JSON" : "1, 2, 3; 4, 5, 6   (rows split by ; or new lines) or JSON" });
      row.append(fields.free, h("span", { class: "shape" }));
    }
    row.append(errOf("data"));
    form.append(row);
  }
  fields.timeout = h("input", { name: "timeout", type: "text", inputmode: "decimal", placeholder: `${cmd.timeout} (declared)` });
  form.append(h("div", { class: "row" }, h("label", { text: "Timeout, s" }), fields.timeout, errOf("timeout")));
  const submit = h("button", { class: "primary", type: "submit", text: "Activate" });
  form.append(h("div", { class: "actions" }, submit, errOf("_")));
  current = { svc, cmd, fields, submit };
  for (const el of form.querySelectorAll("input, textarea")) el.addEventListener("input", () => check(false));
  check(false);
}

/** Check the form; returns {ok, body}. With show=false, only touched fields show errors. */
function check(show) {
  if (!current) return { ok: false };
  const { svc, cmd, fields, submit } = current;
  const errors = {};
  const cellErrors = new Map();
  let data = null;
  const input = cmd.input;
  if (/[\u0000-\u0008\u000a-\u001f]/.test(fields.option.value)) errors.option = "control characters are not allowed";
  if (fields.cells.length) {
    const values = [];
    for (const [i, el] of fields.cells.entries()) {
      const [x, err] = parseElement(el.value, input.type);
      if (err) cellErrors.set(i, err);
      values.push(x);
    }
    if (cellErrors.size) {
      const typed = [...cellErrors].filter(([i]) => show || fields.cells[i].value !== "");
      const listed = typed.length ? typed : [...cellErrors];
      const [i, err] = listed[0];
      errors.data = `value ${i + 1}: ${err}` + (listed.length > 1 ? ` (and ${listed.length - 1} more)` : "");
    } else data = input.type === "String" && input.size.length === 1 && input.size[0] === 1 ? values : reshape(values, input.size);
  } else if (fields.free) {
    const [x, err] = parseFree(fields.free.value, input.type, input.size);
    if (err) errors.data = err; else data = x;
    const shape = fields.free.parentElement.querySelector(".shape");
    shape.textContent = err ? "" : `size ${sizeText(shapeOf(x))} ✓`;
  }
  let timeout = null;
  if (fields.timeout.value.trim()) {
    const [x, err] = parseElement(fields.timeout.value, "Double");
    if (err) errors.timeout = err;
    else if (x <= 0 || x > 604800) errors.timeout = "between 0 and 604800 s";
    else timeout = x;
  }
  if (!svc.alive) errors._ = `${svc.name} has left the cell`;
  const touched = (el) => show || el.value !== "";
  for (const [i, el] of fields.cells.entries()) el.classList.toggle("invalid", cellErrors.has(i) && touched(el));
  if (fields.free) fields.free.classList.toggle("invalid", Boolean(errors.data) && touched(fields.free));
  fields.timeout.classList.toggle("invalid", Boolean(errors.timeout));
  fields.option.classList.toggle("invalid", Boolean(errors.option));
  const anyTouched = show || fields.cells.some((el) => el.value !== "") || (fields.free && fields.free.value !== "");
  showErrors({ ...errors, data: anyTouched ? errors.data : "" });
  const ok = Object.values(errors).every((e) => !e);
  submit.disabled = !ok;
  return { ok, body: { service: svc.name, command: cmd.name, option: fields.option.value, data, timeout } };
}

function showErrors(errors) {
  for (const el of $("#task-form").querySelectorAll(".field-error")) el.textContent = errors[el.dataset.for] || "";
}

function dataText(msg) {
  const d = msg.data;
  if (d && d.value !== undefined) {
    const v = JSON.stringify(d.value, (k, x) => (typeof x === "number" && !Number.isInteger(x) ? Number(x.toFixed(4)) : x));
    return `${d.type}${sizeText(d.size)} ${v.length > 400 ? `${v.slice(0, 400)}…` : v}`;
  }
  if (d && d.mean !== undefined) return `${d.type}${sizeText(d.size)} min ${d.min} max ${d.max} mean ${d.mean.toFixed(3)}`;
  return msg.dataText || "";
}

const results = new Map();
const latest = new Map();   // task id → its last event (it may come before the POST's answer)

function addResult(id, svc, cmd, state0, reason) {
  const li = h("li", { dataset: { state: state0, task: id } });
  results.set(id, { li, svc, cmd, frames: 0 });
  updateResult(id, latest.get(id) || { state: state0, reason });
  const list = $("#task-results");
  list.prepend(li);
  while (list.children.length > 8) list.removeChild(list.lastChild);
}

function updateResult(id, msg) {
  const r = results.get(id);
  if (!r) return;
  if (msg.data) r.frames++;
  r.li.dataset.state = msg.state;
  const stop = r.cmd.type === "MultipleData" && msg.state === "Running"
    ? h("button", { type: "button", class: "danger", text: "Stop", onclick: async () => { const res = await post("/api/tasks/stop", { id }); if (!res.ok) r.li.append(h("div", { class: "field-error", text: firstError(res) })); } })
    : null;
  clear(r.li).append(...[
    h("div", {}, stateBadge(msg.state), ` ${r.svc}.${r.cmd.name}`, r.frames > 1 ? ` · ${r.frames} frames` : "", " ", stop),
    msg.reason ? h("div", { class: "field-error", text: msg.reason }) : null,
    dataText(msg) ? h("div", { class: "data", text: dataText(msg) }) : null,
  ].filter(Boolean));
}

async function submit(ev) {
  ev.preventDefault();
  const { ok, body } = check(true);
  if (!ok) return;
  current.submit.disabled = true;
  const result = await post("/api/tasks", body);
  current.submit.disabled = false;
  if (!result.ok) {
    showErrors(result.errors || { _: firstError(result) });
    if (result.id) addResult(result.id, body.service, current.cmd, "Failed", result.reason);
    return;
  }
  addResult(result.id, body.service, current.cmd, result.state, result.reason);
}

export function initTaskForm() {
  $("#task-form").addEventListener("submit", submit);
  on("select", render);
  on("cell", () => {
    const svc = state.services.get(state.selected.service);
    if (current && svc && svc.alive !== current.svc.alive) render();
    else if (current && svc) { current.svc = svc; check(false); }
  });
  on("task", (msg) => {
    latest.set(msg.id, msg);
    if (latest.size > 200) latest.delete(latest.keys().next().value);
    updateResult(msg.id, msg);
  });
}
