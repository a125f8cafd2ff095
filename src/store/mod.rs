//! Persistence of jobs and checkpoints in SQLite (sqlx), and nothing else: no job logic lives here.
//!
//! The database is embedded (a file, created if missing) and opened in WAL mode with a busy timeout,
//! foreign keys on and `synchronous = FULL`, so that a checkpoint that was committed survives a
//! SIGKILL or a power loss. The schema lives in `migrations/` and is applied at start.
//!
//! A job row carries its resolved spec and bookkeeping; its latest checkpoint (moments, checksum,
//! result document) is one row replaced in the same transaction that advances the job's
//! `iterations_done`, so the two never disagree.
//!
//! Every write is a transaction whose commit is awaited: a write that the database could not store
//! (disk full, I/O error) is an error, never a success that was not kept. `/readyz` asks the
//! database itself whether it has room for more (see [`Store::ready`]).
//!
//! Imports: crate::sim::spec

mod checkpoints;
mod database;
mod error;
mod history;
mod jobs;
mod solves;
mod state;
mod sweeps;

pub use checkpoints::{Checkpoint, CheckpointsTable, StoredResult};
use database::Database;
pub use database::MIGRATOR;
pub use error::StoreError;
pub use history::{HistoryTable, MAX_HISTORY_ROWS, evenly_kept};
pub use jobs::{Inserted, JobFilter, JobRow, JobsTable, NewJob};
pub use solves::{SolveRow, SolvesTable};
pub use state::JobState;
pub use sweeps::{SweepRow, SweepsTable};

/// The store: a handle on the database (cheap to clone), and each table's queries through a
/// handle of its own (`store.jobs().get(id)`, `store.checkpoints().load(id)`, …).
#[derive(Clone, Debug)]
pub struct Store {
    db: Database,
}

impl Store {
    /// Opens (creating if missing) the database at `url` (`sqlite://path` or `sqlite::memory:`) and
    /// applies the migrations.
    pub async fn open(url: &str) -> Result<Self, StoreError> {
        Ok(Self { db: Database::open(url).await? })
    }

    /// Whether the database answers, every embedded migration is applied, a write commits, and
    /// there is room for more (see `Database::ready`): `/readyz`.
    pub async fn ready(&self) -> Result<(), String> {
        self.db.ready().await
    }

    /// Fault injection for tests: makes every connection refuse to grow the database beyond
    /// `pages` pages (`PRAGMA max_page_count`), as a full disk would; `None` lifts the limit.
    #[doc(hidden)]
    pub fn limit_pages(&self, pages: Option<u64>) {
        self.db.limit_pages(pages)
    }

    /// Pages the database file holds now (for fault tests that fill it).
    #[doc(hidden)]
    pub async fn page_count(&self) -> Result<u64, StoreError> {
        self.db.page_count().await
    }

    /// The jobs table.
    pub fn jobs(&self) -> JobsTable<'_> {
        JobsTable { db: &self.db }
    }

    /// Each job's latest checkpoint (moments, checksum, result) and the merged and study rows.
    pub fn checkpoints(&self) -> CheckpointsTable<'_> {
        CheckpointsTable { db: &self.db }
    }

    /// The checkpoints' history points.
    pub fn history(&self) -> HistoryTable<'_> {
        HistoryTable { db: &self.db }
    }

    /// Named solves kept with a job.
    pub fn solves(&self) -> SolvesTable<'_> {
        SolvesTable { db: &self.db }
    }

    /// Sweeps and their runs.
    pub fn sweeps(&self) -> SweepsTable<'_> {
        SweepsTable { db: &self.db }
    }
}

#[cfg(test)]
mod tests {
    use super::database::MIGRATIONS;
    use super::{Inserted, MIGRATOR, NewJob, Store};

    /// Every file of `migrations/` is embedded, with its version and sqlx's description, and the
    /// checksum is the SHA-384 of its text that `sqlx::migrate!` stored in databases it migrated.
    #[test]
    fn every_migration_file_is_embedded_as_sqlx_would_read_it() {
        use sha2::Digest;
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("migrations");
        let mut files: Vec<String> =
            std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
        files.sort();
        assert_eq!(files.len(), MIGRATIONS.len(), "{files:?}");
        for (file, (migration, embedded)) in files.iter().zip(MIGRATOR.iter().zip(MIGRATIONS)) {
            let (number, rest) = file.split_once('_').unwrap();
            let text = std::fs::read_to_string(dir.join(file)).unwrap();
            assert_eq!(migration.version, number.parse::<i64>().unwrap(), "{file}");
            assert_eq!(migration.description, rest.trim_end_matches(".sql").replace('_', " "), "{file}");
            assert_eq!(embedded.2, text, "{file}");
            assert_eq!(&*migration.checksum, sha2::Sha384::digest(text.as_bytes()).as_slice(), "{file}");
        }
    }

    fn job(seed: u64) -> NewJob {
        NewJob {
            spec: format!("{{\"seed\":{seed}}}"),
            fingerprint: format!("f{seed}"),
            iterations_total: 1,
            reference_luminance: None,
            idempotency_key: None,
            request_hash: None,
            now: 0,
        }
    }

    /// The CI failure this replaced: `/readyz` reported a database at its page limit ready,
    /// because its probe ran on a connection the pool had opened after the limit was set, which
    /// `before_acquire` never sees. Every connection, old or new, must carry the limit.
    #[tokio::test]
    async fn the_page_limit_reaches_connections_opened_after_it() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(&format!("sqlite://{}", dir.path().join("t.db").display())).await.unwrap();
        let limit = store.page_count().await.unwrap() + 7;
        store.limit_pages(Some(limit));
        // The pool holds one connection from the migrations; holding four opens three more.
        let mut held = Vec::new();
        for _ in 0..4 {
            held.push(store.db.pool().acquire().await.unwrap());
        }
        for conn in &mut held {
            let n: i64 = sqlx::query_scalar("PRAGMA max_page_count").fetch_one(&mut **conn).await.unwrap();
            assert_eq!(n as u64, limit);
        }
        drop(held);
        assert!(store.ready().await.unwrap_err().contains("less than 1 MiB of room"));
    }

    /// The CI failure this replaced: a write that fits in pages a deletion freed succeeded on a
    /// database that could not grow, and `/readyz` (which remembered only the latest outcome)
    /// reported ready.
    #[tokio::test]
    async fn ready_asks_for_room_not_for_the_latest_write() {
        let dir = tempfile::tempdir().unwrap();
        let store = Store::open(&format!("sqlite://{}", dir.path().join("t.db").display())).await.unwrap();
        store.ready().await.unwrap();
        let mut ids = Vec::new();
        for seed in 0..20 {
            let Inserted::Created(row) = store.jobs().insert(&job(seed)).await.unwrap() else { panic!("inserted") };
            ids.push(row.id);
        }
        for id in &ids[..10] {
            assert!(store.jobs().delete(*id).await.unwrap());
        }
        store.limit_pages(Some(store.page_count().await.unwrap()));
        // Fits in the freed pages: stored, yet the database cannot grow by a megabyte.
        store.jobs().insert(&job(100)).await.unwrap();
        let err = store.ready().await.unwrap_err();
        assert!(err.contains("less than 1 MiB of room"), "{err}");
        store.limit_pages(None);
        store.ready().await.unwrap();
    }
}
