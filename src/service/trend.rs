//! A machine's trend: `GET /v1/machines/{id}/trend?series=&channel=` and the
//! machine view's `trend_summary` (of the wear series, or the novelty series for a machine
//! whose records have no wear figure). The series are read in measurement order (`measured_at`:
//! the record's `recorded_at`, else its receive time) and fitted by the core's
//! [`trend`](crate::trend) (Theil–Sen, Mann–Kendall, bootstrap intervals).

use axum::extract::{Path, RawQuery, State};
use axum::http::HeaderMap;
use axum::response::Response;
use serde::Deserialize;
use serde_json::{Value, json};

use super::AppState;
use super::auth::Caller;
use super::error::{ApiError, ApiResult};
use super::http::{check_machine_id, json_with_etag};
use crate::assessment::Level;
use crate::condition::FindingKind;
use crate::store::{AlertRow, DiagnosisRow};
use crate::time::rfc3339;
use crate::trend::{self, Sample, Trend, TrendOptions};
use gearwear_core::words::UnknownWord;

/// How many of a machine's latest diagnoses (by measurement time) a trend fits: 50 days at
/// 4 records a day.
pub const SERIES_POINTS: i64 = 200;

const MS_PER_DAY: f64 = 86_400_000.0;

/// Which series: `wear`, `novelty` or `finding:<kind>` (a finding's strength; `<kind>` as in
/// a finding's `kind`, optionally `<kind>@<shaft>`).
#[derive(Debug, Clone, PartialEq)]
enum Series {
    Wear,
    Novelty,
    Finding {
        kind: FindingKind,
        shaft: Option<String>,
    },
}

impl Series {
    fn parse(s: Option<&str>) -> ApiResult<Series> {
        match s.unwrap_or("wear") {
            "wear" => Ok(Series::Wear),
            "novelty" => Ok(Series::Novelty),
            f if f.starts_with("finding:") && f.len() > "finding:".len() && f.len() <= 200 => {
                let name = &f["finding:".len()..];
                let (kind, shaft) = match name.split_once('@') {
                    Some((k, s)) => (k, Some(s.to_string())),
                    None => (name, None),
                };
                let kind: FindingKind = kind.parse().map_err(|e: UnknownWord| {
                    ApiError::bad_request(
                        "invalid-query",
                        "Invalid query parameter",
                        format!(
                            "`series=finding:<kind>` names no finding kind: `{}` (one of {})",
                            e.word,
                            e.words
                                .iter()
                                .map(|k| format!("`{k}`"))
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    )
                    .with("parameter", "series")
                })?;
                Ok(Series::Finding { kind, shaft })
            }
            other => Err(ApiError::bad_request(
                "invalid-query",
                "Invalid query parameter",
                format!(
                    "`series` must be `wear`, `novelty` or `finding:<kind>` (a finding's kind, \
                     e.g. `finding:gear-local-damage`, optionally `@<shaft>`), got `{other}`"
                ),
            )
            .with("parameter", "series")),
        }
    }

    fn name(&self) -> String {
        match self {
            Series::Wear => "wear".into(),
            Series::Novelty => "novelty".into(),
            Series::Finding { kind, shaft: None } => format!("finding:{kind}"),
            Series::Finding {
                kind,
                shaft: Some(s),
            } => format!("finding:{kind}@{s}"),
        }
    }

    fn unit(&self) -> &'static str {
        match self {
            Series::Wear => "ea (reference lengths)",
            Series::Novelty => "novelty score",
            Series::Finding { .. } => "finding strength (RMS z of its evidence)",
        }
    }

    /// Does a value need the diagnosis's body (a channel's or a finding's), or do the stored
    /// columns hold it (the deciding channel's wear and novelty)?
    fn needs_body(&self, channel: Option<&str>) -> bool {
        channel.is_some() || matches!(self, Series::Finding { .. })
    }
}

/// One point: `(measured_at ms, value, record id, diagnosis id)`; also the novelty threshold
/// it was judged by.
struct Point<'a> {
    measured_at: i64,
    value: f64,
    row: &'a DiagnosisRow,
    novelty_threshold: Option<f64>,
}

