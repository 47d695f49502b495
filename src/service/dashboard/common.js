// gearwear dashboard, shared pieces: the API call (with the read key), DOM and SVG builders,
// number and time formatting, the alert levels, and the time axis every chart uses.
"use strict";
const POLL_MS = 2000;
const $ = (id) => document.getElementById(id);
const NS = "http://www.w3.org/2000/svg";

// Severity order of the fleet list and what each level means to the person reading it.
const LEVELS = {
  alarm: { rank: 0, icon: "✕", help: "alarm: wear past the alarm threshold, or novelty above twice the baseline's threshold" },
  warning: { rank: 1, icon: "!", help: "warning: wear past the warning threshold, or novelty above the baseline's threshold" },
  unknown: {
    rank: 2, icon: "?",
    help: "unknown: the model does not fit this machine and it has no baseline, so nothing vouches for it. " +
      "Add a baseline (POST at least 3 healthy records with ?baseline=true) or describe its gearbox " +
      "(PUT /v1/gearboxes/{id}, then PUT /v1/machines/{id} with it).",
  },
  ok: { rank: 3, icon: "✓", help: "ok: within the wear thresholds and/or the machine's baseline" },
};
const level = (l) => (l in LEVELS ? l : "unknown");

// The read key lives in sessionStorage: it is gone when the tab closes, and never written
// to disk the way localStorage is. (Earlier versions used localStorage: clear that copy.)
try { localStorage.removeItem("gearwear-key"); } catch (_) { /* storage disabled */ }
function key() { return sessionStorage.getItem("gearwear-key") || ""; }

async function api(path) {
  const headers = {};
  const sent = key();
  if (sent) headers["Authorization"] = "Bearer " + sent;
  const r = await fetch(path, { headers, cache: "no-cache" });
  if (r.status === 401 || r.status === 403) {
    // No key, a wrong or revoked one (401), or one without the read scope (403): ask. A
    // request sent before a key was entered does not forget the key entered meanwhile.
    if (r.status === 401 && key() === sent) sessionStorage.removeItem("gearwear-key");
    $("keyform").hidden = false;
    const p = await r.json().catch(() => ({}));
    throw Object.assign(new Error(p.detail || "a read key is needed"), { status: r.status });
  }
  if (!r.ok) {
    const p = await r.json().catch(() => ({}));
    throw Object.assign(new Error(p.detail || ("HTTP " + r.status)), { status: r.status });
  }
  return r.json();
}

/** POST a JSON body; the answer, or an Error with the problem's detail (never a key prompt). */
async function apiPost(path, body) {
  const headers = { "Content-Type": "application/json" };
  if (key()) headers["Authorization"] = "Bearer " + key();
  const r = await fetch(path, { method: "POST", headers, body: JSON.stringify(body) });
  const p = await r.json().catch(() => ({}));
  if (!r.ok) throw Object.assign(new Error(p.detail || ("HTTP " + r.status)), { status: r.status });
  return p;
}

/**
 * May the key in use acknowledge alerts? Asked once per key: the acknowledge endpoint checks
 * the key's scope before it reads the body, so an empty body answers 400 for a key with the
 * `acknowledge` scope (and acknowledges nothing), 401/403 for one without.
 */
let canAcknowledge = null;
async function probeAcknowledge() {
  const headers = { "Content-Type": "application/json" };
  if (key()) headers["Authorization"] = "Bearer " + key();
  try {
    const r = await fetch("/v1/alerts/-/acknowledge", { method: "POST", headers, body: "{}" });
    return r.status === 400;
  } catch (_) {
    return false;
  }
}

// ---------- small helpers ----------

function el(tag, attrs, parent, text) {
  const e = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  if (parent) parent.appendChild(e);
  return e;
}

function h(tag, attrs, parent, text) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k === "class") e.className = v; else e.setAttribute(k, v);
  }
  if (text !== undefined) e.textContent = text;
  if (parent) parent.appendChild(e);
  return e;
}

const num = (v) => typeof v === "number" && Number.isFinite(v);
const fmt = (v, d) => (num(v) ? v.toFixed(d) : "–");
const pad2 = (n) => String(n).padStart(2, "0");
const MONTHS = ["Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec"];
function dateText(d) { return d.getDate() + " " + MONTHS[d.getMonth()] + " " + d.getFullYear(); }
function clock(d, secs) { return pad2(d.getHours()) + ":" + pad2(d.getMinutes()) + (secs ? ":" + pad2(d.getSeconds()) : ""); }
/**
 * When a record was measured: its `measured_at` when the API gives one (the `recorded_at` it
 * was posted with, else its receive time), else `created_at` (when it was received).
 */
function measuredAt(x) { return (x && (x.measured_at || x.created_at)) || null; }

/** A timestamp for a person: local date and time. */
function when(iso) {
  const t = Date.parse(iso);
  if (!num(t)) return "–";
  const d = new Date(t);
  return dateText(d) + " " + clock(d, true);
}


// ---------- alert levels for people ----------

function levelHelp(l, recordCount) {
  if (level(l) === "unknown" && recordCount === 0) {
    return "unknown: no record yet — post one to /v1/machines/{id}/records";
  }
  return LEVELS[level(l)].help;
}

function dot(l, parent) {
  const s = h("span", { class: "dot " + level(l), "aria-label": level(l) }, parent, LEVELS[level(l)].icon);
  return s;
}
function badge(node, l, recordCount) {
  const lv = level(l);
  node.textContent = LEVELS[lv].icon + " " + lv;
  node.className = "badge " + lv;
  node.title = levelHelp(lv, recordCount);
}

