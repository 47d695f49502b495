//! Tables where the machines run: what a described gearbox's signature table must cover (its
//! **demand**), the table's coverage, and what a record outside it gets.
//!
//! The demand of a gearbox's table is the description's `nominal_input_hz` (± 15 %), each of
//! its machines' `input_shaft_hz` (± 15 %) and `speed_range_hz`, and the input-shaft rates of
//! records that ran outside the table (± 7.5 %; stored per description hash with the record,
//! [`crate::store::TableSpeed`]) — the spans of [`crate::signature::coverage`]. The first table
//! of a gearbox is laid over the demand (the default grid without any); when the demand grows
//! beyond the table's columns the table is **extended** by a job of its own ([`jobs`]), the
//! columns it has kept, while it stays ready and in use. Columns the demand no longer comes
//! near are dropped by the next extension: a table keeps the columns near what its machines
//! are configured for and have been measured at, not the default grid it started from when
//! nothing was asked of it.
//!
//! Bounded: a table that would need more than
//! [`MAX_SIMULATIONS`](crate::signature::coverage::MAX_SIMULATIONS) simulations is refused —
//! a machine configuration that would need it is a 422 (nothing stored), a record's speed
//! that would need it is answered `outside-table` with the reason, and is not queued.
//!
//! A record outside the table is answered `table-in-progress` and read again when the table
//! covers it ([`crate::service::records::reread`]).

pub mod jobs;

use serde_json::{Value, json};

use super::AppState;
use super::error::{ApiError, ApiResult};
use crate::assessment::{Assessment, Reading, TableMiss};
use crate::diagnosis::WithheldReason;
use crate::gearbox::Gearbox;
use crate::signature::TableStatus;
use crate::signature::coverage::{SpeedSpan, covers, described_spans, plan_columns};
use crate::signature::precompute::default_grid;
use crate::store::{GearboxRow, TableSpeed};

/// How long the first table job of a gearbox described without `nominal_input_hz` waits for
/// a machine to be configured on it (a machine's PUT makes it due at once): without one, the
/// default grid is the paper's band, which a machine's speeds would replace.
pub const WAIT_FOR_MACHINES_MS: i64 = 5_000;

/// The spans a machine's configuration asks of its gearbox's table.
pub fn machine_spans(input_shaft_hz: Option<f64>, range: Option<(f64, f64)>) -> Vec<SpeedSpan> {
    let mut v: Vec<SpeedSpan> = input_shaft_hz
        .map(SpeedSpan::configured)
        .into_iter()
        .collect();
    v.extend(range.map(|(lo, hi)| SpeedSpan::range(lo, hi)));
    v
}

/// The demand of `row`'s table (see the [module docs](self)); the configuration of machine
/// `except` left out (its new one is being checked).
pub async fn demand(
    app: &AppState,
    row: &GearboxRow,
    gb: &Gearbox,
    except: Option<&str>,
) -> ApiResult<Vec<SpeedSpan>> {
    let mut spans = described_spans(gb);
    for m in app.store.configured_speeds(&row.id).await? {
        if Some(m.machine_id.as_str()) != except {
            spans.extend(machine_spans(m.input_shaft_hz, m.speed_range_hz));
        }
    }
    for hz in app.store.table_speeds(&row.id, &row.hash).await? {
        spans.push(SpeedSpan::measured(hz));
    }
    Ok(spans)
}

/// Simulations a column of `gb`'s table takes (wear degrees × seeds of the service's grid).
pub fn per_column(gb: &Gearbox) -> usize {
    let g = default_grid(gb);
    g.ea.len() * g.seeds
}

/// The columns that cover `spans`, from `existing` (the stored table's, or none).
pub fn plan(gb: &Gearbox, existing: &[f64], spans: &[SpeedSpan]) -> crate::Result<Vec<f64>> {
    plan_columns(gb, existing, spans, per_column(gb))
}

/// Whether `columns` cover every span.
pub fn covers_all(gb: &Gearbox, columns: &[f64], spans: &[SpeedSpan]) -> bool {
    spans.iter().all(|s| covers(gb, columns, s))
}

/// Input-shaft Hz of column `omega1` of `gb`'s table.
pub fn column_hz(gb: &Gearbox, omega1: f64) -> f64 {
    omega1 * gb.reference_frequency_hz() / gb.f1_per_input_hz
}

/// The stored table's columns of a ready described gearbox (none otherwise).
fn stored_columns(row: &GearboxRow) -> &[f64] {
    match (&row.status, &row.table_columns) {
        (TableStatus::Ready, Some(c)) => c,
        _ => &[],
    }
}

