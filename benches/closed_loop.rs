//! The closed loop on virtual-rig records with effects drawn at random over wide ranges (not a
//! timing benchmark): the confusion matrix, error and wear before/after of `docs/closed-loop.md`.
//!
//! `cargo bench --bench closed_loop` (env: `CL_N` records, default 110 (22 min on the shared 2-core machine); `CL_SEED` base seed,
//! default 2 — seed 1 is the one thresholds may be looked at on, report on another; `CL_OUT`
//! the path of the JSON rows, default `bench/closed_loop.json` under the target directory
//! (`CARGO_TARGET_DIR`, else `target/`); `CL_KINDS` a comma list to run only some kinds; `CL_NULL_Z`, `CL_MARGIN` override
//! `CalibrateOptions::null_z` and `bic_margin`, for tuning on seed 1 only; `CL_CANDIDATE_SEEDS=true`
//! (or `false`) sets `CalibrateOptions::candidate_seeds`, `CL_MEAN_SEEDS=true` `mean_seeds`; `CL_INDICATORS_ONLY=1`
//! skips the closed loop and stores, as each row's `error` text, the record's tacho-less FM4
//! and kurtosis, the drawn tooth damage and speed wander, visibility, each shaft's TSA FM4 and
//! the tracked speed's relative standard deviation — every row then counts as failed in the
//! report). Rows carry `fm4`, `kurtosis`, `tsa_fm4` and `speed_std` (the diagnosis's condition
//! indicators, per-shaft TSA FM4 and its order tracking's speed spread) besides the closed
//! loop's answer, and `ea_refit`, `ea_profile`, `method` (the wear refit, the profile's vertex,
//! `wear_after`'s method); `wander_rate`, `truth_shaft`, `named_shaft`, the report's
//! `sidebands` and a pair's `member_visible`. `CL_INDICES=3,17` runs only those records of the
//! set (same draws) and prints each one's `RigSpec`. `CL_SEEDS=18,19` runs `CL_N` records of
//! each base seed in one run with one report (rows carry `seed` and `index`).
//!
//! Every record: ea ~ U[0.1, 1], Ω1 ~ U over the table's band, gain log-uniform 1e-2 … 1e2,
//! white noise at SNR ~ U[20, 30] dB, 16 kHz, 0.6 s, random initial state. Kinds cycle in a fixed
//! order; each draws its effect's parameters:
//!
//! | kind | draw |
//! | --- | --- |
//! | clean | nothing |
//! | path-resonance | peaking mode, ρ log-U[0.2, 3] f1, Q ~ U[2, 30] (ζ = 1/2Q), peak gain g ~ U[1, 10] |
//! | shaft-modulation | depth m ~ U[0.05, 0.5] on the input or the stage-1 gear shaft (½ each): sideband amplitude m·ea/2 |
//! | planetary-wear | p log-U[0.3, 5] (baseline 0.1) |
//! | tooth-damage | stiffness loss ~ U[0.1, 0.8] on the stage-1 pinion or gear (½ each) |
//! | pair | shaft modulation or tooth damage (drawn as above) + a path resonance |
//! | speed-wander | δ ~ U[0.2, 2] %, rate ~ U[0.003, 0.03] f1 |
//! | tone | at U[0.1, 2.4] f1 (not synchronous), level U[−30, −5] dB re f1, 1–3 harmonics |
//! | mains-hum | 50 or 60 Hz, level U[−35, −10] dB re f1, odd harmonics 3, 5, 7 |
//! | noise-bursts | 2–8 bursts of 10 ms, level U[0, 10] dB re the signal RMS |
//! | gain-drift | gain changes by U[10, 50] % over the record |
//!
//! **Visible** ("changes the spectrum by more than the noise"): the record's log spectrum on the
//! closed loop's grid (at the true f1) differs from the same record without the effect (same
//! seeds) by more than it differs from the same record with the effect and another seed
//! (another initial state and noise): `std(M − M_without) > std(M − M_other seed)` (std: the
//! RMS about the mean difference, so that a level change alone does not count). A pair's
//! members are judged one at a time the same way (the record against the same record without
//! that member, the other kept): `member_visible`.
//!
//! That one-draw measure is a coin toss for a small effect wherever the model is chaotic: any
//! change of the model, however small, sends the trajectory elsewhere, so "the same record
//! without the effect" is in effect another draw, and `v_effect ≈ v_noise` either way
//! (`CL_EFFECT_SCALE`, below, measures it); hence the **K-draw measure**, the primary
//! one (`visible_k`): K = `CL_VIS_DRAWS` (default 4) records with the effect (the record itself
//! and K − 1 other seeds) and K without it (K other seeds), log spectra on the same grid; with
//! `D = std(mean_with − mean_without)` and `s²` the per-point variance between draws, pooled
//! over both sets and averaged over the grid, the effect's own change is
//! `d = sqrt(max(0, D² − (2/K) s²))` (the part of D the draws' scatter does not explain), and
//! the record is visible when `d > √2 s`: the effect changes the expected spectrum by more than
//! two records of the same gearbox differ (the one-draw measure's threshold where it works, a
//! periodic model with the same seeds). Rows carry `vis_d`, `vis_s`, `visible_k` and a pair's
//! `member_visible_k`; the report gives every visibility figure under both measures.
//!
//! `CL_EFFECT_SCALE=x` scales every drawn effect (resonance peak gain, modulation depth,
//! planetary error above the baseline, stiffness loss, wander depth, drift; tones, hum and
//! bursts by 20 log10 x dB): at x = 0.01 no effect should be visible. `CL_VISIBILITY_ONLY=1`
//! computes the visibility alone (no diagnosis, no closed loop) and prints visible counts per
//! kind under both measures.
//!
//! An unexplained feature is a line of the residual (`unexplained`) or a feature of the
//! record's level over time (`unexplained_in_time`: bursts, impacts, level drift);
//! rows carry the count of both and `in_time`, the latter's kinds. `CL_LEVEL_ONLY=1` draws the
//! records and prints one `LEVEL` line each (the level trace's scatter, burst threshold,
//! highest window, runs, drift and its standard error, the time features) and nothing else:
//! seconds for 528 records.

