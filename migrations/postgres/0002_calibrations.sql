-- A machine's current closed-loop calibration (issue 6). Keep in step with
-- ../sqlite/0002_calibrations.sql. One row per machine: a new calibration replaces the old.
-- No foreign key to machines: a machine may be calibrated before its first record.
-- effects: JSON list of {name, kind, parameters} (the accepted effects, held fixed by later
-- diagnoses); report: the full CalibrationReport JSON as answered.
CREATE TABLE calibrations (
    machine_id  TEXT PRIMARY KEY,
    id          TEXT NOT NULL UNIQUE,
    created_at  BIGINT NOT NULL,
    effects     TEXT NOT NULL,
    report      TEXT NOT NULL
);
