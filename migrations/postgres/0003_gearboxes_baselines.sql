-- Gearboxes, machine configuration and baselines (issue 14). Keep in step with
-- ../sqlite/0003_gearboxes_baselines.sql: the same tables, columns and meanings.
--
-- gearboxes: a user's gearbox description (format gearwear-gearbox v1) and the background job
-- that precomputes its signature table. status: queued | running | ready | failed. A job is
-- claimed by one replica (claimed_by) for a lease (lease_until, unix ms) that it renews while it
-- runs; a job whose lease ran out (its replica died) is claimed again by another.
-- description: canonical JSON of the description (what the hash covers); source: the text as
-- submitted. signature_table: the table JSON once ready. builtin: the paper's rig, whose table is
-- the served signatures file (not stored here).
CREATE TABLE gearboxes (
    id               TEXT PRIMARY KEY,
    name             TEXT NOT NULL,
    source           TEXT NOT NULL,
    source_format    TEXT NOT NULL,
    description      TEXT NOT NULL,
    hash             TEXT NOT NULL,
    builtin          BIGINT NOT NULL DEFAULT 0,
    status           TEXT NOT NULL,
    progress         DOUBLE PRECISION NOT NULL DEFAULT 0,
    error            TEXT,
    claimed_by       TEXT,
    lease_until      BIGINT NOT NULL DEFAULT 0,
    attempts         BIGINT NOT NULL DEFAULT 0,
    signature_table  TEXT,
    created_at       BIGINT NOT NULL,
    updated_at       BIGINT NOT NULL,
    started_at       BIGINT,
    finished_at      BIGINT
);
CREATE INDEX gearboxes_jobs ON gearboxes(status, lease_until);

-- A machine's configuration (PUT /v1/machines/{id}): its gearbox (NULL: the paper's rig), the
-- nominal input-shaft rate (Hz) and the channel names it records (JSON list, NULL: any).
ALTER TABLE machines ADD COLUMN gearbox_id TEXT;
ALTER TABLE machines ADD COLUMN input_shaft_hz DOUBLE PRECISION;
ALTER TABLE machines ADD COLUMN channels TEXT;

-- Baseline: records marked healthy (1) and when. channels: JSON list of the channel names of a
-- multichannel record, whose samples are then the channels one after another.
ALTER TABLE records ADD COLUMN baseline BIGINT NOT NULL DEFAULT 0;
ALTER TABLE records ADD COLUMN baseline_at BIGINT;
ALTER TABLE records ADD COLUMN channels TEXT;
CREATE INDEX records_baseline ON records(machine_id, baseline);

-- has_wear 0: no wear degree (the gearbox's table was not ready); ea_* are then 0 and the API
-- answers null. novelty_*: the deciding channel's novelty against the machine's baseline (NULL
-- without one); channel: the channel that decides the alert.
ALTER TABLE diagnoses ADD COLUMN has_wear BIGINT NOT NULL DEFAULT 1;
ALTER TABLE diagnoses ADD COLUMN novelty_score DOUBLE PRECISION;
ALTER TABLE diagnoses ADD COLUMN novelty_threshold DOUBLE PRECISION;
ALTER TABLE diagnoses ADD COLUMN channel TEXT;
