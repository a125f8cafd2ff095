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
//! (disk full, I/O error) is an error, never a success that was not kept. The store remembers the
//! last such failure for a while so that `/readyz` reports it.
//!
//! Imports: nothing from the crate

mod checkpoints;
mod history;
mod jobs;
mod solves;
mod state;
mod sweeps;

use std::str::FromStr;
use std::sync::Arc;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::time::Duration;

use sqlx::SqlitePool;
use sqlx::migrate::Migrator;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};

pub use checkpoints::Checkpoint;
pub use history::{MAX_HISTORY_ROWS, evenly_kept};
pub use jobs::{Inserted, JobRow, NewJob};
pub use solves::SolveRow;
pub use state::JobState;
pub use sweeps::SweepRow;

/// The schema migrations, embedded in the binary.
pub static MIGRATOR: Migrator = sqlx::migrate!("./migrations");

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

/// How long a storage failure keeps `/readyz` failing after it happened (unless a later write
/// succeeds first).
const FAILURE_MEMORY_MS: i64 = 30_000;

/// What the store knows of the database's health, shared by every clone.
#[derive(Debug, Default)]
struct Health {
    /// Unix milliseconds of the last write that failed for lack of storage; 0 if none since the
    /// last successful write.
    last_failure_ms: AtomicI64,
    /// Fault injection for tests: a `max_page_count` every connection applies (0: none set; the
    /// generation makes connections that applied an older value apply the new one).
    page_limit: AtomicU64,
    page_limit_generation: AtomicU64,
}

/// A handle to the database; cheap to clone (it wraps the connection pool's `Arc`).
#[derive(Clone, Debug)]
pub struct Store {
    pool: SqlitePool,
    health: Arc<Health>,
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
        let health = Arc::new(Health::default());
        let hook = health.clone();
        let pool = SqlitePoolOptions::new()
            .max_connections(4)
            .acquire_timeout(Duration::from_secs(30))
            .before_acquire(move |conn, _| {
                let health = hook.clone();
                Box::pin(async move {
                    // Only ever set by fault tests; production pays one atomic load.
                    if health.page_limit_generation.load(Ordering::SeqCst) != 0 {
                        let limit = match health.page_limit.load(Ordering::SeqCst) {
                            0 => u64::from(u32::MAX - 1),
                            n => n,
                        };
                        sqlx::query(sqlx::AssertSqlSafe(format!("PRAGMA max_page_count = {limit}")))
                            .execute(&mut *conn)
                            .await?;
                    }
                    Ok(true)
                })
            })
            .connect_with(options)
            .await?;
        MIGRATOR.run(&pool).await?;
        Ok(Self { pool, health })
    }

    /// Whether the database answers, every embedded migration is applied, and it takes writes: a
    /// one-row write now, and no write refused for lack of storage in the last 30 seconds.
    pub async fn ready(&self) -> Result<(), String> {
        let applied: Vec<i64> = sqlx::query_scalar("SELECT version FROM _sqlx_migrations WHERE success = 1")
            .fetch_all(&self.pool)
            .await
            .map_err(|e| format!("database unreachable: {e}"))?;
        let missing: Vec<i64> = MIGRATOR.iter().map(|m| m.version).filter(|v| !applied.contains(v)).collect();
        if !missing.is_empty() {
            return Err(format!("migrations not applied: {missing:?}"));
        }
        let now = jobs::now_ms();
        sqlx::query(
            "INSERT INTO readiness (id, checked_at) VALUES (1, ?1) ON CONFLICT (id) DO UPDATE SET checked_at = ?1",
        )
        .bind(now)
        .execute(&self.pool)
        .await
        .map_err(|e| format!("the database does not take writes: {e}"))?;
        let failed = self.health.last_failure_ms.load(Ordering::SeqCst);
        if failed != 0 && now - failed < FAILURE_MEMORY_MS {
            return Err(format!(
                "a write was refused for lack of storage {} s ago (disk full or I/O error)",
                (now - failed) / 1000
            ));
        }
        Ok(())
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

    /// Records the outcome of a write for [`Store::ready`].
    fn track<T>(&self, result: Result<T, StoreError>) -> Result<T, StoreError> {
        match &result {
            Ok(_) => self.health.last_failure_ms.store(0, Ordering::SeqCst),
            Err(e) if e.is_storage_failure() => {
                self.health.last_failure_ms.store(jobs::now_ms().max(1), Ordering::SeqCst);
            }
            Err(_) => {}
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
