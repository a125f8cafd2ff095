-- The warnings of the latest checkpoint's result (JSON list, issue 13), shown on the job resource
-- beside the best strategy. NULL for jobs checkpointed before warnings existed.
ALTER TABLE jobs ADD COLUMN warnings TEXT;
