//! `optimis wait URL`: follows a job or a sweep on a server until it ends — exit status 0 when it
//! succeeded, 1 when it failed or was cancelled (with the job's error), 5 when the server does not
//! answer, 3 when it refuses the request (no such job, a bad token) — printing its progress on
//! stderr as it changes. What the README's wait steps use instead of a shell loop that has to
//! parse JSON (and, written with `grep`, could be fooled by a nested state or spin for ever on a
//! server that is gone).
//!
//! It long-polls (`?wait=30`: the server answers when the resource ends), so a wait costs the
//! server one request per 30 s; `OPTIMIS_TOKEN` is sent as the bearer token when set.

use std::time::{Duration, Instant};

use clap::Args;
use serde_json::Value;

use super::CliError;
use super::remote::{Server, runtime};

/// Seconds of each long-poll (the server allows up to 60).
const POLL_SECONDS: u64 = 30;

#[derive(Debug, Args)]
pub struct WaitArgs {
    /// The job or sweep: its URL, e.g. `localhost:8080/v1/jobs/1` or `https://host/v1/sweeps/2`
    /// (http:// when no scheme is given).
    pub url: String,
    /// Give up (exit status 1) after this many seconds; default: as long as it runs.
    #[arg(long, value_parser = super::serve::positive_seconds)]
    pub timeout: Option<f64>,
    /// Print nothing while waiting (the final line still goes to stdout).
    #[arg(long)]
    pub quiet: bool,
}

/// Runs `optimis wait`.
pub fn wait(args: WaitArgs) -> Result<(), CliError> {
    // The server answers a long-poll within POLL_SECONDS; a server that does not is gone.
    let server = Server::new(&args.url, Duration::from_secs(POLL_SECONDS + 30))?;
    let mut target =
        reqwest::Url::parse(&server.url("")).map_err(|e| CliError::Config(format!("URL {}: {e}", args.url)))?;
    target.query_pairs_mut().append_pair("wait", &POLL_SECONDS.to_string());
    runtime()?.block_on(follow(&server, target.as_str(), &args))
}

async fn follow(server: &Server, target: &str, args: &WaitArgs) -> Result<(), CliError> {
    let deadline = args.timeout.map(|s| Instant::now() + Duration::from_secs_f64(s));
    let shown = target.split('?').next().unwrap_or_default().to_string();
    let mut last = String::new();
    loop {
        let answer = server.get(target).await.map_err(|e| match e {
            // A stopped server keeps what it accepted: say so, rather than leave "failed?" open.
            CliError::Unreachable { url, detail } => CliError::Unreachable {
                url,
                detail: format!(
                    "{detail}; {} — a server keeps the jobs it accepted and resumes them from their last \
                     checkpoint when it starts again: run `optimis wait` again then",
                    if last.is_empty() { "nothing was heard yet".to_string() } else { format!("last seen: {last}") }
                ),
            },
            other => other,
        })?;
        if answer.status == reqwest::StatusCode::TOO_MANY_REQUESTS {
            // Too many waiters on the server: come back when it says.
            tokio::time::sleep(Duration::from_secs(answer.retry_after.unwrap_or(5).clamp(1, 60))).await;
            continue;
        }
        let resource = answer.json(&shown)?;
        let Some(state) = resource["state"].as_str() else {
            return Err(CliError::Refused {
                url: shown,
                status: answer.status.as_u16(),
                detail: "the answer has no `state`: not a job or a sweep".into(),
            });
        };
        let line = progress_line(&resource, state);
        match state {
            "succeeded" => {
                println!("{line}");
                return Ok(());
            }
            "failed" | "cancelled" => return Err(CliError::Ended(line)),
            _ => {}
        }
        if !args.quiet && line != last {
            eprintln!("{line}");
        }
        last = line;
        if deadline.is_some_and(|d| Instant::now() >= d) {
            return Err(CliError::Ended(format!("{last} — still not ended after --timeout")));
        }
    }
}

/// `job 3: running, 4,000 of 10,000 iterations` or `sweep 1: running, 4 of 9 runs succeeded`,
/// with a failed job's error.
fn progress_line(resource: &Value, state: &str) -> String {
    let id = resource["id"].as_i64().unwrap_or_default();
    if let Some(runs) = resource["progress"]["runs"].as_u64() {
        let ok = resource["progress"]["runs_by_state"]["succeeded"].as_u64().unwrap_or(0);
        let failed = resource["progress"]["runs_by_state"]["failed"].as_u64().unwrap_or(0);
        let failed = if failed > 0 { format!(", {failed} failed") } else { String::new() };
        return format!("sweep {id}: {state}, {ok} of {runs} runs succeeded{failed}");
    }
    let done = resource["progress"]["iterations_done"].as_u64().unwrap_or(0);
    let total = resource["progress"]["iterations_total"].as_u64().unwrap_or(0);
    let error = resource["error"].as_str().map(|e| format!(": {e}")).unwrap_or_default();
    format!("job {id}: {state}, {done} of {total} iterations{error}")
}
