//! Findings: which part a record's departure from its state's baseline points at, from the
//! explainer's ranking ([`super::explain`]) of every candidate part ([`super::candidates`]).
//!
//! Each candidate the explainer takes becomes a finding, with the **share** of the change it
//! explains; the parts come first, by share, then the common changes (`transfer-path`,
//! `mesh-lines`), then `unexplained` (what is left):
//!
//! | kind | part | from |
//! | --- | --- | --- |
//! | `gear-local-damage` | a gear (its shaft) | a comb of sidebands at its shaft's rate around its mesh's harmonics, impacts at that rate in the envelope; its shaft's TSA turning impulsive supports it |
//! | `gear-eccentricity` | a gear | the first sidebands at its shaft's rate, its shaft's 1× |
//! | `shaft` | a shaft | its 1× (`imbalance or bent shaft`), 2× (`misalignment`), low harmonics (`looseness or rub`) |
//! | `bearing` | a described bearing | its defect lines in the envelope (`outer race`, `inner race`, `ball`, `cage`) |
//! | `non-synchronous` | — | vibration at no shaft's lines: friction, looseness, a bearing not described |
//! | `mesh-lines` | — (`detail` names the stage) | a stage's mesh harmonics changed together: tooth wear, a change of load or contact |
//! | `transfer-path` | — | everything in a band of orders moved together: a sensor remounted, the gearbox reassembled, a resonance moved |
//! | `unexplained` | — | the change left when no candidate explains more of it (its share), or when what is left still departs beyond the threshold |
//!
//! A shaft with no line of its own (the input shaft of a train whose slower shafts turn at
//! whole fractions of its rate) is named by elimination: its gears' sidebands fall in the
//! shared class, which no slower shaft's candidate explains alone.

use serde::{Deserialize, Serialize};

use super::baseline::{Departure, StateScore, TOP_K};
use super::candidates::{Response, candidates};
use super::explain::{Cause, Explanation, Pick, explain};
use super::lines::LineMap;
use super::parts::Parts;

/// Smallest z a supporting feature (a TSA metric) must reach to be listed.
pub const Z_SUPPORT: f64 = 2.0;
/// Evidence listed per finding (the features it moved most).
const EVIDENCE: usize = 4;

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

/// What a finding points at (the API writes it in kebab case: `gear-local-damage`, …).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FindingKind {
    /// One gear's local tooth damage (a crack, a chip, a broken tooth).
    GearLocalDamage,
    /// One gear's eccentricity (its mesh modulated once per revolution).
    GearEccentricity,
    /// A shaft (imbalance, bend, misalignment, looseness).
    Shaft,
    /// A rolling bearing's defect.
    Bearing,
    /// Vibration at no shaft's lines.
    NonSynchronous,
    /// A stage's mesh lines moving together (tooth wear, load or contact).
    MeshLines,
    /// The way vibration reaches the sensor.
    TransferPath,
    /// What no candidate explains.
    Unexplained,
}

crate::words::words!(FindingKind, "a finding kind", {
    GearLocalDamage => "gear-local-damage",
    GearEccentricity => "gear-eccentricity",
    Shaft => "shaft",
    Bearing => "bearing",
    NonSynchronous => "non-synchronous",
    MeshLines => "mesh-lines",
    TransferPath => "transfer-path",
    Unexplained => "unexplained",
});

impl FindingKind {
    /// Does a finding of this kind name a part (a gear's local damage or eccentricity, a
    /// shaft, a bearing) rather than a change every tooth or the whole path shares?
    pub fn names_part(self) -> bool {
        matches!(
            self,
            FindingKind::GearLocalDamage
                | FindingKind::GearEccentricity
                | FindingKind::Shaft
                | FindingKind::Bearing
        )
    }

    /// Is it a gear's (local damage or eccentricity)?
    pub fn is_gear(self) -> bool {
        matches!(
            self,
            FindingKind::GearLocalDamage | FindingKind::GearEccentricity
        )
    }

    /// A change of a whole band or of a stage's mesh lines, not of one part.
    fn is_common(self) -> bool {
        matches!(self, FindingKind::TransferPath | FindingKind::MeshLines)
    }
}

