//! Findings: which part a departure from the state's baseline points at.
//!
//! Each part collects the evidence features that would rise if it were damaged
//! ([`super::evidence`] names them); a feature counts as evidence when its `z` against the
//! state's reference is at least [`Z_EVIDENCE`]. A part's **strength** is the RMS of its two
//! largest such `z`. Parts of strength at least [`MIN_STRENGTH`] become findings, strongest
//! first. The rules, chosen from the physics before any score was seen:
//!
//! * **gear on shaft s, stage i** — located by lines only s makes: sidebands at s's rate
//!   around mesh i's harmonics and the envelope at s's rate (its strength comes from these).
//!   The TSA of s (FM4, NA4, M6A, kurtosis, energy ratio) supports it but does not locate: an
//!   impact once per revolution of one shaft also shows in the TSA of every shaft whose rate
//!   is commensurate with it. With an impulsive sign (a TSA impulsiveness metric of s or the
//!   envelope at s's rate) it is `gear-local-damage` (a chipped, cracked or broken tooth hits
//!   once per revolution); with sidebands alone `gear-eccentricity`.
//!   A gear finding on a shaft whose rate is a whole multiple of another shaft's with a gear
//!   finding is dropped: the slower shaft's comb contains all its lines, and the slower shaft's
//!   own lines rose.
//! * **shaft s** — its 1× and 2× lines: `shaft`, detail "imbalance or bent shaft" (1×),
//!   "misalignment" (2×), "bent shaft or misalignment" (both). A shaft finding **explains**
//!   sidebands at its own rate: a `gear-eccentricity` on the same shaft that is not stronger
//!   than the shaft finding is dropped.
//! * **bearing b** — envelope lines at its defect orders: `bearing`, detail outer race, inner
//!   race, ball or cage (the largest).
//! * **unexplained** — the record departs from its baseline but none of its three largest
//!   departures belongs to a finding above.

use serde::Serialize;

use super::baseline::TOP_K;
use super::baseline::{Departure, StateScore};
use super::parts::{GearPart, Parts};

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

/// Why a feature points at gear `g`; `None` when it does not, else `(why, impulsive,
/// locates)`: `locates` for lines at multiples of the shaft's rate that only this shaft makes
/// (sidebands, envelope), not for TSA metrics (an impact on one shaft also shows in the TSA
/// of every shaft whose rate it is commensurate with).
fn gear_reason(feature: &str, g: &GearPart) -> Option<(String, bool, bool)> {
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
            true,
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
        return Some((why, impulsive, false));
    }
    (feature == format!("env.{s}")).then(|| {
        (
            format!("the envelope repeats at `{s}`'s rate: impacts once per revolution of `{s}`"),
            true,
            true,
        )
    })
}

