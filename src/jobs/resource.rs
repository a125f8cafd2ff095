//! What a job looks like from outside: its state machine, its progress and the job resource that the
//! API returns and the event stream sends.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::sim::spec::JobSpec;

/// The life cycle of a job: `queued → running → succeeded | failed | cancelled`; `extend` sends a
/// succeeded or cancelled job back to `queued`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    Queued,
    Running,
    Succeeded,
    Failed,
    Cancelled,
}

impl JobState {
    pub const ALL: [JobState; 5] = [Self::Queued, Self::Running, Self::Succeeded, Self::Failed, Self::Cancelled];

    pub fn as_str(self) -> &'static str {
        match self {
            Self::Queued => "queued",
            Self::Running => "running",
            Self::Succeeded => "succeeded",
            Self::Failed => "failed",
            Self::Cancelled => "cancelled",
        }
    }

    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|state| state.as_str() == s)
    }

    /// No further change without a user action.
    pub fn is_terminal(self) -> bool {
        matches!(self, Self::Succeeded | Self::Failed | Self::Cancelled)
    }
}

/// The strategy with the lowest RMS so far, among the per-path strategies and the hold-out
/// optimum (in-sample fits are optimistic and left out).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct BestStrategy {
    pub strategy: String,
    pub luminance: f64,
    pub rms_percent: f64,
}

/// How far a job has come.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Progress {
    /// Iterations computed (in memory while running).
    pub iterations_done: u64,
    pub iterations_total: u64,
    /// Iterations held by the latest checkpoint (what `result` reports and a restart resumes from).
    pub iterations_checkpointed: u64,
    /// Recent throughput while running.
    pub light_paths_per_second: Option<f64>,
    /// Estimated seconds to completion while running.
    pub eta_seconds: Option<f64>,
    pub best: Option<BestStrategy>,
}

/// A job as the API shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct JobResource {
    pub id: i64,
    pub state: JobState,
    pub spec: JobSpec,
    /// RFC 3339, UTC.
    pub created_at: String,
    /// RFC 3339, UTC.
    pub updated_at: String,
    pub progress: Progress,
    /// Why the job failed.
    pub error: Option<String>,
    /// Configuration fingerprint (moments merge only between equal fingerprints).
    pub fingerprint: String,
    /// Quadrature value of the expected luminance; null when the quadrature did not converge
    /// within its evaluation budget (extreme geometry).
    pub reference_luminance: Option<f64>,
    /// True when the job holds statistics merged from other runs (shards, peers, documents);
    /// such a job is complete and cannot be extended.
    pub merged: bool,
}

/// Unix milliseconds now.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_millis() as i64)
}

/// RFC 3339 (UTC, milliseconds) of unix milliseconds.
pub fn rfc3339(ms: i64) -> String {
    let t = time::OffsetDateTime::from_unix_timestamp_nanos(i128::from(ms) * 1_000_000)
        .unwrap_or(time::OffsetDateTime::UNIX_EPOCH);
    let format =
        time::macros::format_description!("[year]-[month]-[day]T[hour]:[minute]:[second].[subsecond digits:3]Z");
    t.format(&format).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timestamps_are_rfc3339_utc() {
        assert_eq!(rfc3339(0), "1970-01-01T00:00:00.000Z");
        assert_eq!(rfc3339(1_795_000_000_123), "2026-11-18T11:06:40.123Z"); // checked with Python's datetime
    }

    #[test]
    fn states_round_trip() {
        for s in JobState::ALL {
            assert_eq!(JobState::parse(s.as_str()), Some(s));
        }
        assert_eq!(JobState::parse("paused"), None);
    }
}