/// What a record's departure points at.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    pub kind: FindingKind,
    /// The description's shaft name (`null` when no shaft is named).
    pub shaft: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gear: Option<GearRef>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bearing: Option<String>,
    /// Which fault (`imbalance or bent shaft`, `outer race`, the band of a path change, …).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detail: Option<String>,
    /// RMS of the two largest evidence z.
    pub strength: f64,
    /// Share (0–1) of the record's change (its χ² over the explainable features) this finding
    /// explains.
    pub share: f64,
    /// One sentence a technician reads.
    pub summary: String,
    pub evidence: Vec<Evidence>,
}

/// Share of a record's change a part's finding must explain for the change to be that part's
/// ("mostly": at least as much as every other cause together).
pub const MOSTLY: f64 = 0.5;

/// The part a record's change mostly belongs to: a finding that names a part and explains at
/// least [`MOSTLY`] of the change. Such a change is not of the wear kind — wear moves a
/// stage's mesh lines together (`mesh-lines`) — so a wear figure read off the record would be
/// the part's, not the teeth's. `None` without findings, or when no part explains most of the
/// change (a common change leads, or most of it is unexplained).
pub fn mostly_one_part(findings: &[Finding]) -> Option<&Finding> {
    findings
        .iter()
        .find(|f| f.kind.names_part() && f.share >= MOSTLY)
}

/// Is `feature` a line amplitude (its change reads in dB) rather than a metric?
fn is_amplitude(feature: &str) -> bool {
    !(feature.starts_with("tsa.") || feature == "stat.kurtosis")
}

fn change_text(change: f64, feature: &str) -> String {
    if is_amplitude(feature) {
        format!("{:+.1} dB", 20.0 * change / std::f64::consts::LN_10)
    } else {
        format!("×{:.2}", change.exp())
    }
}

/// A region's name for people: `mesh harmonic 32` or `the low orders`.
fn region_words(region: &str) -> String {
    match region {
        "low" => "the shaft orders below the first mesh harmonic".into(),
        "mesh" => "the orders around the mesh harmonics".into(),
        "high" => "the orders above the mesh harmonics".into(),
        "env" => "the envelope band".into(),
        r => format!("mesh harmonic {}", r.trim_start_matches('m')),
    }
}

/// A novelty feature's departure in words: what it is ([`why`]) and how far from the healthy
/// records it is (`z`: baseline spreads, its sign the direction).
pub fn departure_words(feature: &str, z: f64) -> String {
    format!(
        "{}: {} by {:.1}× the healthy spread",
        why(feature),
        if z >= 0.0 { "up" } else { "down" },
        z.abs()
    )
}

/// Why a feature points where it does, in words.
pub fn why(feature: &str) -> String {
    let parts: Vec<&str> = feature.split('.').collect();
    match parts.as_slice() {
        ["lines", "own", s, "near", r] => format!(
            "first sidebands at shaft `{s}`'s rate around {} (only `{s}` makes them)",
            region_words(r)
        ),
        ["lines", "own", s, "far", r] => format!(
            "a comb of sidebands at shaft `{s}`'s rate around {}: an event once per revolution \
             of `{s}`",
            region_words(r)
        ),
        ["lines", "own", s, r] => {
            format!("lines only shaft `{s}` makes, in {}", region_words(r))
        }
        ["lines", "shared", r] => format!(
            "lines several shafts make (whole orders of the input) in {}",
            region_words(r)
        ),
        ["lines", "mesh", r] => format!("the mesh line at {}", region_words(r)),
        ["lines", "none", r] => format!("vibration at no shaft's lines in {}", region_words(r)),
        ["shaft", s, h] => format!("{h} of shaft `{s}`"),
        ["env", "own", s] => {
            format!("the envelope repeats at shaft `{s}`'s rate: impacts once per revolution")
        }
        ["env", "shared"] => "the envelope repeats at whole orders of the input".into(),
        ["env", "none"] => "impacts at no shaft's rate in the envelope".into(),
        ["env", "level"] => "the envelope's level (impacting)".into(),
        ["bearing", b, d] => format!(
            "envelope lines at bearing `{b}`'s {} frequency ({d})",
            defect_words(d)
        ),
        ["tsa", s, m] => format!(
            "the time-synchronous average of `{s}` turned impulsive ({m}): a tooth on it hits \
             differently once per revolution"
        ),
        ["stat", "ln_rms" | "rms"] => "the overall vibration level (RMS)".into(),
        ["stat", "ln_kurtosis" | "kurtosis"] => {
            "the record's kurtosis (how impulsive it is)".into()
        }
        ["stat", "ln_crest" | "crest"] => "the crest factor (peaks over RMS)".into(),
        ["order", "ln_sync_share"] => {
            "the share of the vibration that repeats with the input shaft".into()
        }
        ["band", f] if f.ends_with("hz") => format!(
            "the power in the third-octave band around {} Hz",
            f.trim_end_matches("hz")
        ),
        _ => format!("{feature} departs from the baseline at this state"),
    }
}

