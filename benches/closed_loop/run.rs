//! One record of the benchmark: drawn, generated, its visibility measured, diagnosed and
//! calibrated (or one of the partial runs: `CL_LEVEL_ONLY`, `CL_VISIBILITY_ONLY`,
//! `CL_INDICATORS_ONLY`).

use std::time::Instant;

use gearwear::closed_loop::effects::{MeshGear, reference_gears};
use gearwear::closed_loop::sidebands::SidebandScan;
use gearwear::closed_loop::spectrum::BAND_HI;
use gearwear::closed_loop::virtual_rig::generate;
use gearwear::closed_loop::{CalibrateOptions, calibrate};
use gearwear::diagnosis::Diagnosis;
use gearwear::gearbox::Gearbox;
use gearwear::record::Record;
use gearwear::signature::SignatureTable;

use super::draw::{Draw, draw};
use super::row::Row;
use super::settings::{Settings, env, flag};
use super::visibility;

/// The benchmark's fixed inputs: its settings and the signature table.
pub struct Bench {
    pub set: Settings,
    pub table: SignatureTable,
    pub gb: Gearbox,
    gears: Vec<MeshGear>,
    /// The gearbox's reference frequency (Hz): f1 = Ω1 · f_ref.
    f_ref: f64,
    /// The table's band of Ω1.
    band: (f64, f64),
}

/// The diagnosis's condition indicators of a record (NaN / empty without a diagnosis).
pub struct Indicators {
    /// FM4 of the difference signal and kurtosis of the record (tacho-less).
    pub fm4: f64,
    pub kurtosis: f64,
    /// FM4 of each shaft's TSA difference signal.
    pub tsa_fm4: Vec<(String, f64)>,
    /// Standard deviation / mean of the tracked shaft rate.
    pub speed_std: f64,
}

impl Bench {
    pub fn new(set: Settings, table: SignatureTable) -> Bench {
        let gb = table.gearbox().clone();
        let band = table.omega_band();
        let gears = reference_gears(&gb);
        let f_ref = gb.reference_frequency_hz();
        Bench {
            set,
            table,
            gb,
            gears,
            f_ref,
            band,
        }
    }

    /// Record `i` of base seed `base`: its row, timed, with a line on stderr.
    pub fn record(&self, base: u64, i: usize) -> Row {
        let d = draw(&self.set, &self.gb, &self.gears, self.band, base, i);
        if !self.set.indices.is_empty() {
            // Looking at single records: the draw in full, to turn a record into a test.
            eprintln!("record {i}: {:?}", d.spec);
        }
        let t = Instant::now();
        let mut row = self.run(&d).unwrap_or_else(|err| d.blank(Some(err)));
        row.seconds = t.elapsed().as_secs_f64();
        eprintln!(
            "{base}:{i:<4} {:16} truth {:?} named {:?} vis {} (K {}, d/s {:.2}) err {:.2}->{:.2} ea {:.3} {:.3}->{:.3} [{:.3},{:.3}] {:.1}s null {:.1} margin {:.1} best eligible {:?}{}",
            d.kind,
            row.truth,
            row.named,
            row.visible,
            row.visible_k,
            row.vis_d / row.vis_s,
            row.error_before,
            row.error_after,
            row.ea,
            row.ea_before,
            row.ea_after,
            row.ea_lower,
            row.ea_upper,
            row.seconds,
            row.null_spread,
            row.claim_margin,
            row.candidates
                .iter()
                .filter(|c| c.2)
                .min_by(|x, y| x.1.total_cmp(&y.1))
                .map(|c| format!("{} {:.1}", c.0, c.1)),
            row.error
                .as_deref()
                .map(|e| format!(" ERROR {e}"))
                .unwrap_or_default()
        );
        row
    }

    /// The record's row, or why it has none (a failure, or a partial run's text).
    fn run(&self, d: &Draw) -> Result<Row, String> {
        let spec = &d.spec;
        let rec = generate(&self.gb, spec).map_err(|e| e.to_string())?;
        let f1 = d.omega1 * self.f_ref;
        if flag("CL_LEVEL_ONLY") {
            level_line(&self.gb, d, &rec, f1);
            return Err("level only".into());
        }
        let seen = visibility::seen(&self.gb, d, &rec.samples, f1, self.set.k_draws)?;
        if flag("CL_VISIBILITY_ONLY") {
            return Ok(Row {
                method: "visibility-only".into(),
                ..seen
            });
        }
        let diag = gearwear::diagnosis::diagnose(&rec, &self.table, &Default::default()).ok();
        let ind = Indicators::of(diag.as_ref());
        if flag("CL_INDICATORS_ONLY") {
            return Err(self.indicators_text(d, &rec, diag.as_ref(), &ind, &seen));
        }
        let mut copts = CalibrateOptions::default();
        copts.null_z = env("CL_NULL_Z", copts.null_z);
        copts.bic_margin = env("CL_MARGIN", copts.bic_margin);
        copts.candidate_seeds = env("CL_CANDIDATE_SEEDS", copts.candidate_seeds);
        copts.mean_seeds = env("CL_MEAN_SEEDS", copts.mean_seeds);
        let rep = calibrate(&rec, &self.table, &copts).map_err(|e| e.to_string())?;
        Ok(Row::answered(seen, &rep, d, f1, ind))
    }

