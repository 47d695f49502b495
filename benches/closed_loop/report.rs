//! The benchmark's report (markdown tables on stdout): the confusion matrix, the issue's
//! targets, error and wear per kind and per effect size, the fitted resonances; or, for
//! `CL_VISIBILITY_ONLY`, visible records per kind.

use std::collections::BTreeMap;

use super::row::Row;
use super::settings::{KINDS, library};

/// `CL_VISIBILITY_ONLY=1`: visible records per kind under both measures.
pub fn report_visibility(rows: &[Row], n: usize, seeds: &[u64], scale: f64, k_draws: usize) {
    println!(
        "visibility: {n} records a seed, base seeds {seeds:?}, effect scale {scale}, K = {k_draws} draws\n"
    );
    println!("| kind | n | visible, one draw | visible, K draws | median d / s |");
    println!("| --- | --- | --- | --- | --- |");
    let ok: Vec<&Row> = rows.iter().filter(|r| r.error.is_none()).collect();
    for kind in KINDS.iter().filter(|k| **k != "clean") {
        let rs: Vec<&&Row> = ok.iter().filter(|r| r.kind == *kind).collect();
        if rs.is_empty() {
            continue;
        }
        let mut ratio: Vec<f64> = rs.iter().map(|r| r.vis_d / r.vis_s).collect();
        ratio.sort_by(f64::total_cmp);
        println!(
            "| {kind} | {} | {} | {} | {:.2} |",
            rs.len(),
            pct(rs.iter().filter(|r| r.visible).count(), rs.len()),
            pct(rs.iter().filter(|r| r.visible_k).count(), rs.len()),
            ratio[ratio.len() / 2]
        );
    }
    for r in rows.iter().filter(|r| r.error.is_some()) {
        println!("failed: {} {:?}", r.kind, r.error);
    }
}

/// `a` of `b` as a percentage, with the counts.
fn pct(a: usize, b: usize) -> String {
    if b == 0 {
        "—".into()
    } else {
        format!("{:.0} % ({a}/{b})", 100.0 * a as f64 / b as f64)
    }
}

/// The report of a run: `n` records a seed of `seeds`, `wall` seconds in all.
pub fn report(rows: &[Row], n: usize, seeds: &[u64], wall: f64) {
    let ok: Vec<&Row> = rows.iter().filter(|r| r.error.is_none()).collect();
    println!(
        "closed-loop benchmark: {n} records a seed, base seeds {seeds:?}, {} failed, wall {:.0} s, mean {:.1} s a record (one thread)\n",
        rows.len() - ok.len(),
        wall,
        ok.iter().map(|r| r.seconds).sum::<f64>() / ok.len().max(1) as f64
    );
    confusion(&ok);
    targets(&ok);
    per_kind(&ok);
    per_size(&ok);
    resonance_fit(&ok);
    let failed: Vec<&Row> = rows.iter().filter(|r| r.error.is_some()).collect();
    for r in failed {
        println!("failed: {} {:?}", r.kind, r.error);
    }
}

/// A record's answer as the confusion matrix counts it: the effects named (sorted, joined by
/// `+`), else `unexplained` or `none`.
fn answer(r: &Row) -> String {
    if !r.named.is_empty() {
        let mut v = r.named.clone();
        v.sort();
        v.join("+")
    } else if r.unexplained > 0 {
        "unexplained".into()
    } else {
        "none".into()
    }
}

/// Whether a record's answer names exactly its truth.
fn named_right(r: &Row) -> bool {
    let mut a = r.named.clone();
    a.sort();
    let mut t = r.truth.clone();
    t.sort();
    a == t
}

