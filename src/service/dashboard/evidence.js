// gearwear dashboard: the record page's evidence — the deciding channel's order spectrum over
// the healthy record nearest its state, its envelope spectrum, the lines the evidence reads
// marked by part, and each finding linked to the lines it rests on (GET /v1/diagnoses/{id}'s
// `evidence`).
"use strict";

const EVC = { W: 980, pad: { l: 56, r: 16, t: 78, b: 40 }, rowH: 13, rows: 4 };
const EV_COLORS = { mesh: "#c62828", sideband: "#d97706", shaft: "#1d4ed8", bearing: "#7c3aed", "shaft-rate": "#1d4ed8" };
// Labels placed first when rows fill up: the selected finding's lines, then by kind, first
// harmonics before higher ones.
const EV_RANK = { mesh: 0, shaft: 1, bearing: 1, "shaft-rate": 1, sideband: 3 };
const evRank = (l) => EV_RANK[l.kind] + (/×[23]$|^[23]×/.test(l.label) ? 1 : 0);
let evidenceView = null; // { r, zoom: [lo, hi] | null, selected: index | null }

/** A person's words for how the record's speed was measured. */
function speedWords(st) {
  if (!st || !num(st.shaft_hz)) return null;
  const how = st.source === "tachometer" ? "counted from the tachometer" : "tracked from the mesh lines (no tachometer)";
  const varies = num(st.speed_variation) ? ", varies " + (100 * st.speed_variation).toFixed(1) + " % over the record" : "";
  return st.shaft_hz.toFixed(2) + " Hz input shaft (" + (60 * st.shaft_hz).toFixed(0) + " rpm), " + how + varies;
}

/** What the record was compared with, in words. */
function referenceWords(sr) {
  if (!sr) return "no baseline with measured states on this channel yet";
  const hz = (sr.reference_hz || []).filter(num).map((v) => v.toFixed(2) + " Hz");
  const words = {
    "same-state": "the healthy records at the same state (same load and speed: " + hz.join(", ") + ")",
    interpolated: "interpolated between the healthy records at " + hz.join(" and ") + " of the same load",
    nearest: "the nearest healthy state (" + hz.join(", ") + "): the baseline has no record at this speed and load",
  };
  return (words[sr.reference] || sr.reference) + "; score " + fmt(sr.score, 2) + " against threshold " + fmt(sr.threshold, 2);
}

/** The record's state and its reference as facts (`fact(name, value, class)`). */
function evidenceFacts(d, fact) {
  const st = d.operating_state;
  fact("Load", st && st.load !== undefined && st.load !== null ? String(st.load) : "not given with the record", "load");
  fact("Speed", speedWords(st) || (d.state_note ? "not measured: " + d.state_note : "not measured"), "speed");
  fact("Deciding channel", d.channel ? d.channel + " (its alert is the record's)" : "–", "channel");
  fact("Compared with", referenceWords(d.state_reference), "reference");
}

function niceStep(span, n) {
  const raw = span / n, p = Math.pow(10, Math.floor(Math.log10(raw)));
  for (const m of [1, 2, 5, 10]) if (m * p >= raw) return m * p;
  return 10 * p;
}

/** `[ymin, ymax]` (dB) over the traces' points in `[lo, hi]`. */
function dbRange(traces, lo, hi) {
  let top = -Infinity, vals = [];
  for (const t of traces) {
    if (!t) continue;
    t.level_db.forEach((v, i) => {
      const o = t.start + i * t.step;
      if (o >= lo && o <= hi) { vals.push(v); if (v > top) top = v; }
    });
  }
  if (!vals.length) return [-100, 0];
  vals.sort((a, b) => a - b);
  const ymax = Math.ceil((top + 3) / 10) * 10;
  const floor = Math.floor(vals[Math.floor(vals.length * 0.02)] / 10) * 10;
  return [Math.max(ymax - 120, Math.min(floor, ymax - 40)), ymax];
}

function tracePath(t, sx, sy, lo, hi, y0, y1) {
  const pts = [];
  t.level_db.forEach((v, i) => {
    const o = t.start + i * t.step;
    if (o >= lo && o <= hi) pts.push(sx(o).toFixed(1) + "," + sy(Math.max(y0, Math.min(y1, v))).toFixed(1));
  });
  return pts.join(" ");
}

/**
 * One spectrum: `spec = {trace, reference, lines, lo, hi, shaftHz, unit, highlight: Set, regions}`.
 * Orders below, Hz above, lines as dashed verticals with their labels in rows that do not
 * overlap (a label that finds no free row is left to the line's tooltip).
 */
