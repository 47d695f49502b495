-- The layout version of a record's stored features. Keep in step with
-- ../sqlite/0010_stored_features_version.sql.
--
-- records.features is the JSON of the core's StoredFeatures (assessment/stored.rs): the
-- gearbox description's id and hash, each channel's novelty features and alert level, the
-- deciding channel's lines and indicators. Rows written before the layout carried its version
-- are version 1: the number is written into them here.
UPDATE records SET features = (features::jsonb || '{"version": 1}'::jsonb)::text
WHERE NOT (features::jsonb ? 'version');