/// What a series reads of a stored diagnosis body (the assessment the service wrote): the
/// deciding channel's view, and each channel's when the record had several.
#[derive(Debug, Default, Deserialize)]
struct StoredBody {
    #[serde(flatten)]
    view: ChannelView,
    channel: Option<String>,
    channels: Option<Vec<ChannelView>>,
}

/// One channel's wear, novelty and findings in a stored body.
#[derive(Debug, Default, Deserialize)]
struct ChannelView {
    name: Option<String>,
    wear_degree: Option<StoredWear>,
    novelty: Option<StoredNovelty>,
    #[serde(default)]
    findings: Vec<StoredFinding>,
}

#[derive(Debug, Deserialize)]
struct StoredWear {
    estimate: Option<f64>,
}

#[derive(Debug, Deserialize)]
struct StoredNovelty {
    score: Option<f64>,
    threshold: Option<f64>,
}

#[derive(Debug, Deserialize)]
struct StoredFinding {
    /// `None`: a kind this service no longer writes (a body stored by an older one).
    #[serde(deserialize_with = "known_kind")]
    kind: Option<FindingKind>,
    shaft: Option<String>,
    strength: Option<f64>,
}

fn known_kind<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<FindingKind>, D::Error> {
    Ok(String::deserialize(d)?.parse().ok())
}

/// The part of a diagnosis body that describes `channel`: the `channels` entry of that name,
/// or the body itself when its deciding channel is that one (a one-channel record).
fn channel_view<'a>(body: &'a StoredBody, channel: &str) -> Option<&'a ChannelView> {
    if let Some(cs) = &body.channels {
        return cs.iter().find(|c| c.name.as_deref() == Some(channel));
    }
    (body.channel.as_deref() == Some(channel)).then_some(&body.view)
}

/// The series' value in one channel's view of a diagnosis (`wear_degree`, `novelty`,
/// `findings`), with the novelty threshold.
fn value_in(view: &ChannelView, series: &Series) -> Option<(f64, Option<f64>)> {
    match series {
        Series::Wear => view.wear_degree.as_ref()?.estimate.map(|v| (v, None)),
        Series::Novelty => {
            let n = view.novelty.as_ref()?;
            n.score.map(|v| (v, n.threshold))
        }
        Series::Finding { kind, shaft } => view
            .findings
            .iter()
            .filter(|f| f.kind == Some(*kind))
            .filter(|f| shaft.is_none() || f.shaft.as_deref() == shaft.as_deref())
            .filter_map(|f| f.strength)
            .reduce(f64::max)
            .map(|v| (v, None)),
    }
}

/// The points of a series in measurement order: a diagnosis without the value (no wear
/// figure, no baseline, not that finding, not that channel) has no point.
fn points<'a>(rows: &'a [DiagnosisRow], series: &Series, channel: Option<&str>) -> Vec<Point<'a>> {
    rows.iter()
        .filter_map(|d| {
            let (value, novelty_threshold) = if series.needs_body(channel) {
                let body: StoredBody = serde_json::from_str(&d.body).ok()?;
                let view = match channel {
                    Some(c) => channel_view(&body, c)?,
                    None => &body.view,
                };
                value_in(view, series)?
            } else {
                match series {
                    Series::Wear => (d.has_wear.then_some(d.ea_estimate)?, None),
                    _ => (d.novelty_score?, d.novelty_threshold),
                }
            };
            Some(Point {
                measured_at: d.measured_at,
                value,
                row: d,
                novelty_threshold,
            })
        })
        .collect()
}

/// The thresholds a series is judged by: the service's wear thresholds; for the novelty score
/// the latest baseline threshold (warning) and twice it (alarm), as the alert policy does;
/// none for a finding.
fn thresholds(app: &AppState, series: &Series, pts: &[Point]) -> Option<(f64, f64)> {
    match series {
        Series::Wear => Some((
            app.settings.thresholds.warning,
            app.settings.thresholds.alarm,
        )),
        Series::Novelty => pts
            .iter()
            .rev()
            .find_map(|p| p.novelty_threshold)
            .map(|t| (t, 2.0 * t)),
        Series::Finding { .. } => None,
    }
}

