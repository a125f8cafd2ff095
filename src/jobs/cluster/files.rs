//! The cluster directory, shared by the server and the nodes:
//!
//! ```text
//! DIR/instance                    this server's tag (job names start with optimis-TAG-)
//! DIR/task.sh                     `exec "$@"`: the batch script of every task (argv only)
//! DIR/job-ID/record.json          the job's rounds and submissions (what a restart reconciles)
//! DIR/job-ID/round-R/spec.json    the round's specification: first_iteration and iterations
//! DIR/job-ID/round-R/task-K.json  task K's moments document (partial, then final; atomic)
//! DIR/job-ID/round-R/task-K.log   its log, every attempt appended
//! ```
//!
//! A round is one array: the job's first iterations, or those an extension added. Every write is
//! atomic (a temporary file and a rename in the same directory).

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// The batch script of every task: it runs its arguments. The command is passed as sbatch's
/// script arguments, so nothing user-given is ever written into a script.
const TASK_SCRIPT: &str = "#!/bin/sh\n# Written by optimis serve --executor slurm: runs its arguments.\nexec \"$@\"\n";

/// Largest task document read (a paper-sized one is well below 1 MiB).
pub const MAX_TASK_DOCUMENT: u64 = 256 << 20;

/// Largest record file read.
const MAX_RECORD: u64 = 16 << 20;

/// The cluster directory, checked.
#[derive(Debug, Clone)]
pub struct ClusterDir {
    root: PathBuf,
    tag: String,
}

impl ClusterDir {
    /// Opens (creating if missing) the directory: it must be a directory this server can write
    /// and others cannot (the nodes run what it holds).
    pub fn open(root: &Path) -> Result<Self, String> {
        let shown = root.display();
        std::fs::create_dir_all(root).map_err(|e| format!("--cluster-dir {shown}: cannot create it: {e}"))?;
        let meta = std::fs::metadata(root).map_err(|e| format!("--cluster-dir {shown}: {e}"))?;
        if !meta.is_dir() {
            return Err(format!("--cluster-dir {shown} is not a directory"));
        }
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            if meta.permissions().mode() & 0o002 != 0 {
                return Err(format!(
                    "--cluster-dir {shown} can be written by other users (mode {:o}): they could change what the nodes run; chmod go-w it",
                    meta.permissions().mode() & 0o777
                ));
            }
        }
        let tag_path = root.join("instance");
        let tag = match std::fs::read_to_string(&tag_path) {
            Ok(tag) if valid_tag(tag.trim()) => tag.trim().to_string(),
            Ok(_) => {
                return Err(format!("--cluster-dir {shown}: {} is not a tag this server wrote", tag_path.display()));
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                let tag = format!("{:08x}", rand::random::<u32>());
                write_atomically(&tag_path, format!("{tag}\n").as_bytes())
                    .map_err(|e| format!("--cluster-dir {shown}: cannot write in it: {e}"))?;
                tag
            }
            Err(e) => return Err(format!("--cluster-dir {shown}: {e}")),
        };
        let script = root.join("task.sh");
        write_atomically(&script, TASK_SCRIPT.as_bytes()).map_err(|e| format!("--cluster-dir {shown}: {e}"))?;
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755))
                .map_err(|e| format!("--cluster-dir {shown}: {e}"))?;
        }
        Ok(Self { root: root.to_path_buf(), tag })
    }

    /// The batch script.
    pub fn script(&self) -> PathBuf {
        self.root.join("task.sh")
    }

    /// Job `id`'s files.
    pub fn job(&self, id: i64) -> JobDir {
        JobDir { dir: self.root.join(format!("job-{id}")), prefix: format!("optimis-{}-{id}-", self.tag) }
    }
}

fn valid_tag(tag: &str) -> bool {
    (1..=16).contains(&tag.len()) && tag.bytes().all(|b| b.is_ascii_hexdigit())
}

/// One job's files and Slurm names.
#[derive(Debug, Clone)]
pub struct JobDir {
    /// `DIR/job-ID`.
    pub dir: PathBuf,
    /// The start of every Slurm job name of this job: `optimis-TAG-ID-`.
    pub prefix: String,
}

impl JobDir {
    /// The name of round `r`'s array.
    pub fn round_name(&self, r: usize) -> String {
        format!("{}r{r}", self.prefix)
    }

    /// The name of a resubmission of task `k` of round `r`.
    pub fn task_name(&self, r: usize, k: u64) -> String {
        format!("{}r{r}-t{k}", self.prefix)
    }

    /// Round `r`'s directory.
    pub fn round_dir(&self, r: usize) -> PathBuf {
        self.dir.join(format!("round-{r}"))
    }

    /// Round `r`'s specification.
    pub fn spec(&self, r: usize) -> PathBuf {
        self.round_dir(r).join("spec.json")
    }