/// A machine configuration's check against its gearbox's table: 422 `table-too-large` when
/// covering its speeds (`spans`) with the rest of the demand would need more simulations
/// than allowed (`member` names what to narrow). The built-in rig's table is the served file:
/// nothing to check.
pub async fn check_machine(
    app: &AppState,
    machine_id: &str,
    row: &GearboxRow,
    spans: &[SpeedSpan],
    member: &str,
) -> ApiResult<()> {
    if row.builtin || spans.is_empty() {
        return Ok(());
    }
    let gb = app
        .tables
        .gearbox(row)
        .map_err(|e| ApiError::internal(format!("gearbox `{}`: {e}", row.id)))?;
    let mut all = demand(app, row, &gb, Some(machine_id)).await?;
    all.extend_from_slice(spans);
    match plan(&gb, stored_columns(row), &all) {
        Ok(_) => Ok(()),
        Err(e @ crate::Error::TableTooLarge { .. }) => Err(too_large(&e, member)),
        Err(e) => Err(ApiError::unprocessable(
            "invalid-machine",
            "Invalid machine configuration",
            e.to_string(),
        )
        .with("member", member)),
    }
}

fn too_large(e: &crate::Error, member: &str) -> ApiError {
    let mut p = ApiError::unprocessable(
        "table-too-large",
        "Signature table too large",
        e.to_string(),
    )
    .with("member", member);
    if let crate::Error::TableTooLarge {
        simulations, limit, ..
    } = e
    {
        p = p
            .with("simulations", *simulations as u64)
            .with("limit", *limit as u64);
    }
    p
}

/// After a change of the demand (a machine configured): queue an extension of `row`'s ready
/// table when its columns no longer cover the demand, and wake the worker. A table not ready
/// yet is laid over the demand when its job starts (a queued one is made due at once) and
/// checked again when it ends.
pub async fn extend_if_needed(app: &AppState, row: &GearboxRow) -> ApiResult<bool> {
    if row.builtin {
        return Ok(false);
    }
    if row.status == TableStatus::Queued {
        if app.store.expedite_gearbox_job(&row.id).await? {
            app.job_wake.notify_one();
        }
        return Ok(false);
    }
    if row.status != TableStatus::Ready {
        return Ok(false);
    }
    let gb = app
        .tables
        .gearbox(row)
        .map_err(|e| ApiError::internal(format!("gearbox `{}`: {e}", row.id)))?;
    let spans = demand(app, row, &gb, None).await?;
    if covers_all(&gb, stored_columns(row), &spans) {
        return Ok(false);
    }
    let queued = app
        .store
        .request_extension(&row.id, &row.hash, crate::store::now_ms())
        .await?;
    if queued {
        tracing::info!(gearbox = %row.id, "table extension queued");
        app.job_wake.notify_one();
    }
    Ok(queued)
}

/// The `covers` member of a gearbox: the input-shaft Hz range of its table's columns (null
/// while it has none).
pub fn covers_json(gb: &Gearbox, columns: &[f64]) -> Value {
    match (columns.first(), columns.last()) {
        (Some(&lo), Some(&hi)) => json!({
            "lo_hz": column_hz(gb, lo),
            "hi_hz": column_hz(gb, hi),
            "columns": columns.len(),
        }),
        _ => Value::Null,
    }
}

/// The `extension` member of a gearbox: a pending (or failed) extension with its progress and,
/// once claimed, the range it extends the table to; null when none.
pub fn extension_json(row: &GearboxRow, gb: &Gearbox) -> Value {
    let Some(x) = &row.extension else {
        return Value::Null;
    };
    let to = x
        .columns
        .as_deref()
        .map_or(Value::Null, |c| covers_json(gb, c));
    json!({
        "status": x.status,
        "progress": x.progress,
        "error": x.error,
        "attempts": x.attempts,
        "queued_at": x.queued_at.map(crate::time::rfc3339),
        "covers": to,
    })
}

/// The deciding channel's `table-in-progress` miss of a record, else any channel's: the
/// input-shaft rate a table must cover for it.
pub fn miss_hz(a: &Assessment) -> Option<f64> {
    let pending = |m: &&TableMiss| m.reason == WithheldReason::TableInProgress;
    a.deciding_channel()
        .table_miss
        .as_ref()
        .filter(pending)
        .or_else(|| {
            a.assessed
                .iter()
                .filter_map(|c| c.table_miss.as_ref())
                .find(pending)
        })
        .map(|m| m.input_hz)
}

