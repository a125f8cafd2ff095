//! The database itself: the SQLite pool opened in WAL mode with `synchronous = FULL`, the
//! embedded migrations, write transactions that always end, and the readiness probe. The tables'
//! queries are in the files beside this one.

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

use super::error::StoreError;

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
pub(super) const MIGRATIONS: [(i64, &str, &str); 10] = [
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
pub(crate) struct Database {
    pool: SqlitePool,
    health: Arc<Health>,
    /// The database file, for the filesystem's free space (an in-memory database has none).
    path: Arc<PathBuf>,
}

impl Database {
    /// Opens (creating if missing) the database at `url` (`sqlite://path` or `sqlite::memory:`) and
    /// applies the migrations.
    pub(super) async fn open(url: &str) -> Result<Self, StoreError> {
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
    pub(super) async fn ready(&self) -> Result<(), String> {
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
        .bind(now_ms())
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
    pub(super) async fn transaction<T>(
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
    pub(super) fn limit_pages(&self, pages: Option<u64>) {
        self.health.page_limit.store(pages.unwrap_or(0), Ordering::SeqCst);
        self.health.page_limit_generation.fetch_add(1, Ordering::SeqCst);
        // Connections idle in the pool apply it on their next acquire (before_acquire).
    }

    /// Pages the database file holds now (for fault tests that fill it).
    pub(super) async fn page_count(&self) -> Result<u64, StoreError> {
        let n: i64 = sqlx::query_scalar("PRAGMA page_count").fetch_one(&self.pool).await?;
        Ok(n as u64)
    }

    pub(super) fn pool(&self) -> &SqlitePool {
        &self.pool
    }
}

/// Now, in Unix milliseconds (the readiness probe's timestamp).
fn now_ms() -> i64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_millis() as i64)
}
