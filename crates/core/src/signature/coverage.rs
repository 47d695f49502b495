//! Tables where the machines run: which speeds a gearbox's table must cover, the columns
//! (Ω1 values) that cover them, and a table extended to new columns without recomputing the
//! columns it has.
//!
//! A machine's configured input-shaft rate is a span of ± [`CONFIGURED_MARGIN`] around it, a
//! declared speed range its own span, a record's measured rate ± [`RECORD_MARGIN`]; the
//! description's `nominal_input_hz` is a span like a machine's. The table's columns cover the
//! hull of the spans without a gap wider than [`MAX_GAP`] (the matcher interpolates between
//! neighbouring columns): the existing columns near the hull are kept, the ends extended and
//! gaps filled in geometric steps of [`STEP`], and a hull that no existing column reaches is
//! laid out afresh. A plan that would need more than [`MAX_SIMULATIONS`] simulations is
//! refused ([`Error::TableTooLarge`]): a gearbox whose machines run over too wide a range
//! needs a narrower one (or one gearbox id per speed range), never a runaway job.

use serde::{Deserialize, Serialize};

use super::precompute::{PrecomputeSpec, precompute};
use super::table::{Grid, SignatureTable};
use crate::error::{Error, Result};
use crate::gearbox::Gearbox;

/// Relative step between new columns (7.5 %: the default grid's).
pub const STEP: f64 = 1.075;
/// Largest relative gap between neighbouring columns left unfilled.
pub const MAX_GAP: f64 = 1.10;
/// A configured input-shaft rate is this relative span around it.
pub const CONFIGURED_MARGIN: f64 = 0.15;
/// A record's measured rate is this relative span around it.
pub const RECORD_MARGIN: f64 = 0.075;
/// Most simulations (wear degrees × columns × seeds) a table may need.
pub const MAX_SIMULATIONS: usize = 3000;

/// A span of input-shaft rates (Hz) a table must cover.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SpeedSpan {
    pub lo_hz: f64,
    pub hi_hz: f64,
}

impl SpeedSpan {
    /// A configured rate: ± [`CONFIGURED_MARGIN`].
    pub fn configured(hz: f64) -> SpeedSpan {
        SpeedSpan {
            lo_hz: hz * (1.0 - CONFIGURED_MARGIN),
            hi_hz: hz * (1.0 + CONFIGURED_MARGIN),
        }
    }

    /// A record's measured rate: ± [`RECORD_MARGIN`].
    pub fn measured(hz: f64) -> SpeedSpan {
        SpeedSpan {
            lo_hz: hz * (1.0 - RECORD_MARGIN),
            hi_hz: hz * (1.0 + RECORD_MARGIN),
        }
    }

    /// A declared range `[lo, hi]` Hz.
    pub fn range(lo_hz: f64, hi_hz: f64) -> SpeedSpan {
        SpeedSpan { lo_hz, hi_hz }
    }

    fn valid(&self) -> bool {
        self.lo_hz.is_finite()
            && self.lo_hz > 0.0
            && self.hi_hz.is_finite()
            && self.hi_hz >= self.lo_hz
    }
}

/// The spans a gearbox's own description asks for: its `nominal_input_hz` (± 15 %), none
/// without one.
pub fn described_spans(gb: &Gearbox) -> Vec<SpeedSpan> {
    gb.description
        .nominal_input_hz
        .map(SpeedSpan::configured)
        .into_iter()
        .collect()
}

