// Shared helpers: the API client, DOM building, formatting, following a run to its end.

export const API = "/api/v1";
const TOKEN_KEY = "ffdic-token";

/** Headers for a request: the bearer token if the user gave one (only needed off loopback). */
function authHeaders(extra = {}) {
  const token = localStorage.getItem(TOKEN_KEY);
  return token ? { ...extra, Authorization: `Bearer ${token}` } : extra;
}

/** An API error with the problem+json detail when there is one. */
export class ApiError extends Error {
  constructor(status, problem) {
    const detail = problem && (problem.detail || problem.title);
    super(detail ? `${status}: ${detail}` : `HTTP ${status}`);
    this.status = status;
    this.problem = problem;
  }
}

async function check(resp) {
  if (resp.ok) return resp;
  let problem = null;
  try { problem = await resp.json(); } catch (_) { /* not JSON */ }
  throw new ApiError(resp.status, problem);
}

/** GET/POST/PATCH `path` under /api/v1; `body` is sent as JSON unless it is FormData. */
export async function api(path, { method = "GET", body, raw = false } = {}) {
  const init = { method, headers: authHeaders() };
  if (body instanceof FormData) {
    init.body = body;
  } else if (body !== undefined) {
    init.body = JSON.stringify(body);
    init.headers["Content-Type"] = "application/json";
  }
  const resp = await check(await fetch(API + path, init));
  if (raw) return resp;
  if (resp.status === 204) return null;
  return resp.json();
}

export async function apiText(path) {
  return (await api(path, { raw: true })).text();
}

/** Builds an element: el("a", {href: "/"}, "home", child…). */
export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === undefined || v === null || v === false) continue;
    if (k === "class") node.className = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else if (k === "dataset") Object.assign(node.dataset, v);
    else node.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children.flat()) {
    if (c === undefined || c === null || c === false) continue;
    node.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return node;
}

/** A table of `head` and `rows` (each row a list of cells: text or nodes). */
export function table(head, rows) {
  return el("table", {},
    el("thead", {}, el("tr", {}, head.map((h) => el("th", {}, h)))),
    el("tbody", {}, rows.map((cells) => el("tr", {}, cells.map((c) => el("td", {}, c))))));
}

/** A list item that downloads `href`. */
export function downloadLink(href, text) {
  return el("li", {}, el("a", { href, download: "" }, text));
}

export function $(sel, root = document) { return root.querySelector(sel); }
export function $$(sel, root = document) { return [...root.querySelectorAll(sel)]; }

export function clear(node, ...children) {
  node.replaceChildren(...children.flat().filter((c) => c !== null && c !== undefined));
  return node;
}

/** A number with `digits` significant digits, or "—". */
export function num(v, digits = 4) {
  if (v === null || v === undefined || !Number.isFinite(Number(v))) return "—";
  const x = Number(v);
  if (x === 0) return "0";
  const a = Math.abs(x);
  if (a >= 1e5 || a < 1e-4) return x.toExponential(digits - 1);
  return Number(x.toPrecision(digits)).toString();
}

export function pct(progress) {
  return `${Math.round(100 * Math.max(0, Math.min(1, progress || 0)))} %`;
}

export function when(iso) {
  if (!iso) return "—";
  const d = new Date(iso);
  return Number.isNaN(d.getTime()) ? iso : d.toLocaleString();
}

export function badge(status) {
  return el("span", { class: `badge ${status}`, "data-status": status }, status);
}

export const TERMINAL = ["succeeded", "failed", "cancelled"];

/** How long an ended run's event stream may take to replay its events, ms. */
const REPLAY_GRACE_MS = 5000;

/**
 * "+0.0208 ± 0.0013": a signed value and its standard error, the error to two significant
 * digits and the value to the same decimal place (report::plus_minus on the server).
 */
