//! The steps of every record path (HTTP and MQTT): the machine and the decoded record
//! ([`prepare`]), the assessment off the async runtime and the store in one transaction
//! ([`accept`]).

use std::sync::Arc;
use std::sync::atomic::Ordering;

use serde::{Deserialize, Serialize};

use super::idempotency::Idempotency;
use super::rows::{Ids, answer, diagnosis_row, event_extras, measured_at, record_row};
use crate::assessment::{
    Assessment, Baselines, Machine, MachineCalibration, OwnModel, RecordFacts, TableDiagnoser,
    TachoChannel, Thresholds, assess, assess_undrawn, reads_as_described,
};
use crate::condition::Load;
use crate::diagnosis::WithheldReason;
use crate::gearbox::Gearbox;
use crate::service::AppState;
use crate::service::context::MachineContext;
use crate::service::error::{ApiError, ApiResult, problem_from_error};
use crate::service::evidence::{Undrawn, stored_evidence};
use crate::service::machines::DEFAULT_TACHO_CHANNEL;
use crate::service::metrics::StageClock;
use crate::service::spectrum::{PlotSpectrum, plot_from_spectrum, plot_spectrum};
use crate::service::tables;
use crate::service::wire::{BodyFormat, Decoded, RecordQuery, decode};
use crate::store::{
    AlertInput, DiagnosisRow, GearboxRow, IdemRow, Ingest, MachineRow, StoreError, TableSpeed,
    new_id, now_ms,
};
use crate::units::MachineUnits;

/// A decoded record with its machine and what came with it: what [`prepare`] hands to
/// [`accept`].
pub struct Prepared {
    machine: Option<MachineRow>,
    /// The decoded record.
    pub dec: Decoded,
    request: RecordRequest,
    /// Warnings about how the body was read (a sniffed format), added to the assessment's.
    pub warnings: Vec<String>,
}

/// The steps of every record path (HTTP and MQTT) before the assessment: the machine (and,
/// with `--require-registered-machines`, that it is registered), the record decoded from
/// `format` with the query parameters `q`, its tachometer.
pub async fn prepare(
    app: &AppState,
    machine_id: &str,
    format: BodyFormat,
    q: RecordQuery,
    bytes: &[u8],
    clock: &mut StageClock,
) -> ApiResult<Prepared> {
    let machine = app.store.get_machine(machine_id).await?;
    crate::service::lifecycle::check_registered(app, machine_id, machine.as_ref())?;
    clock.skip();
    let pulses = tacho_name(machine.as_ref());
    let dec = decode(format, &q, bytes, &app.settings.limits, Some(pulses))?;
    let declared_healthy = q.baseline()?;
    let tacho = tacho_of(machine.as_ref(), &dec, q.tacho_ppr()?)?;
    clock.lap("decode");
    Ok(Prepared {
        machine,
        dec,
        request: RecordRequest {
            channel: q.channel,
            declared_healthy,
            tacho,
        },
        warnings: Vec::new(),
    })
}

/// What [`accept`] did with a record.
pub enum Accepted {
    /// Stored: the answer (the assessment with its ids) and the diagnosis's id.
    Created {
        response_text: String,
        diagnosis_id: String,
    },
    /// A concurrent request with the same idempotency key committed first: its stored answer.
    Replayed(IdemRow),
}

