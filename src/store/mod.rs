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
mod history;
mod jobs;
mod solves;
mod state;
mod sweeps;

use std::path::PathBuf;
use std::str::FromStr;
use std::sync::Arc;
use std::sync::LazyLock;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use sqlx::SqlStr;
use sqlx::SqlitePool;
use sqlx::migrate::{Migration, MigrationType, Migrator};
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};

pub use checkpoints::{Checkpoint, StoredResult};
pub use history::{MAX_HISTORY_ROWS, evenly_kept};
pub use jobs::{Inserted, JobFilter, JobRow, NewJob};
pub use solves::SolveRow;
pub use state::JobState;
pub use sweeps::SweepRow;

/// The schema migrations, embedded in the binary: `migrations/NNNN_words.sql`, version NNNN.
///
/// Listed here with `include_str!` rather than found by sqlx's `migrate!` macro, which made the
/// compiler build a second SQLite and sqlx's macro crates for the build machine (issue 42, item 1:
/// the build time). The checksum is the same SHA-384 of the file's text the macro computed, so
/// databases it migrated stay valid; a test checks that every file of `migrations/` is here.
pub static MIGRATOR: LazyLock<Migrator> = LazyLock::new(|| {
    Migrator::with_migrations(
        MIGRATIONS
            .iter()
            .map(|&(version, description, sql)| {
                let no_tx = sql.starts_with("-- no-transaction");
                Migration::new(version, description.into(), MigrationType::Simple, SqlStr::from_static(sql), no_tx)
            })
            .collect(),
    )
});

/// Every migration: version, description (sqlx's: the file name's words), SQL.
const MIGRATIONS: [(i64, &str, &str); 10] = [
    (1, "jobs", include_str!("../../migrations/0001_jobs.sql")),
    (2, "merged statistics", include_str!("../../migrations/0002_merged_statistics.sql")),
    (3, "checkpoint history", include_str!("../../migrations/0003_checkpoint_history.sql")),
    (4, "bounded work", include_str!("../../migrations/0004_bounded_work.sql")),
    (5, "warnings", include_str!("../../migrations/0005_warnings.sql")),
    (6, "sweeps", include_str!("../../migrations/0006_sweeps.sql")),
    (7, "solves", include_str!("../../migrations/0007_solves.sql")),
    (8, "readiness headroom", include_str!("../../migrations/0008_readiness_headroom.sql")),
    (9, "provenance", include_str!("../../migrations/0009_provenance.sql")),
    (10, "result checksum", include_str!("../../migrations/0010_result_checksum.sql")),
];

