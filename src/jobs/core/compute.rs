//! Where the CPU work a request waits for runs: never on tokio's workers, never on the
//! simulation pool (it would queue behind the running jobs' chunks), and the heavy part of it
//! (reference quadratures, re-fits, re-solves, predictions, evaluations) on a pool of its own so
//! that it cannot starve the light part (parsing, validation, checksums) that every submission and
//! status read needs.
//!
//! The heavy pool is bounded three ways: a fixed number of threads, a fixed number of computations
//! admitted at once (running or queued, [`HEAVY_SLOTS`]), and a bounded wait for admission
//! ([`HEAVY_WAIT`], then 429). A computation keeps its slot until it has actually ended — not until
//! its request went away — so abandoned requests cannot pile work up behind the slots; and it is
//! told when its request went away or the server began to shut down ([`Stop`]), so that long
//! loops end early.

use std::panic::AssertUnwindSafe;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use tokio::sync::{Semaphore, watch};

use super::error::JobError;

/// Threads of the request pool (light work) and of the heavy pool.
const REQUEST_THREADS: usize = 2;
const HEAVY_THREADS: usize = 1;

/// Heavy computations admitted at once, running or queued on the heavy pool's thread.
pub const HEAVY_SLOTS: usize = 4;

/// The longest a request waits for a heavy slot before it is answered 429.
pub const HEAVY_WAIT: Duration = Duration::from_secs(10);

/// The two pools of request computations.
pub struct Pools {
    requests: rayon::ThreadPool,
    heavy: rayon::ThreadPool,
    heavy_slots: Arc<Semaphore>,
}

/// What a heavy computation checks between steps: whether its request went away or the server
/// is shutting down, in which case its result would be thrown away.
pub struct Stop {
    abandoned: Arc<AtomicBool>,
    shutdown: watch::Receiver<bool>,
}

impl Stop {
    /// True once the computation's request went away or the server began to shut down: its
    /// result would be thrown away, so a long loop should end early.
    pub fn stopped(&self) -> bool {
        self.abandoned.load(Ordering::Relaxed) || *self.shutdown.borrow()
    }
}

/// Sets the flag when the request's future is dropped before the computation answered.
struct Abandon {
    flag: Arc<AtomicBool>,
    armed: bool,
}

impl Drop for Abandon {
    fn drop(&mut self) {
        if self.armed {
            self.flag.store(true, Ordering::Relaxed);
        }
    }
}

impl Pools {
    /// Starts both pools (two light threads, one heavy thread with [`HEAVY_SLOTS`] admissions);
    /// fails if a thread cannot be started.
    pub fn new() -> Result<Self, rayon::ThreadPoolBuildError> {
        let pool = |n, name: &'static str| {
            rayon::ThreadPoolBuilder::new().num_threads(n).thread_name(move |i| format!("optimis-{name}-{i}")).build()
        };
        Ok(Self {
            requests: pool(REQUEST_THREADS, "requests")?,
            heavy: pool(HEAVY_THREADS, "heavy")?,
            heavy_slots: Arc::new(Semaphore::new(HEAVY_SLOTS)),
        })
    }

    /// Runs light work `f` on the request pool and awaits its result.
    pub async fn light<T: Send + 'static>(&self, f: impl FnOnce() -> T + Send + 'static) -> Result<T, JobError> {
        let (tx, rx) = tokio::sync::oneshot::channel();
        self.requests.spawn(move || {
            // A panic must not abort the process (rayon's default for spawned work).
            let _ = tx.send(std::panic::catch_unwind(AssertUnwindSafe(f)));
        });
        answer(rx.await)
    }

    /// Runs heavy work `f` on the heavy pool once a slot is free (429 after [`HEAVY_WAIT`]), and
    /// awaits its result. `f` is given a [`Stop`] to check between its steps.
    pub async fn heavy<T: Send + 'static>(
        &self,
        shutdown: watch::Receiver<bool>,
        f: impl FnOnce(&Stop) -> T + Send + 'static,
    ) -> Result<T, JobError> {
        let permit = match tokio::time::timeout(HEAVY_WAIT, self.heavy_slots.clone().acquire_owned()).await {
            Ok(Ok(permit)) => permit,
            Ok(Err(_)) => return Err(JobError::ShuttingDown),
            Err(_) => {
                return Err(JobError::Busy {
                    detail: format!(
                        "the server is busy with {HEAVY_SLOTS} other long computations (re-fits, quadratures, predictions); retry"
                    ),
                    retry_after_seconds: 5,
                });
            }
        };
        let mut abandon = Abandon { flag: Arc::new(AtomicBool::new(false)), armed: true };
        let stop = Stop { abandoned: abandon.flag.clone(), shutdown };
        let (tx, rx) = tokio::sync::oneshot::channel();
        self.heavy.spawn(move || {
            let out = (!stop.stopped()).then(|| std::panic::catch_unwind(AssertUnwindSafe(|| f(&stop))));
            // The slot is free before the answer arrives: whoever got the answer finds it free.
            drop(permit);
            if let Some(out) = out {
                let _ = tx.send(out);
            }
        });
        let out = rx.await;
        abandon.armed = false;
        match out {
            Err(_) => Err(JobError::ShuttingDown),
            ok => answer(ok),
        }
    }
}

