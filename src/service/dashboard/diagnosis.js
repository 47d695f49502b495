// gearwear dashboard: one record's diagnosis, by deep link — `#/diagnoses/{diagnosis_id}`
// (GET /v1/diagnoses/{id}) or `#/records/{record_id}` (GET /v1/records/{id}, the same answer).
"use strict";

let recordDrawn = "";

/** The diagnosis answer (`{id, machine_id, record_id, created_at, …, diagnosis, spectrum, evidence}`) drawn. */
function renderRecord(r) {
  const d = r.diagnosis || {};
  $("record-missing").hidden = true;
  $("record").hidden = false;
  $("record").dataset.id = r.id;
  $("record").dataset.record = r.record_id;
  const ml = $("record-machine");
  ml.textContent = r.machine_id;
  ml.href = machineHref(r.machine_id);
  badge($("record-level"), r.alert_level, 1);
  const measured = r.measured_at || d.measured_at;
  $("record-when").textContent = measured && measured !== r.created_at
    ? "measured " + when(measured) + ", received " + when(r.created_at)
    : "received " + when(r.created_at);
  const a = d.alert || {};
  $("record-reason").textContent = a.reason || "";
  const facts = $("record-facts");
  facts.innerHTML = "";
  const fact = (name, value, cls) => {
    h("dt", {}, facts, name);
    h("dd", { class: cls || "" }, facts, value);
  };
  const w = r.wear_degree;
  fact("Wear degree ea", w && num(w.estimate) ? w.estimate.toFixed(3) + " (90 % " + fmt(w.lower, 3) + " … " + fmt(w.upper, 3) + ")"
    : noWearText(d.wear_withheld) || "no wear figure", "wear");
  const um = d.wear_degree_um;
  if (um && num(um.estimate)) fact("Wear", um.estimate.toFixed(1) + " µm (90 % " + fmt(um.lower, 1) + " … " + fmt(um.upper, 1) + ")", "wear-um");
  for (const p of figureParts(d).filter((p) => !p.cls.startsWith("wear"))) fact(p.cls.startsWith("velocity") ? "Velocity" : "Acceleration", p.text, p.cls);
  const n = r.novelty;
  fact("Novelty", n && num(n.score) ? n.score.toFixed(2) + " (threshold " + fmt(n.threshold, 2) + ")" : "no baseline");
  evidenceFacts(d, fact);
  fact("Motion state", r.motion_state || "–");
  fact("Diagnosis id", r.id, "ids");
  fact("Record id", r.record_id, "ids");
  const ol = $("record-findings");
  ol.innerHTML = "";
  const fs = Array.isArray(d.findings) ? d.findings : [];
  for (const f of fs) {
    const li = h("li", { class: "finding" }, ol);
    codeText(li, f.summary || f.kind || "");
    h("span", { class: "kind" }, li, (f.kind || "") + (num(f.strength) ? ", strength " + f.strength.toFixed(1) : ""));
  }
  if (!fs.length) h("li", { class: "muted none" }, ol, "none: the record does not depart from a baseline at its speed and load (or the machine has none)");
  renderEvidence(r);
  renderSpectrum({ spectrum: r.spectrum }, $("record-spectrum"));
}

function showRecordMissing(message) {
  $("record").hidden = true;
  $("record-missing").hidden = false;
  $("record-missing").textContent = message;
}

/** Draw the routed record (fetched again only when the route changes). */
async function pollRecord(route) {
  const key = route.view + "/" + route.id;
  if (recordDrawn === key) return;
  const path = (route.view === "records" ? "/v1/records/" : "/v1/diagnoses/") + encodeURIComponent(route.id);
  let r;
  try {
    r = await api(path);
  } catch (e) {
    if (e.status === 404) { recordDrawn = key; showRecordMissing(e.message); return; }
    throw e;
  }
  if (currentRoute().id !== route.id) return;
  recordDrawn = key;
  renderRecord(r);
}
