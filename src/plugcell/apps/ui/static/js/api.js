// The controller's web API (plugcell/apps/ui/api.py).  Refusals come back as {ok: false, errors}.
const HEADERS = { "Content-Type": "application/json", "X-Plugcell": "1" };

async function read(response) {
  let body = {};
  try { body = await response.json(); } catch { body = {}; }
  if (!response.ok && body.ok === undefined) body = { ok: false, errors: { _: `HTTP ${response.status}` } };
  if (body.ok === undefined) body.ok = response.ok;
  return body;
}

export async function post(url, payload) {
  try {
    return await read(await fetch(url, { method: "POST", headers: HEADERS, body: JSON.stringify(payload ?? {}) }));
  } catch (exc) {
    return { ok: false, errors: { _: `controller unreachable (${exc.message})` } };
  }
}

export async function get(url) {
  try {
    return await read(await fetch(url, { headers: { Accept: "application/json" } }));
  } catch (exc) {
    return { ok: false, errors: { _: `controller unreachable (${exc.message})` } };
  }
}

export async function getText(url) {
  try {
    const r = await fetch(url);
    return r.ok ? await r.text() : "";
  } catch { return ""; }
}

/** The first error of a refusal, as one line. */
export function firstError(result) {
  const errors = result.errors || {};
  const k = Object.keys(errors)[0];
  return k === undefined ? "" : (k === "_" ? errors[k] : `${k}: ${errors[k]}`);
}
