//! `GET /v1/jobs/{id}/events`: Server-Sent Events of a job's resource as it changes.
//!
//! Each event is named `job` and carries the job resource. The stream sends the current resource
//! first, then changes — at most one event per [`MIN_EVENT_INTERVAL`] (changes in between are
//! coalesced: the next event carries the latest state) — and ends after the event that shows a
//! terminal state, or with a `shutdown` event when the server stops. Every `job` event has an `id:`
//! (the iterations it shows, then the state: `1200`, `1200-succeeded`) and the first a `retry:`
//! (reconnect after 5 s); a reconnecting client gets the current state, which is all the stream
//! promises. A job that has already ended answers **204 No Content**: the status that tells a
//! browser's `EventSource` to stop reconnecting (a 200 with one event would make it reconnect for
//! ever). Only streams that stay open take one of the `--max-event-streams` slots.

use std::convert::Infallible;
use std::time::Duration;

use tokio::time::Instant;

use axum::extract::State;
use axum::http::StatusCode;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use futures_util::stream;
use tokio::sync::watch;

use super::AppState;
use super::error::{ApiError, Problem};
use super::extract::JobId;
use super::responses::{NoSuchJob, ServerFailure};
use crate::jobs::core::resource::JobResource;

/// Shortest time between two events of a stream.
pub const MIN_EVENT_INTERVAL: Duration = Duration::from_millis(250);

/// How long a browser waits before it reconnects a dropped stream.
const RETRY: Duration = Duration::from_secs(5);

fn job_event(resource: &JobResource) -> Event {
    let done = resource.progress.iterations_done;
    let id =
        if resource.state.is_terminal() { format!("{done}-{}", resource.state.as_str()) } else { done.to_string() };
    Event::default().event("job").id(id).json_data(resource).unwrap_or_else(|_| Event::default().event("job"))
}

enum Phase {
    /// Send the current resource next.
    First(watch::Receiver<JobResource>, watch::Receiver<bool>),
    /// Wait for changes, sending none before the instant given.
    Follow(watch::Receiver<JobResource>, watch::Receiver<bool>, Instant),
    Done,
}

/// Stream a job's changes.
#[utoipa::path(
    get, operation_id = "stream_job_events", path = "/v1/jobs/{id}/events", tag = "jobs", params(("id" = i64, Path, description = "Job id")),
    responses(
        (status = 200, description = "Events named `job` with the job resource as data (each with an `id:`, the first with `retry:`); a final `shutdown` event if the server stops",
            content_type = "text/event-stream", body = String),
        (status = 204, description = "The job has already ended: nothing to stream (an EventSource stops reconnecting)"),
        NoSuchJob,
        (status = 429, description = "Too many event streams are open; retry after Retry-After seconds", body = Problem, content_type = "application/problem+json"),
        ServerFailure,
    )
)]
pub async fn events(State(state): State<AppState>, JobId(id): JobId) -> Result<Response, ApiError> {
    let shutdown = state.services.jobs.shutdown_signal();
    let Some(rx) = state.services.jobs.subscribe(id) else {
        state.services.jobs.get(id).await?; // 404 for no such job
        return Ok(StatusCode::NO_CONTENT.into_response());
    };
    // Held by the stream: the slot frees when the stream ends or the client goes away.
    let slot = state.streams.acquire()?;
    let events = stream::unfold((Phase::First(rx, shutdown), slot), |(phase, slot)| async move {
        step(phase).await.map(|(event, next)| (event, (next, slot)))
    });
    Ok(Sse::new(events).keep_alive(KeepAlive::new().interval(Duration::from_secs(15))).into_response())
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
            Some((Ok(job_event(&current).retry(RETRY)), next))
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
        Phase::Done => None,
    }
}
