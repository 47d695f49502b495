-- Physical units (issue 33, units). Keep in step with ../postgres/0007_channel_units.sql: the
-- same columns and meanings.
--
-- channel_units: what a machine's channels measure, JSON object by channel name ("*": every
-- channel not named) of {"unit": "g" | "m/s²" | "mm/s" | "V", "sensitivity_mv_per_g" |
-- "sensitivity_mv_per_m_s2" | "sensitivity_mv_per_mm_s": number (V only)}; NULL: unitless
-- records (no vibration figures). Checked by the service before it is written.
-- iso_group (1 or 2) and iso_support ('rigid' or 'flexible'): the machine's ISO 20816-3 class,
-- both NULL or both set; with them a diagnosis gives its velocity's zone.
ALTER TABLE machines ADD COLUMN channel_units TEXT;
ALTER TABLE machines ADD COLUMN iso_group BIGINT;
ALTER TABLE machines ADD COLUMN iso_support TEXT;
