//! A real `optimis serve` process for tests that need the binary: crash, restart, several servers.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

/// A running `optimis serve` process and its address.
pub struct Process {
    child: Child,
    pub base: String,
}

impl Process {
    /// Starts the binary on `database` with a free port, and reads the port from its JSON log.
    pub fn start(database: &str) -> Self {
        Self::start_with(database, &["--checkpoint-iterations", "3", "--checkpoint-seconds", "0.5"])
    }

    pub fn start_with(database: &str, extra: &[&str]) -> Self {
        Self::start_on(database, 0, extra)
    }

    /// Starts the binary on 127.0.0.1:`port` (0: a free port) with `extra` flags.
    pub fn start_on(database: &str, port: u16, extra: &[&str]) -> Self {
        let bind = format!("127.0.0.1:{port}");
        let mut child = Command::new(env!("CARGO_BIN_EXE_optimis"))
            .args(["serve", "--bind", &bind, "--database", database, "--threads", "2", "--log-format", "json"])
            .args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("optimis starts");
        let stderr = child.stderr.take().unwrap();
        let mut lines = BufReader::new(stderr).lines();
        let address = loop {
            let line = lines.next().expect("the server logs its address").unwrap();
            let entry: Value = serde_json::from_str(&line).unwrap_or(Value::Null);
            if let Some(a) = entry["fields"]["address"].as_str() {
                break a.to_string();
            }
        };
        // Keep draining the log so the server never blocks on a full pipe.
        std::thread::spawn(move || for _ in lines {});
        Self { child, base: format!("http://{address}") }
    }

    pub fn kill(mut self) {
        self.child.kill().unwrap(); // SIGKILL
        self.child.wait().unwrap();
    }

    /// SIGTERM, then the exit status.
    pub fn terminate(mut self) -> std::process::ExitStatus {
        let pid = self.child.id().to_string();
        let sent = Command::new("kill").args(["-TERM", &pid]).status().expect("kill(1) runs");
        assert!(sent.success());
        self.child.wait().unwrap()
    }
}

/// A loopback port that was free a moment ago (for servers that must know each other's address
/// before they start, such as peers on each other's allow-list).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

pub async fn get(client: &reqwest::Client, url: String) -> Value {
    let response = client.get(&url).send().await.unwrap();
    assert_eq!(response.status(), 200, "GET {url}");
    response.json().await.unwrap()
}

pub async fn wait_for(client: &reqwest::Client, base: &str, id: i64, done: impl Fn(&Value) -> bool) -> Value {
    let started = Instant::now();
    loop {
        let job = get(client, format!("{base}/v1/jobs/{id}")).await;
        if done(&job) {
            return job;
        }
        assert!(started.elapsed() < Duration::from_secs(600), "hang guard: {job}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}
