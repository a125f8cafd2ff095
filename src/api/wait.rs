//! `?wait=SECONDS` on `GET /v1/jobs/{id}` and `GET /v1/sweeps/{id}`: a long-poll that answers as
//! soon as the resource has ended (succeeded, failed or cancelled) or the seconds have passed,
//! whichever comes first, so that a client waiting for a result needs neither a busy loop nor a
//! parser of the resource's nested states.
//!
//! Bounded: at most [`MAX_WAIT_SECONDS`] per request (a client loops for longer), no CPU while it
//! waits (a watch channel for a job, one indexed read every half second for a sweep), and each
//! waiting request holds one of the `--max-event-streams` slots (429 with Retry-After beyond
//! them), so that waiters cannot hold every connection. A server that stops answers at once.

use std::time::Duration;

use serde::Deserialize;
use utoipa::IntoParams;

use super::error::ApiError;

/// The longest one request waits.
pub const MAX_WAIT_SECONDS: u32 = 60;

/// Query of a job or a sweep.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct WaitQuery {
    /// Wait up to this many seconds (0 to 60) for the resource to end before answering; the
    /// answer is the resource as it is then (look at its `state`: it may still run).
    #[param(minimum = 0, maximum = 60)]
    wait: Option<u32>,
}

impl WaitQuery {
    /// How long to wait (None: answer at once), checked whether or not there is anything to wait
    /// for.
    pub(super) fn duration(&self) -> Result<Option<Duration>, ApiError> {
        match self.wait {
            None | Some(0) => Ok(None),
            Some(s) if s > MAX_WAIT_SECONDS => Err(ApiError::Invalid {
                field: "wait".into(),
                message: format!("at most {MAX_WAIT_SECONDS} seconds (wait again for longer)"),
            }),
            Some(s) => Ok(Some(Duration::from_secs(u64::from(s)))),
        }
    }
}
