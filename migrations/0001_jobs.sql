-- Jobs and their latest checkpoint.
CREATE TABLE jobs (
    id                  INTEGER PRIMARY KEY AUTOINCREMENT,
    state               TEXT    NOT NULL CHECK (state IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
    -- The resolved job specification (JSON), exactly as validated.
    spec                TEXT    NOT NULL,
    fingerprint         TEXT    NOT NULL,
    iterations_total    INTEGER NOT NULL CHECK (iterations_total > 0),
    -- Iterations held by the latest checkpoint.
    iterations_done     INTEGER NOT NULL DEFAULT 0,
    reference_luminance REAL    NOT NULL,
    -- The per-path strategy with the lowest RMS at the latest checkpoint (JSON), for job listings.
    best                TEXT,
    error               TEXT,
    idempotency_key     TEXT    UNIQUE,
    -- SHA-256 of the submitted body, to tell a replay from a reuse of the key.
    request_hash        TEXT,
    created_at          INTEGER NOT NULL, -- unix milliseconds
    updated_at          INTEGER NOT NULL
);

CREATE INDEX jobs_by_state ON jobs (state, id);

CREATE TABLE checkpoints (
    job_id          INTEGER PRIMARY KEY REFERENCES jobs (id) ON DELETE CASCADE,
    iterations_done INTEGER NOT NULL,
    -- The moments (JSON) and their SHA-256; a mismatch marks the job failed rather than resuming
    -- from corrupted statistics.
    moments         BLOB    NOT NULL,
    checksum        TEXT    NOT NULL,
    -- The result document computed from these moments with the job's solver options.
    result          TEXT    NOT NULL,
    written_at      INTEGER NOT NULL
);
