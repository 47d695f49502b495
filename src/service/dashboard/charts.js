// gearwear dashboard: the machine page's charts — wear and novelty over time, the latest spectrum.
"use strict";

/** The shared time range of a machine's charts: its diagnoses' times, padded. */
function timeDomain(trend) {
  const ts = trend.map((p) => Date.parse(measuredAt(p))).filter(num);
  let t0 = ts.length ? Math.min(...ts) : Date.now() - HOUR;
  let t1 = ts.length ? Math.max(...ts) : Date.now();
  if (t1 - t0 < MIN) { const mid = (t0 + t1) / 2; t0 = mid - MIN / 2; t1 = mid + MIN / 2; }
  const padT = (t1 - t0) * 0.04;
  return [t0 - padT, t1 + padT];
}

/** Does any of the machine's diagnoses have a wear figure? (Real machines' often do not.) */
const hasWear = (m) => (m.trend || []).some((p) => num(p.estimate));

/**
 * The main chart: the wear trend when the machine's records have wear figures; otherwise the
 * novelty — what a real machine's departure shows — with the per-finding strength series
 * (`series`, fetched separately) drawn over it. The small second chart is the novelty beside
 * a wear trend, and is hidden when the novelty is the main chart.
 */
function renderTrend(m, dom, series) {
  const wear = hasWear(m);
  $("trend-caption").textContent = wear ? "Wear trend" : "Novelty and findings";
  $("trend-note").textContent = wear
    ? "estimate with 90 % band on measurement time; gaps where there is no wear figure; thresholds"
    : "no record of this machine has a wear figure, so this is its departure from the baseline on measurement time: " +
      "the score, its thresholds, the baseline records, and the strength of each finding that recurs";
  $("novelty-fig").hidden = !wear;
  $("trend-legend").innerHTML = "";
  // The main chart spans the page when it is alone: a wider drawing, so that its text keeps its size.
  const size = wear ? CHART : WIDE;
  $("trend").setAttribute("viewBox", "0 0 " + size.W + " " + size.H);
  if (!wear) {
    const n = (m.trend || []).length;
    drawNovelty($("trend"), m, dom, { size, series: series || [], legend: true, empty: n ? null : "no diagnosis yet" });
    return;
  }
  drawWear($("trend"), m, dom);
}

function drawWear(svg, m, dom) {
  svg.innerHTML = "";
  svg.dataset.series = "wear";
  const { W, H, pad } = CHART;
  const pts = (m.trend || []).map((p) => ({ ...p, t: Date.parse(measuredAt(p)) })).filter((p) => num(p.t));
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
  // A diagnosis without a wear figure gets no mark (never a point at 0): the line breaks there.
  for (const p of pts.filter((q) => num(q.estimate))) {
    // Each point opens its record's diagnosis.
    const parent = p.diagnosis_id ? el("a", { href: "#/diagnoses/" + encodeURIComponent(p.diagnosis_id) }, svg) : svg;
    const c = el("circle", { cx: sx(p.t), cy: sy(p.estimate), r: 3.5, fill: "#1d4ed8", class: "trend-point", "data-t": measuredAt(p) }, parent);
    tooltip(c, when(measuredAt(p)) + ": ea " + p.estimate.toFixed(3) + (num(p.lower) ? " (" + p.lower.toFixed(2) + " … " + p.upper.toFixed(2) + ")" : "") + ", " + p.alert_level);
  }
  for (const [name, v, c] of [["warning", th.warning, "var(--warning)"], ["alarm", th.alarm, "var(--alarm)"]]) {
    if (!num(v)) continue;
    el("line", { x1: pad.l, x2: W - pad.r, y1: sy(v), y2: sy(v), stroke: c, "stroke-dasharray": "6 4" }, svg);
    el("text", { x: pad.l + 4, y: sy(v) - 3, fill: c }, svg, name + " ea " + v);
  }
  const missing = pts.filter((p) => !num(p.estimate)).length;
  if (!pts.length) note(svg, W, H, "no diagnosis yet");
  else if (missing) el("text", { x: W - pad.r, y: pad.t - 6, "text-anchor": "end", class: "chart-aside" }, svg, missing + " of " + pts.length + " records without a wear figure");
}

/** The novelty chart of the machine page's second figure (beside a wear trend). */
function renderNovelty(m, dom) {
  if (!hasWear(m)) { $("novelty").innerHTML = ""; return; }
  drawNovelty($("novelty"), m, dom, { size: CHART, series: [], legend: false });
}

/** The main chart's size when it spans the page (the novelty of a machine without wear figures). */
const WIDE = { W: 900, H: 300, pad: { l: 44, r: 12, t: 22, b: 34 } };

const SERIES_COLOURS = ["#0f766e", "#b45309", "#be185d", "#4338ca"];

/** The baseline records' measurement times (ms), from the machine's `baseline.records`. */
function baselineTimes(m) {
  const recs = (m.baseline && m.baseline.records) || [];
  return new Set(recs.map((r) => Date.parse(r.measured_at || r.received_at)).filter(num));
}