function drawEvidenceChart(svg, spec) {
  svg.innerHTML = "";
  const { W, pad, rowH, rows } = EVC;
  const H = +svg.getAttribute("viewBox").split(" ")[3];
  const { lo, hi } = spec;
  const [y0, y1] = dbRange([spec.trace, spec.reference], lo, hi);
  const sx = (o) => pad.l + (o - lo) / (hi - lo) * (W - pad.l - pad.r);
  const sy = (v) => H - pad.b - (v - y0) / (y1 - y0) * (H - pad.t - pad.b);
  const top = pad.t, bottom = H - pad.b;
  for (const r of spec.regions || []) {
    if (!spec.highlight.has("region:" + r.name) || r.hi < lo || r.lo > hi) continue;
    const x0 = sx(Math.max(lo, r.lo)), x1 = sx(Math.min(hi, r.hi));
    el("rect", { x: x0, y: top, width: x1 - x0, height: bottom - top, fill: "#fde68a55", class: "ev-region hl", "data-region": r.name }, svg);
  }
  const ys = niceStep(y1 - y0, 5);
  for (let v = Math.ceil(y0 / ys) * ys; v <= y1; v += ys) {
    el("line", { x1: pad.l, x2: W - pad.r, y1: sy(v), y2: sy(v), stroke: "#eef0f3" }, svg);
    el("text", { x: pad.l - 4, y: sy(v) + 4, "text-anchor": "end" }, svg, v.toFixed(0));
  }
  const os = niceStep(hi - lo, 10);
  for (let o = Math.ceil(lo / os) * os; o <= hi + 1e-9; o += os) {
    el("text", { x: sx(o), y: bottom + 14, "text-anchor": "middle", class: "ev-tick-order" }, svg, +o.toFixed(3) + "");
  }
  const hs = niceStep((hi - lo) * spec.shaftHz, 8);
  for (let f = Math.ceil(lo * spec.shaftHz / hs) * hs; f <= hi * spec.shaftHz + 1e-9; f += hs) {
    const x = sx(f / spec.shaftHz);
    el("line", { x1: x, x2: x, y1: top - 4, y2: top, stroke: "#9aa3af" }, svg);
    el("text", { x, y: top - 7, "text-anchor": "middle", class: "ev-tick-hz" }, svg, +f.toFixed(1) + "");
  }
  el("line", { x1: pad.l, y1: bottom, x2: W - pad.r, y2: bottom, stroke: "#9aa3af" }, svg);
  el("line", { x1: pad.l, y1: top, x2: W - pad.r, y2: top, stroke: "#9aa3af" }, svg);
  el("line", { x1: pad.l, y1: top, x2: pad.l, y2: bottom, stroke: "#9aa3af" }, svg);
  el("text", { x: W - pad.r, y: H - 4, "text-anchor": "end" }, svg, "order of the input shaft (× its rate)");
  el("text", { x: W - pad.r, y: 12, "text-anchor": "end" }, svg, "Hz (at " + spec.shaftHz.toFixed(2) + " Hz input)");
  const ym = (top + bottom) / 2;
  el("text", { x: 12, y: ym, "text-anchor": "middle", transform: "rotate(-90 12 " + ym + ")", class: "ev-axis-db" }, svg, "dB re 1 " + spec.unit);
  if (spec.reference) {
    el("polyline", { points: tracePath(spec.reference, sx, sy, lo, hi, y0, y1), fill: "none", stroke: "#16a34a", "stroke-opacity": 0.55, "stroke-width": 1, class: "ev-reference" }, svg);
  }
  el("polyline", { points: tracePath(spec.trace, sx, sy, lo, hi, y0, y1), fill: "none", stroke: "#334155", "stroke-width": 1, class: "ev-trace" }, svg);
  drawEvidenceLines(svg, spec, sx, sy, y0, y1, top, bottom, rows, rowH);
}