fn answer<T>(received: Result<std::thread::Result<T>, tokio::sync::oneshot::error::RecvError>) -> Result<T, JobError> {
    match received {
        Ok(Ok(value)) => Ok(value),
        _ => Err(JobError::Internal("a computation panicked".into())),
    }
}

#[cfg(test)]
mod tests {
    use std::sync::mpsc;

    use super::*;

    fn running() -> watch::Receiver<bool> {
        watch::channel(false).1
    }

    /// Fills every heavy slot with a computation that blocks until the returned senders are
    /// dropped (or sent to).
    async fn fill_heavy(
        pools: &Arc<Pools>,
    ) -> (Vec<mpsc::Sender<()>>, Vec<tokio::task::JoinHandle<Result<(), JobError>>>) {
        let mut release = Vec::new();
        let mut tasks = Vec::new();
        for _ in 0..HEAVY_SLOTS {
            let (tx, rx) = mpsc::channel::<()>();
            release.push(tx);
            let p = pools.clone();
            tasks.push(tokio::spawn(async move {
                p.heavy(running(), move |_| {
                    let _ = rx.recv();
                })
                .await
            }));
        }
        while pools.heavy_slots.available_permits() > 0 {
            tokio::task::yield_now().await;
        }
        (release, tasks)
    }

    #[tokio::test(start_paused = true)]
    async fn light_work_is_answered_while_every_heavy_slot_is_taken() {
        let pools = Arc::new(Pools::new().unwrap());
        let (release, tasks) = fill_heavy(&pools).await;
        assert_eq!(pools.light(|| 6 * 7).await.unwrap(), 42);
        drop(release);
        for t in tasks {
            t.await.unwrap().unwrap();
        }
        assert_eq!(pools.heavy_slots.available_permits(), HEAVY_SLOTS);
    }

    #[tokio::test(start_paused = true)]
    async fn heavy_work_beyond_the_slots_is_refused_after_the_wait_not_queued() {
        let pools = Arc::new(Pools::new().unwrap());
        let (release, tasks) = fill_heavy(&pools).await;
        let started = tokio::time::Instant::now();
        let refused = pools.heavy(running(), |_| ()).await;
        assert!(matches!(refused, Err(JobError::Busy { retry_after_seconds: 5, .. })), "{refused:?}");
        // Paused clock: exactly the stated wait, whatever the machine's speed.
        assert_eq!(started.elapsed(), HEAVY_WAIT);
        drop(release);
        for t in tasks {
            t.await.unwrap().unwrap();
        }
        assert_eq!(pools.heavy(running(), |_| 1).await.unwrap(), 1);
    }

    #[tokio::test]
    async fn an_abandoned_computation_is_told_to_stop_and_keeps_its_slot_until_it_ends() {
        let pools = Arc::new(Pools::new().unwrap());
        let (started_tx, started_rx) = tokio::sync::oneshot::channel();
        let (saw_tx, saw_rx) = mpsc::channel();
        let p = pools.clone();
        let request = tokio::spawn(async move {
            p.heavy(running(), move |stop| {
                let _ = started_tx.send(());
                // A long loop that checks between its steps, as the quadratures do.
                while !stop.stopped() {
                    std::thread::yield_now();
                }
                let _ = saw_tx.send(());
            })
            .await
        });
        started_rx.await.unwrap();
        assert_eq!(pools.heavy_slots.available_permits(), HEAVY_SLOTS - 1);
        request.abort();
        let _ = request.await;
        tokio::task::spawn_blocking(move || saw_rx.recv()).await.unwrap().expect("the computation saw the stop");
        // The slot comes back once the computation has returned, not when the request went away.
        while pools.heavy_slots.available_permits() < HEAVY_SLOTS {
            tokio::task::yield_now().await;
        }
    }

    #[tokio::test]
    async fn shutdown_stops_a_heavy_computation() {
        let pools = Pools::new().unwrap();
        let (tx, rx) = watch::channel(false);
        let (started_tx, started_rx) = mpsc::channel();
        let request = pools.heavy(rx, move |stop| {
            let _ = started_tx.send(());
            let mut steps = 0u64;
            while !stop.stopped() {
                steps += 1;
                std::thread::yield_now();
            }
            steps
        });
        let stopper = async move {
            tokio::task::spawn_blocking(move || started_rx.recv()).await.unwrap().unwrap();
            tx.send(true).unwrap();
            tx
        };
        let (result, _tx) = tokio::join!(request, stopper);
        assert!(result.is_ok(), "it returned what it had when told to stop: {result:?}");
    }

    #[tokio::test]
    async fn a_panic_is_an_internal_error_not_an_abort() {
        let pools = Pools::new().unwrap();
        assert!(matches!(pools.light(|| panic!("light")).await, Err(JobError::Internal(_))));
        assert!(matches!(pools.heavy(running(), |_| panic!("heavy")).await, Err(JobError::Internal(_))));
        assert_eq!(pools.heavy_slots.available_permits(), HEAVY_SLOTS);
    }
}
