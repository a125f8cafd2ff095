//! `GET /v1/jobs/{id}/events`: Server-Sent Events of a job's resource as it changes.
//!
//! Each event is named `job` and carries the job resource. The stream sends the current resource
//! first, then changes — at most one event per [`MIN_EVENT_INTERVAL`] (changes in between are
//! coalesced: the next event carries the latest state) — and ends after the event that shows a
//! terminal state, or with a `shutdown` event when the server stops. A job that is not queued or
//! running gets its one current event, which does not take one of the `--max-event-streams`
//! slots (only streams that stay open do).

use std::convert::Infallible;
use std::time::Duration;

use tokio::time::Instant;

use axum::extract::State;
use axum::response::sse::{Event, KeepAlive, Sse};
use futures_util::stream::{self, Stream};
use tokio::sync::watch;

use super::AppState;
use super::error::{ApiError, Problem};
use super::extract::JobId;
use crate::jobs::resource::JobResource;

/// Shortest time between two events of a stream.
pub const MIN_EVENT_INTERVAL: Duration = Duration::from_millis(250);

fn job_event(resource: &JobResource) -> Event {
    Event::default().event("job").json_data(resource).unwrap_or_else(|_| Event::default().event("job"))
}

enum Phase {
    /// Send the current resource next.
    First(watch::Receiver<JobResource>, watch::Receiver<bool>),
    /// Wait for changes, sending none before the instant given.
    Follow(watch::Receiver<JobResource>, watch::Receiver<bool>, Instant),
    /// Send this one event, then end.
    Last(Event),
    Done,
}

/// Stream a job's changes.
#[utoipa::path(
    get, path = "/v1/jobs/{id}/events", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 200, description = "Events named `job` with the job resource as data; a final `shutdown` event if the server stops",
            content_type = "text/event-stream", body = String),
        (status = 404, description = "No such job", body = Problem, content_type = "application/problem+json"),
        (status = 429, description = "Too many event streams are open; retry after Retry-After seconds", body = Problem, content_type = "application/problem+json"),
        (status = 500, description = "Server failure", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn events(
    State(state): State<AppState>,
    JobId(id): JobId,
) -> Result<Sse<impl Stream<Item = Result<Event, Infallible>>>, ApiError> {
    let shutdown = state.jobs.shutdown_signal();
    let (start, slot) = match state.jobs.subscribe(id) {
        // Held by the stream: the slot frees when the stream ends or the client goes away.
        Some(rx) => (Phase::First(rx, shutdown), Some(state.streams.acquire()?)),
        None => (Phase::Last(job_event(&state.jobs.get(id).await?)), None),
    };
    let events = stream::unfold((start, slot), |(phase, slot)| async move {
        step(phase).await.map(|(event, next)| (event, (next, slot)))
    });
    Ok(Sse::new(events).keep_alive(KeepAlive::new().interval(Duration::from_secs(15))))
}

/// The next event of a stream and the phase after it.
async fn step(phase: Phase) -> Option<(Result<Event, Infallible>, Phase)> {
    match phase {
        Phase::First(mut rx, shutdown) => {
            let current = rx.borrow_and_update().clone();
            let next = if current.state.is_terminal() {
                Phase::Done
            } else {
                Phase::Follow(rx, shutdown, Instant::now() + MIN_EVENT_INTERVAL)
            };
            Some((Ok(job_event(&current)), next))
        }
        Phase::Follow(mut rx, mut shutdown, not_before) => {
            if *shutdown.borrow() {
                return Some((Ok(Event::default().event("shutdown").data("the server is shutting down")), Phase::Done));
            }
            // Pace the stream: changes published meanwhile are coalesced by the watch channel.
            tokio::select! {
                _ = tokio::time::sleep_until(not_before) => {}
                _ = shutdown.changed() => {
                    return Some((Ok(Event::default().event("shutdown").data("the server is shutting down")), Phase::Done));
                }
            }
            tokio::select! {
                changed = rx.changed() => match changed {
                    Ok(()) => {
                        let current = rx.borrow_and_update().clone();
                        let next = if current.state.is_terminal() {
                            Phase::Done
                        } else {
                            Phase::Follow(rx, shutdown, Instant::now() + MIN_EVENT_INTERVAL)
                        };
                        Some((Ok(job_event(&current)), next))
                    }
                    // The job left memory (finished and dropped): its last state was sent.
                    Err(_) => None,
                },
                _ = shutdown.changed() => {
                    Some((Ok(Event::default().event("shutdown").data("the server is shutting down")), Phase::Done))
                }
            }
        }
        Phase::Last(event) => Some((Ok(event), Phase::Done)),
        Phase::Done => None,
    }
}
