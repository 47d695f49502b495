// gearwear dashboard: polls the JSON API every 2 s (the browser revalidates with the ETags the
// API sends, so an unchanged answer is a 304 and is not drawn again).
//
// The selected machine lives in the URL (`#/machines/<id>`; `?machine=<id>` is accepted and
// rewritten to that form), so a link opens a machine and back/forward move between machines.
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
  if (key()) headers["Authorization"] = "Bearer " + key();
  const r = await fetch(path, { headers, cache: "no-cache" });
  if (r.status === 401 || r.status === 403) {
    // No key, a wrong or revoked one (401), or one without the read scope (403): ask.
    if (r.status === 401) sessionStorage.removeItem("gearwear-key");
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
/** A timestamp for a person: local date and time. */
function when(iso) {
  const t = Date.parse(iso);
  if (!num(t)) return "–";
  const d = new Date(t);
  return dateText(d) + " " + clock(d, true);
}

// ---------- the URL holds the selected machine ----------

function machineHref(id) { return "#/machines/" + encodeURIComponent(id); }
function machineFromUrl() {
  const m = location.hash.match(/^#\/machines\/(.+)$/);
  if (m) { try { return decodeURIComponent(m[1]); } catch (_) { return m[1]; } }
  return new URLSearchParams(location.search).get("machine") || null;
}
let selected = machineFromUrl();
if (selected && !location.hash.startsWith("#/machines/")) {
  // `?machine=press-7` → `/#/machines/press-7`, one form from here on.
  history.replaceState(null, "", location.pathname + machineHref(selected));
}
window.addEventListener("hashchange", () => {
  selected = machineFromUrl();
  refresh();
});

// ---------- the fleet ----------

function sortFleet(machines) {
  return [...machines].sort((a, b) =>
    LEVELS[level(a.alert_level)].rank - LEVELS[level(b.alert_level)].rank ||
    (a.id < b.id ? -1 : a.id > b.id ? 1 : 0));
}

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

function tableText(g) {
  if (!g || g.status === "ready") return "";
  if (g.status === "running") return "table " + Math.round(100 * (g.progress || 0)) + " %";
  return "table " + g.status;
}

let fleetDrawn = "";
function renderMachines(list, gearboxes) {
  const ul = $("machines");
  const machines = sortFleet(list.machines || []);
  if (!selected && machines.length) {
    selected = machines[0].id;
    history.replaceState(null, "", location.pathname + machineHref(selected));
  }
  const key = JSON.stringify([machines, gearboxes, selected]);
  if (key === fleetDrawn) return;
  fleetDrawn = key;
  // Redrawn from the answer every time, also when it is empty: a deleted machine leaves the
  // list (the last one too).
  ul.innerHTML = "";
  if (!machines.length) {
    h("li", { class: "muted" }, ul, "no machine has sent a record yet");
    return;
  }
  const gb = new Map((gearboxes || []).map((g) => [g.id, g]));
  for (const m of machines) {
    const lv = level(m.alert_level);
    const li = h("li", { class: "level-" + lv + (m.id === selected ? " selected" : "") }, ul);
    li.dataset.id = m.id;
    li.dataset.level = lv;
    li.title = m.id + " — " + levelHelp(lv, m.record_count);
    const a = h("a", { href: machineHref(m.id) }, li);
    dot(lv, a);
    h("span", { class: "name" }, a, m.id);
    h("small", { class: "muted" }, a, "(" + m.record_count + ")");
    const t = tableText(gb.get(m.gearbox));
    if (t) h("small", { class: "pill table-" + gb.get(m.gearbox).status }, a, t);
  }
}

// ---------- charts on a time axis ----------

const S = 1000, MIN = 60 * S, HOUR = 60 * MIN, DAY = 24 * HOUR;
const STEPS = [1 * S, 2 * S, 5 * S, 10 * S, 15 * S, 30 * S, MIN, 2 * MIN, 5 * MIN, 10 * MIN, 15 * MIN, 30 * MIN,
  HOUR, 2 * HOUR, 3 * HOUR, 6 * HOUR, 12 * HOUR, DAY, 2 * DAY, 7 * DAY, 14 * DAY, 30 * DAY, 91 * DAY, 365 * DAY];

/** The shared time range of a machine's charts: its diagnoses' times, padded. */
function timeDomain(trend) {
  const ts = trend.map((p) => Date.parse(p.measured_at || p.created_at)).filter(num);
  let t0 = ts.length ? Math.min(...ts) : Date.now() - HOUR;
  let t1 = ts.length ? Math.max(...ts) : Date.now();
  if (t1 - t0 < MIN) { const mid = (t0 + t1) / 2; t0 = mid - MIN / 2; t1 = mid + MIN / 2; }
  const padT = (t1 - t0) * 0.04;
  return [t0 - padT, t1 + padT];
}

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

function renderTrend(m, dom) {
  const svg = $("trend");
  svg.innerHTML = "";
  const { W, H, pad } = CHART;
  const pts = (m.trend || []).map((p) => ({ ...p, t: Date.parse(p.measured_at || p.created_at) })).filter((p) => num(p.t));
  const th = m.thresholds || {};
  const uppers = pts.map((p) => p.upper).filter(num);
  const ymax = Math.max(1, num(th.alarm) ? th.alarm * 1.1 : 0, ...uppers);
  const [sx, sy] = timeAxes(svg, W, H, pad, dom[0], dom[1], 0, ymax, "wear degree ea");
  for (const run of runs(pts, (p) => num(p.estimate))) {
    const banded = run.filter((p) => num(p.lower) && num(p.upper));
    if (banded.length) {
      const up = banded.map((p) => sx(p.t) + "," + sy(p.upper));
      const lo = banded.map((p) => sx(p.t) + "," + sy(p.lower)).reverse();
      el("polygon", { points: up.concat(lo).join(" "), fill: "#3b82f633", stroke: "none", class: "trend-band" }, svg);
    }
    el("polyline", { points: run.map((p) => sx(p.t) + "," + sy(p.estimate)).join(" "), fill: "none", stroke: "#1d4ed8", "stroke-width": 2, class: "trend-line" }, svg);
  }
  for (const p of pts) {
    if (num(p.estimate)) {
      const c = el("circle", { cx: sx(p.t), cy: sy(p.estimate), r: 3.5, fill: "#1d4ed8", class: "trend-point", "data-t": p.measured_at || p.created_at }, svg);
      tooltip(c, when(p.measured_at || p.created_at) + ": ea " + p.estimate.toFixed(3) + (num(p.lower) ? " (" + p.lower.toFixed(2) + " … " + p.upper.toFixed(2) + ")" : "") + ", " + p.alert_level);
    } else {
      // A diagnosis without a wear figure: a hollow mark on the axis, no line through it (never
      // a point at 0).
      const c = el("circle", { cx: sx(p.t), cy: H - pad.b, r: 3.5, fill: "#fff", stroke: "#8a8f98", class: "trend-nowear", "data-t": p.measured_at || p.created_at }, svg);
      tooltip(c, when(p.measured_at || p.created_at) + ": no wear figure (the model does not fit the record, or the gearbox's table is not ready), " + p.alert_level);
    }
  }
  for (const [name, v, c] of [["warning", th.warning, "var(--warning)"], ["alarm", th.alarm, "var(--alarm)"]]) {
    if (!num(v)) continue;
    el("line", { x1: pad.l, x2: W - pad.r, y1: sy(v), y2: sy(v), stroke: c, "stroke-dasharray": "6 4" }, svg);
    el("text", { x: W - pad.r - 2, y: sy(v) - 3, "text-anchor": "end", fill: c }, svg, name + " " + v);
  }
  if (!pts.length) note(svg, W, H, "no diagnosis yet");
  else if (!pts.some((p) => num(p.estimate))) note(svg, W, H, "no wear figure: the model does not fit these records, or the table is not ready");
}

function renderNovelty(m, dom) {
  const svg = $("novelty");
  svg.innerHTML = "";
  const { W, H, pad } = CHART;
  const pts = (m.trend || []).map((p) => ({ ...p, t: Date.parse(p.measured_at || p.created_at) })).filter((p) => num(p.t));
  const scored = pts.filter((p) => num(p.novelty));
  const ths = scored.map((p) => p.novelty_threshold).filter(num);
  const ymax = Math.max(1, ...scored.map((p) => p.novelty), ...ths.map((t) => 2 * t)) * 1.1;
  const [sx, sy] = timeAxes(svg, W, H, pad, dom[0], dom[1], 0, ymax, "novelty score");
  const b = m.baseline || {};
  // The baseline's span in time, shaded, when it falls in the chart.
  const b0 = Date.parse(b.first_at), b1 = Date.parse(b.last_at);
  if (num(b0) && num(b1) && b1 >= dom[0] && b0 <= dom[1]) {
    const x0 = Math.max(pad.l, sx(b0) - 3), x1 = Math.min(W - pad.r, sx(b1) + 3);
    const r = el("rect", { x: x0, y: pad.t, width: Math.max(2, x1 - x0), height: H - pad.t - pad.b, fill: "#2e9d4f1a", class: "baseline-span" }, svg);
    tooltip(r, "baseline records: " + when(b.first_at) + " – " + when(b.last_at));
    el("text", { x: x0 + 2, y: pad.t + 11, fill: "#2e7d46" }, svg, "baseline");
  }
  // The threshold each score was judged against, as a step line (it changes with the baseline).
  for (const [cls, k, c] of [["novelty-threshold", 1, "var(--warning)"], ["novelty-alarm", 2, "var(--alarm)"]]) {
    for (const run of runs(scored, (p) => num(p.novelty_threshold))) {
      const xy = [];
      run.forEach((p, i) => {
        const next = i + 1 < run.length ? sx(run[i + 1].t) : W - pad.r;
        xy.push(sx(p.t) + "," + sy(k * p.novelty_threshold), next + "," + sy(k * p.novelty_threshold));
      });
      el("polyline", { points: xy.join(" "), fill: "none", stroke: c, "stroke-dasharray": "6 4", class: cls }, svg);
    }
    const last = scored[scored.length - 1];
    if (last && num(last.novelty_threshold)) {
      el("text", { x: W - pad.r - 2, y: sy(k * last.novelty_threshold) - 3, "text-anchor": "end", fill: c }, svg,
        (k === 1 ? "threshold " : "alarm ") + (k * last.novelty_threshold).toFixed(2));
    }
  }
  for (const run of runs(pts, (p) => num(p.novelty))) {
    el("polyline", { points: run.map((p) => sx(p.t) + "," + sy(p.novelty)).join(" "), fill: "none", stroke: "#7c3aed", "stroke-width": 2, class: "novelty-line" }, svg);
  }
  for (const p of scored) {
    const over = num(p.novelty_threshold) && p.novelty > p.novelty_threshold;
    const c = el("circle", { cx: sx(p.t), cy: sy(p.novelty), r: 3.5, fill: over ? "var(--alarm)" : "#7c3aed", class: "novelty-point" + (over ? " anomalous" : ""), "data-t": p.measured_at || p.created_at }, svg);
    tooltip(c, when(p.measured_at || p.created_at) + ": novelty " + p.novelty.toFixed(2) + (num(p.novelty_threshold) ? " (threshold " + p.novelty_threshold.toFixed(2) + ")" : "") + ", " + p.alert_level);
  }
  if (!scored.length) {
    const need = Math.max(0, (b.min_records || 3) - (b.count || 0));
    note(svg, W, H, b.ready
      ? "baseline ready: records from now on get a novelty score"
      : "no novelty yet: the baseline needs " + need + " more healthy record" + (need === 1 ? "" : "s"));
  }
}

function renderSpectrum(d) {
  const svg = $("spectrum");
  svg.innerHTML = "";
  const W = 640, H = 260, pad = { l: 44, r: 12, t: 18, b: 26 };
  const s = d && d.spectrum;
  if (!s || !s.f_over_f1 || !s.f_over_f1.length) {
    note(svg, W, H, d ? "no spectrum for this diagnosis (no mesh line: the gearbox's table was not ready)" : "no diagnosis yet");
    return;
  }
  const ymin = -80, ymax = 0, xmax = s.f_over_f1[s.f_over_f1.length - 1] || 2.5;
  const sx = (x) => pad.l + x / xmax * (W - pad.l - pad.r);
  const sy = (y) => H - pad.b - (y - ymin) / (ymax - ymin) * (H - pad.t - pad.b);
  el("line", { x1: pad.l, y1: H - pad.b, x2: W - pad.r, y2: H - pad.b, stroke: "#9aa3af" }, svg);
  el("line", { x1: pad.l, y1: pad.t, x2: pad.l, y2: H - pad.b, stroke: "#9aa3af" }, svg);
  for (let i = 0; i <= 4; i++) {
    const y = ymin + (ymax - ymin) * i / 4;
    el("line", { x1: pad.l, x2: W - pad.r, y1: sy(y), y2: sy(y), stroke: "#eef0f3" }, svg);
    el("text", { x: pad.l - 4, y: sy(y) + 4, "text-anchor": "end" }, svg, y.toFixed(0));
  }
  for (let f = 0; f <= xmax + 1e-9; f += 0.5) {
    el("text", { x: sx(f), y: H - pad.b + 14, "text-anchor": "middle" }, svg, f.toFixed(1));
  }
  el("text", { x: W - pad.r, y: H - 1, "text-anchor": "end" }, svg, "f / f1");
  el("text", { x: 4, y: pad.t - 4 }, svg, "dB re f1");
  const pts = s.f_over_f1.map((f, i) => sx(f) + "," + sy(Math.max(ymin, Math.min(ymax, s.level_db[i]))));
  el("polyline", { points: pts.join(" "), fill: "none", stroke: "#334155", "stroke-width": 1, id: "spectrum-line" }, svg);
  const main = new Set(["f1", "f2", "f3"]);
  let k = 0;
  for (const mk of s.marks || []) {
    if (mk.f_over_f1 > xmax) continue;
    const isMain = main.has(mk.name);
    const x = sx(mk.f_over_f1);
    el("line", { x1: x, x2: x, y1: pad.t, y2: H - pad.b, stroke: isMain ? "#d2352b" : "#e0a100", "stroke-dasharray": isMain ? "" : "3 3", class: "mark", "data-name": mk.name }, svg);
    el("text", { x: x + 2, y: pad.t + 10 + (k++ % 4) * 11, fill: isMain ? "#d2352b" : "#a16207" }, svg, mk.name);
  }
}

// ---------- one machine ----------

function badge(node, l, recordCount) {
  const lv = level(l);
  node.textContent = LEVELS[lv].icon + " " + lv;
  node.className = "badge " + lv;
  node.title = levelHelp(lv, recordCount);
}

function renderAlert(m) {
  const l = m.latest;
  const box = $("alert");
  const lv = level(l && l.alert ? l.alert.level : m.alert_level);
  box.className = "alert " + lv;
  box.dataset.level = lv;
  if (!l) {
    $("alert-title").textContent = "No record yet.";
    $("alert-reason").textContent = "Post one to /v1/machines/" + m.id + "/records; nothing vouches for this machine until then.";
    $("alert-basis").textContent = "";
    return;
  }
  const a = l.alert || { level: l.alert_level, basis: null, reason: "" };
  $("alert-title").textContent = LEVELS[lv].icon + " " + lv[0].toUpperCase() + lv.slice(1) + ":";
  $("alert-reason").textContent = a.reason || (lv === "unknown" ? LEVELS.unknown.help : "");
  const bits = [];
  // A single-channel record's channel is just "0": name it only when several were diagnosed.
  if (l.channel && Array.isArray(l.channels) && l.channels.length > 1) bits.push("deciding channel: " + l.channel);
  if (a.basis) bits.push("based on: " + (a.basis === "none" ? "nothing (no fit, no baseline)" : a.basis));
  bits.push("record of " + when(l.created_at));
  $("alert-basis").textContent = bits.join(" · ");
}

function renderChannels(l) {
  const table = $("channels");
  const tb = table.querySelector("tbody");
  tb.innerHTML = "";
  const chs = (l && Array.isArray(l.channels)) ? l.channels : [];
  table.hidden = chs.length < 2;
  if (chs.length < 2) return;
  for (const c of [...chs].sort((a, b) => LEVELS[level(a.alert_level)].rank - LEVELS[level(b.alert_level)].rank || (a.name < b.name ? -1 : 1))) {
    const tr = h("tr", { class: c.name === l.channel ? "deciding" : "" }, tb);
    tr.dataset.channel = c.name;
    tr.dataset.level = level(c.alert_level);
    h("td", {}, tr, c.name + (c.name === l.channel ? " (decides)" : ""));
    const td = h("td", {}, tr);
    badge(h("span", {}, td), c.alert_level, 1);
    const n = c.novelty;
    h("td", {}, tr, n && num(n.score) ? n.score.toFixed(2) + " / " + fmt(n.threshold, 2) : "no baseline");
    const w = c.wear_degree;
    h("td", {}, tr, w && num(w.estimate) ? w.estimate.toFixed(3) : c.fit && c.fit.inflated ? "no figure (poor fit)" : "–");
    const top = n && Array.isArray(n.top_features) ? n.top_features.slice(0, 3).map((f) => f.name + " z " + fmt(f.z, 1)).join(", ") : "";
    h("td", { class: "muted" }, tr, top || (c.alert && c.alert.reason) || "");
  }
}

function renderGearbox(m) {
  const g = m.gearbox || {};
  $("gearbox-name").textContent = g.name || g.id || "–";
  $("gearbox-id").textContent = g.id ? "(" + g.id + (g.builtin ? ", built-in: the paper's rig" : "") + ")" : "";
  const st = $("gearbox-status");
  const running = g.status === "running" || g.status === "queued";
  st.textContent = (g.status || "unknown") + (g.status === "running" && num(g.progress) ? " " + Math.round(100 * g.progress) + " %" : "");
  st.className = "pill table-" + (g.status || "unknown");
  const pr = $("gearbox-progress");
  pr.hidden = !running;
  pr.value = num(g.progress) ? g.progress : 0;
  $("gearbox-note").textContent =
    g.status === "failed" ? "failed: " + (g.error || "no reason stored") + " — PUT a corrected description"
      : running ? "no wear degree until the table is ready; records are judged by the baseline meanwhile"
        : g.status === "ready" && g.finished_at ? "ready since " + when(g.finished_at) : "";
}

function renderBaseline(m) {
  const b = m.baseline || {};
  const count = b.count || 0;
  const min = b.min_records || 3;
  $("baseline-count").textContent = count + " record" + (count === 1 ? "" : "s");
  const chs = Object.entries(b.channels || {});
  const usable = chs.length ? Math.max(...chs.map(([, c]) => c.records || 0)) : 0;
  const need = Math.max(0, min - usable);
  const st = $("baseline-state");
  st.textContent = b.ready ? "ready" : need > 0 ? "needs " + need + " more" : "not fitted";
  st.className = "pill " + (b.ready ? "baseline-ready" : "baseline-missing");
  $("baseline-when").textContent = b.first_at
    ? "since " + when(b.first_at) + (b.last_at && b.last_at !== b.first_at ? ", last marked " + when(b.last_at) : "")
    : "no healthy record marked yet: POST records with ?baseline=true";
  $("baseline-channels").textContent = chs.length > 1 || (chs.length && !b.ready)
    ? chs.map(([n, c]) => n + ": " + c.records + (c.ready ? " (threshold " + fmt(c.threshold, 2) + ")" : " (not ready)")).join(" · ")
    : chs.length ? "threshold " + fmt(chs[0][1].threshold, 2) : "";
  // The operating states the (first) state-aware channel's baseline covers, per load.
  const aware = chs.find(([, c]) => c.state_aware && c.coverage);
  $("baseline-coverage").textContent = aware ? "covers " + coverageText(aware[1].coverage) : "";
}

/** `low: 30.0–40.0 Hz (6) · high: …` — the speeds a state-aware baseline holds per load. */
function coverageText(cov) {
  return (cov.loads || []).map((l) => {
    const where = num(l.min_hz) && num(l.max_hz)
      ? (Math.abs(l.max_hz - l.min_hz) < 0.05 ? l.min_hz.toFixed(1) : l.min_hz.toFixed(1) + "–" + l.max_hz.toFixed(1)) + " Hz"
      : "";
    return (l.load === null || l.load === undefined ? "any load" : "load " + l.load) + ": " + where + " (" + l.records + ")";
  }).join(" · ");
}

/** The wear figure of the latest diagnosis, or why there is none (never a number then). */
function wearText(l, m) {
  if (!l) return "–";
  const w = l.wear_degree;
  if (w && num(w.estimate)) return w.estimate.toFixed(3);
  if (l.wear_note) return "no wear figure (poor fit: the model does not fit this record)";
  const g = m.gearbox || {};
  if (g.status && g.status !== "ready") return "no wear figure (the gearbox's table is not ready)";
  return "no wear figure";
}

/** The measured speed: `35.00 Hz (tachometer)`, or why it was not measured. */
function speedText(l) {
  const st = l && l.operating_state;
  if (st && num(st.shaft_hz)) {
    const varies = num(st.speed_variation) && st.speed_variation > 0.02 ? ", varies " + (100 * st.speed_variation).toFixed(0) + " %" : "";
    return st.shaft_hz.toFixed(2) + " Hz input shaft (" + (st.source || "measured") + varies + ")";
  }
  return l && l.state_note ? "not measured: " + l.state_note : "–";
}

/** `text` into `node`, its `name` spans (the core's sentences quote part names so) as code. */
function codeText(node, text) {
  text.split("`").forEach((part, i) => {
    if (i % 2) h("code", {}, node, part);
    else node.appendChild(document.createTextNode(part));
  });
}

/** The latest diagnosis's findings, each in words, strongest first. */
function renderFindings(l) {
  const box = $("findings-box");
  const ol = $("findings");
  ol.innerHTML = "";
  const fs = (l && Array.isArray(l.findings)) ? l.findings : [];
  box.hidden = !l || (!fs.length && !l.operating_state);
  $("findings-note").textContent = fs.length
    ? "what the departure from the baseline at this speed and load points at, strongest first"
    : "none: the latest record does not depart from its baseline at this speed and load (or the machine has no baseline with states yet)";
  for (const f of fs) {
    const li = h("li", { class: "finding" }, ol);
    codeText(li, f.summary || f.kind || "");
    li.dataset.kind = f.kind || "";
    h("span", { class: "kind" }, li, (f.kind || "") + (num(f.strength) ? ", strength " + f.strength.toFixed(1) : ""));
    const ev = Array.isArray(f.evidence) ? f.evidence : [];
    if (ev.length) li.title = ev.map((e) => e.feature + " " + e.change + " (z " + fmt(e.z, 1) + "): " + e.why).join("\n");
  }
}

function renderLatest(m) {
  const l = m.latest;
  $("records").textContent = m.record_count;
  $("latest-at").textContent = l ? when(l.created_at) : "";
  const w = l && l.wear_degree;
  // No wear figure (the model does not fit, or no table): says why, never a number.
  $("wear-estimate").textContent = wearText(l, m);
  $("wear-estimate").title = (l && l.wear_note) || "";
  $("wear-estimate").classList.toggle("muted", !!l && !(w && num(w.estimate)));
  $("wear-interval").textContent = w && num(w.lower) && num(w.upper) ? w.lower.toFixed(3) + " … " + w.upper.toFixed(3) : "–";
  $("speed").textContent = speedText(l);
  const load = l && l.operating_state ? l.operating_state.load : undefined;
  $("load").textContent = load === undefined || load === null ? (l ? "not given" : "–") : String(load);
  const n = l && l.novelty;
  $("novelty-latest").textContent = n && num(n.score)
    ? n.score.toFixed(2) + " (threshold " + fmt(n.threshold, 2) + (n.anomalous ? ", anomalous)" : ")")
    : "–";
  $("motion-state").textContent = (l && l.motion_state) || "–";
  $("f1").textContent = l && num(l.f1_hz)
    ? l.f1_hz.toFixed(1) + " Hz" + (num(l.shaft_hz) ? " (shaft " + l.shaft_hz.toFixed(2) + " Hz)" : "")
    : "–";
  const flags = [];
  if (l && l.planetary_clearance_elevated) flags.push("planetary clearance elevated");
  for (const f of (l && l.warnings) || []) flags.push(f);
  $("flags").innerHTML = "";
  for (const f of flags) h("div", { class: "flag" }, $("flags"), f);
}

/** Everything about one machine from its `GET /v1/machines/{id}` answer. */
function renderMachine(m) {
  $("placeholder").hidden = true;
  $("machine").hidden = false;
  $("machine").dataset.id = m.id;
  $("machine-name").textContent = m.id;
  badge($("machine-level"), m.alert_level, m.record_count);
  $("machine-updated").textContent = "updated " + when(m.updated_at);
  renderAlert(m);
  renderChannels(m.latest);
  renderGearbox(m);
  renderBaseline(m);
  renderLatest(m);
  renderFindings(m.latest);
  const dom = timeDomain(m.trend || []);
  renderTrend(m, dom);
  renderNovelty(m, dom);
}

function showMissing(id, message) {
  $("machine").hidden = true;
  $("placeholder").hidden = false;
  $("placeholder").textContent = id ? "Machine " + id + ": " + message : message;
}

// ---------- polling ----------

let machineDrawn = "";
let busy = false, again = false;
async function refresh() {
  if (busy) { again = true; return; }
  busy = true;
  try {
    await poll();
  } finally {
    busy = false;
    if (again) { again = false; refresh(); }
  }
}

async function poll() {
  try {
    const [list, gbs] = await Promise.all([
      api("/v1/machines"),
      api("/v1/gearboxes").catch(() => ({ gearboxes: [] })),
    ]);
    renderMachines(list, gbs.gearboxes);
    $("status").textContent = "updated " + new Date().toLocaleTimeString();
    const want = selected;
    if (!want) return;
    let m;
    try {
      m = await api("/v1/machines/" + encodeURIComponent(want));
    } catch (e) {
      if (e.status === 404 && want === selected) { machineDrawn = ""; showMissing(want, e.message); return; }
      throw e;
    }
    if (want !== selected) return; // the URL moved on meanwhile
    const drawn = JSON.stringify(m);
    if (drawn !== machineDrawn) {
      machineDrawn = drawn;
      renderMachine(m);
    }
    const l = m.latest;
    const sp = $("spectrum");
    if (!l) {
      if (sp.dataset.diagnosis !== "") { renderSpectrum(null); sp.dataset.diagnosis = ""; }
    } else if (sp.dataset.diagnosis !== l.id) {
      const d = await api("/v1/diagnoses/" + encodeURIComponent(l.id));
      if (want !== selected) return;
      renderSpectrum(d);
      sp.dataset.diagnosis = l.id;
    }
  } catch (e) {
    $("status").textContent = e.message;
  }
}

$("keyform").addEventListener("submit", (ev) => {
  ev.preventDefault();
  sessionStorage.setItem("gearwear-key", $("key").value.trim());
  $("key").value = "";
  $("keyform").hidden = true;
  refresh();
});
refresh();
setInterval(refresh, POLL_MS);
