//! Findings: which part a departure from the state's baseline points at.
//!
//! Each part collects the evidence features that would rise if it were damaged
//! ([`super::evidence`] names them); a feature counts as evidence when its `z` against the
//! state's reference is at least [`Z_EVIDENCE`]. A part's **strength** is the RMS of its two
//! largest such `z`. Parts of strength at least [`MIN_STRENGTH`] become findings, strongest
//! first. The rules, chosen from the physics before any score was seen:
//!
//! * **gear on shaft s, stage i** — sidebands at s's rate around mesh i's harmonics, the TSA
//!   of s (FM4, NA4, M6A, kurtosis, energy ratio) and the envelope at s's rate. With an
//!   impulsive sign (a TSA impulsiveness metric or the envelope at s's rate) it is
//!   `gear-local-damage` (a chipped, cracked or broken tooth hits once per revolution);
//!   with sidebands alone `gear-eccentricity`.
//! * **shaft s** — its 1× and 2× lines: `shaft`, detail "imbalance or bent shaft" (1×),
//!   "misalignment" (2×), "bent shaft or misalignment" (both). A shaft finding **explains**
//!   sidebands at its own rate: a `gear-eccentricity` on the same shaft that is not stronger
//!   than the shaft finding is dropped.
//! * **bearing b** — envelope lines at its defect orders: `bearing`, detail outer race, inner
//!   race, ball or cage (the largest).
//! * **unexplained** — the record departs from its baseline but none of its three largest
//!   departures belongs to a finding above.

use serde::Serialize;

use super::baseline::{Departure, StateScore};
use super::parts::{GearPart, Parts};
use crate::novelty::TOP_K;

/// Smallest z that counts as evidence.
pub const Z_EVIDENCE: f64 = 2.0;
/// Smallest strength of a finding.
pub const MIN_STRENGTH: f64 = 3.0;

/// The gear a finding names.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GearRef {
    pub stage: usize,
    pub member: &'static str,
    pub teeth: u32,
}

/// One piece of evidence.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Evidence {
    pub feature: String,
    /// For people: `+9.1 dB` for a line's amplitude, `×2.3` for a metric.
    pub change: String,
    /// The change over the baseline's scale for this feature.
    pub z: f64,
    /// Why it points at this part.
    pub why: String,
}

/// What a record's departure points at.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    /// `gear-local-damage`, `gear-eccentricity`, `shaft`, `bearing` or `unexplained`.
    pub kind: &'static str,
    /// The description's shaft name (`null` for `unexplained`).
    pub shaft: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gear: Option<GearRef>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bearing: Option<String>,
    /// Which shaft or bearing fault (`imbalance or bent shaft`, `outer race`, …).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detail: Option<String>,
    /// RMS of the two largest evidence z.
    pub strength: f64,
    /// One sentence a technician reads.
    pub summary: String,
    pub evidence: Vec<Evidence>,
}

/// Is `feature` a line amplitude (its change reads in dB) rather than a metric?
fn is_amplitude(feature: &str) -> bool {
    !(feature.starts_with("tsa.") || feature == "stat.kurtosis")
}

fn change_text(d: &Departure) -> String {
    if is_amplitude(&d.feature) {
        format!("{:+.1} dB", 20.0 * d.change / std::f64::consts::LN_10)
    } else {
        format!("×{:.2}", d.change.exp())
    }
}

fn evidence(d: &Departure, why: String) -> Evidence {
    Evidence {
        feature: d.feature.clone(),
        change: change_text(d),
        z: d.z,
        why,
    }
}

/// RMS of the two largest z of `ev` (sorted, largest first).
fn strength(ev: &[Evidence]) -> f64 {
    let top: Vec<f64> = ev.iter().take(2).map(|e| e.z * e.z).collect();
    if top.is_empty() {
        return 0.0;
    }
    (top.iter().sum::<f64>() / top.len() as f64).sqrt()
}

fn sorted(mut ev: Vec<Evidence>) -> Vec<Evidence> {
    ev.sort_by(|a, b| b.z.total_cmp(&a.z));
    ev
}

/// Why a feature points at gear `g`; `None` when it does not, `Some((why, impulsive))`.
fn gear_reason(feature: &str, g: &GearPart) -> Option<(String, bool)> {
    let s = &g.shaft;
    if let Some(rest) = feature.strip_prefix(&format!("mesh{}.h", g.stage))
        && let Some((k, shaft)) = rest.split_once(".sb.")
        && shaft == s
    {
        return Some((
            format!(
                "sidebands at shaft `{s}`'s rate around mesh {} (harmonic {k}): a gear on `{s}` \
                 modulates that mesh",
                g.stage
            ),
            false,
        ));
    }
    if let Some(m) = feature.strip_prefix(&format!("tsa.{s}.")) {
        let impulsive = m != "er";
        let why = if impulsive {
            format!(
                "the time-synchronous average of `{s}` turned impulsive ({m}): a tooth on it \
                 hits differently once per revolution"
            )
        } else {
            format!("more of `{s}`'s synchronous average is off the mesh lines (energy ratio)")
        };
        return Some((why, impulsive));
    }
    (feature == format!("env.{s}")).then(|| {
        (
            format!("the envelope repeats at `{s}`'s rate: impacts once per revolution of `{s}`"),
            true,
        )
    })
}

