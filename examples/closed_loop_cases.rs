//! Prints the closed-loop table of `docs/closed-loop.md`: virtual-rig records with one effect
//! each (known to this program only), calibrated by `gearwear::closed_loop::calibrate`. The
//! "unexplained" column lists the residual's lines and the level-over-time features.
//!
//! `cargo run --release --example closed_loop_cases [-- --json DIR]`

use gearwear::closed_loop::virtual_rig::{RigEffects, RigSpec, generate};
use gearwear::closed_loop::{CalibrateOptions, CalibrationReport, calibrate};
use gearwear::signature::SignatureTable;
use gearwear::signature::table::DEFAULT_TABLE_PATH;

/// The cases: a name, the effects the rig puts in, the SNR (dB).
fn cases() -> Vec<(&'static str, RigEffects, f64)> {
    vec![
        ("clean", RigEffects::default(), 20.0),
        (
            "eccentricity e=0.1",
            RigEffects {
                eccentricity: Some(0.1),
                ..Default::default()
            },
            20.0,
        ),
        (
            "path resonance 1.6 f1, ζ=0.05",
            RigEffects {
                resonance: Some((1.6, 0.05)),
                ..Default::default()
            },
            20.0,
        ),
        (
            "planetary error 3.0",
            RigEffects {
                planetary: Some(3.0),
                ..Default::default()
            },
            20.0,
        ),
        (
            "tone 1.27 f1 −20 dB (not in library)",
            RigEffects {
                tone: Some((1.27, -20.0)),
                ..Default::default()
            },
            20.0,
        ),
        (
            "speed wander ±1 % at 0.01 f1 (not in library)",
            RigEffects {
                speed_wander: Some((0.01, 0.01)),
                ..Default::default()
            },
            20.0,
        ),
        ("broadband noise, SNR 10 dB", RigEffects::default(), 10.0),
        (
            "noise bursts 4 × 10 ms, +6 dB (not in library)",
            RigEffects {
                bursts: Some((4, 6.0)),
                ..Default::default()
            },
            20.0,
        ),
    ]
}

/// The environment variable `k` parsed, or `d`.
fn env_f64(k: &str, d: f64) -> f64 {
    std::env::var(k)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(d)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let json_dir = args
        .iter()
        .position(|a| a == "--json")
        .and_then(|i| args.get(i + 1).cloned());
    let table = SignatureTable::load(std::path::Path::new(DEFAULT_TABLE_PATH))?;
    let cfg = table.gearbox().clone();
    let ea = env_f64("CL_EA", 0.3);
    let om = env_f64("CL_OMEGA", 1.0);
    println!(
        "| case | effect found | unexplained (f/f1: dB) | error before (dB) | error after (dB) | ea before | ea after | ea truth | planetary before/after/truth | seconds |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for (k, (name, effects, snr)) in cases().iter().enumerate() {
        let spec = RigSpec {
            ea,
            omega1: om,
            sample_rate: 16000.0,
            duration: 0.6,
            gain: 10f64.powf((k as f64 * 0.7) % 3.0 - 1.5),
            snr_db: *snr,
            seed: 1000 + k as u64,
            effects: *effects,
        };
        let t = std::time::Instant::now();
        let rec = generate(&cfg, &spec)?;
        let rep = calibrate(&rec, &table, &CalibrateOptions::default())?;
        let secs = t.elapsed().as_secs_f64();
        let truth_pl = effects
            .planetary
            .or(cfg.planetary_baseline())
            .unwrap_or(0.0);
        print_row(name, &rep, ea, truth_pl, secs);
        if std::env::var("CL_VERBOSE").is_ok() {
            print_verbose(&rep);
        }
        if let Some(dir) = &json_dir {
            std::fs::create_dir_all(dir)?;
            std::fs::write(
                format!("{dir}/case{k}.json"),
                serde_json::to_string_pretty(&rep)?,
            )?;
        }
    }
    Ok(())
}

/// The table's row of a case (`ea`, `truth_pl`: the true wear and planetary error).
fn print_row(name: &str, rep: &CalibrationReport, ea: f64, truth_pl: f64, secs: f64) {
    let found: Vec<String> = rep
        .effects
        .iter()
        .map(|e| {
            let p: Vec<String> = e
                .parameters
                .iter()
                .map(|(k, v)| format!("{k}={v:.3}"))
                .collect();
            format!("{} ({})", e.name, p.join(", "))
        })
        .collect();
    let un: Vec<String> = rep
        .unexplained
        .iter()
        .map(|u| format!("{} {:.3}: {:+.1}", u.kind, u.frequency_ratio, u.size_db))
        .chain(
            rep.unexplained_in_time
                .iter()
                .map(|t| match t.times_s.len() {
                    0 => format!("{}: {:+.1} dB", t.kind, t.size_db),
                    n => format!("{} ×{n}: {:+.1} dB", t.kind, t.size_db),
                }),
        )
        .collect();
    println!(
        "| {name} | {} | {} | {:.2} | {:.2} | {:.3} | {:.3} | {:.3} | {:.2}/{:.2}/{:.2} | {secs:.1} |",
        if found.is_empty() {
            "none".into()
        } else {
            found.join("; ")
        },
        if un.is_empty() {
            "—".into()
        } else {
            un.join("; ")
        },
        rep.error_before,
        rep.error_after,
        rep.wear_before.ea,
        rep.wear_after.ea,
        ea,
        rep.wear_before.planetary,
        rep.wear_after.planetary,
        truth_pl,
    );
}

/// `CL_VERBOSE`: the fit's null and margin, and every candidate, on stderr.
fn print_verbose(rep: &CalibrationReport) {
    eprintln!(
        "   J_eff {:.1}, null spread {:.1}, claim margin {:.1}; wear after {:.3} [{:.3}, {:.3}]",
        rep.effective_points,
        rep.null_spread,
        rep.claim_margin,
        rep.wear_after.ea,
        rep.wear_after.ea_lower,
        rep.wear_after.ea_upper
    );
    for c in &rep.candidates {
        eprintln!(
            "   {:40} err {:6.2} dBIC {:8.1} fingerprint share {:5.2} eligible {}{}",
            c.name,
            c.error_db,
            c.delta_bic,
            c.fingerprint_share,
            c.eligible,
            if c.refused.is_empty() {
                String::new()
            } else {
                format!(" (refused: {})", c.refused.join("; "))
            }
        );
    }
}
