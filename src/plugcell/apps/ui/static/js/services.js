// Services with live/dead status (Figure 7-9) and the selected one's command catalogue (Figure 7-10).
import { $, clear, clock, h } from "./dom.js";
import { emit, on, state } from "./store.js";

export function select(service, command = null) {
  state.selected = { service, command };
  emit("select");
}

function serviceItem(s) {
  const selected = state.selected.service === s.name;
  const partners = s.partners.length ? `→ ${s.partners.join(", ")}` : "no partners";
  const meta = s.alive
    ? `${s.state} · ${s.connection} · ${s.controller ? "subscribed to all" : partners}`
    : `gone since ${clock(s.leftNs)}`;
  return h("li", {
    class: `service${s.alive ? "" : " dead"}${selected ? " selected" : ""}`,
    dataset: { name: s.name, state: s.state, connection: s.connection, alive: String(s.alive) },
    title: s.info || s.name,
    onclick: () => select(s.name),
  },
  h("span", { class: "sdot" }),
  h("span", {}, h("span", { class: "name", text: s.name }), " ", h("span", { class: "kind", text: s.kind || "?" })),
  s.controller ? h("span", { class: "tag", text: "this controller" }) : h("span", { class: "tag", text: s.alive ? "live" : "dead" }),
  h("span", { class: "meta", text: meta }));
}

function renderList() {
  const list = clear($("#service-list"));
  const services = [...state.services.values()].sort((a, b) =>
    (b.alive - a.alive) || (a.controller - b.controller) || a.name.localeCompare(b.name));
  for (const s of services) list.append(serviceItem(s));
  if (!services.length) list.append(h("li", { class: "hint", text: "Discovering services…" }));
  const live = services.filter((s) => s.alive).length;
  $("#service-count").textContent = services.length ? `${live} live · ${services.length - live} gone` : "";
  $("#clients").textContent = state.clients.length ? `clients: ${state.clients.join(", ")}` : "";
}

function declText(d) { return d.text; }

function renderCatalogue() {
  const box = clear($("#catalogue"));
  const s = state.services.get(state.selected.service);
  $("#catalogue-of").textContent = s ? `of ${s.name}` : "";
  if (!s) { box.append(h("p", { class: "hint", text: "Select a service to see its command catalogue." })); return; }
  if (!s.alive) box.append(h("p", { class: "hint", text: `${s.name} has left the cell: its commands cannot be used until it returns.` }));
  if (s.info) box.append(h("p", { class: "hint", text: s.info }));
  for (const c of s.commands) {
    box.append(h("button", {
      class: `cmd${state.selected.command === c.name ? " selected" : ""}`,
      type: "button",
      disabled: !s.alive,
      dataset: { command: c.name },
      onclick: () => select(s.name, c.name),
    },
    h("span", { class: "ctype", text: c.type }),
    h("div", { class: "cname", text: c.name }),
    h("div", { class: "decl", text: `in ${declText(c.input)}  →  out ${declText(c.output)}` }),
    c.info ? h("div", { class: "info", text: c.info }) : null));
  }
}

export function initServices() {
  on("cell", () => { renderList(); renderCatalogue(); });
  on("select", () => { renderList(); renderCatalogue(); });
}