fn defect_words(d: &str) -> &'static str {
    match d {
        "bpfo" => "outer race",
        "bpfi" => "inner race",
        "bsf" => "ball",
        _ => "cage",
    }
}

fn evidence_of(d: &Departure) -> Evidence {
    Evidence {
        feature: d.feature.clone(),
        change: change_text(d.change, &d.feature),
        z: d.z,
        why: why(&d.feature),
    }
}

/// RMS of the two largest |z| of `ev`.
fn strength(ev: &[Evidence]) -> f64 {
    let mut z: Vec<f64> = ev.iter().map(|e| e.z.abs()).collect();
    z.sort_by(|a, b| b.total_cmp(a));
    let top: Vec<f64> = z.iter().take(2).map(|v| v * v).collect();
    if top.is_empty() {
        return 0.0;
    }
    (top.iter().sum::<f64>() / top.len() as f64).sqrt()
}

/// The findings of a record judged against its state (none when it is not anomalous); the
/// gears' simulated `response` when known (else a flat ratio over the harmonics).
pub fn findings(score: &StateScore, parts: &Parts, response: Option<&Response>) -> Vec<Finding> {
    if !score.anomalous {
        return Vec::new();
    }
    explained(score, parts, response).1
}

/// The explanation of a record's change from its reference and its findings, whether the
/// record is anomalous or not (the closed loop reads both: [`super::measured_loop`]).
pub fn explained(
    score: &StateScore,
    parts: &Parts,
    response: Option<&Response>,
) -> (Explanation, Vec<Finding>) {
    let map = LineMap::of(parts);
    let reference = score
        .departures
        .iter()
        .map(|d| (d.feature.clone(), (2.0 * d.reference).exp()))
        .collect();
    let measured = score
        .departures
        .iter()
        .map(|d| (d.feature.clone(), (2.0 * (d.reference + d.change)).exp()))
        .collect();
    let cands = candidates(parts, &map, &reference, &measured, response);
    let ex = explain(&score.departures, &cands);
    let by_name = |f: &str| score.departures.iter().find(|d| d.feature == f);
    let mut out: Vec<Finding> = ex
        .picks
        .iter()
        .map(|p| finding_of(p, parts, score, &by_name))
        .collect();
    // Parts first, then the common changes, each by share; what is left comes last (it is
    // first only when nothing was named).
    out.sort_by(|a, b| {
        a.kind
            .is_common()
            .cmp(&b.kind.is_common())
            .then(b.share.total_cmp(&a.share))
    });
    out.extend(unexplained(&ex, score, &out));
    (ex, out)
}