#[path = "closed_loop/draw.rs"]
mod draw;
#[path = "common/out.rs"]
mod out;
#[path = "closed_loop/report.rs"]
mod report;
#[path = "closed_loop/row.rs"]
mod row;
#[path = "closed_loop/run.rs"]
mod run;
#[path = "closed_loop/settings.rs"]
mod settings;
#[path = "closed_loop/visibility.rs"]
mod visibility;

use std::time::Instant;

use gearwear::signature::SignatureTable;
use rayon::prelude::*;

use row::Row;
use run::Bench;
use settings::{Settings, flag};

fn main() {
    let table_path = concat!(env!("CARGO_MANIFEST_DIR"), "/signatures/model_a_accel.json");
    let table = SignatureTable::load(std::path::Path::new(table_path)).expect("table loads");
    let bench = Bench::new(Settings::from_env(), table);
    let t_all = Instant::now();
    let rows: Vec<Row> = bench
        .set
        .records()
        .into_par_iter()
        .map(|(base, i)| bench.record(base, i))
        .collect();
    let wall = t_all.elapsed().as_secs_f64();
    // Rows: `CL_OUT`, else `bench/closed_loop.json` under the build's target directory.
    let out = out::out_path("CL_OUT", "closed_loop.json");
    std::fs::write(&out, serde_json::to_string_pretty(&rows).expect("json")).expect("write");
    eprintln!("rows: {}", out.display());
    let set = &bench.set;
    if flag("CL_VISIBILITY_ONLY") {
        report::report_visibility(&rows, set.n, &set.seeds, set.scale, set.k_draws);
    } else {
        report::report(&rows, set.n, &set.seeds, wall);
    }
}
