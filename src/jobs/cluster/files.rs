//! The cluster directory, shared by the server and the nodes:
//!
//! ```text
//! DIR/instance                    this server's tag (job names start with optimis-TAG-)
//! DIR/job-ID/record.json          the job's rounds and submissions (what a restart reconciles)
//! DIR/job-ID/round-R/spec.json    the round's specification: first_iteration and iterations
//! DIR/job-ID/round-R/task-K.json  task K's moments document (partial, then final; atomic)
//! DIR/job-ID/round-R/task-K.log   its log, every attempt appended
//! ```
//!
//! A round is one array: the job's first iterations, or those an extension added. Nothing here is
//! run: the tasks' command goes to the batch system itself (Slurm's `sbatch --wrap`), so no script
//! in the directory could be replaced. The directory, its parents and every folder in it must be this user's alone,
//! and nothing in it is read or written through a link ([`super::private`]): another local user
//! can neither plant what the server reads nor redirect what it writes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::private::{FileError, PrivateDir};

/// Largest task document read (a paper-sized one is well below 1 MiB).
pub const MAX_TASK_DOCUMENT: u64 = 256 << 20;

/// Largest record or round specification read.
const MAX_RECORD: u64 = 16 << 20;

/// The batch script earlier versions kept in the directory; removed at start (nothing runs it).
const OLD_SCRIPT: &str = "task.sh";

/// The cluster directory, checked.
#[derive(Debug, Clone)]
pub struct ClusterDir {
    root: PrivateDir,
    tag: String,
}

impl ClusterDir {
    /// Opens (creating if missing) the directory on the server: it and its parents must be such
    /// that only this user (and root) can change them ([`PrivateDir::open`]).
    pub fn open(root: &Path) -> Result<Self, String> {
        let shown = root.display();
        let dir = PrivateDir::open(root, true).map_err(|e| format!("--cluster-dir {shown}: {e}"))?;
        let tag = match dir.read("instance", 64) {
            Ok(tag) => match std::str::from_utf8(&tag).map(str::trim) {
                Ok(tag) if valid_tag(tag) => tag.to_string(),
                _ => return Err(format!("--cluster-dir {shown}: its file `instance` is not a tag this server wrote")),
            },
            Err(e) if e.is_missing() => {
                let tag = format!("{:08x}", rand::random::<u32>());
                dir.write("instance", format!("{tag}\n").as_bytes())
                    .map_err(|e| format!("--cluster-dir {shown}: cannot write in it: {e}"))?;
                tag
            }
            Err(e) => return Err(format!("--cluster-dir {shown}: {e}")),
        };
        dir.remove_file(OLD_SCRIPT).map_err(|e| format!("--cluster-dir {shown}: {e}"))?;
        Ok(Self { root: dir, tag })
    }

    /// Opens the directory on a node (a task): it must exist, and pass the same checks.
    pub fn open_existing(root: &Path) -> Result<Self, FileError> {
        Ok(Self { root: PrivateDir::open(root, false)?, tag: String::new() })
    }

    /// The directory's path.
    pub fn path(&self) -> &Path {
        self.root.path()
    }

    /// Job `id`'s files.
    pub fn job(&self, id: i64) -> JobDir {
        JobDir { root: self.root.clone(), id, name: format!("job-{id}"), prefix: format!("optimis-{}-{id}-", self.tag) }
    }
}

fn valid_tag(tag: &str) -> bool {
    (1..=16).contains(&tag.len()) && tag.bytes().all(|b| b.is_ascii_hexdigit())
}

/// One job's files, and its names in the batch system. Every folder is opened and checked again
/// each time it is used.
#[derive(Debug, Clone)]
pub struct JobDir {
    root: PrivateDir,
    id: i64,
    /// `job-ID`.
    name: String,
    /// The start of every name of this job in the batch system: `optimis-TAG-ID-`.
    pub prefix: String,
}

/// The name of task `k`'s document in its round's folder.
pub fn document_name(k: u64) -> String {
    format!("task-{k}.json")
}

impl JobDir {
    /// The job's id.
    pub fn id(&self) -> i64 {
        self.id
    }

