-- Measurement time (issue 33 item 0). Keep in step with ../postgres/0006_measured_at.sql: the
-- same columns and meanings.
--
-- measured_at: when the record was measured, unix milliseconds: its `recorded_at` (RFC 3339,
-- checked by the service before it is stored) when the sender gave one, else its received_at.
-- Every series (the machine view's trend, GET …/trend, the dashboard) is ordered by it, so a
-- back-filled history gives the same trend as one that arrived live. received_at keeps meaning
-- receive time (retention, idempotency). The diagnosis carries its record's measured_at so that
-- series are read from one table in measurement order.
ALTER TABLE records ADD COLUMN measured_at BIGINT;
UPDATE records SET measured_at = COALESCE(
    CAST(ROUND((julianday(recorded_at) - 2440587.5) * 86400000.0) AS INTEGER),
    received_at);
ALTER TABLE diagnoses ADD COLUMN measured_at BIGINT;
UPDATE diagnoses SET measured_at = COALESCE(
    (SELECT r.measured_at FROM records r WHERE r.id = diagnoses.record_id),
    created_at);
CREATE INDEX diagnoses_machine_measured ON diagnoses(machine_id, measured_at, seq);
