//! Slurm's own commands, driven with argv (nothing user-given is ever interpolated into a script)
//! and a timeout each, and their output parsed defensively: `sbatch --parsable` to submit,
//! `squeue` (one query per poll for all of a job's tasks, finished ones included while Slurm
//! keeps them) to follow, `scancel` to stop.

use std::collections::HashMap;
use std::time::Duration;

use super::command::{CommandError, run};

/// Most lines of a `squeue` answer looked at (the server's own jobs: far fewer).
const MAX_QUEUE_LINES: usize = 200_000;

/// Most job ids per `scancel` call (long argument lists hit limits).
const CANCEL_BATCH: usize = 100;

/// Why Slurm gave no usable answer.
#[derive(Debug, thiserror::Error)]
pub enum SlurmError {
    /// The command could not run, failed or timed out.
    #[error(transparent)]
    Command(#[from] CommandError),
    /// It answered something this server does not understand.
    #[error("{command} answered {answer:?}, which is not what it should print")]
    Unexpected {
        /// The command.
        command: &'static str,
        /// What it printed (its start).
        answer: String,
    },
}

impl SlurmError {
    /// Whether trying again later may succeed: a timeout, or a controller that is busy or
    /// unreachable. QOS, partition, account and limit errors are not.
    pub fn is_transient(&self) -> bool {
        match self {
            SlurmError::Command(CommandError::Timeout { .. }) => true,
            SlurmError::Command(CommandError::Failed { stderr, .. }) => {
                let s = stderr.to_ascii_lowercase();
                [
                    "socket timed out",
                    "unable to contact slurm controller",
                    "temporarily unable",
                    "try again",
                    "resource temporarily unavailable",
                    "connection refused",
                    "slurm_persist_conn_open",
                ]
                .iter()
                .any(|m| s.contains(m))
            }
            _ => false,
        }
    }
}

/// The Slurm commands, each with a timeout.
#[derive(Debug, Clone)]
pub struct Slurm {
    /// Deadline of each command.
    pub timeout: Duration,
    /// Where the commands are (None: on the PATH).
    pub bin_dir: Option<std::path::PathBuf>,
}

/// One line of `squeue -r`: a job, or one task of an array.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct QueueEntry {
    /// `ARRAY_TASK` for a task of an array, else the job id: how this server records submissions.
    pub key: String,
    /// Slurm's state, upper case (`PENDING`, `RUNNING`, `COMPLETED`, `FAILED`, `CANCELLED`…).
    pub state: String,
    /// The job's name.
    pub name: String,
}

impl Slurm {
    /// The path of command `name`.
    fn program(&self, name: &str) -> String {
        match &self.bin_dir {
            Some(dir) => dir.join(name).to_string_lossy().into_owned(),
            None => name.to_string(),
        }
    }

    /// `sbatch --version`, and `squeue` answering: that Slurm is installed and its controller
    /// reachable.
    pub fn check(&self) -> Result<String, SlurmError> {
        let version = run(&self.program("sbatch"), &["--version".to_string()], self.timeout)?;
        self.queue("optimis-check-")?;
        Ok(version.trim().to_string())
    }

    /// Submits the command `command` (argv) with `options` (sbatch's): the job id `sbatch
    /// --parsable` prints. The command goes to Slurm as `--wrap`, each argument quoted for the
    /// shell Slurm wraps it in: Slurm keeps the script it makes in its own spool, so that no file
    /// another user could replace is ever run.
    pub fn submit(&self, options: &[String], command: &[String]) -> Result<String, SlurmError> {
        let mut argv = vec!["--parsable".to_string()];
        argv.extend(options.iter().cloned());
        argv.push(format!("--wrap=exec {}", shell_words(command)));
        parse_submission(&run(&self.program("sbatch"), &argv, self.timeout)?)
    }

    /// This user's jobs (array tasks one per line, finished ones while Slurm keeps them) whose
    /// names start with `prefix`.
    pub fn queue(&self, prefix: &str) -> Result<Vec<QueueEntry>, SlurmError> {
        let args = ["--me", "--noheader", "--array", "--states=all", "--format=%A|%F|%K|%T|%j"];
        let out = run(&self.program("squeue"), &args.map(str::to_string), self.timeout)?;
        Ok(parse_queue(&out, prefix))
    }

    /// Cancels jobs by id (`ID` or `ARRAY_TASK` or a whole array's `ID`), in batches. Ids Slurm
    /// has forgotten are not an error.
    pub fn cancel(&self, ids: &[String]) -> Result<(), SlurmError> {
        for batch in ids.chunks(CANCEL_BATCH) {
            match run(&self.program("scancel"), batch, self.timeout) {
                Ok(_) => {}
                Err(CommandError::Failed { stderr, .. }) if stderr.contains("Invalid job id") => {}
                Err(e) => return Err(e.into()),
            }
        }
        Ok(())
    }
}

/// `argv` as one POSIX shell command line: each argument as it is if it holds only characters the
/// shell gives no meaning, else in single quotes (a quote inside as `'\''`).
pub fn shell_words(argv: &[String]) -> String {
    let plain = |a: &str| !a.is_empty() && a.bytes().all(|b| b.is_ascii_alphanumeric() || b"/._-=:,+@%".contains(&b));
    let quoted: Vec<String> =
        argv.iter().map(|a| if plain(a) { a.clone() } else { format!("'{}'", a.replace('\'', "'\\''")) }).collect();
    quoted.join(" ")
}

