//! The scheduler: starts queued jobs in submission order while workers are free, each on a blocking
//! thread that drives the simulation pool (see `driver`), and notices when a driver ends.

use std::sync::Arc;
use std::sync::atomic::Ordering;

use super::driver;
use super::state::Inner;

/// Starts queued jobs while workers are free; runs until shutdown.
pub(in crate::jobs) async fn scheduler(inner: Arc<Inner>) {
    let mut shutdown = inner.shutdown.subscribe();
    loop {
        if *shutdown.borrow() {
            return;
        }
        start_ready_jobs(&inner).await;
        tokio::select! {
            _ = inner.wake.notified() => {}
            _ = shutdown.changed() => {}
        }
    }
}

async fn start_ready_jobs(inner: &Arc<Inner>) {
    while inner.running.load(Ordering::SeqCst) < inner.policy.workers {
        let _guard = inner.lifecycle.lock().await;
        let next = inner.queue.lock().expect("queue").pop_front();
        let Some(id) = next else { return };
        let Some(job) = inner.active.lock().expect("active map").get(&id).cloned() else { continue };
        inner.running.fetch_add(1, Ordering::SeqCst);
        let driver_inner = inner.clone();
        let handle = tokio::task::spawn_blocking(move || driver::drive(&driver_inner, &job));
        let done_inner = inner.clone();
        tokio::spawn(async move {
            if let Err(e) = handle.await {
                tracing::error!(job = id, error = %e, "job driver panicked");
                let _ = done_inner.fail(id, "internal error: the job's driver panicked").await;
            }
            done_inner.running.fetch_sub(1, Ordering::SeqCst);
            done_inner.driver_ended.notify_waiters();
            done_inner.wake.notify_one();
        });
    }
}