function drawEvidenceLines(svg, spec, sx, sy, y0, y1, top, bottom, rows, rowH) {
  const shown = spec.lines.filter((l) => l.order >= spec.lo && l.order <= spec.hi);
  const anyHl = shown.some((l) => spec.highlight.has(l.feature));
  const placed = Array.from({ length: rows }, () => []);
  const order = shown.map((l, i) => i).sort((a, b) => {
    const la = shown[a], lb = shown[b];
    const ha = spec.highlight.has(la.feature) ? 0 : 1, hb = spec.highlight.has(lb.feature) ? 0 : 1;
    return ha - hb || evRank(la) - evRank(lb) || la.order - lb.order;
  });
  for (const i of order) {
    const l = shown[i];
    const hl = spec.highlight.has(l.feature);
    const c = EV_COLORS[l.kind] || "#555";
    const x = sx(l.order);
    const g = el("g", { class: "ev-mark" + (hl ? " hl" : anyHl ? " dim" : ""), "data-kind": l.kind, "data-feature": l.feature, "data-label": l.label, "data-order": l.order }, svg);
    el("line", { x1: x, x2: x, y1: top, y2: bottom, stroke: c, "stroke-width": hl ? 2 : 1, "stroke-dasharray": l.kind === "sideband" ? "2 3" : "5 3", class: "ev-line" }, g);
    el("circle", { cx: x, cy: sy(Math.max(y0, Math.min(y1, l.level_db))), r: hl ? 3.5 : 2.5, fill: c }, g);
    tooltip(g, l.part + ": order " + (+l.order.toFixed(3)) + " (" + (l.order * spec.shaftHz).toFixed(1) + " Hz), " + l.level_db.toFixed(1) + " dB re 1 " + spec.unit + (l.feature ? " — feeds " + l.feature : ""));
    // A free row for the label: rows from the bottom of the band up, first fit.
    const t = el("text", { x, y: 0, "text-anchor": "middle", style: "fill:" + c, class: "ev-label" + (hl ? " hl" : "") }, g, l.label);
    const w = (t.getComputedTextLength && t.getComputedTextLength()) || 6.2 * l.label.length;
    const left = Math.max(EVC.pad.l + w / 2, Math.min(EVC.W - EVC.pad.r - w / 2, x));
    const span = [left - w / 2 - 3, left + w / 2 + 3];
    const row = placed.findIndex((r) => r.every(([a, b]) => span[1] <= a || span[0] >= b));
    if (row < 0) { t.remove(); continue; }
    placed[row].push(span);
    t.setAttribute("x", left);
    t.setAttribute("y", top - 22 - row * rowH);
  }
}

/** The order range a selection's lines and regions span, padded; `null` when it has none. */
function zoomOf(plot, features) {
  const os = plot.lines.filter((l) => features.has(l.feature)).map((l) => l.order);
  for (const r of plot.regions) if (features.has("region:" + r.name)) os.push(r.lo, r.hi);
  if (!os.length) return null;
  const lo = Math.min(...os), hi = Math.max(...os), m = Math.max(0.6, 0.15 * (hi - lo));
  return [Math.max(0, lo - m), hi + m];
}

/** A finding's evidence features, with `region:<name>` for a feature on a whole line class. */
function findingFeatures(plot, f) {
  const out = new Set();
  for (const e of (f && f.evidence) || []) {
    out.add(e.feature);
    if (!e.feature.startsWith("lines.") || plot.lines.some((l) => l.feature === e.feature)) continue;
    const region = plot.regions.find((r) => e.feature.endsWith("." + r.name));
    if (region) out.add("region:" + region.name);
  }
  return out;
}

/** Draw (or redraw, after a zoom or a selection) the record's evidence. */
function drawEvidence() {
  const { r, selected } = evidenceView;
  const plot = r.evidence, d = r.diagnosis || {};
  const unit = (d.vibration && d.vibration.unit) || "(the record's unit)";
  const f = selected === null ? null : (d.findings || [])[selected];
  const hl = findingFeatures(plot, f);
  const ref = plot.reference;
  const oTop = plot.orders.start + plot.orders.step * (plot.orders.level_db.length - 1);
  const zoom = evidenceView.zoom || [0, oTop];
  drawEvidenceChart($("record-orders"), {
    trace: plot.orders, reference: ref && ref.orders, lines: plot.lines, regions: plot.regions,
    lo: zoom[0], hi: Math.min(oTop, zoom[1]), shaftHz: plot.shaft_hz, unit, highlight: hl,
  });
  const env = plot.envelope;
  $("record-envelope-box").hidden = !env;
  if (env) {
    const t = env.trace;
    drawEvidenceChart($("record-envelope"), {
      trace: t, reference: ref && ref.envelope, lines: env.lines, regions: [],
      lo: 0, hi: t.start + t.step * (t.level_db.length - 1), shaftHz: plot.shaft_hz, unit, highlight: hl,
    });
    $("record-envelope-caption").textContent = "the band " + env.band[0].toFixed(0) + "–" + env.band[1].toFixed(0) +
      " orders (" + (env.band[0] * plot.shaft_hz / 1000).toFixed(2) + "–" + (env.band[1] * plot.shaft_hz / 1000).toFixed(2) + " kHz) demodulated";
  }
  $("record-reference").textContent = ref
    ? "green, beneath: the healthy record nearest this state — " + ref.shaft_hz.toFixed(2) + " Hz, load " + (ref.load === null || ref.load === undefined ? "not given" : ref.load) +
      ", measured " + when(ref.measured_at) + (ref.same_load ? "" : " (no healthy record of this load)")
    : "no healthy reference: the machine has no other baseline record with a measured speed on " + plot.channel;
  for (const b of $("record-zoom").querySelectorAll("button")) {
    b.classList.toggle("on", JSON.stringify(b._zoom || null) === JSON.stringify(evidenceView.zoom));
  }
  $("record-findings").querySelectorAll("li.finding").forEach((li, i) => li.classList.toggle("selected", i === selected));
}