/// What a record that ran at `hz`, outside `row`'s table, gets: its speed to store (the
/// extension queued with it), or why the table is not extended to it (the plan would be too
/// large, or the gearbox's table is not ready to extend).
pub async fn admit(
    app: &AppState,
    machine_id: &str,
    row: &GearboxRow,
    gb: &Gearbox,
    hz: f64,
) -> ApiResult<Result<TableSpeed, String>> {
    let mut spans = demand(app, row, gb, None).await?;
    spans.push(SpeedSpan::measured(hz));
    Ok(match plan(gb, stored_columns(row), &spans) {
        Ok(_) => Ok(TableSpeed {
            gearbox_id: row.id.clone(),
            hash: row.hash.clone(),
            input_hz: hz,
            machine_id: machine_id.to_string(),
        }),
        Err(e) => Err(e.to_string()),
    })
}

/// Re-state each channel's `table-in-progress` miss of `a` with `reason` and the note
/// `note(miss)` — in the channel, its alert (whose reason quotes the note), the record's
/// answer and the channels' summaries.
pub fn restate_miss(
    a: &mut Assessment,
    reason: WithheldReason,
    note: &dyn Fn(&TableMiss) -> String,
) {
    let mut swaps: Vec<(String, String)> = Vec::new();
    for c in a.assessed.iter_mut() {
        let Some(m) = c.table_miss.as_mut() else {
            continue;
        };
        if m.reason != WithheldReason::TableInProgress {
            continue;
        }
        let new = note(m);
        swaps.push((m.note.clone(), new.clone()));
        m.note = new;
        m.reason = reason;
    }
    let swap = |s: &mut String| {
        for (old, new) in &swaps {
            if s.contains(old.as_str()) {
                *s = s.replace(old.as_str(), new);
            }
        }
        if reason == WithheldReason::OutsideTable {
            // No table will follow: the alert's promise of one goes.
            *s = s.replace("; the wear degree follows when the table is ready", "");
        }
    };
    for c in a.assessed.iter_mut() {
        swap(&mut c.alert.reason);
    }
    swap(&mut a.alert.reason);
    if let Some(cs) = a.channels.as_mut() {
        for c in cs {
            swap(&mut c.alert.reason);
        }
    }
    let decide = a.assessed[a.deciding].table_miss.clone();
    if let (Reading::NoTable(n), Some(m)) = (&mut a.reading, decide) {
        n.wear_note = Some(m.note);
        n.wear_withheld = Some(m.reason);
    }
}

/// The reason code of the deciding channel's withheld wear figure, if withheld.
pub fn withheld(a: &Assessment) -> Option<WithheldReason> {
    match &a.reading {
        Reading::NoTable(n) => n.wear_withheld,
        Reading::Table(d) => d.wear_withheld,
    }
}

/// `row`'s table range in words for a note (`34.0–46.0 Hz`), empty without a table.
fn range_words(row: &GearboxRow, gb: &Gearbox) -> String {
    match (stored_columns(row).first(), stored_columns(row).last()) {
        (Some(&lo), Some(&hi)) => {
            format!(" ({:.2}–{:.2} Hz)", column_hz(gb, lo), column_hz(gb, hi))
        }
        _ => String::new(),
    }
}