export function plusMinus(value, se) {
  const [v, e] = [Number(value), Number(se)];
  if (!Number.isFinite(v)) return "—";
  if (!(Number.isFinite(e) && e > 0)) return `${v >= 0 ? "+" : ""}${v.toFixed(5)} ± ${Number.isFinite(e) ? e.toFixed(5) : "—"}`;
  const decimals = Math.min(12, Math.max(0, 1 - Math.floor(Math.log10(e))));
  const text = v.toFixed(decimals);
  // A value that rounds to zero reads "+0.000", not "-0.000".
  const signed = Number(text) === 0 ? `+${text.replace("-", "")}` : `${v >= 0 ? "+" : ""}${text}`;
  return `${signed} ± ${e.toFixed(decimals)}`;
}

/** `v` to `d` decimals, a value that rounds to zero without a minus sign. */
const fixed = (v, d) => (Number(v.toFixed(d)) === 0 ? v.toFixed(d).replace("-", "") : v.toFixed(d));

/** Decimal places that show an error `e` to two significant digits (report::table on the server). */
const decimalsFor = (e) => Math.min(12, Math.max(0, 1 - Math.floor(Math.log10(e))));

/**
 * "0.00202 ± 0.00004": a length debiased for noise and its standard error; "< 0.00038" where the
 * debiasing left zero (below its noise: twice its standard error), never "0" (report::length_pm).
 */
export function lengthPm(value, se) {
  const [v, e] = [Number(value), Number(se)];
  if (value === null || value === undefined || !Number.isFinite(v)) return "—";
  if (!(Number.isFinite(e) && e > 0)) return v.toFixed(5);
  const d = decimalsFor(e);
  return v <= 0 ? `< ${(2 * e).toFixed(d)}` : `${v.toFixed(d)} ± ${e.toFixed(d)}`;
}

/** A fitted parameter ± its error to the digits the error supports: "(1.042 ± 0.026)e-4" (report::value_pm). */
export function valuePm(value, se) {
  const [v, e] = [Number(value), Number(se)];
  if (value === null || value === undefined || !Number.isFinite(v)) return "—";
  // Without an error: five significant digits, as the server writes them ("1.0420e-4").
  if (se === null || se === undefined || !(Number.isFinite(e) && e > 0)) return v.toExponential(4).replace("e+", "e");
  const exponent = Math.floor(Math.log10(Math.max(Math.abs(v), e)));
  if (exponent >= -3 && exponent < 4) {
    const d = decimalsFor(e);
    return `${fixed(v, d)} ± ${e.toFixed(d)}`;
  }
  const unit = 10 ** exponent;
  const d = decimalsFor(e / unit);
  return `(${fixed(v / unit, d)} ± ${(e / unit).toFixed(d)})e${exponent}`;
}

/**
 * A stage position or move in mm to the stage's step `resolutionMm` (GET /stage: the step a move
 * is commanded in), or without one to 9 decimals with the binary tail dropped: never
 * 0.7692307692307693.
 */
export function mm(v, resolutionMm) {
  const x = Number(v);
  if (v === null || v === undefined || !Number.isFinite(x)) return "—";
  const decimals = resolutionMm > 0 ? Math.min(9, Math.max(0, Math.ceil(-Math.log10(resolutionMm) - 1e-9))) : 9;
  const text = x.toFixed(decimals);
  return resolutionMm > 0 ? text : String(Number(text));
}

/** µm for `px` full-resolution pixels at `scalePxPerMm` (µm = px / (px/mm) · 1000). */
export function um(px, scalePxPerMm) {
  if (!Number.isFinite(Number(px)) || !(scalePxPerMm > 0)) return null;
  return (1000 * Number(px)) / scalePxPerMm;
}

/** "0.0264 px (2.03 µm)": a length in px with its µm when the scale is known. */
export function pxUm(px, scalePxPerMm, digits = 4) {
  const u = um(px, scalePxPerMm);
  return u === null ? `${num(px, digits)} px` : `${num(px, digits)} px (${num(u, 3)} µm)`;
}

