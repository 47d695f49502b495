-- Real machines (issue 31). Keep in step with ../sqlite/0004_tacho_wear_flag.sql: the same
-- columns and meanings.
--
-- A machine's tachometer: the record channel that carries its pulses (NULL: a channel named
-- `tacho`, when a record has one) and the pulses per input-shaft revolution. That channel
-- gives the record's measured speed and is not diagnosed itself.
ALTER TABLE machines ADD COLUMN tacho_channel TEXT;
ALTER TABLE machines ADD COLUMN tacho_ppr BIGINT NOT NULL DEFAULT 1;

-- has_wear 0 now also marks a diagnosis whose wear figure was withheld because the model does
-- not fit the record (its answer's wear_degree is null, with wear_note). Diagnoses stored
-- before this migration with a withheld figure have has_wear 1 and ea_* all exactly 0 (what
-- was written in place of the figure; a real interval is never a single point at 0): they
-- stop plotting as a wear of 0.
UPDATE diagnoses SET has_wear = 0
    WHERE has_wear = 1 AND ea_estimate = 0 AND ea_lower = 0 AND ea_upper = 0;
