// gearwear dashboard: a machine's wear trend with its projection (`GET
// /v1/machines/{id}/trend?series=wear`): the series over measurement time, the fitted line
// (level + slope × time), and where it is projected to cross the warning and alarm thresholds
// with the 90 % interval of each crossing's date. Hidden when the service has no trend API.
"use strict";

const PROJ = { W: 720, H: 260, pad: { l: 44, r: 14, t: 22, b: 34 } };

/** The trend answer's wear points, each with its measurement time `t` (ms). */
function trendPoints(tr) {
  return (tr.points || []).map((p) => ({ ...p, t: Date.parse(p.measured_at) })).filter((p) => num(p.t) && num(p.value));
}

/**
 * The fitted line as a function of time: `level` at the reference time (the fit's `level_at`
 * when given, else the latest measurement) plus `slope_per_day` per day from it.
 */
function fitLine(fit, pts) {
  if (!fit || !num(fit.level) || !num(fit.slope_per_day)) return null;
  const tRef = num(Date.parse(fit.level_at)) ? Date.parse(fit.level_at) : pts[pts.length - 1].t;
  return (t) => fit.level + fit.slope_per_day * (t - tRef) / DAY;
}

/** Each projected crossing: `{name, value, at, lo, hi}` in ms (lo/hi: the 90 % interval). */
function crossings(tr) {
  const out = [];
  const p = tr.projection || {};
  const th = tr.thresholds || {};
  for (const name of ["warning", "alarm"]) {
    const c = p[name];
    if (!c || !num(c.days) || !num(th[name])) continue;
    const at = Date.parse(c.at);
    if (!num(at)) continue;
    // `days` counts from the reference time `at` was projected from.
    const ref = at - c.days * DAY;
    const iv = Array.isArray(c.interval_90) ? c.interval_90 : [];
    out.push({ name, value: th[name], days: c.days, at,
      lo: num(iv[0]) ? ref + iv[0] * DAY : null, hi: num(iv[1]) ? ref + iv[1] * DAY : null });
  }
  return out;
}

/** The chart's time range: the measurements and the crossings, the future capped at 4× the history. */
function projectionDomain(pts, cross) {
  const t0 = pts[0].t, tLast = pts[pts.length - 1].t;
  const span = Math.max(tLast - t0, DAY);
  const cap = tLast + 4 * span;
  const ends = cross.flatMap((c) => [c.at, c.hi]).filter(num);
  const t1 = Math.min(cap, Math.max(tLast, ...ends));
  const padT = (t1 - t0) * 0.03 || HOUR;
  return [t0 - padT, t1 + padT];
}

function renderProjection(tr) {
  const fig = $("projection-fig");
  const svg = $("projection");
  svg.innerHTML = "";
  fig.hidden = !tr;
  if (!tr) return;
  $("projection-verdict").textContent = tr.verdict || "";
  const { W, H, pad } = PROJ;
  const pts = trendPoints(tr);
  const th = tr.thresholds || {};
  if (!pts.length) {
    timeAxes(svg, W, H, pad, Date.now() - DAY, Date.now(), 0, 1, "wear degree ea");
    note(svg, W, H, "no wear figure yet: the trend needs records the model fits");
    return;
  }
  const cross = crossings(tr);
  const [t0, t1] = projectionDomain(pts, cross);
  // A top at a multiple of 0.2 so that the four grid steps read as round numbers.
  const ymax = Math.ceil(5 * Math.max(num(th.alarm) ? th.alarm * 1.15 : 1, ...pts.map((p) => p.value))) / 5;
  const ymin = Math.min(0, ...pts.map((p) => p.value));
  const [sx, sy] = timeAxes(svg, W, H, pad, t0, t1, ymin, ymax, tr.unit ? "wear, " + tr.unit : "wear degree ea");
  const clipT = (t) => Math.max(t0, Math.min(t1, t));
  // The 90 % interval of each crossing's date, as a band on its threshold line.
  for (const c of cross) {
    const lo = clipT(num(c.lo) ? c.lo : c.at), hi = clipT(num(c.hi) ? c.hi : t1);
    const r = el("rect", { x: sx(lo), y: sy(c.value) - 5, width: Math.max(2, sx(hi) - sx(lo)), height: 10,
      fill: c.name === "alarm" ? "#d2352b33" : "#d08c0033", class: "crossing-interval", "data-name": c.name }, svg);
    tooltip(r, c.name + ": 90 % interval " + (num(c.lo) ? dateText(new Date(c.lo)) : "?") + " – " + (num(c.hi) ? dateText(new Date(c.hi)) : "?"));
  }
  for (const [name, v, colour] of [["warning", th.warning, "var(--warning)"], ["alarm", th.alarm, "var(--alarm)"]]) {
    if (!num(v)) continue;
    el("line", { x1: pad.l, x2: W - pad.r, y1: sy(v), y2: sy(v), stroke: colour, "stroke-dasharray": "6 4", class: "threshold" }, svg);
    el("text", { x: pad.l + 4, y: sy(v) - 4, fill: colour }, svg, name + " " + v);
  }
  drawFit(svg, tr, pts, cross, sx, sy, t1);
  for (const c of cross) drawCrossing(svg, c, sx, sy, t1);
  for (const p of pts) {
    // Each point opens its record: by diagnosis id when the answer has it, else by record id.
    const href = p.diagnosis_id ? "#/diagnoses/" + encodeURIComponent(p.diagnosis_id)
      : p.record_id ? "#/records/" + encodeURIComponent(p.record_id) : null;
    const parent = href ? el("a", { href }, svg) : svg;
    const c = el("circle", { cx: sx(p.t), cy: sy(p.value), r: 3, fill: "#1d4ed8", class: "proj-point", "data-t": p.measured_at }, parent);
    tooltip(c, "measured " + when(p.measured_at) + ": ea " + p.value.toFixed(3) + (p.record_id ? " — open the record" : ""));
  }
}

