-- /readyz allocates a blob here inside a transaction it rolls back, to ask whether the database
-- can still grow (page limit or disk); no row is ever committed.
CREATE TABLE readiness_headroom (
    id     INTEGER PRIMARY KEY,
    filler BLOB NOT NULL
);
