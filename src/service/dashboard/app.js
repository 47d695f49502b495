// gearwear dashboard: polls the JSON API every 2 s (ETag revalidation keeps polls cheap).
"use strict";
const POLL_MS = 2000;
let selected = null;
const $ = (id) => document.getElementById(id);
const NS = "http://www.w3.org/2000/svg";

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
    throw new Error(p.detail || "a read key is needed");
  }
  if (!r.ok) {
    const p = await r.json().catch(() => ({}));
    throw new Error(p.detail || ("HTTP " + r.status));
  }
  return r.json();
}

function el(tag, attrs, parent, text) {
  const e = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  if (parent) parent.appendChild(e);
  return e;
}

function renderMachines(list) {
  const ul = $("machines");
  if (!list.machines.length) return;
  ul.innerHTML = "";
  for (const m of list.machines) {
    const li = document.createElement("li");
    li.dataset.id = m.id;
    li.dataset.level = m.alert_level;
    if (m.id === selected) li.className = "selected";
    const dot = document.createElement("span");
    dot.className = "dot " + m.alert_level;
    dot.title = m.alert_level;
    li.appendChild(dot);
    li.appendChild(document.createTextNode(m.id + " "));
    const n = document.createElement("small");
    n.className = "muted";
    n.textContent = "(" + m.record_count + ")";
    li.appendChild(n);
    li.onclick = () => { selected = m.id; refresh(); };
    ul.appendChild(li);
  }
  if (!selected && list.machines.length) selected = list.machines[0].id;
}

function axes(svg, W, H, pad, x0, x1, y0, y1, xl, yl) {
  const sx = (x) => pad.l + (x - x0) / (x1 - x0 || 1) * (W - pad.l - pad.r);
  const sy = (y) => H - pad.b - (y - y0) / (y1 - y0 || 1) * (H - pad.t - pad.b);
  el("line", { x1: pad.l, y1: H - pad.b, x2: W - pad.r, y2: H - pad.b, stroke: "#9aa3af" }, svg);
  el("line", { x1: pad.l, y1: pad.t, x2: pad.l, y2: H - pad.b, stroke: "#9aa3af" }, svg);
  for (let i = 0; i <= 4; i++) {
    const y = y0 + (y1 - y0) * i / 4;
    el("line", { x1: pad.l, x2: W - pad.r, y1: sy(y), y2: sy(y), stroke: "#eef0f3" }, svg);
    el("text", { x: pad.l - 4, y: sy(y) + 4, "text-anchor": "end" }, svg, y.toFixed(y1 - y0 < 5 ? 2 : 0));
  }
  el("text", { x: W - pad.r, y: H - 4, "text-anchor": "end" }, svg, xl);
  el("text", { x: 4, y: pad.t - 4 }, svg, yl);
  return [sx, sy];
}

function renderTrend(m) {
  const svg = $("trend");
  svg.innerHTML = "";
  const W = 640, H = 220, pad = { l: 44, r: 12, t: 18, b: 26 };
  const pts = m.trend;
  const n = Math.max(pts.length, 2);
  const ymax = Math.max(1, m.thresholds.alarm * 1.1, ...pts.map((p) => p.upper));
  const [sx, sy] = axes(svg, W, H, pad, 0, n - 1, 0, ymax, "diagnosis # (oldest → newest)", "ea");
  if (pts.length) {
    const up = pts.map((p, i) => sx(i) + "," + sy(p.upper));
    const lo = pts.map((p, i) => sx(i) + "," + sy(p.lower)).reverse();
    el("polygon", { points: up.concat(lo).join(" "), fill: "#3b82f633", stroke: "none", id: "trend-band" }, svg);
    el("polyline", { points: pts.map((p, i) => sx(i) + "," + sy(p.estimate)).join(" "), fill: "none", stroke: "#1d4ed8", "stroke-width": 2 }, svg);
    pts.forEach((p, i) => el("circle", { cx: sx(i), cy: sy(p.estimate), r: 3, fill: "#1d4ed8", class: "trend-point" }, svg));
  }
  for (const [name, v, c] of [["warning", m.thresholds.warning, "var(--warning)"], ["alarm", m.thresholds.alarm, "var(--alarm)"]]) {
    el("line", { x1: pad.l, x2: W - pad.r, y1: sy(v), y2: sy(v), stroke: c, "stroke-dasharray": "6 4" }, svg);
    el("text", { x: W - pad.r - 2, y: sy(v) - 3, "text-anchor": "end", fill: c }, svg, name + " " + v);
  }
}

function renderSpectrum(d) {
  const svg = $("spectrum");
  svg.innerHTML = "";
  const s = d && d.spectrum;
  if (!s) return;
  const W = 640, H = 260, pad = { l: 44, r: 12, t: 18, b: 26 };
  const ymin = -80, ymax = 0, xmax = s.f_over_f1[s.f_over_f1.length - 1] || 2.5;
  const [sx, sy] = axes(svg, W, H, pad, 0, xmax, ymin, ymax, "f / f1", "dB re f1");
  const pts = s.f_over_f1.map((f, i) => sx(f) + "," + sy(Math.max(ymin, Math.min(ymax, s.level_db[i]))));
  el("polyline", { points: pts.join(" "), fill: "none", stroke: "#334155", "stroke-width": 1, id: "spectrum-line" }, svg);
  const main = new Set(["f1", "f2", "f3"]);
  let k = 0;
  for (const mk of s.marks) {
    if (mk.f_over_f1 > xmax) continue;
    const isMain = main.has(mk.name);
    const x = sx(mk.f_over_f1);
    el("line", { x1: x, x2: x, y1: pad.t, y2: H - pad.b, stroke: isMain ? "#d2352b" : "#e0a100", "stroke-dasharray": isMain ? "" : "3 3", class: "mark", "data-name": mk.name }, svg);
    el("text", { x: x + 2, y: pad.t + 10 + (k++ % 4) * 11, fill: isMain ? "#d2352b" : "#a16207" }, svg, mk.name);
  }
}

async function refresh() {
  try {
    const list = await api("/v1/machines");
    renderMachines(list);
    $("status").textContent = "updated " + new Date().toLocaleTimeString();
    if (!selected) return;
    const m = await api("/v1/machines/" + encodeURIComponent(selected));
    $("placeholder").hidden = true;
    $("machine").hidden = false;
    $("machine-name").textContent = m.id;
    const b = $("machine-level");
    b.textContent = m.alert_level;
    b.className = "badge " + m.alert_level;
    $("records").textContent = m.record_count;
    const l = m.latest;
    if (l) {
      $("wear-estimate").textContent = l.wear_degree.estimate.toFixed(3);
      $("wear-interval").textContent = l.wear_degree.lower.toFixed(3) + " … " + l.wear_degree.upper.toFixed(3);
      $("motion-state").textContent = l.motion_state;
      $("f1").textContent = l.f1_hz.toFixed(1) + " Hz (shaft " + l.shaft_hz.toFixed(2) + " Hz)";
      const flags = [];
      if (l.planetary_clearance_elevated) flags.push("planetary clearance elevated");
      for (const w of l.warnings) flags.push(w);
      $("flags").innerHTML = "";
      if (!flags.length) $("flags").textContent = "none";
      for (const f of flags) { const s = document.createElement("div"); s.className = "flag"; s.textContent = f; $("flags").appendChild(s); }
      renderTrend(m);
      if ($("spectrum").dataset.diagnosis !== l.id) {
        const d = await api("/v1/diagnoses/" + encodeURIComponent(l.id));
        renderSpectrum(d);
        $("spectrum").dataset.diagnosis = l.id;
      }
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
