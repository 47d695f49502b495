-- Tables where the machines run, re-read records and the machine's own model. Keep in step
-- with ../sqlite/0012_tables_where_machines_run.sql: the same tables, columns and meanings.
--
-- gearboxes.table_columns: JSON array of the Ω1 columns of the stored table (NULL while none
-- is stored, and for the built-in rig, whose table is the served file). extension_*: an
-- extension of a ready table to new columns, a job of its own beside the table (which stays
-- ready and in use meanwhile): extension_status NULL (none) | queued | running | failed,
-- claimed by one replica (extension_claimed_by) for a lease (extension_lease_until, unix ms)
-- renewed with its progress; extension_columns the columns it computes towards (JSON array,
-- set when claimed).
ALTER TABLE gearboxes ADD COLUMN table_columns TEXT;
ALTER TABLE gearboxes ADD COLUMN extension_status TEXT;
ALTER TABLE gearboxes ADD COLUMN extension_progress DOUBLE PRECISION NOT NULL DEFAULT 0;
ALTER TABLE gearboxes ADD COLUMN extension_error TEXT;
ALTER TABLE gearboxes ADD COLUMN extension_claimed_by TEXT;
ALTER TABLE gearboxes ADD COLUMN extension_lease_until BIGINT NOT NULL DEFAULT 0;
ALTER TABLE gearboxes ADD COLUMN extension_attempts BIGINT NOT NULL DEFAULT 0;
ALTER TABLE gearboxes ADD COLUMN extension_columns TEXT;
ALTER TABLE gearboxes ADD COLUMN extension_queued_at BIGINT;
UPDATE gearboxes SET table_columns = (signature_table::json -> 'grid' -> 'omega1')::text
    WHERE signature_table IS NOT NULL;

-- The input-shaft rates (Hz, rounded to 0.01) records of a gearbox description (hash) ran at
-- outside its table: part of what its table must cover.
CREATE TABLE table_speeds (
    gearbox_id  TEXT NOT NULL,
    hash        TEXT NOT NULL,
    input_hz    DOUBLE PRECISION NOT NULL,
    machine_id  TEXT,
    created_at  BIGINT NOT NULL,
    PRIMARY KEY (gearbox_id, hash, input_hz)
);

-- A machine's declared range of input-shaft rates (Hz), both or neither.
ALTER TABLE machines ADD COLUMN speed_lo_hz DOUBLE PRECISION;
ALTER TABLE machines ADD COLUMN speed_hi_hz DOUBLE PRECISION;

-- diagnoses.wear_withheld: the code of a withheld wear figure (poor-fit, one-part,
-- outside-calibration, table-in-progress, outside-table), NULL when the figure is given (and
-- for diagnoses stored before this migration). reread_status: pending (a table-in-progress
-- diagnosis whose record is read again when the table covers it) | done (it was: a later
-- diagnosis replaces it) | unavailable (the record's raw samples were not kept);
-- reread_request: what the record came with besides its samples (JSON), while pending.
-- replaces: on a re-read diagnosis, the id of the diagnosis it replaces.
ALTER TABLE diagnoses ADD COLUMN wear_withheld TEXT;
ALTER TABLE diagnoses ADD COLUMN reread_status TEXT;
ALTER TABLE diagnoses ADD COLUMN reread_request TEXT;
ALTER TABLE diagnoses ADD COLUMN replaces TEXT;
CREATE INDEX diagnoses_reread ON diagnoses(machine_id) WHERE reread_status = 'pending';

-- A machine's own model: its physics fitted to its baseline records and its own table, one
-- row per machine for the machine (machine_created_at), gearbox description and baseline
-- version it was made from; a change of either queues it again. status: queued | running |
-- ready | refused (the fit was refused: error says why) | failed. report: the fitted physics
-- (JSON), kept once fitted so that a restarted job only computes the table; own_table: the
-- table JSON once ready. Claimed like a table job (claimed_by, lease_until).
CREATE TABLE machine_physics (
    machine_id          TEXT PRIMARY KEY,
    machine_created_at  BIGINT NOT NULL,
    gearbox_id          TEXT NOT NULL,
    gearbox_hash        TEXT NOT NULL,
    baseline_version    BIGINT NOT NULL,
    status              TEXT NOT NULL,
    progress            DOUBLE PRECISION NOT NULL DEFAULT 0,
    error               TEXT,
    report              TEXT,
    own_table           TEXT,
    claimed_by          TEXT,
    lease_until         BIGINT NOT NULL DEFAULT 0,
    attempts            BIGINT NOT NULL DEFAULT 0,
    created_at          BIGINT NOT NULL,
    updated_at          BIGINT NOT NULL,
    started_at          BIGINT,
    finished_at         BIGINT
);
CREATE INDEX machine_physics_jobs ON machine_physics(status, lease_until);