/// Assess a prepared record (off the async runtime, with the core's [`assess`]) and store it
/// with its diagnosis, webhook deliveries and `idem`'s answer in one transaction; the record
/// path every source shares.
pub async fn accept(
    app: &AppState,
    machine_id: &str,
    format: BodyFormat,
    prepared: Prepared,
    idem: &Idempotency,
    mut clock: StageClock,
) -> ApiResult<Accepted> {
    let Prepared {
        machine,
        dec,
        request,
        warnings,
    } = prepared;
    let declared_healthy = request.declared_healthy;
    let again = request.reread_request(&dec);
    let job = request.load(app, machine_id, machine, dec).await?;
    let Assessed {
        dec,
        mut assessment,
        spectrum,
        clock: job_clock,
        gearbox_row,
        gearbox,
        undrawn,
    } = tokio::task::spawn_blocking(move || job.run())
        .await
        .map_err(|e| ApiError::internal(format!("the diagnosis task failed: {e}")))?
        .map_err(|e| problem_from_error(&e))?;
    for note in warnings {
        assessment.warn(note);
    }
    clock.absorb(job_clock);
    let table_speed = table_miss(app, machine_id, &gearbox_row, &gearbox, &mut assessment).await?;
    // The stages are thread CPU time, booked only between awaits: the task may have moved to
    // another thread, whose other work would be booked too.
    clock.skip();

    let ids = Ids {
        now: now_ms(),
        record_id: new_id(),
        diagnosis_id: new_id(),
    };
    // Written once, straight from the typed assessment: the stored diagnosis, and the answer
    // with the ids spliced in.
    let body = serde_json::to_string(&assessment)
        .map_err(|e| ApiError::internal(format!("the assessment did not serialise: {e}")))?;
    let response_text = answer(&body, &ids, machine_id, assessment.level());
    let keeps_raw = !app.settings.raw_retention.is_zero();
    let evidence = stored_evidence(&assessment, undrawn.as_ref(), keeps_raw);
    let mut ing = Ingest {
        record: record_row(
            app,
            &dec,
            &assessment,
            &ids,
            machine_id,
            format,
            idem,
            declared_healthy,
        ),
        diagnosis: with_reread(
            diagnosis_row(
                &assessment,
                body,
                spectrum.as_ref(),
                evidence,
                &ids,
                machine_id,
                measured_at(&dec, &ids),
            ),
            &again,
            keeps_raw,
        ),
        idempotency: idem.row(&response_text),
        event_extras: event_extras(&assessment),
        registered_only: app.settings.require_registered_machines,
        alert: Some(AlertInput {
            severity: assessment.severity(&app.settings.thresholds),
            measured_at: measured_at(&dec, &ids),
            policy: app.settings.alerts,
        }),
        table_speed,
    };
    clock.lap("assemble");
    // The webhook payloads carry the machine's wear trend with this record in it: a read of
    // the history and a bootstrapped fit (≈ 10 ms of CPU at 200 points), so only when a
    // webhook will receive a diagnosis payload.
    if crate::service::trend::payloads_wanted(app).await {
        let trend = crate::service::trend::summary_with(app, &ing.diagnosis).await;
        ing.event_extras.insert("trend_summary".into(), trend);
    }
    let queued = match store(app, ing, idem).await? {
        Ok(queued) => queued,
        Err(prev) => return Ok(Accepted::Replayed(prev)),
    };
    app.metrics.records_accepted.fetch_add(1, Ordering::Relaxed);
    app.metrics.stages(&clock);
    // The webhook worker is woken for the deliveries this record queued (none without
    // subscriptions); it polls for the rest.
    if queued > 0 {
        app.webhook_wake.notify_one();
    }
    let ea = assessment.wear().map(|w| w.estimate);
    tracing::info!(machine = machine_id, diagnosis = %ids.diagnosis_id, ea, alert_level = %assessment.level(), "record accepted");
    Ok(Accepted::Created {
        response_text,
        diagnosis_id: ids.diagnosis_id,
    })
}

/// A record's `table-in-progress` miss as the service answers it ([`crate::service::tables`]):
/// its speed to store with it (the table's extension queued with it), or the answer re-stated
/// `outside-table` when the table is not extended to it.
pub(super) async fn table_miss(
    app: &AppState,
    machine_id: &str,
    row: &GearboxRow,
    gb: &Gearbox,
    a: &mut Assessment,
) -> ApiResult<Option<TableSpeed>> {
    let Some(hz) = tables::miss_hz(a).filter(|_| !row.builtin) else {
        return Ok(None);
    };
    let admitted = tables::admit(app, machine_id, row, gb, hz).await?;
    let keeps = !app.settings.raw_retention.is_zero();
    tables::answer_miss(a, row, gb, &admitted, keeps);
    if let Err(why) = &admitted {
        tracing::info!(machine = machine_id, gearbox = %row.id, hz, why = %why, "a record's speed is not added to its table");
    }
    Ok(admitted.ok())
}