/// A record's table miss as the service answers it: queued (`speed`: the extension's progress
/// in the note; without raw samples the record is not read again) or refused (`outside-table`
/// with the reason).
pub fn answer_miss(
    a: &mut Assessment,
    row: &GearboxRow,
    gb: &Gearbox,
    admitted: &Result<TableSpeed, String>,
    keeps_samples: bool,
) {
    match admitted {
        Ok(_) => {
            let progress = match &row.extension {
                Some(x) if x.status == TableStatus::Running => {
                    format!("; the extension is {:.0} % done", 100.0 * x.progress)
                }
                _ => "; the extension is queued".to_string(),
            };
            restate_miss(a, WithheldReason::TableInProgress, &|m| {
                let mut n = m.note.clone();
                if !keeps_samples {
                    n = n.replace(
                        " and the record will be read again when it is ready",
                        " (this record is not read again: the service keeps no raw samples)",
                    );
                }
                format!("{n}{progress}")
            });
        }
        Err(why) => {
            let range = range_words(row, gb);
            restate_miss(a, WithheldReason::OutsideTable, &|m| {
                format!(
                    "no wear figure: the input shaft ran at {:.2} Hz, outside the speeds the \
                     gearbox's signature table covers{range}, and the table is not extended to \
                     it: {why}; the machine's baseline judges this record",
                    m.input_hz
                )
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::assessment::{Baselines, Machine, RecordFacts, TableDiagnoser, assess};
    use crate::diagnosis::DiagnoseOptions;
    use crate::signature::SensorQuantity;
    use crate::signature::precompute::{
        MeasurementSpec, PrecomputeSpec, precompute, simulate_measurement,
    };
    use crate::signature::table::Grid;

    const SPUR: &str = include_str!("../../../configs/gearboxes/spur-pair.toml");

    /// A record of the spur pair at 40 Hz assessed against a one-column table at 25 Hz, by a
    /// machine whose tables are extended: a `table-in-progress` miss. With its gearbox row.
    fn missed() -> (Assessment, GearboxRow, Arc<Gearbox>) {
        let (mut row, gb) = GearboxRow::described("spur", SPUR, None, "test").unwrap();
        let gb = Arc::new(gb);
        let omega = |hz: f64| gb.f1_hz(hz) / gb.reference_frequency_hz();
        let spec = PrecomputeSpec {
            gearbox: gb.clone(),
            sensor: SensorQuantity::default(),
            grid: Grid {
                ea: vec![0.1, 0.5],
                omega1: vec![(omega(25.0) * 1e6).round() / 1e6],
                seeds: 1,
            },
            settings: crate::signature::SimulationSettings {
                periods: 64,
                ..Default::default()
            },
            created_by: "test".into(),
        };
        let table = precompute(&spec, None, &|| {}).unwrap();
        row.status = TableStatus::Ready;
        row.table_columns = Some(table.grid.omega1.clone());
        let d = TableDiagnoser::new(table, DiagnoseOptions::default()).unwrap();
        let rec = simulate_measurement(
            &gb,
            &MeasurementSpec {
                ea: 0.3,
                omega1: omega(40.0),
                sample_rate: 25_600.0,
                duration: 1.0,
                gain: 3.0,
                snr_db: Some(25.0),
                seed: 3,
                sensor: SensorQuantity::Accel,
                planetary: None,
            },
        )
        .unwrap();
        let baselines = Baselines::default();
        let mut machine = Machine::described("spur", &gb, Some(&d), &baselines);
        machine.extends_tables = true;
        let facts = RecordFacts {
            sample_rate_hz: rec.sample_rate,
            shaft_hz: Some(40.0),
            ..Default::default()
        };
        let mut channels = vec![("0".to_string(), rec.samples)];
        let a = assess(&mut channels, &[0], &facts, &machine, &mut |_| {}).unwrap();
        (a, row, gb.clone())
    }

    fn note(a: &Assessment) -> String {
        match &a.reading {
            Reading::NoTable(n) => n.wear_note.clone().unwrap_or_default(),
            Reading::Table(_) => panic!("a reading"),
        }
    }

    #[test]
    fn a_speed_past_the_limit_is_answered_outside_table_with_the_reason() {
        let (mut a, row, gb) = missed();
        assert_eq!(withheld(&a), Some(WithheldReason::TableInProgress));
        let hz = miss_hz(&a).unwrap();
        assert!((hz / 40.0 - 1.0).abs() < 0.02, "{hz}");
        assert!(
            a.alert.reason.contains("follows when the table is ready"),
            "{}",
            a.alert.reason
        );
        let why = "covering input-shaft rates 1–400 Hz would take 4000 simulations".to_string();
        answer_miss(&mut a, &row, &gb, &Err(why.clone()), true);
        assert_eq!(withheld(&a), Some(WithheldReason::OutsideTable));
        let n = note(&a);
        assert!(n.contains(&why) && n.contains("not extended"), "{n}");
        assert!(n.contains("25.00–25.00 Hz"), "the table's range: {n}");
        assert!(miss_hz(&a).is_none(), "nothing left to queue");
        // The alert quotes the new note and promises no table.
        let r = &a.alert.reason;
        assert!(
            r.contains(&why) && !r.contains("follows when the table is ready"),
            "{r}"
        );
        assert_eq!(a.assessed[0].alert.reason, *r);
        // The stored answer says it too.
        let body = serde_json::to_value(&a).unwrap();
        assert_eq!(body["wear_withheld"], "outside-table", "{body}");
    }

    #[test]
    fn a_queued_speed_says_the_extension_s_progress_and_without_samples_no_reread() {
        let (mut a, row, gb) = missed();
        let speed = Ok(TableSpeed {
            gearbox_id: "spur".into(),
            hash: row.hash.clone(),
            input_hz: 40.0,
            machine_id: "m".into(),
        });
        answer_miss(&mut a, &row, &gb, &speed, false);
        assert_eq!(withheld(&a), Some(WithheldReason::TableInProgress));
        let n = note(&a);
        assert!(
            n.contains("being extended") && n.ends_with("the extension is queued"),
            "{n}"
        );
        assert!(
            n.contains("not read again") && !n.contains("will be read again"),
            "{n}"
        );
        assert!(a.alert.reason.contains(&n), "{}", a.alert.reason);
    }
}
