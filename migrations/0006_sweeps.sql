-- Sweeps: a job document varied along axes. Each run of a sweep is an ordinary job that links
-- back to it (sweep_id, sweep_run); deleting a sweep deletes its jobs (done by the store in one
-- transaction, so a job never points at a missing sweep).
CREATE TABLE sweeps (
    id         INTEGER PRIMARY KEY AUTOINCREMENT,
    -- The sweep document (JSON) as validated: base, axes, mode.
    spec       TEXT    NOT NULL,
    created_at INTEGER NOT NULL
);

ALTER TABLE jobs ADD COLUMN sweep_id INTEGER REFERENCES sweeps (id);
ALTER TABLE jobs ADD COLUMN sweep_run INTEGER;
CREATE INDEX jobs_by_sweep ON jobs (sweep_id, sweep_run) WHERE sweep_id IS NOT NULL;
