//! What a store operation fails with, and how the API tells a full disk or a busy database from
//! a corrupted row.

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