/// What a record came with besides its samples, kept with a diagnosis whose record is read
/// again when its table covers it ([`super::reread`]).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct RereadRequest {
    /// `?channel=`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub channel: Option<String>,
    /// Posted with `?baseline=true`.
    #[serde(default)]
    pub declared_healthy: bool,
    /// The tachometer's pulses per revolution the record was read with.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tacho_ppr: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load: Option<Load>,
}

/// `d` with its re-read state: a `table-in-progress` diagnosis is `pending` with the request
/// it is read again with (`unavailable` when no raw samples are kept).
pub(super) fn with_reread(mut d: DiagnosisRow, again: &RereadRequest, keeps: bool) -> DiagnosisRow {
    if d.wear_withheld.as_deref() == Some(WithheldReason::TableInProgress.as_str()) {
        d.reread_status = Some(if keeps { "pending" } else { "unavailable" }.into());
        d.reread_request = keeps.then(|| serde_json::to_string(again).unwrap_or_default());
    }
    d
}

/// The store calls of one accepted record: its rows in one transaction (the group-commit
/// queue), `Ok(deliveries queued)`; `Err(answer)` when a concurrent request with the same
/// idempotency key committed first (its stored answer).
async fn store(
    app: &AppState,
    ing: Ingest,
    idem: &Idempotency,
) -> ApiResult<Result<usize, IdemRow>> {
    match app.ingest_queue.ingest(ing).await {
        Ok(queued) => Ok(Ok(queued)),
        Err(StoreError::Conflict(_)) if idem.key.is_some() => match idem.stored(app).await? {
            Some(prev) => Ok(Err(prev)),
            None => Err(ApiError::internal(
                "idempotency conflict without a stored answer",
            )),
        },
        Err(e) => Err(e.into()),
    }
}

/// The name of the channel that is the machine's tachometer when a record has it: the
/// machine's `tacho_channel`, else [`DEFAULT_TACHO_CHANNEL`].
pub(super) fn tacho_name(machine: Option<&MachineRow>) -> &str {
    machine
        .and_then(|m| m.tacho_channel.as_deref())
        .unwrap_or(DEFAULT_TACHO_CHANNEL)
}

/// The record's tachometer: the machine's `tacho_channel` (the record must have it), else a
/// channel named [`DEFAULT_TACHO_CHANNEL`] if the record has one; pulses per revolution from
/// `?tacho_ppr=`, else the machine's `tacho_ppr`.
pub(super) fn tacho_of(
    machine: Option<&MachineRow>,
    dec: &Decoded,
    ppr: Option<usize>,
) -> ApiResult<Option<TachoChannel>> {
    let name = tacho_name(machine);
    let configured = machine.is_some_and(|m| m.tacho_channel.is_some());
    let has = dec.channels.iter().any(|(n, _)| n == name);
    if configured && !has {
        let names: Vec<String> = dec.channels.iter().map(|(n, _)| format!("`{n}`")).collect();
        return Err(ApiError::unprocessable(
            "missing-tacho-channel",
            "Tachometer channel missing",
            format!(
                "the machine's tachometer channel `{name}` is not in the record (its channels: \
                 {}); send the tachometer's samples as channel `{name}`, or change the \
                 machine's `tacho_channel` (PUT /v1/machines/{{machine_id}})",
                names.join(", ")
            ),
        )
        .with("tacho_channel", name));
    }
    if !has {
        if ppr.is_some() {
            return Err(ApiError::unprocessable(
                "missing-tacho-channel",
                "Tachometer channel missing",
                format!(
                    "`tacho_ppr` was given but the record has no tachometer channel (a channel \
                     named `{name}`, or the machine's `tacho_channel`)"
                ),
            )
            .with("tacho_channel", name));
        }
        return Ok(None);
    }
    let machine_ppr = machine.map_or(1, |m| m.tacho_ppr.max(1) as usize);
    Ok(Some(TachoChannel {
        name: name.to_string(),
        pulses_per_rev: ppr.unwrap_or(machine_ppr),
    }))
}