fn gear_finding(g: &GearPart, up: &[&Departure]) -> Option<Finding> {
    let mut impulsive = false;
    let mut locating = Vec::new();
    let mut support = Vec::new();
    for d in up {
        if let Some((why, imp, loc)) = gear_reason(&d.feature, g) {
            impulsive |= imp;
            if loc {
                locating.push(evidence(d, why));
            } else {
                support.push(evidence(d, why));
            }
        }
    }
    let locating = sorted(locating);
    let st = strength(&locating);
    if st < MIN_STRENGTH {
        return None;
    }
    let summary = format!(
        "{} on shaft `{}`: {} {}",
        g.label(),
        g.shaft,
        locating[0].why.split(':').next().unwrap_or_default(),
        locating[0].change
    );
    Some(Finding {
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
        summary,
        evidence: locating.into_iter().chain(sorted(support)).collect(),
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

/// Drop a gear finding on a shaft whose rate is a whole multiple of the rate of another shaft
/// that has a gear finding too: every line of the faster shaft is also a line of the slower
/// one, so the slower shaft, whose own lines rose, explains both.
fn drop_nested(gears: &mut Vec<Finding>, parts: &Parts) {
    let rate = |f: &Finding| f.shaft.as_ref().and_then(|s| parts.shafts.get(s)).copied();
    let slower: Vec<f64> = gears.iter().filter_map(rate).collect();
    gears.retain(|f| {
        let Some(rt) = rate(f) else { return true };
        !slower.iter().any(|&rs| {
            let k = rt / rs;
            rs < rt * (1.0 - 1e-9) && (k - k.round()).abs() < 1e-6
        })
    });
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
    drop_nested(&mut out, parts);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gearbox::Gearbox;

    fn parts() -> Parts {
        let gb = Gearbox::parse(
            "format = \"gearwear-gearbox\"\nversion = 1\nname = \"h\"\ninput_shaft = \"in\"\n\
             [[stage]]\nkind = \"parallel\"\npinion = { shaft = \"in\", teeth = 16 }\n\
             gear = { shaft = \"idler\", teeth = 48 }\n\
             [[stage]]\nkind = \"parallel\"\npinion = { shaft = \"idler\", teeth = 24 }\n\
             gear = { shaft = \"out\", teeth = 40 }\n\
             [[bearing]]\nname = \"b-out\"\nshaft = \"out\"\nbpfo = 3.05\nbpfi = 4.95\n\
             bsf = 1.99\nftf = 0.38\n",
            "test",
        )
        .unwrap();
        Parts::of(&gb)
    }

    fn score(anomalous: bool, d: &[(&str, f64)]) -> StateScore {
        let departures: Vec<Departure> = d
            .iter()
            .map(|(f, z)| Departure {
                feature: f.to_string(),
                change: 0.1 * z,
                z: *z,
            })
            .collect();
        StateScore {
            score: 5.0,
            threshold: 3.0,
            anomalous,
            reference: "same-state",
            reference_hz: vec![40.0],
            top: departures.iter().take(3).cloned().collect(),
            departures,
        }
    }

    #[test]
    fn sidebands_at_the_idler_rate_and_an_impulsive_tsa_name_the_24_tooth_pinion() {
        let f = findings(
            &score(
                true,
                &[
                    ("mesh2.h1.sb.idler", 6.0),
                    ("mesh2.h3.sb.idler", 5.0),
                    ("tsa.idler.fm4", 4.0),
                ],
            ),
            &parts(),
        );
        assert_eq!(f[0].kind, "gear-local-damage", "{f:?}");
        assert_eq!(f[0].shaft.as_deref(), Some("idler"));
        assert_eq!(
            f[0].gear,
            Some(GearRef {
                stage: 2,
                member: "pinion",
                teeth: 24
            })
        );
        // Strength: RMS of the two locating z (the TSA supports, it does not locate).
        assert!((f[0].strength - ((36.0 + 25.0) / 2.0f64).sqrt()).abs() < 1e-9);
        assert!(f[0].summary.contains("24T") && f[0].summary.contains("`idler`"));
        assert!(
            f.iter()
                .all(|x| x.gear.as_ref().is_none_or(|g| g.teeth != 48))
        );
        assert_eq!(f[0].evidence[0].change, "+5.2 dB");
    }

    /// The input turns 3 × the idler: lines at the input's rate are also idler harmonics, so
    /// with the idler's own lines up the idler explains both.
    #[test]
    fn the_slower_commensurate_shaft_explains_the_faster_ones_lines() {
        let f = findings(
            &score(
                true,
                &[
                    ("env.in", 8.0),
                    ("mesh1.h1.sb.in", 7.0),
                    ("mesh2.h1.sb.idler", 5.0),
                    ("env.idler", 4.0),
                ],
            ),
            &parts(),
        );
        assert!(f.iter().all(|x| x.shaft.as_deref() != Some("in")), "{f:?}");
        assert_eq!(f[0].shaft.as_deref(), Some("idler"), "{f:?}");
    }

    #[test]
    fn a_shaft_line_explains_sidebands_at_its_own_rate() {
        let f = findings(
            &score(true, &[("shaft.in.1x", 7.0), ("mesh1.h1.sb.in", 5.0)]),
            &parts(),
        );
        assert_eq!(f.len(), 1, "{f:?}");
        assert_eq!(f[0].kind, "shaft");
        assert_eq!(f[0].detail.as_deref(), Some("imbalance or bent shaft"));
    }

    #[test]
    fn bearing_lines_name_the_bearing_and_nothing_else_is_unexplained() {
        let f = findings(&score(true, &[("bearing.b-out.bpfi", 6.0)]), &parts());
        assert_eq!(f[0].kind, "bearing");
        assert_eq!(f[0].bearing.as_deref(), Some("b-out"));
        assert_eq!(f[0].detail.as_deref(), Some("inner race"));
        let f = findings(
            &score(true, &[("stat.rms", 9.0), ("env.level", 4.0)]),
            &parts(),
        );
        assert_eq!(f.len(), 1);
        assert_eq!(f[0].kind, "unexplained");
        assert!(findings(&score(false, &[("mesh2.h1.sb.idler", 9.0)]), &parts()).is_empty());
    }
}
