//! Prometheus metrics (`GET /metrics`, OpenMetrics text format).
//!
//! * `optimis_http_requests_total{method, route, status}` and
//!   `optimis_http_request_duration_seconds{method, route}`: every request, by route *template*
//!   (`/v1/jobs/{id}`, never the raw path; `unmatched` for anything else) and by method (the
//!   standard ones; any other string is `other`), so the label set stays bounded whatever
//!   clients send — before this, 3,000 odd method names grew a scrape from 40 KB to 12 MB;
//! * `optimis_checkpoint_duration_seconds`: writing a checkpoint (report, serialisation, database);
//! * `optimis_jobs{state}`: jobs in the database by state;
//! * `optimis_iterations_total` and `optimis_light_paths_total`: iterations and light paths computed
//!   by every job since the server started (counters: take their `rate()` for the throughput);
//! * `optimis_job_iterations_done{job_id}` and `optimis_job_light_paths_per_second{job_id}`: each
//!   running job, read from memory at scrape time (`job_id`, not `job`: Prometheus' target label is
//!   `job`, and a scraped `job` label would be renamed `exported_job`);
//! * `optimis_build_info{version}` (always 1) and the process's `process_cpu_seconds_total`,
//!   `process_resident_memory_bytes`, `process_open_fds`, `process_start_time_seconds` (read from
//!   `/proc/self` at scrape time on Linux; absent elsewhere), named as every Prometheus client names
//!   them.
//!
//! Request and checkpoint metrics are recorded as they happen; the job gauges are refreshed on
//! each scrape from the job manager, so finished jobs drop out.

use std::sync::atomic::AtomicU64;
use std::time::Duration;

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;

use crate::store::JobState;

/// The `method` label of a request: a standard method's name, or `other` (a method is any token a
/// client sends, up to the header size limit).
pub fn method_label(method: &axum::http::Method) -> &'static str {
    use axum::http::Method;
    match *method {
        Method::GET => "GET",
        Method::HEAD => "HEAD",
        Method::POST => "POST",
        Method::PUT => "PUT",
        Method::DELETE => "DELETE",
        Method::PATCH => "PATCH",
        Method::OPTIONS => "OPTIONS",
        Method::TRACE => "TRACE",
        Method::CONNECT => "CONNECT",
        _ => "other",
    }
}

