-- A machine's baseline version. Keep in step with ../postgres/0009_baseline_version.sql.
--
-- baseline_version: raised in the same transaction as every change of which records are the
-- machine's baseline (a record posted with ?baseline=true, records marked or unmarked, the
-- baseline cleared). A replica keeps the baselines it fitted keyed by this number and refits
-- only when the number it reads with the machine's row differs: the cache holds across
-- replicas without any message between them.
ALTER TABLE machines ADD COLUMN baseline_version BIGINT NOT NULL DEFAULT 0;
