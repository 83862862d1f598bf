// The calibration report and the reproduced thesis figures (docs/results), read-only.
import { $, clear, h } from "./dom.js";
import { get, getText } from "./api.js";
import { on } from "./store.js";

let loaded = false;

/** Inline markdown: `code`, **bold**, *em*, ![img](src), [link](href) → DOM nodes. */
function inline(text, base) {
  const out = [];
  const re = /(`[^`]+`)|(\*\*[^*]+\*\*)|(\*[^*\s][^*]*\*)|(!\[[^\]]*\]\([^)]+\))|(\[[^\]]+\]\([^)]+\))/g;
  let last = 0; let m;
  while ((m = re.exec(text))) {
    if (m.index > last) out.push(text.slice(last, m.index));
    const t = m[0];
    if (m[1]) out.push(h("code", { text: t.slice(1, -1) }));
    else if (m[2]) out.push(h("b", { text: t.slice(2, -2) }));
    else if (m[3]) out.push(h("em", { text: t.slice(1, -1) }));
    else if (m[4]) {
      const [, alt, src] = /!\[([^\]]*)\]\(([^)]+)\)/.exec(t);
      out.push(/^[\w.-]+\.(png|svg)$/.test(src) ? h("img", { alt, src: `${base}${src}` }) : `[${alt}]`);
    } else {
      const [, label, href] = /\[([^\]]+)\]\(([^)]+)\)/.exec(t);
      out.push(/^[\w.-]+\.(png|svg|md|json|html)$/.test(href) ? h("a", { href: `${base}${href}`, target: "_blank", text: label })
        : /^https?:/.test(href) ? h("span", { title: href, text: label }) : h("span", { text: label }));
    }
    last = m.index + t.length;
  }
  if (last < text.length) out.push(text.slice(last));
  return out;
}

/** A small markdown renderer (headings, paragraphs, lists, tables, code) building DOM nodes. */
export function markdown(src, base) {
  const root = h("div", { class: "md" });
  const lines = src.split("\n");
  let i = 0;
  while (i < lines.length) {
    const line = lines[i];
    if (/^```/.test(line)) {
      const code = []; i++;
      while (i < lines.length && !/^```/.test(lines[i])) code.push(lines[i++]);
      i++; root.append(h("pre", { text: code.join("\n") })); continue;
    }
    const hd = /^(#{1,4})\s+(.*)$/.exec(line);
    if (hd) { root.append(h(`h${hd[1].length + 1}`, {}, ...inline(hd[2], base))); i++; continue; }
    if (/^\|/.test(line)) {
      const rows = [];
      while (i < lines.length && /^\|/.test(lines[i])) rows.push(lines[i++]);
      const cells = (r) => r.replace(/^\||\|$/g, "").split("|").map((c) => c.trim());
      const table = h("table");
      rows.forEach((r, k) => {
        if (k === 1 && /^[\s|:-]+$/.test(r)) return;
        table.append(h("tr", {}, ...cells(r).map((c) => h(k === 0 ? "th" : "td", {}, ...inline(c, base)))));
      });
      root.append(table); continue;
    }
    if (/^\s*[*-]\s+/.test(line)) {
      const ul = h("ul");
      while (i < lines.length && /^\s*[*-]\s+/.test(lines[i])) ul.append(h("li", {}, ...inline(lines[i++].replace(/^\s*[*-]\s+/, ""), base)));
      root.append(ul); continue;
    }
    if (!line.trim()) { i++; continue; }
    const para = [];
    while (i < lines.length && lines[i].trim() && !/^(#|\||```|\s*[*-]\s)/.test(lines[i])) para.push(lines[i++]);
    root.append(h("p", {}, ...inline(para.join(" "), base)));
  }
  return root;
}

let shown = 0;   // the latest request wins: a slow earlier one must not land on top

async function show(item, link) {
  const token = ++shown;
  for (const a of document.querySelectorAll(".report-list a")) a.classList.toggle("active", a === link);
  $("#report-title").textContent = item.name;
  let node;
  if (item.kind === "png" || item.kind === "svg") node = h("img", { src: item.url, alt: item.name });
  else if (item.kind === "md") node = markdown(await getText(item.url), "/reports/results/");
  else if (item.kind === "html") node = h("div", {}, h("p", {}, h("a", { href: item.url, target: "_blank", text: "open in a new tab" })), h("iframe", { src: item.url, sandbox: "", title: item.name }));
  else node = h("pre", { text: await getText(item.url) });
  if (token === shown) clear($("#report-view")).append(node);
}

async function load() {
  loaded = true;
  const res = await get("/api/reports");
  const list = clear($("#report-list"));
  let group = "";
  for (const item of res.reports || []) {
    if (item.group !== group) { group = item.group; list.append(h("li", { class: "group", text: group })); }
    const a = h("a", { href: item.url, text: item.name, dataset: { kind: item.kind } });
    a.addEventListener("click", (ev) => { ev.preventDefault(); show(item, a); });
    list.append(h("li", {}, a));
  }
  if (!(res.reports || []).length) list.append(h("li", { class: "hint", text: "No reports: run plugcell reproduce or plugcell calibrate --report, or start the controller with --docs/--report." }));
  const first = (res.reports || []).find((r) => r.kind === "md");
  if (first) show(first, list.querySelector(`a[href="${first.url}"]`));
}

export function initReports() {
  on("tab", (t) => { if (t === "reports" && !loaded) load(); });
}
