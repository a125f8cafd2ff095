-- The reference luminance may be missing: the quadrature has an evaluation budget and reports a
-- geometry it cannot resolve as not converged (NULL) instead of computing for ever. SQLite cannot
-- drop NOT NULL in place, so the column is moved.
ALTER TABLE jobs ADD COLUMN reference REAL;
UPDATE jobs SET reference = reference_luminance;
ALTER TABLE jobs DROP COLUMN reference_luminance;
ALTER TABLE jobs RENAME COLUMN reference TO reference_luminance;

-- A cancel is stored the moment it is acknowledged: a shutdown or a crash before the running job
-- stops must not run it again.
ALTER TABLE jobs ADD COLUMN cancel_requested INTEGER NOT NULL DEFAULT 0;

-- /readyz proves that the database still takes writes by updating this row.
CREATE TABLE readiness (
    id         INTEGER PRIMARY KEY CHECK (id = 1),
    checked_at INTEGER NOT NULL
);

-- Histories are bounded (see store::jobs::thin_history, which keeps at most ~2,000 rows per job,
-- evenly spaced in iterations). Thin those written before the bound: per job with more than 2,000
-- rows, keep the first row of each of ~1,000 equal buckets of iterations, and the last row.
DELETE FROM checkpoint_history WHERE rowid IN (
    SELECT rid FROM (
        SELECT rid, iterations, last, n,
               ROW_NUMBER() OVER (PARTITION BY job_id, iterations / ((last + 999) / 1000) ORDER BY iterations) AS r
        FROM (
            SELECT rowid AS rid, job_id, iterations,
                   MAX(iterations) OVER (PARTITION BY job_id) AS last,
                   COUNT(*) OVER (PARTITION BY job_id) AS n
            FROM checkpoint_history
        )
    )
    WHERE n > 2000 AND r > 1 AND iterations < last
);
