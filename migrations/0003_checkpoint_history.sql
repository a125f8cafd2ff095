-- One row per checkpoint: each strategy's luminance and RMS at that many iterations, for the
-- dashboard's plot of the noise against the number of iterations.
CREATE TABLE checkpoint_history (
    job_id     INTEGER NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    iterations INTEGER NOT NULL,
    -- JSON: [{"strategy": …, "luminance": …, "rms_percent": …}, …]
    strategies TEXT    NOT NULL,
    written_at INTEGER NOT NULL,
    PRIMARY KEY (job_id, iterations)
);