fn round(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

/// Whether `columns` (Ω1 of `gb`, ascending) cover `span`: its ends within half a step of the
/// outer columns and no gap wider than [`MAX_GAP`] inside it.
pub fn covers(gb: &Gearbox, columns: &[f64], span: &SpeedSpan) -> bool {
    let (Some(&first), Some(&last)) = (columns.first(), columns.last()) else {
        return false;
    };
    let f_ref = gb.reference_frequency_hz();
    let (lo, hi) = (gb.f1_hz(span.lo_hz) / f_ref, gb.f1_hz(span.hi_hz) / f_ref);
    let half = STEP.sqrt();
    if lo < first / half || hi > last * half {
        return false;
    }
    columns
        .windows(2)
        .filter(|w| w[1] >= lo && w[0] <= hi)
        .all(|w| w[1] / w[0] <= MAX_GAP)
}

/// The columns (Ω1 of `gb`, ascending) that cover `spans` starting from the table's `existing`
/// ones (see the [module docs](self)); `existing` itself when `spans` is empty.
///
/// Errors: a span that is not a positive range; a plan needing more than
/// [`MAX_SIMULATIONS`] simulations for `ea × seeds` simulations a column
/// ([`Error::TableTooLarge`]).
pub fn plan_columns(
    gb: &Gearbox,
    existing: &[f64],
    spans: &[SpeedSpan],
    per_column: usize,
) -> Result<Vec<f64>> {
    if let Some(bad) = spans.iter().find(|s| !s.valid()) {
        return Err(Error::param(
            "speed span",
            bad.lo_hz,
            "a span of input-shaft rates must be positive, lowest first",
        ));
    }
    if spans.is_empty() {
        return Ok(existing.to_vec());
    }
    let f_ref = gb.reference_frequency_hz();
    let to_omega = |hz: f64| gb.f1_hz(hz) / f_ref;
    let lo = spans
        .iter()
        .map(|s| to_omega(s.lo_hz))
        .fold(f64::INFINITY, f64::min);
    let hi = spans
        .iter()
        .map(|s| to_omega(s.hi_hz))
        .fold(f64::NEG_INFINITY, f64::max);
    let mut cols: Vec<f64> = existing
        .iter()
        .copied()
        .filter(|&c| c >= lo / STEP && c <= hi * STEP)
        .collect();
    if cols.is_empty() {
        let n = ((hi / lo).ln() / STEP.ln()).ceil().max(1.0) as usize;
        cols = (0..=n)
            .map(|k| round(lo * (hi / lo).powf(k as f64 / n as f64)))
            .collect();
    } else {
        while cols[0] > lo * (1.0 + 1e-9) {
            let c = round(cols[0] / STEP);
            cols.insert(0, c);
        }
        while cols[cols.len() - 1] < hi * (1.0 - 1e-9) {
            let c = round(cols[cols.len() - 1] * STEP);
            cols.push(c);
        }
        let mut filled = vec![cols[0]];
        for w in cols.windows(2) {
            let ratio = w[1] / w[0];
            if ratio > MAX_GAP {
                let n = (ratio.ln() / STEP.ln()).ceil() as usize;
                for k in 1..n {
                    filled.push(round(w[0] * ratio.powf(k as f64 / n as f64)));
                }
            }
            filled.push(w[1]);
        }
        cols = filled;
    }
    cols.dedup();
    let needed = cols.len() * per_column;
    if needed > MAX_SIMULATIONS {
        let per = gb.f1_per_input_hz;
        return Err(Error::TableTooLarge {
            lo_hz: lo * f_ref / per,
            hi_hz: hi * f_ref / per,
            simulations: needed,
            limit: MAX_SIMULATIONS,
        });
    }
    Ok(cols)
}

/// `table` with exactly the Ω1 `columns`: those it has are kept as they are, the others
/// precomputed with the table's own settings (`on_point` once per new grid point) — a column
/// it has that `columns` lacks is dropped. The result's header is the table's, its grid the
/// new one; `precompute_seconds` counts the new columns only.
pub fn extend(
    table: &SignatureTable,
    columns: &[f64],
    partial: Option<&std::path::Path>,
    on_point: &(dyn Fn() + Sync),
) -> Result<SignatureTable> {
    let have = &table.grid.omega1;
    let missing: Vec<f64> = columns
        .iter()
        .copied()
        .filter(|c| !have.contains(c))
        .collect();
    let mut out = table.clone();
    out.grid.omega1 = columns.to_vec();
    let fresh = if missing.is_empty() {
        None
    } else {
        let spec = PrecomputeSpec {
            gearbox: table.gearbox_arc(),
            sensor: table.sensor,
            grid: Grid {
                ea: table.grid.ea.clone(),
                omega1: missing.clone(),
                seeds: table.grid.seeds,
            },
            settings: table.simulation.clone(),
            created_by: table.created_by.clone(),
        };
        Some(precompute(&spec, partial, on_point)?)
    };
    out.precompute_seconds = fresh.as_ref().map_or(0.0, |f| f.precompute_seconds);
    out.entries = Vec::with_capacity(table.grid.ea.len() * columns.len());
    for i in 0..table.grid.ea.len() {
        for &c in columns {
            let e = match have.iter().position(|&h| h == c) {
                Some(j) => table.entry(i, j).clone(),
                None => {
                    let f = fresh.as_ref().expect("a missing column was computed");
                    let j = missing
                        .iter()
                        .position(|&m| m == c)
                        .expect("the column is missing");
                    f.entry(i, j).clone()
                }
            };
            out.entries.push(e);
        }
    }
    Ok(out)
}

/// The grid of a new table of `gb` covering `spans` (the description's default wear degrees
/// and seeds); `None` without spans (the caller keeps its default grid).
pub fn grid_for(gb: &Gearbox, spans: &[SpeedSpan]) -> Result<Option<Grid>> {
    if spans.is_empty() {
        return Ok(None);
    }
    let base = super::precompute::default_grid(gb);
    let cols = plan_columns(gb, &[], spans, base.ea.len() * base.seeds)?;
    Ok(Some(Grid {
        omega1: cols,
        ..base
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spur() -> Gearbox {
        Gearbox::from_file(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../configs/gearboxes/phm09-spur.toml"),
        )
        .unwrap()
    }

    #[test]
    fn a_configured_rate_is_covered_by_a_fresh_lattice() {
        let gb = spur();
        let span = SpeedSpan::configured(40.0);
        let cols = plan_columns(&gb, &[], &[span], 57).unwrap();
        assert!(covers(&gb, &cols, &span), "{cols:?}");
        assert!(cols.windows(2).all(|w| w[1] / w[0] <= STEP * 1.0001));
        // ±15 % in 7.5 % steps: 0.85 … 1.15 is ln(1.353)/ln(1.075) = 4.2 → 5 steps.
        assert_eq!(cols.len(), 6);
        // A rate far outside is not covered.
        assert!(!covers(&gb, &cols, &SpeedSpan::measured(60.0)));
    }

    #[test]
    fn an_extension_keeps_the_existing_columns_and_fills_gaps() {
        let gb = Gearbox::paper_rig();
        // The paper band's columns 0.5 … 1.6 step 0.1 (20 % steps at the bottom).
        let existing: Vec<f64> = (0..=11).map(|k| round(0.5 + 0.1 * k as f64)).collect();
        let f_ref = gb.reference_frequency_hz();
        let hz = |om: f64| om * f_ref / gb.f1_per_input_hz;
        let span = SpeedSpan::range(hz(0.4), hz(0.7));
        let cols = plan_columns(&gb, &existing, &[span], 57).unwrap();
        assert!(covers(&gb, &cols, &span), "{cols:?}");
        for c in existing.iter().filter(|&&c| c <= 0.7 * STEP) {
            assert!(cols.contains(c), "{c} kept");
        }
        assert!(cols.iter().all(|&c| c <= 0.7 * STEP * 1.0001), "{cols:?}");
        assert!(cols.windows(2).all(|w| w[1] / w[0] <= MAX_GAP));
        // Nothing asked: the columns stay.
        assert_eq!(plan_columns(&gb, &existing, &[], 57).unwrap(), existing);
    }

    #[test]
    fn a_plan_beyond_the_limit_is_refused_with_the_figures() {
        let gb = spur();
        let e = plan_columns(&gb, &[], &[SpeedSpan::range(1.0, 400.0)], 57).unwrap_err();
        match e {
            Error::TableTooLarge {
                simulations, limit, ..
            } => assert!(simulations > limit),
            other => panic!("{other}"),
        }
        assert!(plan_columns(&gb, &[], &[SpeedSpan::range(5.0, 1.0)], 57).is_err());
    }

    #[test]
    fn an_extended_table_keeps_its_entries_and_computes_only_the_new_columns() {
        let gb = std::sync::Arc::new(
            Gearbox::from_file(
                &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                    .join("../../configs/gearboxes/spur-pair.toml"),
            )
            .unwrap(),
        );
        let spec = PrecomputeSpec {
            gearbox: gb.clone(),
            sensor: Default::default(),
            grid: Grid {
                ea: vec![0.1, 0.5],
                omega1: vec![0.7, 0.75],
                seeds: 1,
            },
            settings: crate::signature::SimulationSettings {
                periods: 64,
                ..Default::default()
            },
            created_by: "test".into(),
        };
        let t = precompute(&spec, None, &|| {}).unwrap();
        let count = std::sync::atomic::AtomicUsize::new(0);
        let x = extend(&t, &[0.65, 0.7, 0.75], None, &|| {
            count.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        })
        .unwrap();
        assert_eq!(count.into_inner(), 2, "one new column × two wear degrees");
        assert_eq!(x.grid.omega1, vec![0.65, 0.7, 0.75]);
        assert_eq!(x.entries.len(), 6);
        for i in 0..2 {
            assert_eq!(x.entry(i, 1).samples, t.entry(i, 0).samples);
            assert_eq!(x.entry(i, 2).samples, t.entry(i, 1).samples);
            assert_eq!(x.entry(i, 0).omega1, 0.65);
        }
        // It reads back as a table.
        let back = SignatureTable::from_json(&x.to_json().unwrap(), "test").unwrap();
        assert_eq!(back.grid, x.grid);
    }
}
