-- Jobs may hold statistics merged from other runs (shards, peers, documents). Such a job is
-- complete as it is: it is never resumed or extended.
ALTER TABLE jobs ADD COLUMN merged INTEGER NOT NULL DEFAULT 0;
