//! How well the trend finds the time to alarm on simulated degradations, and how often it
//! calls a flat history a trend.
//!
//! `cargo run --release --example trend_eval`. Env: `TREND_EVAL_RUNS` runs of each kind
//! (default 40), `TREND_EVAL_SEED` the seed base (default 2026: the evaluation seeds; develop
//! on others).
//!
//! A run is one machine: 10 days of records, 4 a day (every 6 h), each a 1 s, 25.6 kHz record
//! of the paper rig at Ω1 = 1 from the `gearwear synth` generator (20 dB white noise, the run's
//! own sensor gain, log-uniform over ×0.1 … ×10) with its own seed, diagnosed by the committed
//! signature table with the shaft rate given (`?shaft_hz=30`), as the service does; a record
//! whose model fit is poor has no wear figure and no point, as in the service. The wear series
//! is fitted by `gearwear::trend` with the service's options and thresholds (warning 0.5,
//! alarm 0.8).
//! * **degradation**: ea rises linearly over 60 days from `a ~ U[0.15, 0.35]` to
//!   `b ~ U[0.85, 1.0]`; the truth is the time from the latest record (day 9.75) to the day ea
//!   reaches 0.8. Scored: a projection exists and its `days` is within 20 % of the truth; its
//!   90 % interval covers the truth.
//! * **flat**: ea constant at `c ~ U[0.15, 0.7]`; scored: "no significant trend".

use gearwear::assessment::Thresholds;
use gearwear::closed_loop::virtual_rig::{RigSpec, generate};
use gearwear::diagnosis::{DiagnoseOptions, Matcher, diagnose_with};
use gearwear::gearbox::Gearbox;
use gearwear::signature::{SignatureTable, SplitMix64, mix_seed};
use gearwear::trend::{self, Sample, TrendOptions};
use rayon::prelude::*;

/// Records a day, and the days of history when the projection is scored.
const PER_DAY: usize = 4;
const DAYS: usize = 10;
/// The degradation runs over this many days.
const LIFE_DAYS: f64 = 60.0;

fn env<T: std::str::FromStr>(k: &str, d: T) -> T {
    std::env::var(k)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(d)
}

struct Rig {
    gb: Gearbox,
    table: SignatureTable,
    matcher: Matcher,
    opts: DiagnoseOptions,
}

impl Rig {
    /// The wear figure the service would show for a record at `ea` (None: poor fit).
    fn wear(&self, ea: f64, gain: f64, seed: u64) -> Option<f64> {
        let rec = generate(
            &self.gb,
            &RigSpec {
                ea,
                omega1: 1.0,
                sample_rate: 25_600.0,
                duration: 1.0,
                gain,
                snr_db: 20.0,
                seed,
                effects: Default::default(),
            },
        )
        .ok()?;
        let d = diagnose_with(&rec, &self.table, &self.matcher, &self.opts).ok()?;
        (!d.fit.inflated).then_some(d.wear_degree.estimate)
    }

    /// The run's wear series: `ea_at(day)` sampled every 6 h for [`DAYS`] days.
    fn series(&self, run_seed: u64, gain: f64, ea_at: impl Fn(f64) -> f64) -> Vec<Sample> {
        (0..DAYS * PER_DAY)
            .filter_map(|k| {
                let t = k as f64 / PER_DAY as f64;
                let v = self.wear(ea_at(t), gain, mix_seed(&[run_seed, k as u64]))?;
                Some(Sample {
                    t_days: t,
                    value: v,
                })
            })
            .collect()
    }
}

/// One degradation run: (projected days, 90 % interval, truth days), or None without a
/// projection.
struct Outcome {
    truth: f64,
    days: Option<f64>,
    interval: [Option<f64>; 2],
    points: usize,
}

fn degradation(rig: &Rig, base: u64, run: u64, th: &Thresholds) -> Outcome {
    let seed = mix_seed(&[base, 0xDE6, run]);
    let mut rng = SplitMix64::new(seed);
    let (a, b) = (rng.range(0.15, 0.35), rng.range(0.85, 1.0));
    let gain = 10f64.powf(rng.range(-1.0, 1.0));
    let ea_at = |t: f64| a + (b - a) * t / LIFE_DAYS;
    let pts = rig.series(seed, gain, ea_at);
    let t_end = pts.last().map_or(0.0, |p| p.t_days);
    let truth = LIFE_DAYS * (th.alarm - a) / (b - a) - t_end;
    let fit = trend::fit(&pts, &TrendOptions::default());
    let c = fit.as_ref().and_then(|f| f.crossing(th.alarm));
    Outcome {
        truth,
        days: c.as_ref().map(|c| c.days),
        interval: c.map_or([None, None], |c| c.interval_90),
        points: pts.len(),
    }
}