/// The finding of one pick.
fn finding_of<'a>(
    p: &Pick,
    parts: &Parts,
    score: &'a StateScore,
    by_name: &dyn Fn(&str) -> Option<&'a Departure>,
) -> Finding {
    // The features it moved whose change (against what earlier picks left) went its way, most
    // first.
    let mut support: Vec<(&Departure, f64)> = p
        .moved
        .iter()
        .filter_map(|(f, dz, z)| by_name(f).map(|d| (d, z * dz.signum())))
        .filter(|(_, s)| *s > 0.0)
        .collect();
    support.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut ev: Vec<Evidence> = support
        .iter()
        .take(EVIDENCE)
        .map(|(d, _)| evidence_of(d))
        .collect();
    let st = strength(&ev);
    let lead = ev
        .first()
        .map(|e| format!("{} {}", e.why, e.change))
        .unwrap_or_default();
    let explains = format!("explains {:.0} % of the change", 100.0 * p.share);
    let mut f = Finding {
        kind: FindingKind::Unexplained,
        shaft: None,
        gear: None,
        bearing: None,
        detail: None,
        strength: st,
        share: p.share,
        summary: String::new(),
        evidence: Vec::new(),
    };
    match &p.cause {
        Cause::GearLocal { gear } | Cause::GearEccentric { gear } => {
            let g = &parts.gears[*gear];
            let local = matches!(p.cause, Cause::GearLocal { .. });
            f.kind = if local {
                FindingKind::GearLocalDamage
            } else {
                FindingKind::GearEccentricity
            };
            f.shaft = Some(g.shaft.clone());
            f.gear = Some(GearRef {
                stage: g.stage,
                member: g.member,
                teeth: g.teeth,
            });
            if local {
                ev.extend(
                    score
                        .departures
                        .iter()
                        .filter(|d| d.feature.starts_with(&format!("tsa.{}.", g.shaft)))
                        .filter(|d| d.z >= Z_SUPPORT)
                        .map(evidence_of),
                );
            }
            f.summary = format!(
                "{} on shaft `{}`, {}: {lead} ({explains})",
                g.label(),
                g.shaft,
                if local {
                    "local damage"
                } else {
                    "eccentricity"
                }
            );
        }
        Cause::Shaft { shaft } => {
            let detail = match p
                .amplitudes
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))
                .map(|x| x.0)
            {
                Some(0) => "imbalance or bent shaft",
                Some(1) => "misalignment",
                _ => "looseness or rub",
            };
            f.kind = FindingKind::Shaft;
            f.shaft = Some(shaft.clone());
            f.detail = Some(detail.into());
            f.summary = format!("shaft `{shaft}` ({detail}): {lead} ({explains})");
        }
        Cause::Bearing { bearing, defect } => {
            let shaft = parts
                .bearings
                .iter()
                .find(|b| &b.name == bearing)
                .map(|b| b.shaft.clone());
            f.kind = FindingKind::Bearing;
            f.detail = Some(defect_words(defect).into());
            f.summary = format!(
                "bearing `{bearing}`{} ({}): {lead} ({explains})",
                shaft
                    .as_ref()
                    .map(|s| format!(" on shaft `{s}`"))
                    .unwrap_or_default(),
                defect_words(defect)
            );
            f.shaft = shaft;
            f.bearing = Some(bearing.clone());
        }
        Cause::NonSynchronous => {
            f.kind = FindingKind::NonSynchronous;
            f.detail = Some("friction, looseness or a bearing not described".into());
            f.summary = format!(
                "vibration at no shaft's lines (friction, looseness or a bearing not \
                 described): {lead} ({explains})"
            );
        }
        Cause::MeshLines { stage } => {
            let tau = p.amplitudes.first().copied().unwrap_or(0.0);
            f.kind = FindingKind::MeshLines;
            f.detail = Some(format!("stage {stage}: tooth wear, load or contact"));
            f.summary = format!(
                "the mesh lines of stage {stage} changed together by {:+.1} dB (tooth wear, or \
                 a change of load or contact) ({explains})",
                10.0 * (1.0 + tau).max(1e-12).log10()
            );
        }
        Cause::Path { region } => {
            let tau = p.amplitudes.first().copied().unwrap_or(0.0);
            f.kind = FindingKind::TransferPath;
            f.detail = Some(region_words(region));
            f.summary = format!(
                "the way vibration reaches the sensor changed in {}: every line there moved \
                 together by {:+.1} dB (a sensor remounted, the gearbox reassembled, a \
                 resonance moved) ({explains})",
                region_words(region),
                10.0 * (1.0 + tau).max(1e-12).log10()
            );
        }
    }
    f.evidence = ev;
    f
}