/// What the request says about the record besides its samples.
pub(super) struct RecordRequest {
    /// `?channel=`.
    pub channel: Option<String>,
    /// Posted with `?baseline=true`.
    pub declared_healthy: bool,
    pub tacho: Option<TachoChannel>,
}

/// Everything the blocking part of an ingest needs: the decoded record, the chosen channels
/// and the machine's context (gearbox, table, baseline, calibration).
pub(super) struct AssessJob {
    dec: Decoded,
    chosen: Vec<usize>,
    ctx: MachineContext,
    calibration: Option<MachineCalibration>,
    baselines: Arc<Baselines>,
    thresholds: Thresholds,
    /// Posted with `?baseline=true`.
    declared_healthy: bool,
    tacho: Option<TachoChannel>,
    /// The machine's declared units and ISO class.
    units: MachineUnits,
    /// Draw the evidence plot on the path: the record's samples are not kept to draw it from
    /// later.
    draws: bool,
    /// The machine's own model, when one is ready for its baseline.
    own: Option<Arc<OwnModel>>,
}

/// What [`AssessJob::run`] gives back: the record, its assessment, the spectrum plot, the
/// stages' clock, the gearbox it was assessed with, and what drawing its evidence plot later
/// needs (when it has one).
pub(super) struct Assessed {
    pub dec: Decoded,
    pub assessment: Assessment,
    pub spectrum: Option<PlotSpectrum>,
    pub clock: StageClock,
    pub gearbox_row: GearboxRow,
    pub gearbox: Arc<Gearbox>,
    pub undrawn: Option<Undrawn>,
}

impl RecordRequest {
    /// What a re-read of the record needs of this request (and of the record's load).
    fn reread_request(&self, dec: &Decoded) -> RereadRequest {
        RereadRequest {
            channel: self.channel.clone(),
            declared_healthy: self.declared_healthy,
            tacho_ppr: self.tacho.as_ref().map(|t| t.pulses_per_rev),
            load: dec.load.clone(),
        }
    }

    /// The machine's gearbox (and its table, when ready), baseline and calibration, and the
    /// channels to assess (never the tachometer's).
    pub(super) async fn load(
        self,
        app: &AppState,
        machine_id: &str,
        machine: Option<MachineRow>,
        dec: Decoded,
    ) -> ApiResult<AssessJob> {
        let ctx = crate::service::context::context_of(app, machine_id, machine).await?;
        let tacho_index = self
            .tacho
            .as_ref()
            .and_then(|t| dec.channels.iter().position(|(n, _)| *n == t.name));
        let chosen = dec.select(
            self.channel.as_deref(),
            ctx.machine.as_ref().and_then(|m| m.channels.as_deref()),
            tacho_index,
        )?;
        let units = crate::service::units::machine_units(ctx.machine.as_ref())?;
        let baselines = crate::service::context::baselines(
            app,
            ctx.machine.as_ref(),
            &ctx.gearbox_row.hash,
            ctx.diagnoser.clone(),
        )
        .await?;
        let calibration = app
            .store
            .get_calibration(machine_id)
            .await?
            .map(|c| calibration_of(&c));
        let own = match ctx.diagnoser {
            Some(_) => {
                crate::service::physics::own_model(app, ctx.machine.as_ref(), &ctx.gearbox_row.hash)
                    .await?
            }
            None => None,
        };
        Ok(AssessJob {
            own,
            dec,
            chosen,
            ctx,
            calibration,
            baselines,
            thresholds: app.settings.thresholds,
            declared_healthy: self.declared_healthy,
            tacho: self.tacho,
            units,
            draws: app.settings.raw_retention.is_zero(),
        })
    }
}

