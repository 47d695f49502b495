//! A record read again once its gearbox's table covers it: a diagnosis answered
//! `table-in-progress` is stored `pending` with what its record came with; when the table of
//! its machine's gearbox is ready (first computed, or extended to the record's speed), the
//! replica that stored the table reads each pending record again from its stored raw samples
//! through the record path's own steps ([`super::accept`]'s machine context, assessment and
//! rows), and stores a new diagnosis for it — the record's latest, with `replaces` naming the
//! one before, announced like any new diagnosis (`diagnosis.created`). The record's stored
//! features become the new reading's (a baseline record's line ratios at the new speed join its
//! machine's baseline). The machine's alert episode is not stepped again: the record was
//! counted when it came.
//!
//! A record whose speed the table still does not cover stays pending (its speed is added to
//! the table's demand, as at ingest); one whose raw samples are gone is marked `unavailable`,
//! one whose reading now fails `failed`. Two replicas reading the same record again store one
//! diagnosis: the store marks the pending one `done` by compare-and-set.

use super::accept::{Assessed, RecordRequest, RereadRequest, table_miss, tacho_of};
use super::rows::{Ids, diagnosis_row, event_extras};
use crate::diagnosis::WithheldReason;
use crate::service::AppState;
use crate::service::error::ApiResult;
use crate::service::evidence::stored_evidence;
use crate::service::tables;
use crate::service::wire::Decoded;
use crate::store::{PendingReread, Reread, new_id, now_ms};

/// Most pending records one pass reads again (the next pass, at the worker's next idle poll,
/// takes the rest).
const BATCH: i64 = 200;

/// What became of one pending record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// A new diagnosis was stored.
    Stored,
    /// Its speed is still outside the table (its extension is queued): it stays pending.
    StillPending,
    /// Another replica stored its re-read first, or its machine is gone.
    Skipped,
    /// Marked `unavailable` (no raw samples) or `failed` (the reading failed).
    Given,
}

/// The re-read worker: whenever a table job stores a table (`reread_wake`), and at every idle
/// poll (records a stopped replica left waiting for a table that is ready now), the pending
/// records of every gearbox whose table covers them are read again.
pub async fn worker(app: AppState, mut stop: tokio::sync::watch::Receiver<bool>) {
    loop {
        if *stop.borrow() {
            break;
        }
        match app.store.reread_gearboxes().await {
            Ok(gearboxes) => {
                for g in gearboxes {
                    reread_gearbox(&app, &g).await;
                }
            }
            Err(e) => tracing::warn!(error = %e, "re-reads: store unavailable"),
        }
        tokio::select! {
            _ = tokio::time::sleep(crate::service::tables::jobs::IDLE_POLL) => {}
            _ = app.reread_wake.notified() => {}
            _ = stop.changed() => break,
        }
    }
}

/// Read again the pending records of the machines whose gearbox is `gearbox_id`; how many
/// new diagnoses were stored. Errors are logged, never returned: a record left pending is
/// taken at the worker's next idle poll.
pub async fn reread_gearbox(app: &AppState, gearbox_id: &str) -> usize {
    let pending = match app.store.pending_rereads(gearbox_id, BATCH).await {
        Ok(p) => p,
        Err(e) => {
            tracing::warn!(gearbox = gearbox_id, error = %e, "re-reads: store unavailable");
            return 0;
        }
    };
    let mut stored = 0;
    for p in &pending {
        match reread(app, p).await {
            Ok(Outcome::Stored) => stored += 1,
            Ok(_) => {}
            Err(e) => {
                tracing::warn!(record = %p.record_id, error = %e.detail, "a record's re-read failed");
                let _ = app.store.mark_reread(&p.diagnosis_id, "failed").await;
            }
        }
    }
    if !pending.is_empty() {
        tracing::info!(
            gearbox = gearbox_id,
            pending = pending.len(),
            stored,
            "records read again"
        );
    }
    stored
}

/// Read one pending record again.
pub async fn reread(app: &AppState, p: &PendingReread) -> ApiResult<Outcome> {
    let Some(machine) = app.store.get_machine(&p.machine_id).await? else {
        return Ok(Outcome::Skipped);
    };
    let rec = app.store.stored_record(&p.record_id).await?;
    let Some((rec, bytes)) = rec.and_then(|mut r| r.samples.take().map(|b| (r, b))) else {
        app.store
            .mark_reread(&p.diagnosis_id, "unavailable")
            .await?;
        return Ok(Outcome::Given);
    };
    let again: RereadRequest = p
        .request
        .as_deref()
        .and_then(|t| serde_json::from_str(t).ok())
        .unwrap_or_default();
    let dec = Decoded {
        channels: crate::service::wire::stored_channels(&rec, &bytes),
        sample_rate_hz: rec.sample_rate_hz,
        shaft_hz: rec.shaft_hz,
        recorded_at: rec.recorded_at.clone(),
        sensor: rec.sensor.clone(),
        load: again.load.clone(),
        record_id: None,
    };
    let tacho = tacho_of(Some(&machine), &dec, again.tacho_ppr)?;
    let request = RecordRequest {
        channel: again.channel.clone(),
        declared_healthy: again.declared_healthy,
        tacho,
    };
    let job = request.load(app, &p.machine_id, Some(machine), dec).await?;
    let Assessed {
        mut assessment,
        spectrum,
        gearbox_row,
        gearbox,
        undrawn,
        ..
    } = tokio::task::spawn_blocking(move || job.run())
        .await
        .map_err(|e| crate::service::ApiError::internal(format!("the re-read failed: {e}")))?
        .map_err(|e| crate::service::error::problem_from_error(&e))?;
    let speed = table_miss(app, &p.machine_id, &gearbox_row, &gearbox, &mut assessment).await?;
    if let Some(s) = speed {
        // Still outside: the speed joins the table's demand (its extension queued), the
        // record waits for it.
        app.store.add_table_speed(&s, now_ms()).await?;
        app.job_wake.notify_one();
        return Ok(Outcome::StillPending);
    }
    if tables::withheld(&assessment) == Some(WithheldReason::TableInProgress) {
        // The table is not ready (its description was replaced meanwhile): it waits.
        return Ok(Outcome::StillPending);
    }
    let ids = Ids {
        now: now_ms(),
        record_id: rec.id.clone(),
        diagnosis_id: new_id(),
    };
    let body = serde_json::to_string(&assessment).map_err(|e| {
        crate::service::ApiError::internal(format!("the assessment did not serialise: {e}"))
    })?;
    // Read again from its stored samples, which are kept: the plot is drawn when asked for.
    let evidence = stored_evidence(&assessment, undrawn.as_ref(), true);
    let mut d = diagnosis_row(
        &assessment,
        body,
        spectrum.as_ref(),
        evidence,
        &ids,
        &p.machine_id,
        rec.measured_at,
    );
    d.replaces = Some(p.diagnosis_id.clone());
    let mut extras = event_extras(&assessment);
    extras.insert("replaces".into(), p.diagnosis_id.clone().into());
    let r = Reread {
        diagnosis: d,
        features: serde_json::to_string(&assessment.stored_features()).unwrap_or_default(),
        event_extras: extras,
    };
    if !app.store.store_reread(&r).await? {
        return Ok(Outcome::Skipped);
    }
    app.webhook_wake.notify_one();
    tracing::info!(machine = %p.machine_id, record = %rec.id, diagnosis = %r.diagnosis.id, replaces = %p.diagnosis_id, "record read again");
    Ok(Outcome::Stored)
}
