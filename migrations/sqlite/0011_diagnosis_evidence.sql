-- The evidence plot of each diagnosis. Keep in step with
-- ../postgres/0011_diagnosis_evidence.sql.
--
-- diagnoses.evidence is the JSON of the core's EvidencePlot (condition/plot.rs): the deciding
-- channel's order and envelope spectra with the lines its findings rest on, what the record
-- page draws; 'null' when the record had no measured speed or no described gearbox, and for
-- diagnoses stored before it existed.
ALTER TABLE diagnoses ADD COLUMN evidence TEXT NOT NULL DEFAULT 'null';