    /// Task `k`'s document (`{shard}` for the task's own index in the array's command).
    pub fn document(&self, r: usize, k: &str) -> PathBuf {
        self.round_dir(r).join(format!("task-{k}.json"))
    }

    /// Task `k`'s log (`%a` for the array's).
    pub fn log(&self, r: usize, k: &str) -> PathBuf {
        self.round_dir(r).join(format!("task-{k}.log"))
    }

    /// The job's record; empty if it has none yet.
    pub fn load_record(&self) -> Result<Record, String> {
        let path = self.dir.join("record.json");
        match read_bounded(&path, MAX_RECORD) {
            Ok(bytes) => serde_json::from_slice(&bytes).map_err(|e| format!("{}: {e}", path.display())),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Record::default()),
            Err(e) => Err(format!("{}: {e}", path.display())),
        }
    }

    /// Stores the job's record (atomically).
    pub fn save_record(&self, record: &Record) -> Result<(), String> {
        std::fs::create_dir_all(&self.dir).map_err(|e| format!("{}: {e}", self.dir.display()))?;
        let path = self.dir.join("record.json");
        let bytes = serde_json::to_vec_pretty(record).expect("a record serialises");
        write_atomically(&path, &bytes).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Removes every file of the job.
    pub fn remove(&self) -> std::io::Result<()> {
        match std::fs::remove_dir_all(&self.dir) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
            _ => Ok(()),
        }
    }
}

/// What a restart needs to know of a job's work on the cluster.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Record {
    /// The job's rounds, in the order of their iterations.
    pub rounds: Vec<Round>,
}

/// One array: `tasks` shards of iterations [first, first + iterations).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Round {
    /// The round's first iteration.
    pub first: u64,
    /// Its iterations.
    pub iterations: u64,
    /// Its tasks.
    pub tasks: u64,
    /// The array's Slurm job id; null between the intent and sbatch's answer.
    pub array: Option<String>,
    /// Resubmissions by task index: each a Slurm job id (null between the intent and the answer).
    #[serde(default)]
    pub resubmits: BTreeMap<u64, Vec<Option<String>>>,
}

/// Reads a file of at most `limit` bytes.
pub fn read_bounded(path: &Path, limit: u64) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let file = std::fs::File::open(path)?;
    let mut bytes = Vec::new();
    file.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(std::io::Error::other(format!("larger than {limit} bytes")));
    }
    Ok(bytes)
}

/// Writes `bytes` to `path` through a synced temporary file in the same directory and a rename
/// (the files here are optimis' own: no devices or links to keep, unlike the command line's
/// outputs); a failed write removes its temporary file.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = path.with_extension(format!("partial-{}", std::process::id()));
    let written = std::fs::File::create(&tmp)
        .and_then(|mut file| file.write_all(bytes).and_then(|()| file.sync_all()))
        .and_then(|()| std::fs::rename(&tmp, path));
    if written.is_err() {
        // Best effort: the error is what the caller needs; the temporary file is only litter.
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_directory_is_checked_and_records_round_trip() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("cluster");
        let dir = ClusterDir::open(&root).unwrap();
        let again = ClusterDir::open(&root).unwrap();
        assert_eq!(dir.tag, again.tag, "the tag is kept across starts");
        assert!(std::fs::read_to_string(dir.script()).unwrap().contains("exec \"$@\""));
        let job = dir.job(7);
        assert_eq!(job.round_name(1), format!("optimis-{}-7-r1", dir.tag));
        assert_eq!(job.load_record().unwrap(), Record::default());
        let record = Record {
            rounds: vec![Round {
                first: 0,
                iterations: 100,
                tasks: 4,
                array: Some("12".into()),
                resubmits: BTreeMap::from([(2, vec![Some("15".into()), None])]),
            }],
        };
        job.save_record(&record).unwrap();
        assert_eq!(job.load_record().unwrap(), record);
        job.remove().unwrap();
        assert!(!job.dir.exists());
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&root, std::fs::Permissions::from_mode(0o777)).unwrap();
            assert!(ClusterDir::open(&root).unwrap_err().contains("other users"));
        }
        let file = tmp.path().join("file");
        std::fs::write(&file, "x").unwrap();
        assert!(ClusterDir::open(&file).is_err());
    }

    #[test]
    fn a_failed_write_leaves_no_temporary_file() {
        let tmp = tempfile::tempdir().unwrap();
        let taken = tmp.path().join("record.json");
        std::fs::create_dir(&taken).unwrap();
        assert!(write_atomically(&taken, b"{}").is_err(), "a directory cannot be replaced by a file");
        let names: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, [std::ffi::OsString::from("record.json")]);
        let file = tmp.path().join("other.json");
        write_atomically(&file, b"{}").unwrap();
        assert_eq!(std::fs::read(&file).unwrap(), b"{}");
    }
}