/// Database failures.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// A query, a connection or the pool failed (see [`StoreError::is_storage_failure`] and
    /// [`StoreError::is_transient`]).
    #[error("database error: {0}")]
    Database(#[from] sqlx::Error),
    /// An embedded migration could not be applied at start.
    #[error("database migration failed: {0}")]
    Migrate(#[from] sqlx::migrate::MigrateError),
    /// Job `job`'s stored data cannot be used (a checkpoint whose checksum does not match, a spec
    /// that no longer parses); `detail` says what. Raised by the job layer as it reads the rows.
    #[error("stored data of job {job} is corrupted: {detail}")]
    Corrupt {
        /// The job's id.
        job: i64,
        /// What is wrong with its data.
        detail: String,
    },
}

impl StoreError {
    /// Whether the database could not store data at all: SQLITE_FULL (13: disk or page limit
    /// full), SQLITE_IOERR (10) or SQLITE_CANTOPEN (14). A write that failed this way stored
    /// nothing; it may succeed once space or the device comes back.
    pub fn is_storage_failure(&self) -> bool {
        match self {
            StoreError::Database(sqlx::Error::Database(e)) => {
                matches!(e.code().as_deref().and_then(|c| c.parse::<i32>().ok()).map(|c| c & 0xff), Some(10 | 13 | 14))
            }
            StoreError::Database(sqlx::Error::Io(_)) => true,
            _ => false,
        }
    }

    /// Whether retrying may succeed (the database was busy or locked).
    pub fn is_transient(&self) -> bool {
        match self {
            StoreError::Database(sqlx::Error::Database(e)) => {
                let code = e.code();
                // SQLITE_BUSY (5) and SQLITE_LOCKED (6), with their extended codes.
                matches!(code.as_deref().and_then(|c| c.parse::<i32>().ok()).map(|c| c & 0xff), Some(5 | 6))
            }
            StoreError::Database(sqlx::Error::PoolTimedOut) => true,
            _ => false,
        }
    }
}

/// The room `/readyz` asks for: one allocation of this many bytes must fit under the database's
/// page limit, and the filesystem must have it free. Small enough to stay in SQLite's page cache
/// (2 MiB by default), so that a probe of an unauthenticated route writes nothing to disk.
const HEADROOM_BYTES: u64 = 1 << 20;

/// Fault injection for tests, shared by every clone of a store.
#[derive(Debug, Default)]
struct Health {
    /// A `max_page_count` every connection applies (0: none set; the generation makes connections
    /// that applied an older value apply the new one).
    page_limit: AtomicU64,
    page_limit_generation: AtomicU64,
}

impl Health {
    /// Sets `max_page_count` on `conn` if a fault test asked for a limit (production pays one
    /// atomic load).
    async fn apply_page_limit(&self, conn: &mut sqlx::SqliteConnection) -> Result<(), sqlx::Error> {
        if self.page_limit_generation.load(Ordering::SeqCst) != 0 {
            let limit = match self.page_limit.load(Ordering::SeqCst) {
                0 => u64::from(u32::MAX - 1),
                n => n,
            };
            sqlx::query(sqlx::AssertSqlSafe(format!("PRAGMA max_page_count = {limit}"))).execute(&mut *conn).await?;
        }
        Ok(())
    }
}

/// A handle to the database; cheap to clone (it wraps the connection pool's `Arc`).
#[derive(Clone, Debug)]
pub struct Store {
    pool: SqlitePool,
    health: Arc<Health>,
    /// The database file, for the filesystem's free space (an in-memory database has none).
    path: Arc<PathBuf>,
}

impl Store {
    /// Opens (creating if missing) the database at `url` (`sqlite://path` or `sqlite::memory:`) and
    /// applies the migrations.
    pub async fn open(url: &str) -> Result<Self, StoreError> {
        let options = SqliteConnectOptions::from_str(url)?
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Full)
            .foreign_keys(true)
            .busy_timeout(Duration::from_secs(10));
        let path = Arc::new(options.get_filename().to_path_buf());
        let health = Arc::new(Health::default());
        let (on_connect, on_acquire) = (health.clone(), health.clone());
        // The fault tests' page limit goes on every connection: `before_acquire` runs only for
        // connections taken from the idle queue, `after_connect` for the ones the pool opens (a
        // readiness probe on a fresh connection once saw no limit and reported a full database
        // ready).
        let pool = SqlitePoolOptions::new()
            .max_connections(4)
            .acquire_timeout(Duration::from_secs(30))
            .after_connect(move |conn, _| {
                let health = on_connect.clone();
                Box::pin(async move { health.apply_page_limit(conn).await })
            })
            .before_acquire(move |conn, _| {
                let health = on_acquire.clone();
                Box::pin(async move {
                    health.apply_page_limit(conn).await?;
                    Ok(true)
                })
            })
            .connect_with(options)
            .await?;
        MIGRATOR.run(&pool).await?;
        Ok(Self { pool, health, path })
    }

    /// Whether the database answers, every embedded migration is applied, a write commits, and
    /// there is room for more: 1 MiB (`HEADROOM_BYTES`) must fit under the database's page limit (an
    /// allocation inside a transaction that is rolled back) and be free on the filesystem.
    ///
    /// Why not remember failed writes instead: a write that fits in pages a previous write freed
    /// succeeds on a database that cannot grow, and a memory cleared by it reported such a
    /// database ready while every new submission was refused.
    pub async fn ready(&self) -> Result<(), String> {
        let applied: Vec<i64> = sqlx::query_scalar("SELECT version FROM _sqlx_migrations WHERE success = 1")
            .fetch_all(&self.pool)
            .await
            .map_err(|e| format!("database unreachable: {e}"))?;
        let missing: Vec<i64> = MIGRATOR.iter().map(|m| m.version).filter(|v| !applied.contains(v)).collect();
        if !missing.is_empty() {
            return Err(format!("migrations not applied: {missing:?}"));
        }
        sqlx::query(
            "INSERT INTO readiness (id, checked_at) VALUES (1, ?1) ON CONFLICT (id) DO UPDATE SET checked_at = ?1",
        )
        .bind(jobs::now_ms())
        .execute(&self.pool)
        .await
        .map_err(|e| format!("the database does not take writes: {e}"))?;
        let room = format!("the database has less than {} MiB of room for writes", HEADROOM_BYTES >> 20);
        // The allocation is rolled back, never kept.
        let mut conn = self.pool.acquire().await.map_err(|e| format!("database unreachable: {e}"))?;
        let probe = async {
            sqlx::query("BEGIN IMMEDIATE").execute(&mut *conn).await?;
            sqlx::query("INSERT INTO readiness_headroom (filler) VALUES (zeroblob(?))")
                .bind(HEADROOM_BYTES as i64)
                .execute(&mut *conn)
                .await
        }
        .await
        .map_err(StoreError::from);
        // SQLite may have rolled back already (after SQLITE_FULL); that error is moot.
        let _ = sqlx::query("ROLLBACK").execute(&mut *conn).await;
        drop(conn);
        match probe {
            Err(e) if e.is_storage_failure() => return Err(format!("{room} (page limit or disk): {e}")),
            Err(e) => return Err(format!("the database does not take writes: {e}")),
            Ok(_) => {}
        }
        // A missing file is an in-memory database; anything else the filesystem says counts.
        match rustix::fs::statvfs(self.path.as_path()) {
            Ok(fs) if fs.f_bavail.saturating_mul(fs.f_frsize) < HEADROOM_BYTES => {
                Err(format!("{room}: the filesystem has {} bytes free", fs.f_bavail.saturating_mul(fs.f_frsize)))
            }
            Ok(_) | Err(rustix::io::Errno::NOENT) => Ok(()),
            Err(e) => Err(format!("cannot tell the filesystem's free space: {e}")),
        }
    }

    /// Runs `steps` as one write transaction (`BEGIN IMMEDIATE` … `COMMIT`) on one connection. If a
    /// step or the commit fails, the transaction is rolled back before the connection goes back to
    /// the pool: sqlx's `Transaction` defers a rollback to the connection's next use, and a
    /// commit refused on a full disk left its write lock held meanwhile, so that every other writer
    /// waited out the busy timeout.
    pub(crate) async fn transaction<T>(
        &self,
        steps: impl AsyncFnOnce(&mut sqlx::SqliteConnection) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        let mut conn = self.pool.acquire().await?;
        sqlx::query("BEGIN IMMEDIATE").execute(&mut *conn).await?;
        let result = match steps(&mut conn).await {
            Ok(value) => sqlx::query("COMMIT").execute(&mut *conn).await.map(|_| value).map_err(StoreError::from),
            Err(e) => Err(e),
        };
        if result.is_err() {
            // SQLite may have rolled back already (after SQLITE_FULL); that error is moot.
            let _ = sqlx::query("ROLLBACK").execute(&mut *conn).await;
        }
        result
    }

    /// Fault injection for tests: makes every connection refuse to grow the database beyond
    /// `pages` pages (`PRAGMA max_page_count`), as a full disk would; `None` lifts the limit.
    #[doc(hidden)]
    pub fn limit_pages(&self, pages: Option<u64>) {
        self.health.page_limit.store(pages.unwrap_or(0), Ordering::SeqCst);
        self.health.page_limit_generation.fetch_add(1, Ordering::SeqCst);
        // Connections idle in the pool apply it on their next acquire (before_acquire).
    }

    /// Pages the database file holds now (for fault tests that fill it).
    #[doc(hidden)]
    pub async fn page_count(&self) -> Result<u64, StoreError> {
        let n: i64 = sqlx::query_scalar("PRAGMA page_count").fetch_one(&self.pool).await?;
        Ok(n as u64)
    }

    pub(crate) fn pool(&self) -> &SqlitePool {
        &self.pool
    }
}

#[cfg(test)]
mod tests {
    use super::{Inserted, MIGRATIONS, MIGRATOR, NewJob, Store};

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
            held.push(store.pool.acquire().await.unwrap());
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
            let Inserted::Created(row) = store.insert_job(&job(seed)).await.unwrap() else { panic!("inserted") };
            ids.push(row.id);
        }
        for id in &ids[..10] {
            assert!(store.delete_job(*id).await.unwrap());
        }
        store.limit_pages(Some(store.page_count().await.unwrap()));
        // Fits in the freed pages: stored, yet the database cannot grow by a megabyte.
        store.insert_job(&job(100)).await.unwrap();
        let err = store.ready().await.unwrap_err();
        assert!(err.contains("less than 1 MiB of room"), "{err}");
        store.limit_pages(None);
        store.ready().await.unwrap();
    }
}
