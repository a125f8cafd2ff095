-- Named re-solves kept with a job: the solver options (a merge patch on the job's `solver`), not
-- their result, which is recomputed from the job's latest checkpoint when asked for (so it follows
-- the job as it runs or is extended, and the table stays small). At most 32 per job (jobs::solves).
CREATE TABLE solves (
    job_id     INTEGER NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    name       TEXT    NOT NULL,
    -- JSON: the patch on the job's solver options, as validated.
    patch      TEXT    NOT NULL,
    created_at INTEGER NOT NULL,
    PRIMARY KEY (job_id, name)
);