/// The median of the finite values (NaN: none).
fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Confusion matrix: truth kind × what was named (or unexplained / none).
fn confusion(ok: &[&Row]) {
    let mut cols: Vec<String> = ok.iter().map(|r| answer(r)).collect();
    cols.sort();
    cols.dedup();
    println!("| truth \\ answer | {} |", cols.join(" | "));
    println!("| --- |{}", " --- |".repeat(cols.len()));
    for kind in KINDS {
        let rs: Vec<&&Row> = ok.iter().filter(|r| r.kind == kind).collect();
        if rs.is_empty() {
            continue;
        }
        let cells: Vec<String> = cols
            .iter()
            .map(|c| {
                let k = rs.iter().filter(|r| answer(r) == *c).count();
                if k == 0 { "·".into() } else { k.to_string() }
            })
            .collect();
        println!("| {kind} ({}) | {} |", rs.len(), cells.join(" | "));
    }
    println!();
}

/// The targets, one row each.
fn targets(ok: &[&Row]) {
    println!("| target | measured | issue's target |");
    println!("| --- | --- | --- |");
    library_targets(ok);
    pair_members(ok);
    other_targets(ok);
    println!();
}

/// The targets of the library's effects.
fn library_targets(ok: &[&Row]) {
    let lib_vis: Vec<&&Row> = ok
        .iter()
        .filter(|r| library(&r.kind) && r.visible_k)
        .collect();
    let lib_vis1: Vec<&&Row> = ok
        .iter()
        .filter(|r| library(&r.kind) && r.visible)
        .collect();
    let lib_all: Vec<&&Row> = ok.iter().filter(|r| library(&r.kind)).collect();
    println!(
        "| library effect named exactly (visible records, K-draw measure) | {} | ≥ 90 % |",
        pct(
            lib_vis.iter().filter(|r| named_right(r)).count(),
            lib_vis.len()
        )
    );
    println!(
        "| library effect named exactly (visible records, one-draw measure) | {} | — |",
        pct(
            lib_vis1.iter().filter(|r| named_right(r)).count(),
            lib_vis1.len()
        )
    );
    effect_by_effect(&lib_all);
    println!(
        "| library records with an effect claimed that is not in the truth | {} | — |",
        pct(
            lib_all
                .iter()
                .filter(|r| r.named.iter().any(|x| !r.truth.contains(x)))
                .count(),
            lib_all.len()
        )
    );
    println!(
        "| library effect named exactly (all records, visible or not) | {} | — |",
        pct(
            lib_all.iter().filter(|r| named_right(r)).count(),
            lib_all.len()
        )
    );
}

/// Effect by effect (the issue's target reads "a library effect named in ≥ 90 % of records
/// where it changes the spectrum by more than the noise"): a single effect when its record is
/// visible, each pair member when visible on its own (K-draw measure); and, over the records
/// holding at least one such effect, the answer names all of them and nothing else.
fn effect_by_effect(lib_all: &[&&Row]) {
    let visible_effects = |r: &Row| -> Vec<String> {
        if r.kind == "pair" {
            r.member_visible_k
                .iter()
                .filter(|m| m.1)
                .map(|m| m.0.clone())
                .collect()
        } else if r.visible_k {
            r.truth.clone()
        } else {
            Vec::new()
        }
    };
    let effects: Vec<bool> = lib_all
        .iter()
        .flat_map(|r| {
            visible_effects(r)
                .into_iter()
                .map(|v| r.named.contains(&v))
                .collect::<Vec<_>>()
        })
        .collect();
    println!(
        "| visible library effects named, effect by effect (K-draw measure; pair members on their own) | {} | ≥ 90 % |",
        pct(effects.iter().filter(|b| **b).count(), effects.len())
    );
    let with_visible: Vec<(&&Row, Vec<String>)> = lib_all
        .iter()
        .map(|r| (*r, visible_effects(r)))
        .filter(|(_, v)| !v.is_empty())
        .collect();
    println!(
        "| … records with a visible effect: all visible effects named and nothing outside the truth | {} | — |",
        pct(
            with_visible
                .iter()
                .filter(|(r, vis)| {
                    vis.iter().all(|v| r.named.contains(v))
                        && r.named.iter().all(|x| r.truth.contains(x))
                })
                .count(),
            with_visible.len()
        )
    );
}