/// `unexplained`, when no candidate was taken or what is left still departs beyond the
/// record's threshold: the largest departures left (the fitted features' residuals, and the
/// features no candidate fits), with the share no finding took.
fn unexplained(ex: &Explanation, score: &StateScore, found: &[Finding]) -> Option<Finding> {
    let fitted: std::collections::BTreeMap<&str, f64> =
        ex.residual.iter().map(|(f, z)| (f.as_str(), *z)).collect();
    let mut left: Vec<Evidence> = score
        .departures
        .iter()
        .map(|d| {
            let z = fitted.get(d.feature.as_str()).copied().unwrap_or(d.z);
            Evidence {
                feature: d.feature.clone(),
                change: change_text(z * d.scale, &d.feature),
                z,
                why: "departs from the baseline at this state; no described part explains it"
                    .into(),
            }
        })
        .collect();
    left.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
    left.truncate(TOP_K);
    let rms = (left.iter().map(|e| e.z * e.z).sum::<f64>() / left.len().max(1) as f64).sqrt();
    if !(found.is_empty() || rms > score.threshold) {
        return None;
    }
    let share = (1.0 - found.iter().map(|f| f.share).sum::<f64>()).max(0.0);
    Some(Finding {
        kind: FindingKind::Unexplained,
        shaft: None,
        gear: None,
        bearing: None,
        detail: None,
        strength: rms,
        share,
        summary: format!(
            "unexplained: {} depart from the healthy baseline at this speed and load",
            left.iter()
                .map(|e| format!("{} ({})", why(&e.feature), e.change))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        evidence: left,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gearbox::Gearbox;

    fn parts() -> Parts {
        let gb = Gearbox::parse(
            "format = \"gearwear-gearbox\"\nversion = 1\nname = \"s\"\ninput_shaft = \"in\"\n\
             [[stage]]\nkind = \"parallel\"\npinion = { shaft = \"in\", teeth = 32 }\n\
             gear = { shaft = \"idler\", teeth = 96 }\n\
             [[stage]]\nkind = \"parallel\"\npinion = { shaft = \"idler\", teeth = 48 }\n\
             gear = { shaft = \"out\", teeth = 80 }\n\
             [[bearing]]\nname = \"b-out\"\nshaft = \"out\"\nbpfo = 3.05\nbpfi = 4.95\n\
             bsf = 1.99\nftf = 0.38\n",
            "test",
        )
        .unwrap();
        Parts::of(&gb)
    }

    /// A score whose every feature sits at reference `r` (ln) with scale 0.15, except the
    /// changes given.
    fn score(features: &[(&str, f64)], changes: &[(&str, f64)]) -> StateScore {
        let mut departures: Vec<Departure> = features
            .iter()
            .map(|(f, r)| {
                let change = changes.iter().find(|c| c.0 == *f).map_or(0.0, |c| c.1);
                Departure {
                    feature: f.to_string(),
                    change,
                    z: change / 0.15,
                    reference: *r,
                    scale: 0.15,
                }
            })
            .collect();
        departures.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
        StateScore {
            score: 5.0,
            threshold: 3.5,
            anomalous: true,
            reference: "same-state",
            reference_hz: vec![40.0],
            top: departures.iter().take(3).cloned().collect(),
            departures,
        }
    }

    /// The reference features of the spur train: every class of every region at −4 (ln), the
    /// mesh carriers at 0, the shaft lines at −3, the envelope at −5.
    fn reference() -> Vec<(String, f64)> {
        let p = parts();
        let map = LineMap::of(&p);
        let mut v = Vec::new();
        for r in &map.regions {
            let n = &r.name;
            let mut names = vec![format!("lines.shared.{n}"), format!("lines.none.{n}")];
            for s in ["idler", "out"] {
                if r.centre.is_some() {
                    names.push(format!("lines.own.{s}.near.{n}"));
                    names.push(format!("lines.own.{s}.far.{n}"));
                } else {
                    names.push(format!("lines.own.{s}.{n}"));
                }
            }
            v.extend(names.into_iter().map(|k| (k, -4.0)));
            if r.centre.is_some() {
                v.push((format!("lines.mesh.{n}"), 0.0));
            }
        }
        for s in ["in", "idler", "out"] {
            v.push((format!("shaft.{s}.1x"), -3.0));
            v.push((format!("shaft.{s}.2x"), -3.0));
        }
        for e in ["env.own.idler", "env.own.out", "env.shared", "env.none"] {
            v.push((e.into(), -5.0));
        }
        for d in ["bpfo", "bpfi", "bsf"] {
            v.push((format!("bearing.b-out.{d}"), -6.0));
        }
        v
    }

    fn run(changes: &[(&str, f64)]) -> Vec<Finding> {
        let r = reference();
        let f: Vec<(&str, f64)> = r.iter().map(|(k, v)| (k.as_str(), *v)).collect();
        findings(&score(&f, changes), &parts(), None)
    }

    /// Energy added to the reference in the pattern of local damage on the 48T idler pinion
    /// (its comb around mesh 2's harmonics, its impacts in the envelope), and 1 dB of other
    /// changes: a gear on the idler with local damage, first, explaining most of the change.
    #[test]
    fn a_comb_at_the_idlers_rate_names_an_idler_gear() {
        let p = parts();
        let map = LineMap::of(&p);
        let r = reference();
        let energy: std::collections::BTreeMap<String, f64> = r
            .iter()
            .map(|(k, v)| (k.clone(), (2.0 * v).exp()))
            .collect();
        let g48 = p.gears.iter().position(|g| g.teeth == 48).unwrap();
        let c = candidates(&p, &map, &energy, &energy, None);
        let local = c
            .iter()
            .find(|x| x.cause == Cause::GearLocal { gear: g48 })
            .unwrap();
        let mut changes: Vec<(String, f64)> = Vec::new();
        for (k, e) in &energy {
            let added = 3e-3 * local.components[0].get(k).copied().unwrap_or(0.0)
                + 2e-3 * local.components[1].get(k).copied().unwrap_or(0.0);
            let wobble = 0.1 * ((k.len() % 7) as f64 / 7.0 - 0.5);
            changes.push((k.clone(), 0.5 * ((e + added) / e).ln() + wobble));
        }
        let ch: Vec<(&str, f64)> = changes.iter().map(|(k, v)| (k.as_str(), *v)).collect();
        let f = run(&ch);
        assert_eq!(f[0].kind.as_str(), "gear-local-damage", "{f:#?}");
        assert_eq!(f[0].shaft.as_deref(), Some("idler"));
        assert_eq!(f[0].gear.as_ref().unwrap().teeth, 48, "{f:#?}");
        assert!(f[0].share > 0.8, "{f:#?}");
    }

    #[test]
    fn a_first_order_line_names_the_shaft() {
        let f = run(&[("shaft.in.1x", 1.5)]);
        assert_eq!(f[0].kind.as_str(), "shaft", "{f:#?}");
        assert_eq!(f[0].shaft.as_deref(), Some("in"));
        assert_eq!(f[0].detail.as_deref(), Some("imbalance or bent shaft"));
    }

    #[test]
    fn bearing_lines_name_the_bearing() {
        let f = run(&[("bearing.b-out.bpfi", 1.5), ("env.none", 0.3)]);
        assert_eq!(f[0].kind.as_str(), "bearing", "{f:#?}");
        assert_eq!(f[0].bearing.as_deref(), Some("b-out"));
        assert_eq!(f[0].detail.as_deref(), Some("inner race"));
    }

    /// Everything around the mesh harmonics down by the same 6 dB: the path, not a part.
    #[test]
    fn a_common_change_in_a_band_is_the_path() {
        let r = reference();
        let changes: Vec<(&str, f64)> = r
            .iter()
            .filter(|(k, _)| k.starts_with("lines.") && k.contains(".m"))
            .map(|(k, _)| (k.as_str(), -0.7))
            .collect();
        let f = run(&changes);
        assert_eq!(f[0].kind.as_str(), "transfer-path", "{f:#?}");
        assert!(f[0].detail.as_deref().unwrap().contains("mesh harmonics"));
    }

    /// Every mesh line up together (wear's pattern) leaves the change no part's; a shaft's
    /// line or a bearing's makes it that part's.
    #[test]
    fn only_a_part_leading_the_change_makes_it_one_parts() {
        let r = reference();
        let up: Vec<(&str, f64)> = r
            .iter()
            .filter(|(k, _)| k.starts_with("lines.mesh."))
            .map(|(k, _)| (k.as_str(), 0.7))
            .collect();
        let f = run(&up);
        assert!(f.iter().any(|x| x.kind == FindingKind::MeshLines), "{f:#?}");
        assert!(mostly_one_part(&f).is_none(), "{f:#?}");
        let f = run(&[("shaft.in.1x", 1.5)]);
        assert_eq!(
            mostly_one_part(&f).map(|x| x.kind),
            Some(FindingKind::Shaft)
        );
        let f = run(&[("bearing.b-out.bpfi", 1.5), ("env.none", 0.3)]);
        assert_eq!(
            mostly_one_part(&f).map(|x| x.kind),
            Some(FindingKind::Bearing)
        );
        assert!(mostly_one_part(&[]).is_none());
    }

    /// A change in a metric no candidate fits is unexplained.
    #[test]
    fn a_change_no_part_makes_is_unexplained() {
        let r = reference();
        let mut f: Vec<(&str, f64)> = r.iter().map(|(k, v)| (k.as_str(), *v)).collect();
        f.push(("stat.kurtosis", 1.0));
        let out = findings(&score(&f, &[("stat.kurtosis", 1.5)]), &parts(), None);
        assert_eq!(out.len(), 1, "{out:#?}");
        assert_eq!(out[0].kind.as_str(), "unexplained");
        // In words, not the feature's code.
        let summary = &out[0].summary;
        assert!(
            summary.contains("the record's kurtosis (how impulsive it is)"),
            "{summary}"
        );
        assert!(!summary.contains("stat.kurtosis"), "{summary}");
    }
}
