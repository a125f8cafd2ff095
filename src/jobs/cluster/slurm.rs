//! Slurm as the cluster executor's batch system ([`BatchSystem`]): its settings (the
//! `--slurm-*` and `--sbatch-option` flags), and its own commands, driven with argv (nothing
//! user-given is ever interpolated into a script) and a timeout each, their output parsed
//! defensively: `sbatch --parsable` to submit, `squeue` (one query per poll for all of a job's
//! tasks, finished ones included while Slurm keeps them) to follow, `scancel` to stop.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::Duration;

use super::command::{CommandError, run};
use super::system::{BatchError, BatchSystem, Phase, QueueEntry, Submission, Tasks};

/// Most lines of a `squeue` answer looked at (the server's own jobs: far fewer).
const MAX_QUEUE_LINES: usize = 200_000;

/// Most job ids per `scancel` call (long argument lists hit limits).
const CANCEL_BATCH: usize = 100;

/// sbatch options this server sets itself; `--sbatch-option` may not set them.
const RESERVED: &[&str] =
    &["--array", "--output", "--error", "--job-name", "--parsable", "--open-mode", "--wrap", "-a", "-o", "-e", "-J"];

/// Slurm's own settings (those of every batch system are [`super::options::ClusterOptions`]).
#[derive(Debug, Clone)]
pub struct SlurmOptions {
    /// Where `sbatch`, `squeue` and `scancel` are (None: on the PATH).
    pub bin_dir: Option<PathBuf>,
    /// `--partition`, if any.
    pub partition: Option<String>,
    /// `--account`, if any.
    pub account: Option<String>,
    /// `--time`, if any.
    pub time_limit: Option<String>,
    /// Further sbatch options, passed as they are (one argument each).
    pub sbatch_options: Vec<String>,
    /// Deadline of each Slurm command.
    pub command_timeout: Duration,
}

impl SlurmOptions {
    /// Checks the settings that need no cluster: the extra sbatch options, the one-word values.
    pub fn validate(&self) -> Result<(), String> {
        for option in &self.sbatch_options {
            if !option.starts_with('-') || option.chars().any(char::is_control) {
                return Err(format!("--sbatch-option {option:?}: expected one sbatch option such as --qos=normal"));
            }
            let name = option.split('=').next().unwrap_or(option);
            if RESERVED.contains(&name) {
                return Err(format!("--sbatch-option {option:?}: {name} is set by the server"));
            }
        }
        for (flag, value) in [
            ("--slurm-partition", &self.partition),
            ("--slurm-account", &self.account),
            ("--slurm-time", &self.time_limit),
        ] {
            if value.as_deref().is_some_and(|v| v.is_empty() || v.chars().any(|c| c.is_control() || c.is_whitespace()))
            {
                return Err(format!("{flag} must be one word"));
            }
        }
        Ok(())
    }
}

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

impl From<SlurmError> for BatchError {
    fn from(e: SlurmError) -> Self {
        if e.is_transient() { BatchError::Transient(Box::new(e)) } else { BatchError::Refused(Box::new(e)) }
    }
}

/// Slurm, driven through its commands.
#[derive(Debug, Clone)]
pub struct Slurm {
    options: SlurmOptions,
}

impl Slurm {
    /// Slurm with these settings (checked by [`SlurmOptions::validate`]).
    pub fn new(options: SlurmOptions) -> Self {
        Self { options }
    }

    /// The path of command `name`.
    fn program(&self, name: &str) -> String {
        match &self.options.bin_dir {
            Some(dir) => dir.join(name).to_string_lossy().into_owned(),
            None => name.to_string(),
        }
    }

    /// sbatch's arguments for `submission`. The command goes to Slurm as `--wrap`, each argument
    /// quoted for the shell Slurm wraps it in: Slurm keeps the script it makes in its own spool, so
    /// that no file another user could replace is ever run.
    fn sbatch_argv(&self, submission: &Submission<'_>) -> Vec<String> {
        let o = &self.options;
        // A clean environment: the server's own (its tokens, its database URL) stays out of the
        // cluster's jobs; paths are absolute, so nothing needs the PATH.
        let mut argv = vec!["--parsable".to_string(), "--export=NONE".to_string(), "--open-mode=append".to_string()];
        argv.push(format!("--cpus-per-task={}", submission.cpus));
        if let Some(p) = &o.partition {
            argv.push(format!("--partition={p}"));
        }
        if let Some(a) = &o.account {
            argv.push(format!("--account={a}"));
        }
        if let Some(t) = &o.time_limit {
            argv.push(format!("--time={t}"));
        }
        argv.extend(o.sbatch_options.iter().cloned());
        argv.push(format!("--job-name={}", submission.name));
        let log = match submission.tasks {
            Tasks::Array(count) => {
                argv.push(format!("--array=0-{}", count - 1));
                (submission.log)("%a")
            }
            Tasks::One(k) => (submission.log)(&k.to_string()),
        };
        argv.push(format!("--output={}", log.to_string_lossy()));
        argv.push(format!("--wrap=exec {}", shell_words(submission.command)));
        argv
    }

    /// This user's jobs (array tasks one per line, finished ones while Slurm keeps them) whose
    /// names start with `prefix`.
    fn squeue(&self, prefix: &str) -> Result<Vec<QueueEntry>, SlurmError> {
        let args = ["--me", "--noheader", "--array", "--states=all", "--format=%A|%F|%K|%T|%j"];
        let out = run(&self.program("squeue"), &args.map(str::to_string), self.options.command_timeout)?;
        Ok(parse_queue(&out, prefix))
    }

