// gearwear dashboard, the planner's view (`#/`): every machine ordered by urgency with its
// figures in physical units, its trend verdict and its latest findings, and the open alerts.
//
// Urgency, most urgent first:
//   0. alarm   — an open alarm alert, or the latest record at alarm;
//   1. warning — an open warning alert, or the latest record at warning;
//   2. trend   — no alert, but the wear trend projects a crossing: nearest projected alarm first;
//   3. the rest — `unknown` (nothing vouches for it) before `ok`.
// Within a tier: machines with an open alert first, then the nearest projected alarm, then id.
// Before the alerts API exists (a 404 on GET /v1/alerts) the latest record's level stands alone;
// without a `trend_summary` in the machine's view, tier 2 is empty.
"use strict";

/** The machine views the overview reads, by id: `{stamp, view}` (refetched when `stamp` moves). */
const views = new Map();
/** The open alerts (`GET /v1/alerts?state=open`), or null when the service has no alerts API. */
let openAlerts = null;

const viewStamp = (m) => [m.updated_at, m.last_diagnosis_id, m.record_count].join("|");

/** Fetch the views of machines that changed since the last poll; forget deleted ones. */
async function refreshViews(machines) {
  const ids = new Set(machines.map((m) => m.id));
  for (const id of [...views.keys()]) if (!ids.has(id)) views.delete(id);
  const stale = machines.filter((m) => (views.get(m.id) || {}).stamp !== viewStamp(m));
  await Promise.all(stale.map(async (m) => {
    try {
      views.set(m.id, { stamp: viewStamp(m), view: await api("/v1/machines/" + encodeURIComponent(m.id)) });
    } catch (e) {
      if (e.status === 401 || e.status === 403) throw e;
      views.delete(m.id); // deleted meanwhile, or a passing error: asked again next poll
    }
  }));
}

/** The open alerts, or null (the panel hides) when the service has no alerts API. */
async function fetchOpenAlerts() {
  try {
    const r = await api("/v1/alerts?state=open");
    return Array.isArray(r.alerts) ? r.alerts : [];
  } catch (e) {
    if (e.status === 401 || e.status === 403) throw e;
    return null;
  }
}

const SEVERE = { alarm: 2, warning: 1 };
const worse = (a, b) => ((SEVERE[a] || 0) >= (SEVERE[b] || 0) ? a : b);

/** Days to the projected alarm (else warning) crossing of a machine's wear trend, or null. */
function projectedDays(view) {
  const p = view && view.trend_summary && view.trend_summary.projection;
  if (!p) return null;
  for (const k of ["alarm", "warning"]) {
    if (p[k] && num(p[k].days)) return { threshold: k, days: p[k].days, interval: p[k].interval_90, at: p[k].at };
  }
  return null;
}

/** Where a machine stands: `{tier, level, alert, projection}` (see the header). */
function urgency(m, view, alerts) {
  const mine = (alerts || []).filter((a) => a.machine_id === m.id);
  const alert = mine.reduce((w, a) => (!w || (SEVERE[a.level] || 0) > (SEVERE[w.level] || 0) ? a : w), null);
  const lv = worse(level(m.alert_level), alert ? alert.level : "ok");
  const projection = projectedDays(view);
  const tier = lv === "alarm" ? 0 : lv === "warning" ? 1 : projection ? 2 : 3;
  return { tier, level: SEVERE[lv] ? lv : level(m.alert_level), alert, projection };
}

/** The fleet, most urgent first. */
function byUrgency(machines) {
  const u = new Map(machines.map((m) => [m.id, urgency(m, (views.get(m.id) || {}).view, openAlerts)]));
  const days = (x) => (x.projection && x.projection.threshold === "alarm" ? x.projection.days : Infinity);
  const rest = (x) => (x.level === "unknown" ? 0 : 1);
  return [...machines].sort((a, b) => {
    const x = u.get(a.id), y = u.get(b.id);
    return x.tier - y.tier || (x.alert ? 0 : 1) - (y.alert ? 0 : 1) || days(x) - days(y) ||
      (x.tier === 3 ? rest(x) - rest(y) : 0) || (a.id < b.id ? -1 : a.id > b.id ? 1 : 0);
  }).map((m) => ({ m, u: u.get(m.id) }));
}

// ---------- figures in words ----------

/** The ISO 20816-3 class a machine declared, in words with the standard's scope. */
function isoScope(z) {
  return "ISO 20816-3 (machines above 15 kW; group " + z.group + ", " + z.support + " support)";
}