impl AssessJob {
    /// The assessment (timed by stage) and the spectrum plot of the deciding channel.
    pub(super) fn run(mut self) -> crate::Result<Assessed> {
        let mut clock = StageClock::new();
        let facts = RecordFacts {
            sample_rate_hz: self.dec.sample_rate_hz,
            shaft_hz: self.dec.shaft_hz,
            sensor: self.dec.sensor.clone(),
            declared_healthy: self.declared_healthy,
            load: self.dec.load.clone(),
            tacho: self.tacho.clone(),
        };
        let ctx = &self.ctx;
        let diagnoser: Option<&TableDiagnoser> = ctx.diagnoser.as_deref();
        let machine = Machine {
            gearbox: &ctx.gearbox,
            gearbox_ref: ctx.gearbox_ref(),
            described: reads_as_described(&ctx.gearbox, self.tacho.is_some()),
            diagnoser,
            table_note: ctx.table_note(),
            input_shaft_hz: ctx.input_shaft_hz(),
            baselines: &self.baselines.pooled,
            state_baselines: &self.baselines.states,
            baseline_counts: &self.baselines.counts,
            calibration: self.calibration.as_ref(),
            paths: &self.baselines.paths,
            own_model: self.own.as_deref(),
            // A described gearbox's table is extended to the speeds its records run at (the
            // built-in rig's is the served file).
            extends_tables: !ctx.gearbox_row.builtin,
            thresholds: self.thresholds,
            units: std::mem::take(&mut self.units),
        };
        // With raw samples kept the evidence plot is not drawn here but when first asked for
        // (`service::evidence`), from the stored samples.
        let assess_with = if self.draws { assess } else { assess_undrawn };
        let a = assess_with(
            &mut self.dec.channels,
            &self.chosen,
            &facts,
            &machine,
            &mut |stage| clock.lap(stage),
        )?;
        let samples = &self.dec.channels[self.chosen[a.deciding]].1;
        let spectrum = plot(&a, samples, &facts, &ctx.gearbox, ctx.input_shaft_hz());
        // The plot is drawn where the record's state is measured on a described machine
        // (the core's rule); what drawing it later needs.
        let deciding = self.chosen[a.deciding];
        let undrawn = (machine.described && a.operating_state.is_some()).then(|| Undrawn {
            chosen: self.chosen.clone(),
            deciding,
            channel: self.dec.channels[deciding].0.clone(),
            tacho: facts.tacho.map(|t| (t.name, t.pulses_per_rev)),
            shaft_hz: facts.shaft_hz,
            input_shaft_hz: ctx.input_shaft_hz(),
            load: facts.load,
            gearbox_id: ctx.gearbox_row.id.clone(),
            gearbox_hash: ctx.gearbox_row.hash.clone(),
        });
        clock.lap("plot");
        Ok(Assessed {
            dec: self.dec,
            assessment: a,
            spectrum,
            clock,
            gearbox_row: self.ctx.gearbox_row,
            gearbox: self.ctx.gearbox,
            undrawn,
        })
    }
}

/// A stored calibration as the assessment holds it.
pub fn calibration_of(c: &crate::store::CalibrationRow) -> MachineCalibration {
    MachineCalibration {
        id: c.id.clone(),
        calibrated_at: crate::time::rfc3339(c.created_at),
        effects: serde_json::from_str(&c.effects).unwrap_or(serde_json::Value::Array(vec![])),
    }
}

/// The spectrum plot of the deciding channel: from the spectrum its diagnosis computed when it
/// has one, else from its samples.
fn plot(
    a: &Assessment,
    samples: &[f64],
    facts: &RecordFacts,
    gearbox: &Arc<Gearbox>,
    input_shaft_hz: Option<f64>,
) -> Option<PlotSpectrum> {
    let fs = facts.sample_rate_hz;
    match &a.deciding_channel().reading {
        Some(r) => {
            let f1 = r.diagnosis.f1_hz;
            match &r.spectrum {
                Some(s) => plot_from_spectrum(s, f1, &r.marks()),
                None => plot_spectrum(samples, fs, f1, &r.marks()),
            }
        }
        None => {
            let f1 = input_shaft_hz.map(|h| gearbox.f1_hz(h)).unwrap_or(f64::NAN);
            plot_spectrum(samples, fs, f1, &[])
        }
    }
}
