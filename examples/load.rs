//! Load benchmark: C concurrent clients poll a job's status and result for T seconds.
//!
//! cargo run --release --example load -- http://127.0.0.1:8080 1 100 30
//!
//! Arguments: base URL, job id, clients (default 100), seconds (default 30). With `OPTIMIS_TOKEN`
//! set, requests carry it as a bearer token. Each client alternates `GET /v1/jobs/{id}` and
//! `GET /v1/jobs/{id}/result` on its own keep-alive connection and reads every body in full.
//! Prints requests per second, p50/p99/max latency per route, and errors (any non-200 answer or
//! transport failure). A benchmark for docs/results.md, not a test: it asserts nothing about time.

use std::time::{Duration, Instant};

/// What one client measured.
#[derive(Default)]
struct Tally {
    status: Vec<Duration>,
    result: Vec<Duration>,
    errors: Vec<String>,
    states: Vec<String>,
}

async fn client_loop(base: String, id: String, token: Option<String>, until: Instant) -> Tally {
    // One client per connection: a dashboard tab or a polling script.
    optimis::trust::pins::install_crypto_provider();
    let client = reqwest::Client::builder().pool_max_idle_per_host(1).build().expect("client");
    let urls = [format!("{base}/v1/jobs/{id}"), format!("{base}/v1/jobs/{id}/result")];
    let mut tally = Tally::default();
    let mut turn = 0usize;
    while Instant::now() < until {
        let which = turn % 2;
        turn += 1;
        let mut request = client.get(&urls[which]);
        if let Some(token) = &token {
            request = request.bearer_auth(token);
        }
        let started = Instant::now();
        let outcome = match request.send().await {
            Ok(response) if response.status() == 200 => response.bytes().await.map_err(|e| e.to_string()),
            Ok(response) => Err(format!("{} from {}", response.status(), urls[which])),
            Err(e) => Err(e.to_string()),
        };
        let elapsed = started.elapsed();
        match outcome {
            Ok(body) if which == 0 => {
                tally.status.push(elapsed);
                if let Ok(job) = serde_json::from_slice::<serde_json::Value>(&body) {
                    tally.states.push(job["state"].as_str().unwrap_or("?").to_string());
                }
            }
            Ok(_) => tally.result.push(elapsed),
            Err(e) => tally.errors.push(e),
        }
    }
    tally
}

fn summary(name: &str, latencies: &mut [Duration], seconds: f64) -> String {
    latencies.sort();
    let pick = |q: f64| {
        latencies.get(((latencies.len() as f64 - 1.0) * q).round() as usize).copied().unwrap_or(Duration::ZERO)
    };
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    format!(
        "{name}: {} requests, {:.0} req/s, p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
        latencies.len(),
        latencies.len() as f64 / seconds,
        ms(pick(0.5)),
        ms(pick(0.99)),
        ms(pick(1.0))
    )
}

#[tokio::main]
async fn main() {
    let args: Vec<String> = std::env::args().collect();
    let base = args.get(1).cloned().unwrap_or_else(|| "http://127.0.0.1:8080".into());
    let id = args.get(2).cloned().unwrap_or_else(|| "1".into());
    let clients: usize = args.get(3).and_then(|n| n.parse().ok()).unwrap_or(100);
    let seconds: f64 = args.get(4).and_then(|n| n.parse().ok()).unwrap_or(30.0);
    let token = std::env::var("OPTIMIS_TOKEN").ok();

    let started = Instant::now();
    let until = started + Duration::from_secs_f64(seconds);
    let tasks: Vec<_> =
        (0..clients).map(|_| tokio::spawn(client_loop(base.clone(), id.clone(), token.clone(), until))).collect();
    let mut all = Tally::default();
    for task in tasks {
        let tally = task.await.expect("client task");
        all.status.extend(tally.status);
        all.result.extend(tally.result);
        all.errors.extend(tally.errors);
        all.states.extend(tally.states);
    }
    let wall = started.elapsed().as_secs_f64();
    let mut both: Vec<Duration> = all.status.iter().chain(&all.result).copied().collect();
    let mut states = std::collections::BTreeMap::<&str, usize>::new();
    for state in &all.states {
        *states.entry(state.as_str()).or_default() += 1;
    }
    println!("{clients} clients for {wall:.1} s against job {id} at {base}");
    println!("{}", summary("all", &mut both, wall));
    println!("{}", summary("GET /v1/jobs/{id}", &mut all.status, wall));
    println!("{}", summary("GET /v1/jobs/{id}/result", &mut all.result, wall));
    println!("job states seen by the status polls: {states:?}");
    println!("errors: {}", all.errors.len());
    for error in all.errors.iter().take(5) {
        println!("  {error}");
    }
}
