-- The result document's own SHA-256 (issue 39, item 12): the moments' checksum never covered the
-- stored result, so an edited one was served and a garbage one answered 500. Written with every
-- checkpoint by the job layer; rows written before it are filled in once at the next start.
ALTER TABLE checkpoints ADD COLUMN result_checksum TEXT;
