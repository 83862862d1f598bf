// Tiny DOM helpers: build elements without innerHTML (so nothing from the cell is ever parsed as HTML).
const SVG = "http://www.w3.org/2000/svg";

function build(el, attrs, children) {
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === undefined || v === null || v === false) continue;
    if (k === "class") el.setAttribute("class", v);
    else if (k === "text") el.textContent = v;
    else if (k === "dataset") Object.assign(el.dataset, v);
    else if (k.startsWith("on")) el.addEventListener(k.slice(2), v);
    else if (k === "value") el.value = v;
    else if (k === "checked") el.checked = Boolean(v);
    else el.setAttribute(k, v === true ? "" : String(v));
  }
  for (const c of children.flat()) {
    if (c === null || c === undefined || c === false) continue;
    el.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return el;
}

/** An HTML element: h("div", {class: "x", onclick: f}, child, "text"). */
export function h(tag, attrs = {}, ...children) {
  return build(document.createElement(tag), attrs, children);
}

/** An SVG element. */
export function s(tag, attrs = {}, ...children) {
  return build(document.createElementNS(SVG, tag), attrs, children);
}

export const $ = (sel, root = document) => root.querySelector(sel);
export const $$ = (sel, root = document) => [...root.querySelectorAll(sel)];

export function clear(el) { while (el.firstChild) el.removeChild(el.firstChild); return el; }

/** hh:mm:ss.mmm of a time in ns since 1970. */
export function clock(ns) {
  if (!ns) return "";
  const d = new Date(Number(ns) / 1e6);
  const p = (n, w = 2) => String(n).padStart(w, "0");
  return `${p(d.getHours())}:${p(d.getMinutes())}:${p(d.getSeconds())}.${p(d.getMilliseconds(), 3)}`;
}

export function seconds(x) {
  if (x === null || x === undefined) return "";
  if (x < 1) return `${(x * 1000).toFixed(x < 0.01 ? 2 : 0)} ms`;
  if (x < 120) return `${x.toFixed(2)} s`;
  return `${Math.floor(x / 60)} min ${Math.round(x % 60)} s`;
}

export function stateBadge(state) { return h("span", { class: `st st-${state}`, text: state }); }
