-- Machine lifecycle (issue 32). Keep in step with ../postgres/0005_machine_lifecycle.sql: the
-- same columns and meanings.
--
-- registered_at: when the machine was first configured with PUT /v1/machines/{id} (or
-- `gearwear machine set`); NULL for a machine that exists only because records were posted
-- for it. `serve --require-registered-machines` takes records only for registered machines.
-- A machine configured before this migration counts as registered when its configuration
-- differs from the defaults (a gearbox, a rate hint, channels or a tachometer): a PUT that
-- set nothing but defaults left no trace to tell it from a machine made by a record. Their
-- registration time is not known; their created_at stands in for it.
ALTER TABLE machines ADD COLUMN registered_at BIGINT;
UPDATE machines SET registered_at = created_at
    WHERE gearbox_id IS NOT NULL OR input_shaft_hz IS NOT NULL OR channels IS NOT NULL
       OR tacho_channel IS NOT NULL OR tacho_ppr <> 1;

-- machine_id: the machine a stored Idempotency-Key answer is about, so that deleting the
-- machine deletes the answers pointing at its records (a replayed key must not answer with
-- a diagnosis that is gone). Answers stored before this migration get it from their JSON
-- (the answer's top-level `machine_id`).
ALTER TABLE idempotency_keys ADD COLUMN machine_id TEXT;
UPDATE idempotency_keys SET machine_id = json_extract(response, '$.machine_id')
    WHERE json_valid(response) AND json_type(response, '$.machine_id') = 'text';
CREATE INDEX idempotency_keys_machine ON idempotency_keys(machine_id);
