//! Latency of sequential status polls: `GET /v1/jobs/{id}` N times on one keep-alive connection.
//!
//! cargo run --release --example poll_latency -- http://127.0.0.1:8080 1 1000
//!
//! Prints the median, p90, p99 and maximum latency and the number of failed requests. A benchmark
//! for docs/results.md, not a test.

use std::time::{Duration, Instant};

#[tokio::main(flavor = "current_thread")]
async fn main() {
    let args: Vec<String> = std::env::args().collect();
    let base = args.get(1).cloned().unwrap_or_else(|| "http://127.0.0.1:8080".into());
    let id = args.get(2).cloned().unwrap_or_else(|| "1".into());
    let count: usize = args.get(3).and_then(|n| n.parse().ok()).unwrap_or(1000);
    optimis::trust::pins::install_crypto_provider();
    let client = reqwest::Client::new();
    let url = format!("{base}/v1/jobs/{id}");
    let mut latencies = Vec::with_capacity(count);
    let mut errors = 0;
    let mut states = std::collections::BTreeMap::<String, usize>::new();
    for _ in 0..count {
        let started = Instant::now();
        match client.get(&url).send().await {
            Ok(r) if r.status().is_success() => {
                let body: serde_json::Value = r.json().await.unwrap_or_default();
                latencies.push(started.elapsed());
                *states.entry(body["state"].as_str().unwrap_or("?").to_string()).or_default() += 1;
            }
            _ => errors += 1,
        }
    }
    latencies.sort();
    let pick = |q: f64| {
        latencies.get(((latencies.len() as f64 - 1.0) * q).round() as usize).copied().unwrap_or(Duration::ZERO)
    };
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "{} polls of {url}: median {:.3} ms, p90 {:.3} ms, p99 {:.3} ms, max {:.3} ms, errors {errors}, states seen {states:?}",
        latencies.len(),
        ms(pick(0.5)),
        ms(pick(0.9)),
        ms(pick(0.99)),
        ms(pick(1.0)),
    );
}
