//! External commands (a batch system's: Slurm's `sbatch`, `squeue`, `scancel`) run with a deadline
//! and a bounded capture of their output: a controller that does not answer, or a command that
//! prints without end, costs the follower a timeout and a few MiB, never a hung thread.

use std::io::Read;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Most bytes kept of a command's stdout and of its stderr (the rest is read and dropped, so the
/// command never blocks on a full pipe).
pub const MAX_OUTPUT: u64 = 4 << 20;

/// Why a command gave no usable answer.
#[derive(Debug, thiserror::Error)]
pub enum CommandError {
    /// It could not be started (not installed, not executable).
    #[error("cannot run {program}: {source}")]
    Spawn {
        /// The program.
        program: String,
        /// Why.
        source: std::io::Error,
    },
    /// It did not finish in time (it was killed).
    #[error("{program} did not answer within {seconds} s")]
    Timeout {
        /// The program.
        program: String,
        /// The deadline.
        seconds: f64,
    },
    /// It exited unsuccessfully.
    #[error("{program} failed ({status}): {stderr}")]
    Failed {
        /// The program.
        program: String,
        /// Its exit status.
        status: String,
        /// The end of what it printed on stderr.
        stderr: String,
    },
}

/// Runs `program` with `args` (argv: nothing passes through a shell), stdin closed, and returns
/// its stdout if it exits successfully within `timeout`.
pub fn run(program: &str, args: &[String], timeout: Duration) -> Result<String, CommandError> {
    let mut child = Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|source| CommandError::Spawn { program: program.to_string(), source })?;
    let started = Instant::now();
    let stdout = Captured::start(child.stdout.take());
    let stderr = Captured::start(child.stderr.take());
    let status = match wait(&mut child, timeout) {
        Some(status) => status,
        None => {
            let _ = child.kill();
            let _ = child.wait();
            return Err(CommandError::Timeout { program: program.to_string(), seconds: timeout.as_secs_f64() });
        }
    };
    // A command may leave children holding its pipes open: wait for the end of its output only
    // until the deadline, then take what arrived.
    let deadline = Instant::now().max(started + timeout);
    let stdout = stdout.take_by(deadline);
    let stderr = stderr.take_by(deadline);
    if !status.success() {
        return Err(CommandError::Failed {
            program: program.to_string(),
            status: status.to_string(),
            stderr: tail(&stderr),
        });
    }
    Ok(stdout)
}

/// The exit status, or None at the deadline.
fn wait(child: &mut Child, timeout: Duration) -> Option<std::process::ExitStatus> {
    let deadline = Instant::now() + timeout;
    let mut pause = Duration::from_millis(5);
    loop {
        if let Ok(Some(status)) = child.try_wait() {
            return Some(status);
        }
        let now = Instant::now();
        if now >= deadline {
            return None;
        }
        std::thread::sleep(pause.min(deadline - now));
        pause = (pause * 2).min(Duration::from_millis(50));
    }
}

/// A pipe read to its end on a thread of its own, keeping the first [`MAX_OUTPUT`] bytes.
struct Captured {
    kept: Arc<Mutex<Vec<u8>>>,
    reader: JoinHandle<()>,
}

impl Captured {
    fn start(pipe: Option<impl Read + Send + 'static>) -> Self {
        let kept = Arc::new(Mutex::new(Vec::new()));
        let into = kept.clone();
        let reader = std::thread::spawn(move || {
            let Some(pipe) = pipe else { return };
            let mut limited = pipe.take(MAX_OUTPUT);
            let mut buffer = [0u8; 8192];
            while let Ok(n) = limited.read(&mut buffer) {
                if n == 0 {
                    break;
                }
                into.lock().expect("captured output").extend_from_slice(&buffer[..n]);
            }
            let _ = std::io::copy(&mut limited.into_inner(), &mut std::io::sink());
        });
        Self { kept, reader }
    }

    /// What arrived once the pipe closed, or by `deadline` if it stays open (the reader thread
    /// then ends when the last holder closes it).
    fn take_by(self, deadline: Instant) -> String {
        while !self.reader.is_finished() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
        let kept = self.kept.lock().expect("captured output");
        String::from_utf8_lossy(&kept).into_owned()
    }
}

/// The last 500 characters of a message, trimmed.
fn tail(text: &str) -> String {
    let text = text.trim();
    let start = text.char_indices().rev().nth(499).map_or(0, |(i, _)| i);
    text[start..].to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_answer_fail_or_time_out() {
        let args = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(run("sh", &args(&["-c", "echo 12345"]), Duration::from_secs(10)).unwrap(), "12345\n");
        let failed = run("sh", &args(&["-c", "echo no >&2; exit 3"]), Duration::from_secs(10)).unwrap_err();
        assert!(matches!(&failed, CommandError::Failed { stderr, .. } if stderr == "no"), "{failed}");
        let slow = run("sleep", &args(&["30"]), Duration::from_millis(200)).unwrap_err();
        assert!(matches!(slow, CommandError::Timeout { .. }), "{slow}");
        let missing = run("/nonexistent/sbatch", &[], Duration::from_secs(1)).unwrap_err();
        assert!(matches!(missing, CommandError::Spawn { .. }));
        // A child that keeps the pipe open costs the deadline, not a hang.
        let started = Instant::now();
        let out = run("sh", &args(&["-c", "(sleep 30 &) ; echo 7"]), Duration::from_millis(500)).unwrap();
        assert_eq!(out, "7\n");
        assert!(started.elapsed() < Duration::from_secs(20));
        // Output beyond the bound is read and dropped, not waited on.
        let big = run("sh", &args(&["-c", "head -c 6000000 /dev/zero"]), Duration::from_secs(20)).unwrap();
        assert_eq!(big.len() as u64, MAX_OUTPUT);
    }
}