    /// `CL_INDICATORS_ONLY`: the record's indicators as the row's error text.
    fn indicators_text(
        &self,
        d: &Draw,
        rec: &Record,
        diag: Option<&Diagnosis>,
        ind: &Indicators,
        seen: &Row,
    ) -> String {
        let sb: Vec<String> = diag
            .and_then(|dg| SidebandScan::new(&rec.samples, d.spec.sample_rate, dg.f1_hz, BAND_HI))
            .map(|scan| {
                reference_gears(&self.gb)
                    .iter()
                    .filter_map(|g| scan.check(&g.shaft, g.shaft_ratio))
                    .map(|c| {
                        format!(
                            "{} s {:.4} at {:.4} prom {:.1} dB shaft prom {:.1} off {}",
                            c.shaft,
                            c.shaft_ratio,
                            c.spacing_ratio,
                            c.prominence_db,
                            c.shaft_prominence_db,
                            c.off_rate
                        )
                    })
                    .collect()
            })
            .unwrap_or_default();
        format!(
            "indicators only: members visible {:?} sidebands {sb:?} fm4 {:.3} kurtosis {:.3} tooth {:?} wander {:?} visible {} tsa {:?} speed_std {:.6}",
            seen.member_visible,
            ind.fm4,
            ind.kurtosis,
            d.e.tooth,
            d.e.speed_wander,
            seen.v_effect > seen.v_noise,
            ind.tsa_fm4,
            ind.speed_std
        )
    }
}

impl Indicators {
    fn of(diag: Option<&Diagnosis>) -> Indicators {
        let (fm4, kurtosis) = diag
            .map(|d| (d.condition_indicators.fm4, d.condition_indicators.kurtosis))
            .unwrap_or((f64::NAN, f64::NAN));
        let tsa_fm4: Vec<(String, f64)> = diag
            .and_then(|d| d.order.as_ref())
            .map(|o| {
                o.shafts
                    .iter()
                    .map(|s| (s.shaft.clone(), s.metrics.fm4.unwrap_or(f64::NAN)))
                    .collect()
            })
            .unwrap_or_default();
        let speed_std = diag
            .and_then(|d| d.order.as_ref())
            .map_or(f64::NAN, |o| o.tracking.speed_std);
        Indicators {
            fm4,
            kurtosis,
            tsa_fm4,
            speed_std,
        }
    }
}

/// `CL_LEVEL_ONLY`: one `LEVEL` line of the record's level trace on stderr.
fn level_line(gb: &Gearbox, d: &Draw, rec: &Record, f1: f64) {
    use gearwear::closed_loop::level::{LevelTrace, level_features};
    let shafts = gearwear::closed_loop::effects::shaft_rates(gb);
    let fs = d.spec.sample_rate;
    let tr = LevelTrace::new(&rec.samples, fs, f1);
    let feats = level_features(&rec.samples, fs, f1, &shafts, None);
    let line = match &tr {
        None => "no trace".to_string(),
        Some(tr) => {
            let runs = tr.runs();
            let peak = (0..tr.levels_db.len())
                .map(|k| tr.excess_db(k))
                .fold(f64::MIN, f64::max);
            let dr = tr.drift(&runs).unwrap_or((f64::NAN, f64::NAN));
            format!(
                "spread {:.3} thr {:.2} peak {:.2} runs {} drift {:.2} se {:.3} feats {:?}",
                tr.spread_db,
                tr.burst_threshold_db(),
                peak,
                runs.len(),
                dr.0,
                dr.1,
                feats.iter().map(|f| f.kind).collect::<Vec<_>>()
            )
        }
    };
    eprintln!(
        "LEVEL {} {} {} size {:.3} f1 {f1:.1} {line}",
        d.base, d.i, d.kind, d.size
    );
}
