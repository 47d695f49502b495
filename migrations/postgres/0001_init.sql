-- gearwear service schema (PostgreSQL). Times are unix milliseconds (BIGINT); JSON is TEXT.
-- Keep in step with ../sqlite/0001_init.sql: the same tables, columns and meanings.
CREATE TABLE machines (
    id                 TEXT PRIMARY KEY,
    created_at         BIGINT NOT NULL,
    updated_at         BIGINT NOT NULL,
    record_count       BIGINT NOT NULL DEFAULT 0,
    last_diagnosis_id  TEXT,
    alert_level        TEXT NOT NULL DEFAULT 'unknown'
);

CREATE TABLE records (
    id              TEXT PRIMARY KEY,
    machine_id      TEXT NOT NULL REFERENCES machines(id),
    received_at     BIGINT NOT NULL,
    recorded_at     TEXT,
    sensor          TEXT,
    content_type    TEXT NOT NULL,
    sample_rate_hz  DOUBLE PRECISION NOT NULL,
    shaft_hz        DOUBLE PRECISION,
    sample_count    BIGINT NOT NULL,
    sha256          TEXT NOT NULL,
    features        TEXT NOT NULL,
    samples         BYTEA
);
CREATE INDEX records_machine ON records(machine_id, received_at);

CREATE TABLE diagnoses (
    seq             BIGSERIAL PRIMARY KEY,
    id              TEXT NOT NULL UNIQUE,
    record_id       TEXT NOT NULL REFERENCES records(id),
    machine_id      TEXT NOT NULL REFERENCES machines(id),
    created_at      BIGINT NOT NULL,
    ea_estimate     DOUBLE PRECISION NOT NULL,
    ea_lower        DOUBLE PRECISION NOT NULL,
    ea_upper        DOUBLE PRECISION NOT NULL,
    alert_level     TEXT NOT NULL,
    motion_state    TEXT NOT NULL,
    body            TEXT NOT NULL,
    spectrum        TEXT NOT NULL
);
CREATE INDEX diagnoses_machine ON diagnoses(machine_id, seq);

CREATE TABLE api_keys (
    id          TEXT PRIMARY KEY,
    hash        TEXT NOT NULL,
    scopes      TEXT NOT NULL,
    label       TEXT NOT NULL DEFAULT '',
    created_at  BIGINT NOT NULL,
    revoked_at  BIGINT
);

CREATE TABLE idempotency_keys (
    key_id        TEXT NOT NULL,
    idem_key      TEXT NOT NULL,
    request_hash  TEXT NOT NULL,
    status        BIGINT NOT NULL,
    response      TEXT NOT NULL,
    created_at    BIGINT NOT NULL,
    PRIMARY KEY (key_id, idem_key)
);

CREATE TABLE webhooks (
    id          TEXT PRIMARY KEY,
    url         TEXT NOT NULL,
    secret      TEXT NOT NULL,
    events      TEXT NOT NULL,
    created_at  BIGINT NOT NULL,
    deleted_at  BIGINT
);

CREATE TABLE deliveries (
    id               TEXT PRIMARY KEY,
    webhook_id       TEXT NOT NULL REFERENCES webhooks(id),
    event            TEXT NOT NULL,
    payload          TEXT NOT NULL,
    status           TEXT NOT NULL,
    attempts         BIGINT NOT NULL DEFAULT 0,
    next_attempt_at  BIGINT NOT NULL,
    created_at       BIGINT NOT NULL,
    delivered_at     BIGINT
);
CREATE INDEX deliveries_due ON deliveries(status, next_attempt_at);
CREATE INDEX deliveries_webhook ON deliveries(webhook_id, created_at);

CREATE TABLE delivery_attempts (
    delivery_id   TEXT NOT NULL REFERENCES deliveries(id),
    attempt       BIGINT NOT NULL,
    attempted_at  BIGINT NOT NULL,
    status_code   BIGINT,
    error         TEXT,
    duration_ms   BIGINT NOT NULL,
    PRIMARY KEY (delivery_id, attempt)
);