    /// `scancel` in batches; ids Slurm has forgotten are not an error.
    fn scancel(&self, ids: &[String]) -> Result<(), SlurmError> {
        for batch in ids.chunks(CANCEL_BATCH) {
            match run(&self.program("scancel"), batch, self.options.command_timeout) {
                Ok(_) => {}
                Err(CommandError::Failed { stderr, .. }) if stderr.contains("Invalid job id") => {}
                Err(e) => return Err(e.into()),
            }
        }
        Ok(())
    }
}

impl BatchSystem for Slurm {
    fn name(&self) -> &'static str {
        "Slurm"
    }

    /// `sbatch --version`, and `squeue` answering: that Slurm is installed and its controller
    /// reachable. `sacct` is not needed: the queue and the task documents say everything.
    fn check(&self) -> Result<String, BatchError> {
        let version = run(&self.program("sbatch"), &["--version".to_string()], self.options.command_timeout)
            .map_err(SlurmError::from)?;
        self.squeue("optimis-check-")?;
        Ok(version.trim().to_string())
    }

    /// `sbatch --parsable`: the job id it prints (an array's for an array).
    fn submit(&self, submission: &Submission<'_>) -> Result<String, BatchError> {
        let out = run(&self.program("sbatch"), &self.sbatch_argv(submission), self.options.command_timeout)
            .map_err(SlurmError::from)?;
        Ok(parse_submission(&out)?)
    }

    fn queue(&self, prefix: &str) -> Result<Vec<QueueEntry>, BatchError> {
        Ok(self.squeue(prefix)?)
    }

    /// `ARRAY_TASK`, as squeue and scancel write it.
    fn array_task_id(&self, array: &str, k: u64) -> String {
        format!("{array}_{k}")
    }

    fn cancel(&self, ids: &[String]) -> Result<(), BatchError> {
        Ok(self.scancel(ids)?)
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
        let (key, submission) = if digits(array) && digits(task) {
            (format!("{array}_{task}"), array)
        } else if digits(job) {
            (job.to_string(), job)
        } else {
            continue;
        };
        let phase = match state {
            "COMPLETED" => Phase::Completed,
            _ if is_active(state) => Phase::Active,
            _ => Phase::Ended,
        };
        let entry = QueueEntry {
            id: key.clone(),
            submission: submission.to_string(),
            state: state.to_string(),
            phase,
            name: name.to_string(),
        };
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
pub(crate) mod tests {
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
        let keys: Vec<(&str, &str, &str)> =
            q.iter().map(|e| (e.id.as_str(), e.submission.as_str(), e.state.as_str())).collect();
        assert_eq!(
            keys,
            [
                ("100_0", "100", "RUNNING"),
                ("100_1", "100", "PENDING"),
                ("100", "100", "PENDING"),
                ("105", "105", "FAILED"),
                ("106", "106", "PENDING")
            ]
        );
        let phases: Vec<Phase> = parse_queue("1|1|0|COMPLETED|x\n1|1|1|NODE_FAIL|x\n1|1|2|REQUEUED|x\n", "x")
            .into_iter()
            .map(|e| e.phase)
            .collect();
        assert_eq!(phases, [Phase::Completed, Phase::Ended, Phase::Active]);
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
        assert!(BatchError::from(transient).is_transient() && !BatchError::from(permanent).is_transient());
    }

    pub(crate) fn options() -> SlurmOptions {
        SlurmOptions {
            bin_dir: None,
            partition: Some("batch".into()),
            account: None,
            time_limit: Some("01:00:00".into()),
            sbatch_options: vec!["--qos=normal".into()],
            command_timeout: Duration::from_secs(20),
        }
    }

    #[test]
    fn options_are_checked_at_the_edge_and_submissions_become_sbatch_argv() {
        assert!(options().validate().is_ok());
        let broken = |f: fn(&mut SlurmOptions)| {
            let mut o = options();
            f(&mut o);
            o.validate().unwrap_err()
        };
        assert!(broken(|o| o.sbatch_options = vec!["--array=0-9".into()]).contains("set by the server"));
        assert!(broken(|o| o.sbatch_options = vec!["qos".into()]).contains("expected one sbatch option"));
        assert!(broken(|o| o.partition = Some("a b".into())).contains("one word"));
        let slurm = Slurm::new(options());
        let command = ["/opt/optimis".to_string(), "cluster-task".to_string()];
        let log = |k: &str| PathBuf::from(format!("/shared/job-1/round-0/task-{k}.log"));
        let mut submission =
            Submission { name: "optimis-ab-1-r0", tasks: Tasks::Array(4), command: &command, cpus: 2, log: &log };
        let common = [
            "--parsable",
            "--export=NONE",
            "--open-mode=append",
            "--cpus-per-task=2",
            "--partition=batch",
            "--time=01:00:00",
            "--qos=normal",
        ];
        let array: Vec<String> = common
            .iter()
            .map(|s| s.to_string())
            .chain([
                "--job-name=optimis-ab-1-r0".into(),
                "--array=0-3".into(),
                "--output=/shared/job-1/round-0/task-%a.log".into(),
                "--wrap=exec /opt/optimis cluster-task".into(),
            ])
            .collect();
        assert_eq!(slurm.sbatch_argv(&submission), array);
        submission.name = "optimis-ab-1-r0-t2";
        submission.tasks = Tasks::One(2);
        let one = slurm.sbatch_argv(&submission);
        assert_eq!(
            one[common.len()..],
            [
                "--job-name=optimis-ab-1-r0-t2",
                "--output=/shared/job-1/round-0/task-2.log",
                "--wrap=exec /opt/optimis cluster-task"
            ]
        );
        assert_eq!(slurm.array_task_id("100", 3), "100_3");
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