/**
 * `4.21 mm/s (ISO B)`, the acceleration and the wear in µm: the latest record's figures. The
 * zone only for a machine that declared its ISO class (`cfg.iso_20816`); with a class but no
 * velocity in units, "zone unknown".
 */
function figureParts(d, cfg) {
  const out = [];
  const v = d && d.vibration;
  const iso = cfg && cfg.iso_20816;
  if (v && num(v.velocity_rms_mm_s)) {
    const z = v.iso_20816_3;
    out.push({ cls: "velocity", text: v.velocity_rms_mm_s.toFixed(2) + " mm/s RMS" + (z ? " · ISO zone " + z.zone : ""),
      title: "velocity RMS over " + (v.velocity_band_hz || [10, 1000]).join("–") + " Hz" + (z ? "; " + isoScope(z) + " zone " + z.zone + ": " + z.meaning : "") });
  } else if (v && v.velocity_note) {
    out.push({ cls: "velocity muted", text: "no velocity", title: v.velocity_note });
  } else if (d && iso) {
    out.push({ cls: "velocity muted", text: "ISO zone unknown: sensor gain not stated",
      title: "the machine declares its ISO 20816-3 class, but the deciding channel " + (d.channel || "") +
        " has no unit: declare it in channel_units (with the sensor's sensitivity for a channel in V)" });
  }
  if (v && num(v.acceleration_rms_m_s2)) {
    out.push({ cls: "acceleration", text: v.acceleration_rms_m_s2.toFixed(2) + " m/s² RMS, peak " + fmt(v.acceleration_peak_m_s2, 1) + " m/s²",
      title: fmt(v.acceleration_rms_g, 3) + " g RMS, " + fmt(v.acceleration_peak_g, 3) + " g peak" });
  }
  const w = d && d.wear_degree, um = d && d.wear_degree_um;
  if (w && num(w.estimate)) {
    out.push({ cls: "wear", text: "wear " + (um && num(um.estimate) ? um.estimate.toFixed(1) + " µm" : "ea " + w.estimate.toFixed(2)),
      title: "wear degree ea " + w.estimate.toFixed(3) + " (90 % " + fmt(w.lower, 3) + "–" + fmt(w.upper, 3) + ")" +
        (um && num(um.estimate) ? " × " + um.reference_length_um + " µm reference length" : "") });
  }
  return out;
}

/** "alarm in 41 days (28–70)", or the API's verdict ("no significant trend"), or null. */
function verdictText(view) {
  const s = view && view.trend_summary;
  if (!s) return null;
  const p = projectedDays(view);
  if (!p) return s.verdict || null;
  if (p.days <= 0) return "above " + p.threshold;
  // The 90 % interval of the days; an unbounded upper end (null) reads "≥ lower".
  const iv = Array.isArray(p.interval) ? p.interval : [];
  const ivText = num(iv[0]) && num(iv[1]) ? " (" + Math.round(iv[0]) + "–" + Math.round(iv[1]) + ")"
    : num(iv[0]) ? " (≥ " + Math.round(iv[0]) + ")" : "";
  return p.threshold + " in " + Math.round(p.days) + " day" + (Math.round(p.days) === 1 ? "" : "s") + ivText;
}

function recordHref(d) { return "#/diagnoses/" + encodeURIComponent(d.id); }

/** The level as colour + icon + word: readable without colour. */
function stateTag(lv, parent) {
  const s = h("span", { class: "state " + level(lv) }, parent);
  dot(lv, s);
  h("span", { class: "word" }, s, level(lv));
  return s;
}

// ---------- the overview ----------

let overviewDrawn = "";
function renderOverview(machines) {
  const rows = byUrgency(machines);
  // A view is redrawn when its stamp moves (it is refetched then), not compared whole.
  const drawnKey = JSON.stringify([rows.map((r) => [r.m, r.u, (views.get(r.m.id) || {}).stamp]), openAlerts]);
  if (drawnKey === overviewDrawn) return;
  overviewDrawn = drawnKey;
  const tb = $("fleet-rows");
  tb.innerHTML = "";
  $("fleet-empty").hidden = rows.length > 0;
  for (const { m, u } of rows) fleetRow(tb, m, u, (views.get(m.id) || {}).view);
  renderAlerts(openAlerts);
}

