//! A real `optimis serve` process for tests that need the binary: crash, restart, several servers.

use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};

use super::Client;

/// A running `optimis serve` process and its address; it dereferences to a [`Client`] of that
/// address (without a token).
pub struct Process {
    child: Child,
    pub base: String,
    pub api: Client,
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
        let base = format!("http://{address}");
        Self { child, api: Client::new(&base), base }
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

impl std::ops::Deref for Process {
    type Target = Client;

    fn deref(&self) -> &Client {
        &self.api
    }
}

/// A loopback port that was free a moment ago (for servers that must know each other's address
/// before they start, such as peers on each other's allow-list).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}
