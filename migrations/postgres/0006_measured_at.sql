-- Measurement time (issue 33 item 0). Keep in step with ../sqlite/0006_measured_at.sql: the
-- same columns and meanings.
--
-- measured_at: when the record was measured, unix milliseconds: its `recorded_at` (RFC 3339,
-- checked by the service before it is stored) when the sender gave one, else its received_at.
-- Every series (the machine view's trend, GET …/trend, the dashboard) is ordered by it, so a
-- back-filled history gives the same trend as one that arrived live. received_at keeps meaning
-- receive time (retention, idempotency). The diagnosis carries its record's measured_at so that
-- series are read from one table in measurement order.
ALTER TABLE records ADD COLUMN measured_at BIGINT;
UPDATE records SET measured_at = CASE
    WHEN recorded_at ~ '^\d{4}-\d{2}-\d{2}[Tt ]\d{2}:\d{2}:\d{2}(\.\d+)?([Zz]|[+-]\d{2}:\d{2})$'
    THEN ROUND(EXTRACT(EPOCH FROM recorded_at::timestamptz) * 1000)::BIGINT
    ELSE received_at END;
ALTER TABLE diagnoses ADD COLUMN measured_at BIGINT;
UPDATE diagnoses SET measured_at = COALESCE(
    (SELECT r.measured_at FROM records r WHERE r.id = diagnoses.record_id),
    created_at);
CREATE INDEX diagnoses_machine_measured ON diagnoses(machine_id, measured_at, seq);