/** Which gears make each mesh, from the mesh lines' parts: "GM1: in 16T / idler 48T; …". */
function meshKey(plot) {
  const stages = new Map();
  for (const l of plot.lines.filter((l) => l.kind === "mesh")) {
    for (const m of l.part.matchAll(/mesh (\d+) \(([^)]*)\)/g)) stages.set(+m[1], m[2]);
  }
  return [...stages.keys()].sort((a, b) => a - b).map((k) => "GM" + k + ": " + stages.get(k)).join("; ");
}

/** The zoom buttons: every order, the shafts' lines, each mesh harmonic's region. */
function zoomButtons(plot) {
  const box = $("record-zoom");
  box.innerHTML = "";
  const add = (text, zoom) => {
    const b = h("button", { type: "button" }, box, text);
    b._zoom = zoom;
    b.addEventListener("click", () => { evidenceView.zoom = zoom; drawEvidence(); });
  };
  add("all orders", null);
  const fastest = Math.max(...plot.shafts.map((s) => s.order));
  add("shafts (0–" + (2.5 * fastest).toFixed(1) + " orders)", [0, 2.5 * fastest]);
  for (const l of plot.lines.filter((l) => l.kind === "mesh")) {
    const r = plot.regions.find((g) => l.feature === "lines.mesh." + g.name);
    if (r) add(l.label + " (" + r.lo.toFixed(1) + "–" + r.hi.toFixed(1) + " orders)", [r.lo, r.hi]);
  }
}

/** Where a piece of evidence was read, in words: its marked lines, the band of its line class, or the whole record. */
function restsOn(plot, feature) {
  if (!plot) return "";
  const lines = plot.lines.concat(plot.envelope ? plot.envelope.lines : []).filter((l) => l.feature === feature);
  if (lines.length) return "on " + lines.map((l) => l.label).join(", ");
  const r = feature.startsWith("lines.") && plot.regions.find((g) => feature.endsWith("." + g.name));
  if (r) return "on the band " + r.lo.toFixed(1) + "–" + r.hi.toFixed(1) + " orders (shaded when selected)";
  return "over the whole record (no single line)";
}

/** The findings, each selectable: its evidence listed with the lines it rests on. */
function evidenceFindings(r, ol) {
  const d = r.diagnosis || {}, plot = r.evidence;
  ol.classList.remove("selectable");
  (d.findings || []).forEach((f, i) => {
    const li = ol.children[i];
    if (!li) return;
    li.tabIndex = 0;
    const ul = h("ul", { class: "evidence" }, li);
    for (const e of f.evidence || []) h("li", {}, ul, e.change + " (z " + fmt(e.z, 1) + ") " + restsOn(plot, e.feature) + " — " + e.why);
    if (!plot) return;
    ol.classList.add("selectable");
    const pick = () => {
      const same = evidenceView.selected === i;
      evidenceView.selected = same ? null : i;
      evidenceView.zoom = same ? null : zoomOf(plot, findingFeatures(plot, f));
      drawEvidence();
    };
    li.addEventListener("click", pick);
    li.addEventListener("keydown", (ev) => { if (ev.key === "Enter" || ev.key === " ") { ev.preventDefault(); pick(); } });
  });
}

/** The record's evidence section: charts when the diagnosis has a plot, else a note. */
function renderEvidence(r) {
  const plot = r.evidence;
  $("record-evidence").hidden = !plot;
  $("record-spectrum-box").hidden = !!plot;
  evidenceFindings(r, $("record-findings"));
  if (!plot) return;
  evidenceView = { r, zoom: null, selected: null };
  $("record-orders-caption").textContent = "channel " + plot.channel + ", " + plot.revolutions + " input revolutions resampled to the shaft's measured angle";
  $("record-meshes").textContent = meshKey(plot);
  zoomButtons(plot);
  drawEvidence();
}