/**
 * The novelty score on measurement time in `svg`: the threshold each score was judged by
 * (warning) and twice it (alarm) as step lines, baseline records in green, scores above the
 * threshold in red; `opts.series`: `[{name, points: [{t, value}]}]` finding strengths (the
 * same unit: baseline spreads); `opts.legend` draws a legend.
 */
function drawNovelty(svg, m, dom, opts) {
  svg.innerHTML = "";
  svg.dataset.series = "novelty";
  const { W, H, pad } = opts.size;
  const pts = (m.trend || []).map((p) => ({ ...p, t: Date.parse(measuredAt(p)) })).filter((p) => num(p.t));
  const scored = pts.filter((p) => num(p.novelty));
  const ths = scored.map((p) => p.novelty_threshold).filter(num);
  const extra = opts.series.flatMap((s) => s.points.map((p) => p.value));
  const ymax = Math.max(1, ...scored.map((p) => p.novelty), ...ths.map((t) => 2 * t), ...extra) * 1.1;
  const [sx, sy] = timeAxes(svg, W, H, pad, dom[0], dom[1], 0, ymax, "score (baseline spreads)");
  const base = baselineTimes(m);
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
  }
  opts.series.forEach((s, i) => {
    const c = SERIES_COLOURS[i % SERIES_COLOURS.length];
    const sp = s.points.map((p) => ({ ...p, t: Date.parse(p.measured_at) })).filter((p) => num(p.t) && num(p.value));
    el("polyline", { points: sp.map((p) => sx(p.t) + "," + sy(p.value)).join(" "), fill: "none", stroke: c, "stroke-width": 1.5, class: "finding-series", "data-name": s.name }, svg);
    for (const p of sp) {
      tooltip(el("rect", { x: sx(p.t) - 2.5, y: sy(p.value) - 2.5, width: 5, height: 5, fill: c, class: "finding-point" }, svg),
        when(p.measured_at) + ": " + s.label + " strength " + p.value.toFixed(1));
    }
  });
  for (const run of runs(pts, (p) => num(p.novelty))) {
    el("polyline", { points: run.map((p) => sx(p.t) + "," + sy(p.novelty)).join(" "), fill: "none", stroke: "#7c3aed", "stroke-width": 2, class: "novelty-line" }, svg);
  }
  for (const p of scored) {
    const over = num(p.novelty_threshold) && p.novelty > p.novelty_threshold;
    const inBase = base.has(p.t);
    const parent = p.diagnosis_id ? el("a", { href: "#/diagnoses/" + encodeURIComponent(p.diagnosis_id) }, svg) : svg;
    const c = el("circle", { cx: sx(p.t), cy: sy(p.novelty), r: 3.5, fill: inBase ? "#2e9d4f" : over ? "var(--alarm)" : "#7c3aed",
      class: "novelty-point" + (over ? " anomalous" : "") + (inBase ? " baseline-point" : ""), "data-t": measuredAt(p) }, parent);
    tooltip(c, when(measuredAt(p)) + ": novelty " + p.novelty.toFixed(2) + (num(p.novelty_threshold) ? " (threshold " + p.novelty_threshold.toFixed(2) + ")" : "") +
      ", " + p.alert_level + (inBase ? ", baseline record" : ""));
  }
  // Baseline records the chart has no score for (the first ones: nothing to score them against).
  for (const t of base) {
    if (t < dom[0] || t > dom[1] || scored.some((p) => p.t === t)) continue;
    tooltip(el("path", { d: "M" + (sx(t) - 4) + "," + (H - pad.b) + "l4,-7l4,7z", fill: "#2e9d4f", class: "baseline-mark" }, svg), "baseline record, " + when(new Date(t).toISOString()));
  }
  if (opts.legend) noveltyLegend($("trend-legend"), opts.series);
  if (opts.empty) note(svg, W, H, opts.empty);
  else if (!scored.length) {
    const b = m.baseline || {};
    const need = Math.max(0, (b.min_records || 3) - (b.count || 0));
    note(svg, W, H, b.ready
      ? "baseline ready: records from now on get a novelty score"
      : "no novelty yet: the baseline needs " + need + " more healthy record" + (need === 1 ? "" : "s"));
  }
}

/** The main chart's legend (HTML, under the chart): the score, the thresholds, the baseline, the findings. */
function noveltyLegend(ul, series) {
  ul.innerHTML = "";
  const items = [["novelty score", "#7c3aed", "line"], ["warning: the baseline's threshold", "var(--warning)", "dash"],
    ["alarm: twice the threshold", "var(--alarm)", "dash"], ["baseline record", "#2e9d4f", "dot"]]
    .concat(series.map((s, i) => [s.label + " (strength)", SERIES_COLOURS[i % SERIES_COLOURS.length], "square"]));
  for (const [text, c, kind] of items) {
    const li = h("li", { class: "legend-" + kind }, ul);
    h("span", { class: "swatch " + kind, style: (kind === "dash" ? "border-color: " : "background: ") + c }, li);
    h("span", {}, li, text);
  }
}

function renderSpectrum(d, svg = $("spectrum")) {
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
