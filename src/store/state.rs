//! The states of a job's life cycle, as stored in the `jobs.state` column and shown by the API.
//!
//! The store binds and decodes them through this type only, so no query compares a state spelled by
//! hand, and a row whose state is not one of them is reported as corrupted.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// The life cycle of a job: `queued → running → succeeded | failed | cancelled`; `extend` sends a
/// succeeded or cancelled job back to `queued`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    /// Waiting for a worker (new, extended, or recovered at start).
    Queued,
    /// A worker is running its iterations.
    Running,
    /// Every iteration ran (or its statistics were merged in).
    Succeeded,
    /// Stopped by an error; the row's `error` says which.
    Failed,
    /// Stopped by a user; its latest checkpoint is kept.
    Cancelled,
}

impl JobState {
    /// Every state, in life-cycle order.
    pub const ALL: [JobState; 5] = [Self::Queued, Self::Running, Self::Succeeded, Self::Failed, Self::Cancelled];

    /// The state as stored and shown: its snake-case name (`queued`, …).
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Queued => "queued",
            Self::Running => "running",
            Self::Succeeded => "succeeded",
            Self::Failed => "failed",
            Self::Cancelled => "cancelled",
        }
    }

    /// The state named `s` ([`JobState::as_str`]), if any.
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|state| state.as_str() == s)
    }

    /// No further change without a user action.
    pub fn is_terminal(self) -> bool {
        matches!(self, Self::Succeeded | Self::Failed | Self::Cancelled)
    }
}

impl std::fmt::Display for JobState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn states_round_trip() {
        for s in JobState::ALL {
            assert_eq!(JobState::parse(s.as_str()), Some(s));
        }
        assert_eq!(JobState::parse("paused"), None);
    }
}