/** The fitted line: solid over the measurements, dashed from the latest one to the chart's end. */
function drawFit(svg, tr, pts, cross, sx, sy, t1) {
  const f = fitLine(tr.fit, pts);
  if (!f) return;
  const tA = pts[0].t, tB = pts[pts.length - 1].t;
  el("line", { x1: sx(tA), y1: sy(f(tA)), x2: sx(tB), y2: sy(f(tB)), stroke: "#0f766e", "stroke-width": 2, class: "fit-line" }, svg);
  if (tr.fit.significant && cross.length) {
    const tEnd = Math.min(t1, Math.max(...cross.map((c) => c.at)));
    el("line", { x1: sx(tB), y1: sy(f(tB)), x2: sx(tEnd), y2: sy(f(tEnd)), stroke: "#0f766e", "stroke-width": 2,
      "stroke-dasharray": "5 4", class: "fit-projection" }, svg);
  }
}

/** A projected crossing: a marker on its threshold at the projected date (an arrow past the chart). */
function drawCrossing(svg, c, sx, sy, t1) {
  const colour = c.name === "alarm" ? "var(--alarm)" : "var(--warning)";
  const label = c.days <= 0 ? "above " + c.name : c.name + " ≈ " + dateText(new Date(c.at));
  if (c.at > t1) {
    el("text", { x: sx(t1) - 2, y: sy(c.value) + 14, "text-anchor": "end", fill: colour, class: "crossing-label", "data-name": c.name },
      svg, label + " →");
    return;
  }
  const x = sx(c.at), y = sy(c.value);
  el("line", { x1: x, x2: x, y1: y, y2: PROJ.H - PROJ.pad.b, stroke: colour, "stroke-dasharray": "2 3", class: "crossing", "data-name": c.name }, svg);
  const m = el("circle", { cx: x, cy: y, r: 5, fill: "#fff", stroke: colour, "stroke-width": 2, class: "crossing-mark", "data-name": c.name }, svg);
  tooltip(m, c.name + " projected " + when(new Date(c.at).toISOString()) + " (in " + Math.round(c.days) + " days)");
  el("text", { x: x - 4, y: y + 16, "text-anchor": "end", fill: colour, class: "crossing-label", "data-name": c.name }, svg, label);
}

/** Fetch and draw the trend of the shown machine when its view changed; hide it without the API. */
let projectionFor = "";
async function refreshProjection(m, stamp) {
  if (projectionFor === stamp) return;
  if (!hasWear(m)) {
    // No wear figure to project (a real machine the model does not fit): no empty chart; the
    // main chart shows its novelty instead.
    projectionFor = stamp;
    renderProjection(null);
    return;
  }
  let tr = null;
  try {
    tr = await api("/v1/machines/" + encodeURIComponent(m.id) + "/trend?series=wear");
  } catch (e) {
    if (e.status === 401 || e.status === 403) throw e;
    tr = null; // no trend API in this service (404), or no trend to show
  }
  if (selected !== m.id) return;
  projectionFor = stamp;
  renderProjection(tr);
}