/// Fit the points: times in days before the latest point.
fn fit_points(pts: &[Point]) -> Option<Trend> {
    let last = pts.iter().map(|p| p.measured_at).max()?;
    let samples: Vec<Sample> = pts
        .iter()
        .map(|p| Sample {
            t_days: (p.measured_at - last) as f64 / MS_PER_DAY,
            value: p.value,
        })
        .collect();
    trend::fit(&samples, &TrendOptions::default())
}

/// `{fit, thresholds, projection, verdict}` of a series' points. With the machine's open
/// alert: no projection to a level the alert already holds (the verdict says it is open
/// since when instead, never "alarm in 6 days" over an open alarm).
fn assess(pts: &[Point], limits: Option<(f64, f64)>, open: Option<&AlertRow>) -> Value {
    let t = fit_points(pts);
    let last = pts.iter().map(|p| p.measured_at).max().unwrap_or(0);
    let held = |name: &str| {
        let lv = if name == "alarm" {
            Level::Alarm
        } else {
            Level::Warning
        };
        limits.is_some() && open.is_some_and(|a| a.level >= lv)
    };
    let crossing = |name: &str, threshold: f64| -> Value {
        match t.as_ref().and_then(|t| t.crossing(threshold)) {
            Some(c) if !held(name) => json!({
                "days": c.days,
                "interval_90": c.interval_90,
                // Beyond a century the date means nothing (and would overflow).
                "at": (c.days <= 36_500.0)
                    .then(|| rfc3339(last + (c.days * MS_PER_DAY).round() as i64)),
            }),
            _ => Value::Null,
        }
    };
    let significant = t.as_ref().is_some_and(|t| t.fit.significant);
    let projection = match limits {
        Some((w, a)) if significant => {
            json!({"warning": crossing("warning", w), "alarm": crossing("alarm", a)})
        }
        _ => Value::Null,
    };
    let names: Vec<(&str, f64)> = limits
        .map(|(w, a)| vec![("warning", w), ("alarm", a)])
        .unwrap_or_default()
        .into_iter()
        .filter(|(n, _)| !held(n))
        .collect();
    let mut verdict = match &t {
        None => format!("not enough points for a trend ({})", pts.len()),
        Some(_) => trend::verdict(t.as_ref(), &names),
    };
    if let Some(a) = open.filter(|_| limits.is_some()) {
        let since = rfc3339(a.opened_at);
        let open_text = format!(
            "{} open since {} {} UTC",
            a.level,
            &since[..10],
            &since[11..16]
        );
        verdict = if names.is_empty() || t.is_none() {
            open_text
        } else {
            format!("{open_text}; {verdict}")
        };
    }
    json!({
        "fit": t.as_ref().map(|t| &t.fit),
        "thresholds": limits.map(|(w, a)| json!({"warning": w, "alarm": a})),
        "projection": projection,
        "verdict": verdict,
    })
}

/// The machine view's `trend_summary`: `{series, verdict, fit, projection}` over `rows` (the
/// latest diagnoses in measurement order) of the series that exists — the wear degree when
/// any record has a wear figure, else the novelty score when any has one — agreeing with the
/// machine's open alert (`open`).
pub fn summary(app: &AppState, rows: &[DiagnosisRow], open: Option<&AlertRow>) -> Value {
    let mut series = Series::Wear;
    let mut pts = points(rows, &series, None);
    if pts.is_empty() {
        let novelty = points(rows, &Series::Novelty, None);
        if !novelty.is_empty() {
            (series, pts) = (Series::Novelty, novelty);
        }
    }
    let mut a = assess(&pts, thresholds(app, &series, &pts), open);
    a["series"] = series.name().into();
    if let Value::Object(m) = &mut a {
        m.remove("thresholds");
    }
    a
}