    /// `DIR/job-ID`.
    pub fn path(&self) -> PathBuf {
        self.root.path().join(&self.name)
    }

    /// The name of round `r`'s array.
    pub fn round_name(&self, r: usize) -> String {
        format!("{}r{r}", self.prefix)
    }

    /// The name of a resubmission of task `k` of round `r`.
    pub fn task_name(&self, r: usize, k: u64) -> String {
        format!("{}r{r}-t{k}", self.prefix)
    }

    /// The job's folder, checked (created if `create`).
    fn folder(&self, create: bool) -> Result<PrivateDir, FileError> {
        self.root.subdir(&self.name, create)
    }

    /// Round `r`'s folder, checked (created if `create`).
    pub fn round(&self, r: usize, create: bool) -> Result<PrivateDir, FileError> {
        self.folder(create)?.subdir(&format!("round-{r}"), create)
    }

    /// Task `k`'s log (or the batch system's placeholder for an array's index, Slurm's `%a`): a
    /// path the batch system writes the task's output to.
    pub fn log(&self, r: usize, k: &str) -> PathBuf {
        self.path().join(format!("round-{r}")).join(format!("task-{k}.log"))
    }

    /// Writes round `r`'s specification (creating its folder).
    pub fn write_spec(&self, r: usize, bytes: &[u8]) -> Result<(), FileError> {
        self.round(r, true)?.write("spec.json", bytes)
    }

    /// Round `r`'s specification.
    pub fn read_spec(&self, r: usize) -> Result<Vec<u8>, FileError> {
        self.round(r, false)?.read("spec.json", MAX_RECORD)
    }

    /// The job's record; empty if it has none yet.
    pub fn load_record(&self) -> Result<Record, String> {
        let folder = match self.folder(false) {
            Ok(folder) => folder,
            Err(e) if e.is_missing() => return Ok(Record::default()),
            Err(e) => return Err(e.to_string()),
        };
        match folder.read("record.json", MAX_RECORD) {
            Ok(bytes) => serde_json::from_slice(&bytes)
                .map_err(|e| format!("{}: {e}", self.path().join("record.json").display())),
            Err(e) if e.is_missing() => Ok(Record::default()),
            Err(e) => Err(e.to_string()),
        }
    }

    /// Stores the job's record (atomically).
    pub fn save_record(&self, record: &Record) -> Result<(), FileError> {
        let bytes = serde_json::to_vec_pretty(record).expect("a record serialises");
        self.folder(true)?.write("record.json", &bytes)
    }

    /// Removes every file of the job.
    pub fn remove(&self) -> Result<(), FileError> {
        self.root.remove_tree(&self.name)
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
    /// The array's id in the batch system; null between the intent and the system's answer.
    pub array: Option<String>,
    /// Resubmissions by task index: each an id in the batch system (null between the intent and
    /// the answer).
    #[serde(default)]
    pub resubmits: BTreeMap<u64, Vec<Option<String>>>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_directory_is_checked_and_records_round_trip() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("cluster");
        // A directory an earlier version used: its script goes (nothing runs it any more).
        std::fs::create_dir(&root).unwrap();
        std::fs::write(root.join(OLD_SCRIPT), "#!/bin/sh\n").unwrap();
        let dir = ClusterDir::open(&root).unwrap();
        let again = ClusterDir::open(&root).unwrap();
        assert_eq!(dir.tag, again.tag, "the tag is kept across starts");
        assert!(!root.join(OLD_SCRIPT).exists());
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
        job.write_spec(0, b"{}").unwrap();
        assert_eq!(job.read_spec(0).unwrap(), b"{}");
        assert!(job.log(0, "%a").ends_with("job-7/round-0/task-%a.log"));
        job.remove().unwrap();
        assert!(!job.path().exists());
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            for mode in [0o777, 0o775] {
                std::fs::set_permissions(&root, std::fs::Permissions::from_mode(mode)).unwrap();
                assert!(ClusterDir::open(&root).unwrap_err().contains("group or by other users"), "{mode:o}");
            }
        }
        let file = tmp.path().join("file");
        std::fs::write(&file, "x").unwrap();
        assert!(ClusterDir::open(&file).is_err());
    }
}