/// Pairs member by member: each member that is visible on its own, named or not.
fn pair_members(ok: &[&Row]) {
    for (label, k_measure) in [("K-draw", true), ("one-draw", false)] {
        let members: Vec<(bool, bool)> = ok
            .iter()
            .filter(|r| r.kind == "pair")
            .flat_map(|r| {
                let vis = if k_measure {
                    &r.member_visible_k
                } else {
                    &r.member_visible
                };
                vis.iter()
                    .map(|(n, v)| (*v, r.named.contains(n)))
                    .collect::<Vec<_>>()
            })
            .collect();
        println!(
            "| pair members visible on their own ({label} measure): named | {} | — |",
            pct(
                members.iter().filter(|m| m.0 && m.1).count(),
                members.iter().filter(|m| m.0).count()
            )
        );
    }
}

/// The targets of the records without a library effect, and the error and wear before and
/// after.
fn other_targets(ok: &[&Row]) {
    let non: Vec<&&Row> = ok
        .iter()
        .filter(|r| !library(&r.kind) && r.kind != "clean")
        .collect();
    let non_ok = |r: &Row| r.named.is_empty() && (r.unexplained > 0 || !r.visible_k);
    let non_ok1 = |r: &Row| r.named.is_empty() && (r.unexplained > 0 || !r.visible);
    let clean: Vec<&&Row> = ok.iter().filter(|r| r.kind == "clean").collect();
    let err_ok = ok
        .iter()
        .filter(|r| r.error_after <= r.error_before + 1e-9)
        .count();
    let wear_ok = ok
        .iter()
        .filter(|r| (r.ea_after - r.ea).abs() <= (r.ea_before - r.ea).abs() + 1e-9)
        .count();
    let changed: Vec<&&Row> = ok.iter().filter(|r| !r.named.is_empty()).collect();
    let wear_ok_changed = changed
        .iter()
        .filter(|r| (r.ea_after - r.ea).abs() <= (r.ea_before - r.ea).abs() + 1e-9)
        .count();
    println!(
        "| non-library effect: no library effect claimed and (unexplained reported or not visible, K-draw measure) | {} | ≥ 80 % |",
        pct(non.iter().filter(|r| non_ok(r)).count(), non.len())
    );
    println!(
        "| non-library effect: no library effect claimed and (unexplained reported or not visible, one-draw measure) | {} | — |",
        pct(non.iter().filter(|r| non_ok1(r)).count(), non.len())
    );
    println!(
        "| non-library effect: no library effect claimed | {} | — |",
        pct(non.iter().filter(|r| r.named.is_empty()).count(), non.len())
    );
    println!(
        "| non-library effect, visible (K-draw measure): unexplained reported and nothing claimed | {} | — |",
        pct(
            non.iter()
                .filter(|r| r.visible_k && r.named.is_empty() && r.unexplained > 0)
                .count(),
            non.iter().filter(|r| r.visible_k).count()
        )
    );
    println!(
        "| clean: no effect claimed | {} | ≥ 90 % |",
        pct(
            clean.iter().filter(|r| r.named.is_empty()).count(),
            clean.len()
        )
    );
    println!(
        "| model error after ≤ before | {} | every record |",
        pct(err_ok, ok.len())
    );
    println!(
        "| wear error after ≤ before | {} | ≥ 90 % |",
        pct(wear_ok, ok.len())
    );
    println!(
        "| … of records where an effect was claimed (wear refitted) | {} | — |",
        pct(wear_ok_changed, changed.len())
    );
}