function fleetRow(tb, m, u, view) {
  const tr = h("tr", { class: "level-" + u.level + " tier-" + u.tier }, tb);
  tr.dataset.id = m.id;
  tr.dataset.level = u.level;
  tr.dataset.tier = u.tier;
  const st = h("td", { class: "state-cell" }, tr);
  stateTag(u.level, st).title = levelHelp(u.level, m.record_count);
  if (u.alert) {
    h("div", { class: "muted alert-note" }, st, "alert open since " + when(u.alert.opened_at) +
      (u.alert.state === "acknowledged" ? ", acknowledged" : ", not acknowledged"));
  }
  h("a", { href: machineHref(m.id), class: "machine-link" }, h("td", {}, tr), m.id);
  const l = view && view.latest;
  const fig = h("td", { class: "figures" }, tr);
  const parts = figureParts(l, view && view.configuration);
  for (const p of parts) h("div", { class: p.cls, title: p.title }, fig, p.text);
  if (!parts.length) h("span", { class: "muted" }, fig, l ? (noWearText(l.wear_withheld, true) || "no figure in units") : "no record yet");
  const verdict = verdictText(view);
  const tdv = h("td", { class: "verdict" + (u.projection ? " projected" : "") }, tr, verdict || "–");
  if (view && view.trend_summary && view.trend_summary.verdict) tdv.title = view.trend_summary.verdict;
  if (!verdict) tdv.classList.add("muted");
  const tdf = h("td", { class: "findings-cell" }, tr);
  // What the open alert is about (the record that opened or last escalated it), then the
  // latest record's findings when it is another record.
  const ev = view && view.open_alert && view.open_alert.evidence;
  if (ev) {
    findingLines(tdf, ev.findings, "alert-finding", level(view.open_alert.level) + " (record of " + when(ev.measured_at) + "): ");
    if (ev.record_id !== (l && l.record_id)) findingLines(tdf, l && l.findings, "latest-finding", "latest: ");
  } else {
    findingLines(tdf, l && l.findings, "latest-finding", "");
    if (!(l && l.findings && l.findings.length)) {
      tdf.innerHTML = "";
      h("span", { class: "muted" }, tdf, l ? "none" : "–");
    }
  }
  const tdr = h("td", { class: "last-record" }, tr);
  if (l) h("a", { href: recordHref(l), class: "record-link" }, tdr, when(measuredAt(l)));
  else h("span", { class: "muted" }, tdr, "–");
}

/** Up to two findings as lines, `prefix` first, "+N more", or "none" after the prefix. */
function findingLines(td, findings, cls, prefix) {
  const fs = Array.isArray(findings) ? findings : [];
  if (!fs.length) {
    if (prefix) h("div", { class: "muted " + cls }, td, prefix + "no finding");
    return;
  }
  fs.slice(0, 2).forEach((f, i) => codeText(h("div", { class: "finding " + cls }, td), (i ? "" : prefix) + (f.summary || f.kind || "")));
  if (fs.length > 2) h("div", { class: "muted" }, td, "+" + (fs.length - 2) + " more");
}

/** The open alerts, most severe then oldest first; hidden when the service has no alerts API. */
function renderAlerts(alerts) {
  const box = $("alerts-box");
  box.hidden = alerts === null;
  if (alerts === null) return;
  const ul = $("alerts");
  ul.innerHTML = "";
  $("alerts-empty").hidden = alerts.length > 0;
  const sorted = [...alerts].sort((a, b) => (SEVERE[b.level] || 0) - (SEVERE[a.level] || 0) ||
    (Date.parse(a.opened_at) || 0) - (Date.parse(b.opened_at) || 0));
  for (const a of sorted) {
    const li = h("li", { class: "open-alert level-" + level(a.level) }, ul);
    li.dataset.id = a.id;
    li.dataset.machine = a.machine_id;
    li.dataset.state = a.state;
    stateTag(a.level, li);
    h("a", { href: machineHref(a.machine_id), class: "machine-link" }, li, a.machine_id);
    h("span", { class: "muted" }, li, "opened " + when(a.opened_at));
    const ack = a.state === "acknowledged"
      ? "acknowledged" + ackBy(a) + (a.acknowledged_at ? " " + when(a.acknowledged_at) : "") +
        (a.note ? ": " + a.note : "")
      : "not acknowledged";
    h("span", { class: "ack " + (a.state === "acknowledged" ? "acked" : "unacked") }, li, ack);
    if (a.record_id) h("a", { href: "#/records/" + encodeURIComponent(a.record_id), class: "record-link" }, li, "record that opened it");
  }
}