/**
 * The event kinds runs and jobs emit, as the server states them (the `EventKind` schema of its
 * OpenAPI document): EventSource only delivers named events one listens to. Fetched once.
 */
let eventKinds = null;
function loadEventKinds() {
  eventKinds ??= api("/openapi.json").then((doc) => doc.components.schemas.EventKind.enum);
  return eventKinds;
}

/**
 * Follows a run or job: its events over SSE (`eventsUrl`), with a poll of `recordUrl` as a
 * safety net for event kinds this page does not know. Calls `onEvent(event)` for every event
 * and resolves with the final record once the run is terminal.
 */
export function follow(recordUrl, eventsUrl, onEvent, onRecord) {
  return new Promise((resolve) => {
    let done = false;
    let source = null;
    let timer = null;
    const finish = async () => {
      if (done) return;
      done = true;
      if (source) source.close();
      clearInterval(timer);
      clearTimeout(replayTimer);
      const record = await api(recordUrl);
      if (onRecord) onRecord(record);
      resolve(record);
    };
    // A run the poll finds ended may still be replaying its events over SSE (a finished run's
    // stream replays them all, then ends): give the stream that long before closing it, so a
    // page opened on a finished run shows its events too.
    let replayTimer = null;
    let streamOpen = false;
    const poll = async () => {
      try {
        const record = await api(recordUrl);
        if (onRecord && !done) onRecord(record);
        if (TERMINAL.includes(record.status)) {
          if (!streamOpen) finish();
          else if (!replayTimer) replayTimer = setTimeout(finish, REPLAY_GRACE_MS);
        }
      } catch (_) { /* keep trying */ }
    };
    const listen = (kinds) => {
      source = new EventSource(API + eventsUrl);
      const handler = (msg) => {
        let data = null;
        try { data = JSON.parse(msg.data); } catch (_) { return; }
        if (onEvent) onEvent(data);
        if (TERMINAL.includes(data.kind || msg.type)) finish();
      };
      for (const kind of kinds) source.addEventListener(kind, handler);
      source.onerror = () => {
        if (source.readyState === EventSource.CLOSED) streamOpen = false;
        if (!done) poll();
      };
    };
    // Counted as open from the start, so a first poll that finds the run ended waits for the
    // replay; without the kinds (or without EventSource) the poll alone follows the run.
    streamOpen = typeof EventSource !== "undefined";
    loadEventKinds()
      .then((kinds) => { if (!done) listen(kinds); })
      .catch(() => { streamOpen = false; });
    timer = setInterval(poll, 2000);
    poll();
  });
}

/**
 * The handler of a run page's events: moves `bar`, shows the message in `messageNode` and
 * appends the event to the `list` (at most 200 kept).
 */
export function eventLog(bar, messageNode, list) {
  return (e) => {
    // A status change says its status in `data` (the server's word, not a list kept here).
    bar.set(e.progress, e.data ? e.data.status : undefined);
    if (e.message) messageNode.textContent = e.message;
    list.append(el("li", { "data-kind": e.kind }, el("span", { class: "mono" }, e.kind), " — ", e.message || ""));
    while (list.children.length > 200) list.firstElementChild.remove();
    list.scrollTop = list.scrollHeight;
  };
}

/**
 * Fills `tbody` with the runs `path` lists (id linked to `/{page}/{id}`, name, status,
 * progress, created, message), or `emptyText` when there is none.
 */
export async function loadRunList(path, page, tbody, emptyText) {
  try {
    const runs = await api(path);
    const rows = runs.map((r) => el("tr", { "data-id": r.id },
      el("td", {}, el("a", { href: `/${page}/${r.id}`, class: "mono" }, r.id)),
      el("td", {}, (r.request && r.request.name) || ""),
      el("td", {}, badge(r.status)),
      el("td", { class: "num" }, pct(r.progress)),
      el("td", {}, when(r.created_at)),
      el("td", { class: "small muted" }, r.message || "")));
    clear(tbody, rows.length ? rows : [el("tr", {}, el("td", { colspan: 6, class: "muted" }, emptyText))]);
  } catch (e) {
    clear(tbody, el("tr", {}, el("td", { colspan: 6, class: "error" }, e.message)));
  }
}