/// Per kind: error and wear before/after, interval coverage.
fn per_kind(ok: &[&Row]) {
    println!(
        "| kind | n | visible (K draws / one draw) | named exactly | error before → after (dB, median) | wear MAE before → after | 90 % interval covers ea (before / after) | after interval width (median) |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    for kind in KINDS {
        let rs: Vec<&&Row> = ok.iter().filter(|r| r.kind == kind).collect();
        if rs.is_empty() {
            continue;
        }
        let k = rs.len();
        let mae = |f: &dyn Fn(&Row) -> f64| {
            rs.iter().map(|r| (f(r) - r.ea).abs()).sum::<f64>() / k as f64
        };
        let cov_b = rs
            .iter()
            .filter(|r| r.ea_before_lower <= r.ea && r.ea <= r.ea_before_upper)
            .count();
        let cov_a = rs
            .iter()
            .filter(|r| r.ea_lower <= r.ea && r.ea <= r.ea_upper)
            .count();
        println!(
            "| {kind} | {k} | {} | {} | {:.2} → {:.2} | {:.3} → {:.3} | {} / {} | {:.3} |",
            if kind == "clean" {
                "—".into()
            } else {
                format!(
                    "{} / {}",
                    rs.iter().filter(|r| r.visible_k).count(),
                    rs.iter().filter(|r| r.visible).count()
                )
            },
            if library(kind) {
                rs.iter().filter(|r| named_right(r)).count().to_string()
            } else {
                "—".into()
            },
            median(rs.iter().map(|r| r.error_before).collect()),
            median(rs.iter().map(|r| r.error_after).collect()),
            mae(&|r| r.ea_before),
            mae(&|r| r.ea_after),
            pct(cov_b, k),
            pct(cov_a, k),
            median(rs.iter().map(|r| r.ea_upper - r.ea_lower).collect()),
        );
    }
    println!();
}

/// Per effect size: library kinds in three bins of their size measure.
fn per_size(ok: &[&Row]) {
    println!(
        "| kind | size measure | bin | n | visible (K draws) | named exactly | named exactly when visible |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    let measures: BTreeMap<&str, &str> = [
        ("path-resonance", "peak gain g"),
        ("shaft-modulation", "modulation depth m"),
        ("planetary-wear", "planetary error p (b)"),
        ("tooth-damage", "stiffness loss"),
        ("pair", "modulation depth / stiffness loss"),
        ("tone", "level dB re f1"),
        ("mains-hum", "level dB re f1"),
    ]
    .into_iter()
    .collect();
    for (kind, measure) in &measures {
        let mut rs: Vec<&&Row> = ok.iter().filter(|r| r.kind == *kind).collect();
        if rs.is_empty() {
            continue;
        }
        rs.sort_by(|a, b| a.size.total_cmp(&b.size));
        for b in 0..3 {
            let lo = b * rs.len() / 3;
            let hi = (b + 1) * rs.len() / 3;
            let part = &rs[lo..hi];
            if part.is_empty() {
                continue;
            }
            let vis: Vec<&&&Row> = part.iter().filter(|r| r.visible_k).collect();
            let right = |r: &Row| {
                if library(kind) {
                    named_right(r)
                } else {
                    r.named.is_empty() && r.unexplained > 0
                }
            };
            println!(
                "| {kind} | {measure} | {:.3} … {:.3} | {} | {} | {} | {} |",
                part[0].size,
                part[part.len() - 1].size,
                part.len(),
                vis.len(),
                part.iter().filter(|r| right(r)).count(),
                pct(vis.iter().filter(|r| right(r)).count(), vis.len()),
            );
        }
    }
    println!(
        "(for tone and mains-hum, \"named exactly\" means: nothing claimed and unexplained reported)\n"
    );
}

/// The fitted resonances against the truth, over the records where a path resonance was named.
fn resonance_fit(ok: &[&Row]) {
    let res: Vec<&&Row> = ok.iter().filter(|r| r.rho_ratio.is_some()).collect();
    if !res.is_empty() {
        let within = |tol: f64| {
            res.iter()
                .filter(|r| (r.rho_ratio.unwrap() - 1.0).abs() <= tol)
                .count()
        };
        println!(
            "path resonance named ({} records): fitted frequency within 5 % of the truth {}, within 20 % {}; damping within a factor 2 {}",
            res.len(),
            pct(within(0.05), res.len()),
            pct(within(0.2), res.len()),
            pct(
                res.iter()
                    .filter(|r| {
                        let z = r.zeta_ratio.unwrap();
                        (0.5..=2.0).contains(&z)
                    })
                    .count(),
                res.len()
            )
        );
    }
}