/// Does any webhook subscribe to an event whose payload carries the `trend_summary`
/// (`diagnosis.created`, `wear.threshold_crossed`, or `*`)? True when the list cannot be read
/// (the payloads are then complete; the cost is only CPU).
pub async fn payloads_wanted(app: &AppState) -> bool {
    match app.store.list_webhooks().await {
        Ok(hooks) => hooks.iter().any(|h| {
            h.events.iter().any(|e| {
                matches!(
                    e.as_str(),
                    "diagnosis.created" | "wear.threshold_crossed" | "*"
                )
            })
        }),
        Err(_) => true,
    }
}

/// The machine's `trend_summary` with a new diagnosis in it (not stored yet): the latest
/// stored diagnoses by measurement time plus this one, for the record's webhook payloads.
/// Null when the history cannot be read (the record is still stored; its payloads then lack
/// the trend). It agrees with the alert open when the record arrived (this record's own
/// transition is made in its ingest transaction, after the payload is written).
pub async fn summary_with(app: &AppState, d: &DiagnosisRow) -> Value {
    let mut rows = match app
        .store
        .recent_diagnoses(&d.machine_id, SERIES_POINTS)
        .await
    {
        Ok(rows) => rows,
        Err(e) => {
            tracing::warn!(machine_id = %d.machine_id, error = %e, "trend for the webhook payload");
            return Value::Null;
        }
    };
    let at = rows.partition_point(|r| r.measured_at <= d.measured_at);
    let mut row = d.clone();
    (row.body, row.spectrum, row.evidence) = (String::new(), String::new(), String::new());
    rows.insert(at, row);
    if rows.len() > SERIES_POINTS as usize {
        rows.remove(0);
    }
    let open = match super::alerts::open_alert(app, &d.machine_id).await {
        Ok(open) => open,
        Err(e) => {
            tracing::warn!(machine_id = %d.machine_id, error = ?e, "open alert for the webhook payload");
            None
        }
    };
    summary(app, &rows, open.as_ref())
}

#[derive(Debug, Default, Deserialize)]
struct TrendQuery {
    series: Option<String>,
    channel: Option<String>,
}

/// `GET /v1/machines/{machine_id}/trend?series=wear|novelty|finding:<kind>&channel=`.
pub async fn get_trend(
    State(app): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    RawQuery(query): RawQuery,
    headers: HeaderMap,
) -> ApiResult<Response> {
    caller.require_read(&app)?;
    check_machine_id(&id)?;
    let q: TrendQuery =
        serde_urlencoded::from_str(query.as_deref().unwrap_or("")).map_err(|e| {
            ApiError::bad_request("invalid-query", "Invalid query parameter", e.to_string())
                .with("parameter", "query")
        })?;
    let series = Series::parse(q.series.as_deref())?;
    let channel = q.channel.as_deref().filter(|c| !c.is_empty());
    if channel.is_some_and(|c| c.len() > 100) {
        return Err(ApiError::bad_request(
            "invalid-query",
            "Invalid query parameter",
            "`channel` is a channel name of at most 100 characters",
        )
        .with("parameter", "channel"));
    }
    if app.store.get_machine(&id).await?.is_none() {
        return Err(super::error::unknown_machine(&id));
    }
    let rows = if series.needs_body(channel) {
        app.store.series_diagnoses(&id, SERIES_POINTS).await?
    } else {
        app.store.recent_diagnoses(&id, SERIES_POINTS).await?
    };
    let pts = points(&rows, &series, channel);
    let open = super::alerts::open_alert(&app, &id).await?;
    let mut body = assess(&pts, thresholds(&app, &series, &pts), open.as_ref());
    body["machine_id"] = id.as_str().into();
    body["series"] = series.name().into();
    body["channel"] = channel.map_or(Value::Null, Value::from);
    body["unit"] = series.unit().into();
    body["points"] = pts
        .iter()
        .map(|p| {
            json!({
                "measured_at": rfc3339(p.measured_at),
                "value": p.value,
                "record_id": p.row.record_id,
                "diagnosis_id": p.row.id,
            })
        })
        .collect::<Vec<_>>()
        .into();
    Ok(json_with_etag(&headers, &body))
}