/// One flat run: is it called a significant trend?
fn flat(rig: &Rig, base: u64, run: u64) -> (bool, usize) {
    let seed = mix_seed(&[base, 0xF1A7, run]);
    let mut rng = SplitMix64::new(seed);
    let c = rng.range(0.15, 0.7);
    let gain = 10f64.powf(rng.range(-1.0, 1.0));
    let pts = rig.series(seed, gain, |_| c);
    let sig = trend::fit(&pts, &TrendOptions::default()).is_some_and(|f| f.fit.significant);
    (sig, pts.len())
}

fn pct(k: usize, n: usize) -> f64 {
    100.0 * k as f64 / n.max(1) as f64
}

fn main() {
    let runs: u64 = env("TREND_EVAL_RUNS", 40);
    let base: u64 = env("TREND_EVAL_SEED", 2026);
    let gb = Gearbox::paper_rig();
    let table_path = concat!(env!("CARGO_MANIFEST_DIR"), "/signatures/model_a_accel.json");
    let table = SignatureTable::load(std::path::Path::new(table_path)).expect("table loads");
    let opts = DiagnoseOptions {
        shaft_hz: Some(gb.reference_frequency_hz() / gb.f1_hz(1.0)),
        ..DiagnoseOptions::default()
    };
    let matcher = Matcher::new(&table, &opts).expect("matcher");
    let rig = Rig {
        gb,
        table,
        matcher,
        opts,
    };
    let th = Thresholds::default();
    let t0 = std::time::Instant::now();

    let outs: Vec<Outcome> = (0..runs)
        .into_par_iter()
        .map(|r| degradation(&rig, base, r, &th))
        .collect();
    let n = outs.len();
    let projected = outs.iter().filter(|o| o.days.is_some()).count();
    let within = outs
        .iter()
        .filter(|o| o.days.is_some_and(|d| (d - o.truth).abs() <= 0.2 * o.truth))
        .count();
    // The looser reading: the alarm date within 20 % of the degradation's age at the truth.
    let within_date = outs
        .iter()
        .filter(|o| {
            o.days
                .is_some_and(|d| (d - o.truth).abs() <= 0.2 * (o.truth + (DAYS as f64 - 0.25)))
        })
        .count();
    let covered = outs
        .iter()
        .filter(|o| {
            o.days.is_some()
                && o.interval[0].is_some_and(|lo| lo <= o.truth)
                && o.interval[1].is_none_or(|hi| o.truth <= hi)
        })
        .count();
    let mut rel: Vec<f64> = outs
        .iter()
        .filter_map(|o| o.days.map(|d| (d - o.truth) / o.truth))
        .collect();
    rel.sort_by(f64::total_cmp);
    let med_rel = rel.get(rel.len() / 2).copied().unwrap_or(f64::NAN);
    let pts_min = outs.iter().map(|o| o.points).min().unwrap_or(0);

    let flats: Vec<(bool, usize)> = (0..runs)
        .into_par_iter()
        .map(|r| flat(&rig, base, r))
        .collect();
    let no_trend = flats.iter().filter(|f| !f.0).count();

    println!(
        "trend_eval: {runs} degradation + {runs} flat runs, seed base {base}, {DAYS} days × {PER_DAY} records/day ({:.0} s)",
        t0.elapsed().as_secs_f64()
    );
    println!(
        "degradation: projection given {projected}/{n} ({:.0} %); alarm time within 20 % of the truth (from the latest record) {within}/{n} ({:.0} %); alarm date within 20 % of the degradation's age {within_date}/{n} ({:.0} %); 90 % interval covers the truth {covered}/{n} ({:.0} %); median relative error {:+.1} %; fewest wear points in a run {pts_min}/{}",
        pct(projected, n),
        pct(within, n),
        pct(within_date, n),
        pct(covered, n),
        100.0 * med_rel,
        DAYS * PER_DAY
    );
    println!(
        "flat: no significant trend {no_trend}/{} ({:.0} %)",
        flats.len(),
        pct(no_trend, flats.len())
    );
    if std::env::var("TREND_EVAL_VERBOSE").is_ok() {
        for (i, o) in outs.iter().enumerate() {
            println!(
                "run {i}: truth {:.1} d, projected {:?}, interval {:?}, points {}",
                o.truth, o.days, o.interval, o.points
            );
        }
    }
}
