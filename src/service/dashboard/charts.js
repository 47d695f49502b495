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

function renderTrend(m, dom) {
  const svg = $("trend");
  svg.innerHTML = "";
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
  for (const p of pts) {
    if (num(p.estimate)) {
      // Each point opens its record's diagnosis.
      const parent = p.diagnosis_id ? el("a", { href: "#/diagnoses/" + encodeURIComponent(p.diagnosis_id) }, svg) : svg;
      const c = el("circle", { cx: sx(p.t), cy: sy(p.estimate), r: 3.5, fill: "#1d4ed8", class: "trend-point", "data-t": measuredAt(p) }, parent);
      tooltip(c, when(measuredAt(p)) + ": ea " + p.estimate.toFixed(3) + (num(p.lower) ? " (" + p.lower.toFixed(2) + " … " + p.upper.toFixed(2) + ")" : "") + ", " + p.alert_level);
    } else {
      // A diagnosis without a wear figure: a hollow mark on the axis, no line through it (never
      // a point at 0).
      const c = el("circle", { cx: sx(p.t), cy: H - pad.b, r: 3.5, fill: "#fff", stroke: "#8a8f98", class: "trend-nowear", "data-t": measuredAt(p) }, svg);
      tooltip(c, when(measuredAt(p)) + ": no wear figure (the model does not fit the record, or the gearbox's table is not ready), " + p.alert_level);
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
  const pts = (m.trend || []).map((p) => ({ ...p, t: Date.parse(measuredAt(p)) })).filter((p) => num(p.t));
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
    const c = el("circle", { cx: sx(p.t), cy: sy(p.novelty), r: 3.5, fill: over ? "var(--alarm)" : "#7c3aed", class: "novelty-point" + (over ? " anomalous" : ""), "data-t": measuredAt(p) }, svg);
    tooltip(c, when(measuredAt(p)) + ": novelty " + p.novelty.toFixed(2) + (num(p.novelty_threshold) ? " (threshold " + p.novelty_threshold.toFixed(2) + ")" : "") + ", " + p.alert_level);
  }
  if (!scored.length) {
    const need = Math.max(0, (b.min_records || 3) - (b.count || 0));
    note(svg, W, H, b.ready
      ? "baseline ready: records from now on get a novelty score"
      : "no novelty yet: the baseline needs " + need + " more healthy record" + (need === 1 ? "" : "s"));
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
