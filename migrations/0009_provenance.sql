-- Where a merged job's statistics come from (issue 25): its sources — peer URLs, documents, the
-- job's own iterations — each with the seeds and iterations it brought, and every seed held.
-- JSON written by the job layer (`jobs::provenance`); NULL for a job that merged nothing.
ALTER TABLE jobs ADD COLUMN provenance TEXT;