/** A progress bar with its percentage: returns {node, set(progress, status)}. */
export function progressBar(id) {
  const fill = el("div", { class: "fill" });
  const bar = el("div", {
    class: "progress", id, role: "progressbar",
    "aria-valuemin": "0", "aria-valuemax": "100", "aria-valuenow": "0",
  }, fill);
  const text = el("span", { class: "pct", id: `${id}-text` }, "0 %");
  const node = el("div", { class: "progress-line" }, bar, text);
  let shown = 0;
  return {
    node,
    set(progress, status) {
      // Progress never goes back (events may arrive after a poll).
      shown = Math.max(shown, Math.max(0, Math.min(1, progress || 0)));
      if (status === "succeeded") shown = 1;
      fill.style.width = `${(100 * shown).toFixed(1)}%`;
      bar.setAttribute("aria-valuenow", String(Math.round(100 * shown)));
      bar.className = `progress ${status || ""}`;
      text.textContent = pct(shown);
    },
  };
}

/** Fetches an SVG the server drew and puts it inline in `container` (so it scales with the page). */
export async function inlineSvg(container, url) {
  const resp = await fetch(url, { headers: authHeaders() });
  if (!resp.ok) throw new ApiError(resp.status, null);
  const text = await resp.text();
  const doc = new DOMParser().parseFromString(text, "image/svg+xml");
  const svg = doc.documentElement;
  if (svg.nodeName !== "svg") throw new Error(`${url} is not an SVG`);
  // Scale with the container, keep the drawing's proportions.
  svg.removeAttribute("width");
  svg.removeAttribute("height");
  svg.setAttribute("preserveAspectRatio", "xMidYMid meet");
  clear(container, document.importNode(svg, true));
  container.dataset.loaded = "true";
  return container;
}

/** Shows an error under `node` (or clears it with null). */
export function showError(node, err) {
  if (!node) return;
  node.textContent = err ? (err.message || String(err)) : "";
}

/** The header's token box: stored in this browser only, sent as a bearer token. */
export function setupToken() {
  const box = document.getElementById("token");
  if (!box) return;
  box.value = localStorage.getItem(TOKEN_KEY) || "";
  box.addEventListener("change", () => {
    if (box.value) localStorage.setItem(TOKEN_KEY, box.value.trim());
    else localStorage.removeItem(TOKEN_KEY);
  });
}

/** The last path segment of the page URL (an experiment's or a dataset's id). */
export function pageId() {
  const parts = location.pathname.split("/").filter(Boolean);
  return decodeURIComponent(parts[parts.length - 1] || "");
}

/**
 * The life of one run's page: show its record, wire the cancel button (`#cancel-btn`), follow
 * its events until it ends, then show its results, or why it did not succeed in `#run-error`.
 * `what` names the run in that message ("the sweep cancelled: …").
 */
export async function runPage({ recordUrl, eventsUrl, cancelUrl, what, showRecord, onEvent, showResults }) {
  $("#cancel-btn").addEventListener("click", async () => {
    try {
      showRecord(await api(cancelUrl, { method: "POST" }));
    } catch (e) {
      showError($("#run-error"), e);
    }
  });
  try {
    showRecord(await api(recordUrl));
  } catch (e) {
    showError($("#run-error"), e);
    return;
  }
  const final = await follow(recordUrl, eventsUrl, onEvent, showRecord);
  showRecord(final);
  if (final.status === "succeeded") await showResults(final);
  else showError($("#run-error"), `${what} ${final.status}: ${final.message || ""}`);
}