/// Media type of the exposition.
pub const CONTENT_TYPE: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RequestLabels {
    method: String,
    route: String,
    status: u16,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RouteLabels {
    method: String,
    route: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct StateLabels {
    state: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct JobLabels {
    job_id: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct BuildLabels {
    version: String,
}

/// The server's metrics.
pub struct Metrics {
    registry: Registry,
    requests: Family<RequestLabels, Counter>,
    request_seconds: Family<RouteLabels, Histogram>,
    checkpoint_seconds: Histogram,
    jobs: Family<StateLabels, Gauge>,
    job_iterations: Family<JobLabels, Gauge>,
    job_rate: Family<JobLabels, Gauge<f64, AtomicU64>>,
    iterations: Counter,
    light_paths: Counter<f64, AtomicU64>,
    sweep_refits: Counter,
    cluster_tasks: Family<StateLabels, Gauge>,
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}

/// A running job's figures for the gauges.
pub struct JobSample {
    /// The job's id (the `job_id` label).
    pub id: i64,
    /// Iterations computed so far (in memory: ahead of the latest checkpoint between writes).
    pub iterations_done: u64,
    /// Light paths traced per second since the job last started running (0 before its first
    /// batch).
    pub light_paths_per_second: f64,
}

impl Metrics {
    /// A registry with every metric registered (prefixed `optimis_`) and the process collector.
    pub fn new() -> Self {
        let mut root = Registry::default();
        crate::process_metrics::ProcessCollector::started();
        root.register_collector(Box::new(crate::process_metrics::ProcessCollector));
        let registry = root.sub_registry_with_prefix("optimis");
        let requests = Family::<RequestLabels, Counter>::default();
        registry.register("http_requests", "HTTP requests by method, route template and status", requests.clone());
        // 100 µs to ~50 s.
        let request_seconds = Family::<RouteLabels, Histogram>::new_with_constructor(|| {
            Histogram::new(exponential_buckets(1e-4, 2.5, 15))
        });
        registry.register("http_request_duration_seconds", "Time to answer a request", request_seconds.clone());
        let checkpoint_seconds = Histogram::new(exponential_buckets(1e-3, 2.0, 14));
        registry.register("checkpoint_duration_seconds", "Time to write one checkpoint", checkpoint_seconds.clone());
        let jobs = Family::<StateLabels, Gauge>::default();
        registry.register("jobs", "Jobs in the database by state", jobs.clone());
        let job_iterations = Family::<JobLabels, Gauge>::default();
        registry.register("job_iterations_done", "Iterations a running job has computed", job_iterations.clone());
        let job_rate = Family::<JobLabels, Gauge<f64, AtomicU64>>::default();
        registry.register("job_light_paths_per_second", "Recent throughput of a running job", job_rate.clone());
        let iterations = Counter::default();
        registry.register("iterations", "Iterations computed by all jobs since the server started", iterations.clone());
        let light_paths = Counter::<f64, AtomicU64>::default();
        registry.register(
            "light_paths",
            "Light paths (N_F per iteration) of all jobs' iterations since the server started",
            light_paths.clone(),
        );
        let sweep_refits = Counter::default();
        registry.register(
            "sweep_refits",
            "Re-fits of a sweep run's predicted points (one per checkpoint read, single flight)",
            sweep_refits.clone(),
        );
        let cluster_tasks = Family::<StateLabels, Gauge>::default();
        registry.register(
            "cluster_tasks",
            "Tasks of the jobs followed on a cluster (--executor slurm) by state",
            cluster_tasks.clone(),
        );
        let build = Family::<BuildLabels, Gauge>::default();
        build.get_or_create(&BuildLabels { version: env!("CARGO_PKG_VERSION").to_string() }).set(1);
        registry.register("build_info", "The optimis version serving (always 1)", build);
        Self {
            registry: root,
            requests,
            request_seconds,
            checkpoint_seconds,
            jobs,
            job_iterations,
            job_rate,
            iterations,
            light_paths,
            sweep_refits,
            cluster_tasks,
        }
    }

    /// Sets the counts of cluster tasks by state (the states absent count none).
    pub fn set_cluster_tasks(&self, by_state: &std::collections::BTreeMap<String, i64>) {
        self.cluster_tasks.clear();
        for (state, n) in by_state {
            self.cluster_tasks.get_or_create(&StateLabels { state: state.clone() }).set(*n);
        }
    }

    /// Counts one re-fit of a sweep run's predicted points.
    pub fn count_sweep_refit(&self) {
        self.sweep_refits.inc();
    }

    /// Counts iterations a job computed, with their light paths.
    pub fn add_iterations(&self, iterations: u64, light_paths_each: u64) {
        self.iterations.inc_by(iterations);
        self.light_paths.inc_by(iterations as f64 * light_paths_each as f64);
    }

    /// Records one answered request.
    pub fn observe_request(&self, method: &str, route: &str, status: u16, elapsed: Duration) {
        let route = route.to_string();
        self.requests.get_or_create(&RequestLabels { method: method.into(), route: route.clone(), status }).inc();
        self.request_seconds
            .get_or_create(&RouteLabels { method: method.into(), route })
            .observe(elapsed.as_secs_f64());
    }

    /// Records one checkpoint write.
    pub fn observe_checkpoint(&self, elapsed: Duration) {
        self.checkpoint_seconds.observe(elapsed.as_secs_f64());
    }

    /// Renders the exposition with the given job counts by state and running jobs.
    pub fn render(&self, states: &[(JobState, i64)], running: &[JobSample]) -> String {
        self.jobs.clear();
        for (state, count) in states {
            self.jobs.get_or_create(&StateLabels { state: state.as_str().to_string() }).set(*count);
        }
        self.job_iterations.clear();
        self.job_rate.clear();
        for job in running {
            let labels = JobLabels { job_id: job.id.to_string() };
            self.job_iterations.get_or_create(&labels).set(job.iterations_done as i64);
            self.job_rate.get_or_create(&labels).set(job.light_paths_per_second);
        }
        let mut out = String::new();
        prometheus_client::encoding::text::encode(&mut out, &self.registry).expect("writing to a String cannot fail");
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exposition_has_every_family() {
        let m = Metrics::new();
        m.observe_request("GET", "/v1/jobs/{id}", 200, Duration::from_millis(3));
        m.observe_checkpoint(Duration::from_millis(20));
        m.add_iterations(3, 1_000_000);
        m.add_iterations(2, 1_000_000);
        m.set_cluster_tasks(&[("running".to_string(), 3), ("pending".to_string(), 1)].into());
        let build = format!(r#"optimis_build_info{{version="{}"}} 1"#, env!("CARGO_PKG_VERSION"));
        let text = m.render(
            &[(JobState::Running, 1), (JobState::Succeeded, 4)],
            &[JobSample { id: 7, iterations_done: 12, light_paths_per_second: 5e7 }],
        );
        for needle in [
            r#"optimis_http_requests_total{method="GET",route="/v1/jobs/{id}",status="200"} 1"#,
            "optimis_http_request_duration_seconds_bucket",
            "optimis_checkpoint_duration_seconds_count 1",
            r#"optimis_jobs{state="succeeded"} 4"#,
            r#"optimis_job_iterations_done{job_id="7"} 12"#,
            r#"optimis_job_light_paths_per_second{job_id="7"} 50000000"#,
            "optimis_iterations_total 5",
            "optimis_light_paths_total 5000000",
            r#"optimis_cluster_tasks{state="running"} 3"#,
            build.as_str(),
            "# EOF",
        ] {
            assert!(text.contains(needle), "missing {needle} in\n{text}");
        }
        let again = m.render(&[], &[]);
        assert!(!again.contains(r#"job_id="7""#), "finished jobs drop out");
        if cfg!(target_os = "linux") {
            assert!(
                text.contains("process_cpu_seconds_total ") && text.contains("process_resident_memory_bytes "),
                "{text}"
            );
        }
    }

    #[test]
    fn odd_methods_share_one_label() {
        let odd = axum::http::Method::from_bytes(b"FROBNICATE").unwrap();
        assert_eq!(method_label(&odd), "other");
        assert_eq!(method_label(&axum::http::Method::DELETE), "DELETE");
    }
}