function codeText(node, text) {
  text.split("`").forEach((part, i) => {
    if (i % 2) h("code", {}, node, part);
    else node.appendChild(document.createTextNode(part));
  });
}

/** The latest diagnosis's findings, each in words, strongest first. */
// ---------- charts on a time axis ----------

const S = 1000, MIN = 60 * S, HOUR = 60 * MIN, DAY = 24 * HOUR;
const STEPS = [1 * S, 2 * S, 5 * S, 10 * S, 15 * S, 30 * S, MIN, 2 * MIN, 5 * MIN, 10 * MIN, 15 * MIN, 30 * MIN,
  HOUR, 2 * HOUR, 3 * HOUR, 6 * HOUR, 12 * HOUR, DAY, 2 * DAY, 7 * DAY, 14 * DAY, 30 * DAY, 91 * DAY, 365 * DAY];

/** The shared time range of a machine's charts: its diagnoses' times, padded. */
/** Tick times at a round local step, about five over [t0, t1]. */
function timeTicks(t0, t1) {
  const step = STEPS.find((s) => (t1 - t0) / s <= 6) || STEPS[STEPS.length - 1];
  // Align to the local clock (whole minutes, hours, local midnight).
  const off = -new Date(t0).getTimezoneOffset() * MIN;
  const ticks = [];
  for (let t = Math.ceil((t0 + off) / step) * step - off; t <= t1; t += step) ticks.push(t);
  return { step, ticks };
}

function tickLabel(t, step) {
  const d = new Date(t);
  if (step >= DAY) return d.getDate() + " " + MONTHS[d.getMonth()];
  if (d.getHours() === 0 && d.getMinutes() === 0 && d.getSeconds() === 0) return d.getDate() + " " + MONTHS[d.getMonth()];
  return clock(d, step < MIN);
}

/** Axes with a time x (ms since the epoch) and a numeric y; returns the scales. */
function timeAxes(svg, W, H, pad, t0, t1, y0, y1, yl) {
  const sx = (t) => pad.l + (t - t0) / (t1 - t0 || 1) * (W - pad.l - pad.r);
  const sy = (y) => H - pad.b - (y - y0) / (y1 - y0 || 1) * (H - pad.t - pad.b);
  for (let i = 0; i <= 4; i++) {
    const y = y0 + (y1 - y0) * i / 4;
    el("line", { x1: pad.l, x2: W - pad.r, y1: sy(y), y2: sy(y), stroke: "#eef0f3" }, svg);
    el("text", { x: pad.l - 4, y: sy(y) + 4, "text-anchor": "end" }, svg, y.toFixed(y1 - y0 < 5 ? 2 : 0));
  }
  const { step, ticks } = timeTicks(t0, t1);
  for (const t of ticks) {
    const x = sx(t);
    el("line", { x1: x, x2: x, y1: pad.t, y2: H - pad.b, stroke: "#f2f3f5" }, svg);
    el("line", { x1: x, x2: x, y1: H - pad.b, y2: H - pad.b + 4, stroke: "#9aa3af" }, svg);
    // Labels at the edges stay inside the chart.
    const anchor = x > W - pad.r - 24 ? "end" : x < pad.l + 24 ? "start" : "middle";
    el("text", { x, y: H - pad.b + 15, "text-anchor": anchor, class: "tick-x", "data-t": new Date(t).toISOString() }, svg,
      tickLabel(t, step));
  }
  el("line", { x1: pad.l, y1: H - pad.b, x2: W - pad.r, y2: H - pad.b, stroke: "#9aa3af" }, svg);
  el("line", { x1: pad.l, y1: pad.t, x2: pad.l, y2: H - pad.b, stroke: "#9aa3af" }, svg);
  const span = step >= DAY ? "" : dateText(new Date(t0)) + (new Date(t0).toDateString() === new Date(t1).toDateString() ? "" : " – " + dateText(new Date(t1)));
  el("text", { x: W - pad.r, y: H - 3, "text-anchor": "end", class: "axis-label" }, svg, "local time" + (span ? ", " + span : ""));
  el("text", { x: 4, y: pad.t - 6 }, svg, yl);
  return [sx, sy];
}

/** Runs of consecutive items for which `ok` holds: lines break where a value is missing. */
function runs(items, ok) {
  const out = [];
  let cur = [];
  for (const p of items) {
    if (ok(p)) cur.push(p); else if (cur.length) { out.push(cur); cur = []; }
  }
  if (cur.length) out.push(cur);
  return out;
}

function note(svg, W, H, text) {
  el("text", { x: W / 2, y: H / 2, "text-anchor": "middle", class: "chart-note" }, svg, text);
}

function tooltip(node, text) { el("title", {}, node, text); }

const CHART = { W: 480, H: 240, pad: { l: 40, r: 10, t: 20, b: 34 } };

/**
 * Why a diagnosis has no wear figure, in a few words, from its typed reason `withheld`
 * (`wear_withheld`: the API's codes, never its sentences). `short` drops the explanation
 * (the fleet table's cell). `null` when the code is not given (an answer stored before codes).
 */
const WITHHELD = {
  "poor-fit": ["poor fit", "poor fit: the model does not fit this record"],
  "one-part": ["one part's change", "the change is one part's, not wear"],
  "outside-calibration": ["outside the calibration", "the record ran at a speed outside the machine's calibration"],
  "table-in-progress": ["table in progress", "the table at this speed is being computed; the record is read again when it is ready"],
  "outside-table": ["outside the table", "no table covers the record's speed"],
};
function noWearText(withheld, short) {
  const w = WITHHELD[withheld];
  if (!w) return null;
  return "no wear figure (" + w[short ? 0 : 1] + ")";
}
