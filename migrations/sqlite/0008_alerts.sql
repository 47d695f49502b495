-- Alerts as events (issue 33 item 3). Keep in step with ../postgres/0008_alerts.sql: the same
-- columns and meanings.
--
-- alerts: one row per episode of a machine (opened → acknowledged → closed). Times are unix
-- milliseconds; opened_at and closed_at are the measurement time of the record that opened or
-- closed it (its recorded_at when given, else when it was received). At most one episode per
-- machine is not closed (the partial unique index): two replicas, or a crash and a retry,
-- cannot open a second one.
CREATE TABLE alerts (
    id               TEXT PRIMARY KEY,
    machine_id       TEXT NOT NULL,
    level            TEXT NOT NULL,
    state            TEXT NOT NULL,
    opened_at        BIGINT NOT NULL,
    record_id        TEXT NOT NULL,
    acknowledged_at  BIGINT,
    acknowledged_by  TEXT,
    note             TEXT,
    closed_at        BIGINT,
    closed_record_id TEXT,
    peak_severity    DOUBLE PRECISION NOT NULL,
    created_at       BIGINT NOT NULL
);
CREATE INDEX alerts_machine ON alerts(machine_id, opened_at);
CREATE INDEX alerts_state ON alerts(state, opened_at);
CREATE UNIQUE INDEX alerts_one_open ON alerts(machine_id) WHERE state <> 'closed';

-- alert_events: the audit trail (opened, escalated, acknowledged, closed), in order.
CREATE TABLE alert_events (
    seq        INTEGER PRIMARY KEY AUTOINCREMENT,
    alert_id   TEXT NOT NULL,
    at         BIGINT NOT NULL,
    event      TEXT NOT NULL,
    by_key     TEXT,
    note       TEXT,
    record_id  TEXT,
    level      TEXT,
    severity   DOUBLE PRECISION
);
CREATE INDEX alert_events_alert ON alert_events(alert_id, seq);

-- alert_trackers: each machine's runs of records between transitions (the state machine of
-- crates/core/src/assessment/episodes.rs); the open episode itself is its row in alerts.
CREATE TABLE alert_trackers (
    machine_id TEXT PRIMARY KEY,
    rising     BIGINT NOT NULL DEFAULT 0,
    alarm_run  BIGINT NOT NULL DEFAULT 0,
    falling    BIGINT NOT NULL DEFAULT 0,
    run_peak   DOUBLE PRECISION NOT NULL DEFAULT 0
);
