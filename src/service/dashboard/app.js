// gearwear dashboard: polls the JSON API every 2 s (the browser revalidates with the ETags the
// API sends, so an unchanged answer is a 304 and is not drawn again).
//
// The view lives in the URL, so a link opens it and back/forward move between views:
//   `#/`                       the planner's overview: the fleet by urgency, the open alerts;
//   `#/machines/<id>`          one machine (`?machine=<id>` is accepted and rewritten to it);
//   `#/diagnoses/<id>`, `#/records/<id>`   one record's diagnosis.
"use strict";

// ---------- the URL holds the view ----------

function machineHref(id) { return "#/machines/" + encodeURIComponent(id); }
/** `{view: "overview"|"machine"|"diagnoses"|"records", id}` from the URL. */
function currentRoute() {
  const m = location.hash.match(/^#\/(machines|diagnoses|records)\/(.+)$/);
  if (m) {
    let id = m[2];
    try { id = decodeURIComponent(id); } catch (_) { /* keep it as written */ }
    return { view: m[1] === "machines" ? "machine" : m[1], id };
  }
  const q = new URLSearchParams(location.search).get("machine");
  return q ? { view: "machine", id: q } : { view: "overview", id: null };
}
let route = currentRoute();
let selected = route.view === "machine" ? route.id : null;
if (selected && !location.hash.startsWith("#/machines/")) {
  // `?machine=press-7` → `/#/machines/press-7`, one form from here on.
  history.replaceState(null, "", location.pathname + machineHref(selected));
}
function showView() {
  document.body.dataset.view = route.view;
  $("overview").hidden = route.view !== "overview";
  $("detail").hidden = route.view !== "machine";
  $("record-view").hidden = route.view !== "diagnoses" && route.view !== "records";
}
showView();
window.addEventListener("hashchange", () => {
  route = currentRoute();
  selected = route.view === "machine" ? route.id : null;
  showView();
  window.scrollTo(0, 0);
  refresh();
});

// ---------- the fleet ----------

function tableText(g) {
  if (!g || g.status === "ready") return "";
  if (g.status === "running") return "table " + Math.round(100 * (g.progress || 0)) + " %";
  return "table " + g.status;
}

let fleetDrawn = "";
/** The side list on a machine's page: the fleet by urgency (see planner.js). */
function renderMachines(list, gearboxes) {
  const ul = $("machines");
  const machines = byUrgency(list.machines || []);
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
  for (const { m, u } of machines) {
    const lv = u.level;
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

// ---------- one machine ----------

/** The machine's state: the worse of its latest record's level and its open alert's (`state`). */
function machineState(m) {
  const st = m.state || {};
  return { level: level(st.level || m.alert_level), fromAlert: st.source === "alert", st };
}

function renderAlert(m) {
  const l = m.latest;
  const box = $("alert");
  const { level: lv, fromAlert } = machineState(m);
  box.className = "alert " + lv;
  box.dataset.level = lv;
  box.dataset.source = fromAlert ? "alert" : "record";
  if (!l) {
    $("alert-title").textContent = "No record yet.";
    $("alert-reason").textContent = "Post one to /v1/machines/" + m.id + "/records; nothing vouches for this machine until then.";
    $("alert-basis").textContent = "";
    return;
  }
  const a = l.alert || { level: l.alert_level, basis: null, reason: "" };
  const title = LEVELS[lv].icon + " " + lv[0].toUpperCase() + lv.slice(1);
  const oa = m.open_alert;
  if (fromAlert && oa) {
    // The alert is worse than the latest record: say so, and what opened it.
    $("alert-title").textContent = title + " open since " + when(oa.opened_at) + " — last record " + level(l.alert_level) + ".";
    const ev = oa.evidence;
    $("alert-reason").textContent = ev && ev.reason
      ? "The record of " + when(ev.measured_at) + " that " + ev.event + " it: " + ev.reason
      : "";
  } else {
    $("alert-title").textContent = title + ":";
    $("alert-reason").textContent = a.reason || (lv === "unknown" ? LEVELS.unknown.help : "");
  }
  const bits = [];
  // A single-channel record's channel is just "0": name it only when several were diagnosed.
  if (l.channel && Array.isArray(l.channels) && l.channels.length > 1) bits.push("deciding channel: " + l.channel);
  if (a.basis) bits.push("based on: " + (a.basis === "none" ? "nothing (no fit, no baseline)" : a.basis));
  if (fromAlert && a.reason) bits.push("last record of " + when(measuredAt(l)) + ": " + a.reason);
  else bits.push("record of " + when(measuredAt(l)));
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
    h("td", {}, tr, w && num(w.estimate) ? w.estimate.toFixed(3) : noWearText(c.wear_withheld, true) || "–");
    // The departures in words (`says`); a stored answer from before they were given: the feature's name.
    const top = n && Array.isArray(n.top_features) ? n.top_features.slice(0, 2).map((f) => f.says || f.name + " (" + fmt(f.z, 1) + " spreads)") : [];
    const why = h("td", { class: "muted why" }, tr);
    if (top.length) top.forEach((t) => codeText(h("div", {}, why), t));
    else why.textContent = (c.alert && c.alert.reason) || "";
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
  const why = noWearText(l.wear_withheld);
  if (why) return why;
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

/** One finding as a list item: its sentence, its kind and strength, its evidence in sentences. */
function findingItem(ol, f) {
  const li = h("li", { class: "finding" }, ol);
  codeText(li, f.summary || f.kind || "");
  li.dataset.kind = f.kind || "";
  h("span", { class: "kind" }, li, (f.kind || "") + (num(f.strength) ? ", strength " + f.strength.toFixed(1) + " baseline spreads" : ""));
  const ev = Array.isArray(f.evidence) ? f.evidence : [];
  if (!ev.length) return;
  const ul = h("ul", { class: "evidence" }, li);
  for (const e of ev.slice(0, 3)) codeText(h("li", {}, ul), e.why + ": " + e.change);
}

/**
 * The findings beside each other: those of the record that opened or last escalated the open
 * alert (what the alert is about), and the latest record's.
 */
function renderFindings(m) {
  const l = m.latest;
  const ev = m.open_alert && m.open_alert.evidence;
  const abox = $("alert-findings-box");
  abox.hidden = !ev;
  $("alert-findings").innerHTML = "";
  if (ev) {
    $("alert-findings-title").textContent = "What the " + level(m.open_alert.level) + " is about";
    const fs = Array.isArray(ev.findings) ? ev.findings : [];
    const note = $("alert-findings-note");
    note.textContent = "";
    const a = h("a", { href: "#/records/" + encodeURIComponent(ev.record_id), class: "record-link" }, note, "the record of " + when(ev.measured_at));
    a.dataset.record = ev.record_id;
    note.appendChild(document.createTextNode(" " + ev.event + " the alert" + (fs.length ? "" : "; it names no part (no measured speed or no baseline with states)")));
    for (const f of fs) findingItem($("alert-findings"), f);
  }
  const box = $("findings-box");
  const ol = $("findings");
  ol.innerHTML = "";
  const fs = (l && Array.isArray(l.findings)) ? l.findings : [];
  box.hidden = !l || (!fs.length && !l.operating_state && !ev);
  $("findings-note").textContent = (l ? "record of " + when(measuredAt(l)) + ": " : "") + (fs.length
    ? "what its departure from the baseline at this speed and load points at, strongest first"
    : "none: it does not depart from its baseline at this speed and load (or the machine has no baseline with states yet)");
  for (const f of fs) findingItem(ol, f);
}

function renderLatest(m) {
  const l = m.latest;
  $("records").textContent = m.record_count;
  $("latest-at").textContent = l ? when(measuredAt(l)) : "";
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
  // The model's terms only where its reading counts (a wear figure); the record page has them all.
  const modelView = !!(w && num(w.estimate));
  for (const e of document.querySelectorAll("#machine .model-term")) e.hidden = !modelView;
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
  badge($("machine-level"), machineState(m).level, m.record_count);
  $("machine-updated").textContent = "updated " + when(m.updated_at);
  renderAlert(m);
  renderChannels(m.latest);
  renderGearbox(m);
  renderBaseline(m);
  renderLatest(m);
  renderFindings(m);
  renderPlanning(m);
  const dom = timeDomain(m.trend || []);
  renderTrend(m, dom, findingSeries.get(m.id));
  renderNovelty(m, dom);
}

/** What a planner reads first on a machine's page: its figures in units, trend verdict, alerts. */
function renderPlanning(m) {
  const l = m.latest;
  const parts = figureParts(l, m.configuration);
  const pick = (c) => parts.find((p) => p.cls.startsWith(c));
  for (const [id, c] of [["velocity", "velocity"], ["acceleration", "acceleration"]]) {
    const p = pick(c);
    const z = id === "velocity" && l && l.vibration && l.vibration.iso_20816_3;
    $(id).textContent = p ? p.text + (z ? " — " + isoScope(z) : "") : l ? "– (no unit declared for this channel)" : "–";
    $(id).title = p ? p.title : "declare the channel's unit: PUT /v1/machines/{id} with channel_units";
  }
  const um = l && l.wear_degree_um;
  $("wear-um").textContent = um && num(um.estimate)
    ? um.estimate.toFixed(1) + " µm (90 % " + fmt(um.lower, 1) + " … " + fmt(um.upper, 1) + ")" : "–";
  const link = $("latest-link");
  link.hidden = !l;
  if (l) link.href = recordHref(l);
  const verdict = verdictText(m);
  const series = m.trend_summary && m.trend_summary.series === "novelty" ? "Novelty trend: " : "Wear trend: ";
  $("machine-verdict").textContent = verdict ? series + verdict : "";
  $("machine-verdict").title = (m.trend_summary && m.trend_summary.verdict) || "";
  const ul = $("machine-alerts");
  ul.innerHTML = "";
  for (const a of (openAlerts || []).filter((x) => x.machine_id === m.id)) {
    const li = h("li", { class: "open-alert level-" + level(a.level) }, ul);
    li.dataset.id = a.id;
    li.dataset.state = a.state;
    stateTag(a.level, li);
    h("span", {}, li, " alert open since " + when(a.opened_at) + (a.state === "acknowledged"
      ? ", acknowledged" + ackBy(a) + (a.acknowledged_at ? " " + when(a.acknowledged_at) : "") + (a.note ? ": " + a.note : "")
      : ", not acknowledged"));
    if (a.state === "open" && canAcknowledge) ackForm(li, a);
  }
}

/** An acknowledgement's author: the key's label (its id when the key is gone). */
function ackBy(a) {
  const who = a.acknowledged_by_label || a.acknowledged_by;
  return who ? " by " + who : "";
}

/** The acknowledge button with its note, for a key with the `acknowledge` scope. */
function ackForm(li, a) {
  const f = h("form", { class: "ack-form" }, li);
  const input = h("input", { type: "text", name: "note", maxlength: "4000", required: "", placeholder: "what was done, e.g. bearing ordered", "aria-label": "acknowledgement note" }, f);
  h("button", { type: "submit", class: "ack-button" }, f, "Acknowledge");
  const err = h("span", { class: "ack-error" }, f);
  f.addEventListener("submit", async (ev) => {
    ev.preventDefault();
    try {
      await apiPost("/v1/alerts/" + encodeURIComponent(a.id) + "/acknowledge", { note: input.value.trim() });
      machineDrawn = "";
      refresh();
    } catch (e) {
      err.textContent = e.message;
    }
  });
}

function showMissing(id, message) {
  $("machine").hidden = true;
  $("placeholder").hidden = false;
  $("placeholder").textContent = id ? "Machine " + id + ": " + message : message;
}

// ---------- per-finding strength series ----------

/** The strength series of the findings that recur, by machine id: `[{name, label, points}]`. */
const findingSeries = new Map();
const seriesDrawn = new Map();

/** The findings a machine's page names (the alert's record's, then the latest's), by `kind@shaft`. */
function namedFindings(m) {
  const ev = m.open_alert && m.open_alert.evidence;
  const all = [...((ev && ev.findings) || []), ...((m.latest && m.latest.findings) || [])];
  const out = new Map();
  for (const f of all) {
    if (!f.kind || f.kind === "unexplained") continue;
    const name = "finding:" + f.kind + (f.shaft ? "@" + f.shaft : "");
    if (!out.has(name)) out.set(name, f.kind.replace(/-/g, " ") + (f.shaft ? " on " + f.shaft : ""));
  }
  return [...out.entries()].slice(0, 4);
}

/** Fetch the named findings' series when the machine changed; true when they changed. */
async function refreshFindingSeries(m) {
  if (hasWear(m)) return false;
  const stamp = viewStamp(m) + "|" + JSON.stringify(namedFindings(m));
  if (seriesDrawn.get(m.id) === stamp) return false;
  seriesDrawn.set(m.id, stamp);
  const got = await Promise.all(namedFindings(m).map(async ([name, label]) => {
    try {
      const t = await api("/v1/machines/" + encodeURIComponent(m.id) + "/trend?series=" + encodeURIComponent(name));
      return { name, label, points: t.points || [] };
    } catch (_) {
      return null;
    }
  }));
  // A finding that recurs: at least two records carry it.
  findingSeries.set(m.id, got.filter((s) => s && s.points.length >= 2));
  return true;
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
    const [list, gbs, alerts] = await Promise.all([
      api("/v1/machines"),
      api("/v1/gearboxes").catch(() => ({ gearboxes: [] })),
      fetchOpenAlerts(),
    ]);
    openAlerts = alerts;
    if (canAcknowledge === null) canAcknowledge = await probeAcknowledge();
    await refreshViews(list.machines || []);
    renderMachines(list, gbs.gearboxes);
    renderOverview(list.machines || []);
    $("status").textContent = "updated " + new Date().toLocaleTimeString();
    const r = route;
    if (r.view === "machine") await pollMachine(r.id);
    else if (r.view === "diagnoses" || r.view === "records") await pollRecord(r);
  } catch (e) {
    $("status").textContent = e.message;
  }
}

/** The shown machine: its view (every poll: an ETag makes an unchanged one a 304), trend, spectrum. */
async function pollMachine(want) {
  let m;
  try {
    m = await api("/v1/machines/" + encodeURIComponent(want));
  } catch (e) {
    if (e.status === 404 && want === selected) { machineDrawn = ""; showMissing(want, e.message); return; }
    throw e;
  }
  if (want !== selected) return; // the URL moved on meanwhile
  const drawn = JSON.stringify([m, (openAlerts || []).filter((a) => a.machine_id === m.id), canAcknowledge]);
  if (drawn !== machineDrawn) {
    machineDrawn = drawn;
    renderMachine(m);
  }
  if (await refreshFindingSeries(m) && want === selected) {
    const dom = timeDomain(m.trend || []);
    renderTrend(m, dom, findingSeries.get(m.id));
  }
  await refreshProjection(m, m.id + "|" + viewStamp(m));
  if (want !== selected) return;
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
}

$("keyform").addEventListener("submit", (ev) => {
  ev.preventDefault();
  sessionStorage.setItem("gearwear-key", $("key").value.trim());
  canAcknowledge = null;
  machineDrawn = "";
  $("key").value = "";
  $("keyform").hidden = true;
  refresh();
});
refresh();
setInterval(refresh, POLL_MS);
