//! External commands (Slurm's) run with a deadline and a bounded capture of their output: a
//! controller that does not answer, or a command that prints without end, costs the follower a
//! timeout and a few MiB, never a hung thread.

use std::io::Read;
use std::process::{Child, Command, Stdio};
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
    let stdout = capture(child.stdout.take());
    let stderr = capture(child.stderr.take());
    let status = match wait(&mut child, timeout) {
        Some(status) => status,
        None => {
            let _ = child.kill();
            let _ = child.wait();
            return Err(CommandError::Timeout { program: program.to_string(), seconds: timeout.as_secs_f64() });
        }
    };
    let stdout = stdout.join().unwrap_or_default();
    let stderr = stderr.join().unwrap_or_default();
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

/// Reads a pipe to its end on a thread of its own, keeping the first [`MAX_OUTPUT`] bytes.
fn capture(pipe: Option<impl Read + Send + 'static>) -> JoinHandle<String> {
    std::thread::spawn(move || {
        let Some(pipe) = pipe else { return String::new() };
        let mut kept = Vec::new();
        let mut limited = pipe.take(MAX_OUTPUT);
        let _ = limited.read_to_end(&mut kept);
        let _ = std::io::copy(&mut limited.into_inner(), &mut std::io::sink());
        String::from_utf8_lossy(&kept).into_owned()
    })
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
        // Output beyond the bound is read and dropped, not waited on.
        let big = run("sh", &args(&["-c", "head -c 6000000 /dev/zero"]), Duration::from_secs(20)).unwrap();
        assert_eq!(big.len() as u64, MAX_OUTPUT);
    }
}