/// The job id of `sbatch --parsable`'s answer: `ID` or `ID;CLUSTER`, digits only.
pub fn parse_submission(out: &str) -> Result<String, SlurmError> {
    let line = out.lines().map(str::trim).rfind(|l| !l.is_empty()).unwrap_or("");
    let id = line.split(';').next().unwrap_or("");
    if !id.is_empty() && id.len() <= 20 && id.bytes().all(|b| b.is_ascii_digit()) {
        Ok(id.to_string())
    } else {
        Err(SlurmError::Unexpected { command: "sbatch --parsable", answer: out.chars().take(200).collect() })
    }
}

/// The lines of `squeue --format=%A|%F|%K|%T|%j` whose name starts with `prefix`; lines that do
/// not parse are skipped. With several lines for one key (a requeued task), the last wins.
pub fn parse_queue(out: &str, prefix: &str) -> Vec<QueueEntry> {
    let mut seen: HashMap<String, usize> = HashMap::new();
    let mut entries: Vec<QueueEntry> = Vec::new();
    for line in out.lines().take(MAX_QUEUE_LINES) {
        let fields: Vec<&str> = line.trim().splitn(5, '|').collect();
        let [job, array, task, state, name] = fields[..] else { continue };
        if !name.starts_with(prefix) || !state.bytes().all(|b| b.is_ascii_uppercase() || b == b'_') {
            continue;
        }
        let digits = |s: &str| !s.is_empty() && s.len() <= 20 && s.bytes().all(|b| b.is_ascii_digit());
        let key = if digits(array) && digits(task) {
            format!("{array}_{task}")
        } else if digits(job) {
            job.to_string()
        } else {
            continue;
        };
        let entry = QueueEntry { key: key.clone(), state: state.to_string(), name: name.to_string() };
        match seen.get(&key) {
            Some(&at) => entries[at] = entry,
            None => {
                seen.insert(key, entries.len());
                entries.push(entry);
            }
        }
    }
    entries
}

/// Slurm states in which a job is still on its way (it may yet write its document).
pub fn is_active(state: &str) -> bool {
    matches!(
        state,
        "PENDING"
            | "RUNNING"
            | "CONFIGURING"
            | "COMPLETING"
            | "SUSPENDED"
            | "REQUEUED"
            | "REQUEUE_FED"
            | "REQUEUE_HOLD"
            | "RESIZING"
            | "SIGNALING"
            | "STAGE_OUT"
            | "STOPPED"
            | "RESV_DEL_HOLD"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn submissions_and_queues_parse_defensively() {
        assert_eq!(parse_submission("1234\n").unwrap(), "1234");
        assert_eq!(parse_submission("1234;cluster-a\n").unwrap(), "1234");
        assert_eq!(parse_submission("sbatch: warning: x\n77\n").unwrap(), "77");
        for bad in ["", "Submitted batch job 12", "12a", "-1", "1;2;3x\nabc"] {
            assert!(parse_submission(bad).is_err(), "{bad:?}");
        }
        let out = "\
101|100|0|RUNNING|optimis-ab-7-r0
100|100|1|PENDING|optimis-ab-7-r0
100|100|N/A|PENDING|optimis-ab-7-r0
105|105|N/A|FAILED|optimis-ab-7-r0-t1
200|200|0|RUNNING|someone-else
garbage line
300|300|0|running|optimis-ab-7-r0
106|105|N/A|PENDING|optimis-ab-7-r0-t1
";
        let q = parse_queue(out, "optimis-ab-7-");
        let keys: Vec<(&str, &str)> = q.iter().map(|e| (e.key.as_str(), e.state.as_str())).collect();
        assert_eq!(
            keys,
            [("100_0", "RUNNING"), ("100_1", "PENDING"), ("100", "PENDING"), ("105", "FAILED"), ("106", "PENDING")]
        );
        assert!(is_active("PENDING") && is_active("RUNNING") && !is_active("COMPLETED") && !is_active("NODE_FAIL"));
        let transient = SlurmError::Command(CommandError::Failed {
            program: "sbatch".into(),
            status: "exit status: 1".into(),
            stderr: "sbatch: error: Batch job submission failed: Socket timed out on send/recv operation".into(),
        });
        assert!(transient.is_transient());
        let permanent = SlurmError::Command(CommandError::Failed {
            program: "sbatch".into(),
            status: "exit status: 1".into(),
            stderr:
                "sbatch: error: Batch job submission failed: Invalid account or account/partition combination specified"
                    .into(),
        });
        assert!(!permanent.is_transient());
    }

    #[test]
    fn commands_are_quoted_for_the_shell_slurm_wraps_them_in() {
        let argv: Vec<String> =
            ["/opt/optimis", "--cluster-dir", "/a b/it's $HOME;`x`", "", "--job", "3"].map(String::from).into();
        let line = shell_words(&argv);
        assert_eq!(line, r#"/opt/optimis --cluster-dir '/a b/it'\''s $HOME;`x`' '' --job 3"#);
        // What sh makes of it is the argv, word for word.
        let out = std::process::Command::new("sh").arg("-c").arg(format!("printf '%s\\n' {line}")).output().unwrap();
        assert_eq!(String::from_utf8(out.stdout).unwrap(), format!("{}\n", argv.join("\n")));
    }
}
