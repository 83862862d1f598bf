// Robot programs on one or several robots, sequentially or concurrently (thesis 7.6, Figure 7-10),
// each with its values (name=value, one per line: the program's variables, docs/robot-programs.md).
import { $, clear, clock, h, seconds, stateBadge } from "./dom.js";
import { firstError, get, getText, post } from "./api.js";
import { liveServices, on, state } from "./store.js";

let programs = [];

function robots() {
  return liveServices((s) => s.commands.some((c) => c.name.toUpperCase() === "ACTIVATE")).map((s) => s.name).sort();
}

const VALUE = /^\s*[A-Za-z_]\w*\s*=/;

/** The lines of a values box as ["name=value", …]; returns [values, error]. */
export function parseValues(text) {
  const values = [];
  for (const [i, raw] of text.split("\n").entries()) {
    if (!raw.trim() || raw.trim().startsWith("--")) continue;
    if (!VALUE.test(raw)) return [null, `values line ${i + 1}: expected name=value`];
    values.push(raw.trim());
  }
  return [values, ""];
}

function row() {
  const robot = h("select", { class: "run-robot", "aria-label": "robot" });
  const program = h("input", { class: "run-program", type: "text", list: "program-names", placeholder: "program name or path", "aria-label": "program" });
  const values = h("textarea", { class: "run-values", rows: 1, spellcheck: "false", placeholder: "values (optional): name=value, one per line", "aria-label": "program values" });
  const remove = h("button", { type: "button", text: "×", title: "remove", onclick: () => { el.remove(); } });
  const el = h("div", { class: "run-row" }, h("div", { class: "run-head" }, robot, program, remove), values);
  const edited = (x) => () => { x.classList.remove("invalid"); $("#run-error").textContent = ""; };
  program.addEventListener("input", edited(program));
  values.addEventListener("input", () => {
    edited(values)();
    values.rows = Math.min(6, Math.max(1, values.value.split("\n").length));
    const [, err] = parseValues(values.value);
    if (err) { values.classList.add("invalid"); $("#run-error").textContent = err; }
  });
  return el;
}

function fillRobots(sel) {
  const keep = sel.value;
  const names = robots();
  clear(sel).append(h("option", { value: "", text: names.length ? "robot…" : "no robot service" }), ...names.map((n) => h("option", { value: n, text: n })));
  if (names.includes(keep)) sel.value = keep;
  else if (names.length) {
    const index = [...document.querySelectorAll(".run-robot")].indexOf(sel);
    sel.value = names[Math.max(index, 0) % names.length];
  }
}

async function run() {
  const err = $("#run-error");
  err.textContent = "";
  const items = [];
  for (const r of document.querySelectorAll(".run-row")) {
    const robot = r.querySelector(".run-robot"); const program = r.querySelector(".run-program");
    const box = r.querySelector(".run-values");
    robot.classList.toggle("invalid", !robot.value);
    program.classList.toggle("invalid", !program.value.trim());
    if (!robot.value || !program.value.trim()) { err.textContent = "choose a robot and a program on every row"; return; }
    const [values, bad] = parseValues(box.value);
    box.classList.toggle("invalid", Boolean(bad));
    if (bad) { err.textContent = bad; return; }
    items.push({ robot: robot.value, program: program.value.trim(), values });
  }
  if (!items.length) { err.textContent = "add a robot"; return; }
  const mode = document.querySelector("input[name=run-mode]:checked").value;
  $("#run-btn").disabled = true;
  const result = await post("/api/runs", { items, mode });
  $("#run-btn").disabled = false;
  if (!result.ok) err.textContent = firstError(result);
}

function renderRuns() {
  const list = clear($("#runs"));
  const runs = [...state.runs.values()].slice(-6).reverse();
  for (const r of runs) {
    const took = r.endedNs ? seconds((r.endedNs - r.startedNs) / 1e9) : "";
    list.append(h("li", { dataset: { run: r.id, state: r.state } },
      h("div", {}, stateBadge(r.state), ` ${r.id} · ${r.mode} · started ${clock(r.startedNs)} ${took ? `· ${took}` : ""}`),
      h("div", { class: "items" }, ...r.items.map((i) => h("span", { class: "item", title: [i.reason || i.state, ...(i.console || [])].join("\n"), dataset: { robot: i.robot, programState: i.programState || "" } },
        stateBadge(i.state), ` ${i.robot}:${i.program}`, i.values ? h("span", { class: "muted", text: ` (${i.values} values)` }) : null,
        i.programState ? h("span", { class: `pstate ps-${i.programState}`, text: ` ${i.programState}${i.simS !== null && i.simS !== undefined ? ` · ${seconds(i.simS)} simulated` : ""}` }) : null,
        i.programState && i.programState !== "FINISHED" && (i.message || (i.console || []).length) ? h("span", { class: "field-error", text: ` ${i.message || i.console[i.console.length - 1]}` }) : null,
        i.reason ? h("span", { class: "field-error", text: ` ${i.reason}` }) : null)))));
  }
  if (!runs.length) list.append(h("li", { class: "hint", text: "No program runs yet." }));
}

async function loadLibrary() {
  const res = await get("/api/programs");
  programs = res.programs || [];
  const dl = h("datalist", { id: "program-names" }, ...programs.filter((p) => !p.library).map((p) => h("option", { value: p.name })));
  document.body.append(dl);
  const list = clear($("#program-list"));
  for (const p of programs) {
    list.append(h("li", { onclick: async () => { $("#program-source").textContent = await getText(`/api/programs/${encodeURIComponent(p.name)}`); } },
      h("b", { class: "mono", text: p.name }), p.library ? h("span", { class: "muted", text: " (library)" }) : "", " ",
      h("div", { class: "about", text: p.about })));
  }
}

function addRow() {
  const el = row();
  $("#run-rows").append(el);
  fillRobots(el.querySelector(".run-robot"));
}

export function initPrograms() {
  addRow();
  $("#add-run-row").addEventListener("click", addRow);
  $("#run-btn").addEventListener("click", run);
  on("cell", () => { for (const sel of document.querySelectorAll(".run-robot")) fillRobots(sel); });
  on("runs", renderRuns);
  loadLibrary();
}