fn gear_finding(g: &GearPart, up: &[&Departure]) -> Option<Finding> {
    let mut impulsive = false;
    let ev: Vec<Evidence> = up
        .iter()
        .filter_map(|d| {
            gear_reason(&d.feature, g).map(|(why, imp)| {
                impulsive |= imp;
                evidence(d, why)
            })
        })
        .collect();
    let ev = sorted(ev);
    let st = strength(&ev);
    (st >= MIN_STRENGTH).then(|| Finding {
        kind: if impulsive {
            "gear-local-damage"
        } else {
            "gear-eccentricity"
        },
        shaft: Some(g.shaft.clone()),
        gear: Some(GearRef {
            stage: g.stage,
            member: g.member,
            teeth: g.teeth,
        }),
        bearing: None,
        detail: None,
        strength: st,
        summary: format!(
            "{} on shaft `{}`: {} {}",
            g.label(),
            g.shaft,
            ev[0].why.split(':').next().unwrap_or_default(),
            ev[0].change
        ),
        evidence: ev,
    })
}

fn shaft_finding(s: &str, up: &[&Departure]) -> Option<Finding> {
    let z = |h: &str| {
        up.iter()
            .find(|d| d.feature == format!("shaft.{s}.{h}"))
            .copied()
    };
    let (one, two) = (z("1x"), z("2x"));
    let detail = match (one.is_some(), two.is_some()) {
        (true, false) => "imbalance or bent shaft",
        (false, true) => "misalignment",
        (true, true) => "bent shaft or misalignment",
        (false, false) => return None,
    };
    let ev = sorted(
        [
            (one, "1×: once-per-revolution force"),
            (two, "2×: twice-per-revolution force"),
        ]
        .into_iter()
        .filter_map(|(d, why)| d.map(|d| evidence(d, format!("{why} on shaft `{s}`"))))
        .collect(),
    );
    let st = strength(&ev);
    (st >= MIN_STRENGTH).then(|| Finding {
        kind: "shaft",
        shaft: Some(s.to_string()),
        gear: None,
        bearing: None,
        detail: Some(detail.into()),
        strength: st,
        summary: format!(
            "shaft `{s}` ({detail}): its {} line up {}",
            if one.is_some() { "1×" } else { "2×" },
            ev[0].change
        ),
        evidence: ev,
    })
}

fn bearing_finding(name: &str, shaft: &str, up: &[&Departure]) -> Option<Finding> {
    let ev = sorted(
        up.iter()
            .filter_map(|d| {
                let defect = d.feature.strip_prefix(&format!("bearing.{name}."))?;
                let what = match defect {
                    "bpfo" => "outer race",
                    "bpfi" => "inner race",
                    "bsf" => "ball",
                    _ => "cage",
                };
                Some(evidence(
                    d,
                    format!(
                        "envelope lines at bearing `{name}`'s {what} defect frequency ({defect})"
                    ),
                ))
            })
            .collect(),
    );
    let st = strength(&ev);
    let detail = ev.first().map(|e| match e.feature.rsplit('.').next() {
        Some("bpfo") => "outer race",
        Some("bpfi") => "inner race",
        Some("bsf") => "ball",
        _ => "cage",
    })?;
    (st >= MIN_STRENGTH).then(|| Finding {
        kind: "bearing",
        shaft: Some(shaft.to_string()),
        gear: None,
        bearing: Some(name.to_string()),
        detail: Some(detail.into()),
        strength: st,
        summary: format!(
            "bearing `{name}` on shaft `{shaft}` ({detail}): defect lines in the envelope up {}",
            ev[0].change
        ),
        evidence: ev,
    })
}

/// The findings of a record judged against its state (none when it is not anomalous).
pub fn findings(score: &StateScore, parts: &Parts) -> Vec<Finding> {
    if !score.anomalous {
        return Vec::new();
    }
    let up: Vec<&Departure> = score
        .departures
        .iter()
        .filter(|d| d.z >= Z_EVIDENCE)
        .collect();
    let mut out: Vec<Finding> = Vec::new();
    let shafts: Vec<Finding> = parts
        .shafts
        .keys()
        .filter_map(|s| shaft_finding(s, &up))
        .collect();
    for g in &parts.gears {
        if let Some(f) = gear_finding(g, &up) {
            let explained = f.kind == "gear-eccentricity"
                && shafts
                    .iter()
                    .any(|s| s.shaft == f.shaft && s.strength >= f.strength);
            if !explained {
                out.push(f);
            }
        }
    }
    out.extend(shafts);
    out.extend(
        parts
            .bearings
            .iter()
            .filter_map(|b| bearing_finding(&b.name, &b.shaft, &up)),
    );
    out.sort_by(|a, b| b.strength.total_cmp(&a.strength));
    let explained = |f: &str| {
        out.iter()
            .any(|x| x.evidence.iter().any(|e| e.feature == f))
    };
    let loose: Vec<&Departure> = score
        .departures
        .iter()
        .take(TOP_K)
        .filter(|d| !explained(&d.feature))
        .collect();
    if out.is_empty() || loose.len() == TOP_K {
        let ev: Vec<Evidence> = loose
            .iter()
            .map(|d| {
                evidence(
                    d,
                    "departs from the baseline at this state; no described part explains it".into(),
                )
            })
            .collect();
        let st = (ev.iter().map(|e| e.z * e.z).sum::<f64>() / ev.len().max(1) as f64).sqrt();
        out.push(Finding {
            kind: "unexplained",
            shaft: None,
            gear: None,
            bearing: None,
            detail: None,
            strength: st,
            summary: format!(
                "unexplained: {} departs from the healthy baseline at this speed and load",
                ev.iter()
                    .map(|e| format!("{} ({})", e.feature, e.change))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            evidence: ev,
        });
        out.sort_by(|a, b| b.strength.total_cmp(&a.strength));
    }
    out
}
