//! A directory only this process's user can change, used without following links: the ground
//! the cluster directory stands on (`files`).
//!
//! The server and its tasks on the nodes share the cluster directory; whatever another local user
//! could change there, they could turn against the server — a replaced script runs as the server's
//! user, a planted symbolic link makes it write where the link points, a replaced document enters
//! the job's statistics. So, as OpenSSH's `StrictModes` does for `~/.ssh`:
//!
//! * [`PrivateDir::open`] checks every ancestor of the directory (owned by root or this user, and
//!   not writable by group or others unless sticky, like `/tmp`: then nobody else can rename what
//!   is ours in it) and the directory itself (owned by this user, not writable by group or
//!   others), then keeps it open: every later step starts from that descriptor, so swapping a
//!   parent afterwards changes nothing;
//! * every folder it opens below ([`PrivateDir::subdir`]) is checked the same way each time it is
//!   used, and opened with `O_NOFOLLOW`;
//! * files are read with `O_NOFOLLOW` and only if they are regular files of this user that nobody
//!   else can write ([`PrivateDir::read`]);
//! * files are written through a temporary file with a fresh random name, created exclusively
//!   (`O_EXCL | O_NOFOLLOW`: a link planted under any name is never followed), synced, and renamed
//!   over the final name ([`PrivateDir::write`]) — a rename replaces a link, it does not write
//!   through it.
//!
//! Errors carry the path and the operating system's reason; [`FileError::is_full`] tells a full
//! disk or quota (worth waiting for) from the rest.

use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::{AsFd, OwnedFd};
use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rustix::fs::{AtFlags, Mode, OFlags};

/// Permission bits that let group or others change a file or a folder's entries.
const OTHERS_WRITE: u32 = 0o022;
/// The sticky bit: in such a folder only an entry's owner may rename or remove it.
const STICKY: u32 = 0o1000;

/// Why a file or folder of a private directory cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The operating system refused (`source` says why).
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// It is not what it should be (a link, not a regular file, another user's, writable by
    /// others); the message says what and how to fix it.
    #[error("{path}: {message}")]
    Unsafe {
        /// The file or folder.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// A file is larger than its reader accepts.
    #[error("{path}: larger than {limit} bytes")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// The most bytes read.
        limit: u64,
    },
}

impl FileError {
    /// Whether the filesystem is full or the user's quota spent: worth waiting for, not a failure.
    pub fn is_full(&self) -> bool {
        matches!(self, FileError::Io { source, .. } if is_full(source))
    }

    /// Whether the file or folder does not exist.
    pub fn is_missing(&self) -> bool {
        matches!(self, FileError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound)
    }
}

/// Whether an I/O error means the filesystem is full or the quota spent (ENOSPC, EDQUOT).
pub fn is_full(e: &std::io::Error) -> bool {
    e.kind() == std::io::ErrorKind::StorageFull
        || e.kind() == std::io::ErrorKind::QuotaExceeded
        || e.raw_os_error().is_some_and(|c| {
            c == rustix::io::Errno::NOSPC.raw_os_error() || c == rustix::io::Errno::DQUOT.raw_os_error()
        })
}

/// This process's effective user.
pub fn effective_uid() -> u32 {
    rustix::process::geteuid().as_raw()
}

/// An open directory that only this user can change.
#[derive(Debug, Clone)]
pub struct PrivateDir {
    fd: Arc<OwnedFd>,
    path: PathBuf,
}

fn io(path: &Path) -> impl FnOnce(rustix::io::Errno) -> FileError + '_ {
    move |e| FileError::Io { path: path.to_path_buf(), source: e.into() }
}

fn io_std(path: &Path) -> impl FnOnce(std::io::Error) -> FileError + '_ {
    move |source| FileError::Io { path: path.to_path_buf(), source }
}

fn unsafe_(path: &Path, message: String) -> FileError {
    FileError::Unsafe { path: path.to_path_buf(), message }
}

/// Checks that a folder (its metadata `meta`) is this user's and nobody else can change its
/// entries.
fn check_own_dir(path: &Path, meta: &std::fs::Metadata) -> Result<(), FileError> {
    let uid = effective_uid();
    if !meta.is_dir() {
        return Err(unsafe_(path, "is not a directory".into()));
    }
    if meta.uid() != uid {
        return Err(unsafe_(
            path,
            format!(
                "belongs to user {} but this process runs as user {uid}: another user could change what the nodes \
                 run and read; use a directory of this user's own",
                meta.uid()
            ),
        ));
    }
    let mode = meta.permissions().mode();
    if mode & OTHERS_WRITE != 0 {
        return Err(unsafe_(
            path,
            format!(
                "can be written by its group or by other users (mode {:o}): they could replace what the nodes run \
                 and read; chmod go-w it",
                mode & 0o7777
            ),
        ));
    }
    Ok(())
}

/// Checks the ancestors of `path` (an absolute path without links): each owned by root or this
/// user, and writable by group or others only if sticky.
fn check_ancestors(path: &Path) -> Result<(), FileError> {
    let uid = effective_uid();
    for ancestor in path.ancestors().skip(1) {
        let meta = std::fs::symlink_metadata(ancestor).map_err(io_std(ancestor))?;
        if meta.uid() != 0 && meta.uid() != uid {
            return Err(unsafe_(
                ancestor,
                format!(
                    "belongs to user {} (neither root nor this process's user {uid}), who could move the cluster \
                     directory under it and put another in its place; use a directory whose every parent is \
                     root's or yours",
                    meta.uid()
                ),
            ));
        }
        let mode = meta.permissions().mode();
        if mode & OTHERS_WRITE != 0 && mode & STICKY == 0 {
            return Err(unsafe_(
                ancestor,
                format!(
                    "can be written by its group or by other users and is not sticky (mode {:o}): they could move \
                     the cluster directory under it and put another in its place; use a directory under a parent \
                     only you (or root) can write",
                    mode & 0o7777
                ),
            ));
        }
    }
    Ok(())
}

impl PrivateDir {
    /// Opens `path` (created with mode 0700 if missing and `create`), after checking it and every
    /// ancestor.
    pub fn open(path: &Path, create: bool) -> Result<Self, FileError> {
        if create {
            match std::fs::DirBuilder::new().recursive(true).mode(0o700).create(path) {
                Ok(()) => {}
                Err(e) => return Err(FileError::Io { path: path.to_path_buf(), source: e }),
            }
        }
        // The real path: a link among the ancestors (a site's /shared → /mnt/nfs/shared) is fine
        // as long as where it leads is checked.
        let real = std::fs::canonicalize(path).map_err(io_std(path))?;
        check_ancestors(&real)?;
        let flags = OFlags::RDONLY | OFlags::DIRECTORY | OFlags::NOFOLLOW | OFlags::CLOEXEC;
        let fd = rustix::fs::open(&real, flags, Mode::empty()).map_err(io(&real))?;
        let meta = File::from(fd.try_clone().map_err(io_std(&real))?).metadata().map_err(io_std(&real))?;
        check_own_dir(&real, &meta)?;
        Ok(Self { fd: Arc::new(fd), path: real })
    }

    /// The directory's path (for messages, and for the commands that name files in it).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The folder `name` in this one (created with mode 0700 if missing and `create`), checked.
    pub fn subdir(&self, name: &str, create: bool) -> Result<Self, FileError> {
        let path = self.path.join(name);
        if create {
            match rustix::fs::mkdirat(self.fd.as_fd(), name, Mode::from_raw_mode(0o700)) {
                Ok(()) | Err(rustix::io::Errno::EXIST) => {}
                Err(e) => return Err(io(&path)(e)),
            }
        }
        let flags = OFlags::RDONLY | OFlags::DIRECTORY | OFlags::NOFOLLOW | OFlags::CLOEXEC;
        let fd = rustix::fs::openat(self.fd.as_fd(), name, flags, Mode::empty()).map_err(|e| match e {
            rustix::io::Errno::LOOP | rustix::io::Errno::NOTDIR => {
                unsafe_(&path, "is not a directory (a link, or a file): not created by this server".into())
            }
            e => io(&path)(e),
        })?;
        let meta = File::from(fd.try_clone().map_err(io_std(&path))?).metadata().map_err(io_std(&path))?;
        check_own_dir(&path, &meta)?;
        Ok(Self { fd: Arc::new(fd), path })
    }

    /// Reads the regular file `name` of at most `limit` bytes, without following a link, if it
    /// is this user's and nobody else can write it.
    pub fn read(&self, name: &str, limit: u64) -> Result<Vec<u8>, FileError> {
        let path = self.path.join(name);
        let flags = OFlags::RDONLY | OFlags::NOFOLLOW | OFlags::NONBLOCK | OFlags::CLOEXEC;
        let fd = rustix::fs::openat(self.fd.as_fd(), name, flags, Mode::empty()).map_err(|e| match e {
            rustix::io::Errno::LOOP => unsafe_(&path, "is a symbolic link: not written by this server".into()),
            e => io(&path)(e),
        })?;
        let file = File::from(fd);
        let meta = file.metadata().map_err(io_std(&path))?;
        if !meta.is_file() {
            return Err(unsafe_(&path, "is not a regular file: not written by this server".into()));
        }
        if meta.uid() != effective_uid() || meta.permissions().mode() & OTHERS_WRITE != 0 {
            return Err(unsafe_(
                &path,
                format!(
                    "belongs to user {} with mode {:o}: not a file this server's user wrote (another user could \
                     have written it)",
                    meta.uid(),
                    meta.permissions().mode() & 0o7777
                ),
            ));
        }
        let mut bytes = Vec::new();
        file.take(limit + 1).read_to_end(&mut bytes).map_err(io_std(&path))?;
        if bytes.len() as u64 > limit {
            return Err(FileError::TooLarge { path, limit });
        }
        Ok(bytes)
    }

    /// The modification time and length of the regular file `name` (without following a link),
    /// or why not.
    pub fn stamp(&self, name: &str) -> Result<(std::time::SystemTime, u64), FileError> {
        let path = self.path.join(name);
        let stat = rustix::fs::statat(self.fd.as_fd(), name, AtFlags::SYMLINK_NOFOLLOW).map_err(io(&path))?;
        let modified = std::time::UNIX_EPOCH
            + std::time::Duration::new(
                u64::try_from(stat.st_mtime).unwrap_or(0),
                u32::try_from(stat.st_mtime_nsec).unwrap_or(0),
            );
        Ok((modified, u64::try_from(stat.st_size).unwrap_or(0)))
    }

    /// Writes `bytes` as the file `name`: a fresh temporary file (random name, created
    /// exclusively, no link followed, mode 0644), synced, renamed over `name`. A failed write
    /// removes its temporary file.
    pub fn write(&self, name: &str, bytes: &[u8]) -> Result<(), FileError> {
        let path = self.path.join(name);
        let tmp = format!(".{name}.{:016x}.partial", rand::random::<u64>());
        let flags = OFlags::WRONLY | OFlags::CREATE | OFlags::EXCL | OFlags::NOFOLLOW | OFlags::CLOEXEC;
        let fd =
            rustix::fs::openat(self.fd.as_fd(), tmp.as_str(), flags, Mode::from_raw_mode(0o644)).map_err(io(&path))?;
        let mut file = File::from(fd);
        let written = file.write_all(bytes).and_then(|()| file.sync_all()).map_err(io_std(&path)).and_then(|()| {
            rustix::fs::renameat(self.fd.as_fd(), tmp.as_str(), self.fd.as_fd(), name).map_err(io(&path))
        });
        if written.is_err() {
            // Best effort: the error is what the caller needs; the temporary file is only litter.
            let _ = rustix::fs::unlinkat(self.fd.as_fd(), tmp.as_str(), AtFlags::empty());
        }
        written
    }

    /// Removes the file `name` (a link is removed, not followed); a missing one is not an error.
    pub fn remove_file(&self, name: &str) -> Result<(), FileError> {
        match rustix::fs::unlinkat(self.fd.as_fd(), name, AtFlags::empty()) {
            Ok(()) | Err(rustix::io::Errno::NOENT) => Ok(()),
            Err(e) => Err(io(&self.path.join(name))(e)),
        }
    }

    /// Removes the folder `name` and everything in it (links are removed, never followed); a
    /// missing one is not an error.
    pub fn remove_tree(&self, name: &str) -> Result<(), FileError> {
        let path = self.path.join(name);
        let stat = match rustix::fs::statat(self.fd.as_fd(), name, AtFlags::SYMLINK_NOFOLLOW) {
            Ok(stat) => stat,
            Err(rustix::io::Errno::NOENT) => return Ok(()),
            Err(e) => return Err(io(&path)(e)),
        };
        if rustix::fs::FileType::from_raw_mode(stat.st_mode) != rustix::fs::FileType::Directory {
            return self.remove_file(name);
        }
        let dir = self.subdir(name, false)?;
        let entries = std::fs::read_dir(&path).map_err(io_std(&path))?;
        for entry in entries {
            let entry = entry.map_err(io_std(&path))?;
            let Some(child) = entry.file_name().to_str().map(str::to_string) else {
                return Err(unsafe_(&path, "holds a name that is not UTF-8: not written by this server".into()));
            };
            dir.remove_tree(&child)?;
        }
        match rustix::fs::unlinkat(self.fd.as_fd(), name, AtFlags::REMOVEDIR) {
            Ok(()) | Err(rustix::io::Errno::NOENT) => Ok(()),
            Err(e) => Err(io(&path)(e)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mode(path: &Path, mode: u32) {
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
    }

    #[test]
    fn a_directory_others_can_change_is_refused_with_how_to_fix_it() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("cluster");
        let dir = PrivateDir::open(&root, true).unwrap();
        assert_eq!(std::fs::metadata(&root).unwrap().permissions().mode() & 0o777, 0o700);
        for bad in [0o770, 0o775, 0o757, 0o777] {
            mode(&root, bad);
            let e = PrivateDir::open(&root, true).unwrap_err().to_string();
            assert!(e.contains("chmod go-w"), "{bad:o}: {e}");
        }
        mode(&root, 0o755);
        PrivateDir::open(&root, false).unwrap();
        // A parent others can write (not sticky): they could swap the directory.
        mode(tmp.path(), 0o777);
        let e = PrivateDir::open(&root, false).unwrap_err().to_string();
        assert!(e.contains("not sticky"), "{e}");
        // Sticky, like /tmp: nobody else can rename what is ours.
        mode(tmp.path(), 0o1777);
        PrivateDir::open(&root, false).unwrap();
        mode(tmp.path(), 0o700);
        // A folder below that others can write is refused when used.
        std::fs::create_dir(root.join("job-3")).unwrap();
        mode(&root.join("job-3"), 0o777);
        assert!(dir.subdir("job-3", true).unwrap_err().to_string().contains("chmod go-w"));
    }

    #[test]
    fn links_are_never_followed_and_temporary_names_are_fresh() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = PrivateDir::open(&tmp.path().join("c"), true).unwrap();
        let decoy = tmp.path().join("decoy");
        std::fs::write(&decoy, "root's file").unwrap();
        // A link where a file is written: replaced, not written through.
        std::os::unix::fs::symlink(&decoy, dir.path().join("record.json")).unwrap();
        dir.write("record.json", b"{}").unwrap();
        assert_eq!(std::fs::read_to_string(&decoy).unwrap(), "root's file");
        assert!(std::fs::symlink_metadata(dir.path().join("record.json")).unwrap().is_file());
        // A link where a file is read: refused.
        std::os::unix::fs::symlink(&decoy, dir.path().join("task-0.json")).unwrap();
        let e = dir.read("task-0.json", 1 << 20).unwrap_err().to_string();
        assert!(e.contains("symbolic link"), "{e}");
        // A link where a folder is opened: refused.
        std::os::unix::fs::symlink(tmp.path(), dir.path().join("job-1")).unwrap();
        assert!(dir.subdir("job-1", true).is_err());
        // A file others can write: refused.
        dir.write("spec.json", b"{}").unwrap();
        mode(&dir.path().join("spec.json"), 0o666);
        assert!(dir.read("spec.json", 1 << 20).unwrap_err().to_string().contains("mode 666"));
        // Bounded reads.
        dir.write("big", &[b'x'; 100]).unwrap();
        assert!(matches!(dir.read("big", 99), Err(FileError::TooLarge { .. })));
        assert_eq!(dir.read("big", 100).unwrap().len(), 100);
        // No temporary file is left behind, and a failed write removes its own.
        std::fs::create_dir(dir.path().join("taken")).unwrap();
        assert!(dir.write("taken", b"x").is_err());
        let names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(names.iter().all(|n| !n.contains("partial")), "{names:?}");
        // Removal deletes links, not what they point to.
        let job = dir.subdir("job-2", true).unwrap();
        std::os::unix::fs::symlink(&decoy, job.path().join("link")).unwrap();
        dir.remove_tree("job-2").unwrap();
        assert!(!dir.path().join("job-2").exists() && decoy.exists());
    }

    /// With a second local user (the test runs as root, and `nobody` exists), a directory or a
    /// folder of that user is refused; without one, the checks above stand in for it.
    #[test]
    fn another_users_directory_or_folder_is_refused() {
        if effective_uid() != 0 {
            eprintln!("skipped: needs root to give a folder to `nobody` (the mode checks above still run)");
            return;
        }
        let nobody = 65534;
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("cluster");
        std::fs::create_dir(&root).unwrap();
        mode(&root, 0o755);
        std::os::unix::fs::chown(&root, Some(nobody), Some(nobody)).unwrap();
        let e = PrivateDir::open(&root, true).unwrap_err().to_string();
        assert!(e.contains("belongs to user 65534"), "{e}");
        // Ours, but a parent of another user's: refused too.
        let theirs = tmp.path().join("theirs");
        std::fs::create_dir(&theirs).unwrap();
        std::os::unix::fs::chown(&theirs, Some(nobody), Some(nobody)).unwrap();
        let e = PrivateDir::open(&theirs.join("cluster"), true).unwrap_err().to_string();
        assert!(e.contains("neither root nor"), "{e}");
        // A job folder of another user, and a file of another user.
        let ours = PrivateDir::open(&tmp.path().join("ours"), true).unwrap();
        let job = ours.path().join("job-3");
        std::fs::create_dir(&job).unwrap();
        mode(&job, 0o755);
        std::os::unix::fs::chown(&job, Some(nobody), Some(nobody)).unwrap();
        assert!(ours.subdir("job-3", true).unwrap_err().to_string().contains("belongs to user 65534"));
        ours.write("task-0.json", b"{}").unwrap();
        std::os::unix::fs::chown(ours.path().join("task-0.json"), Some(nobody), Some(nobody)).unwrap();
        assert!(ours.read("task-0.json", 100).unwrap_err().to_string().contains("belongs to user 65534"));
    }
}
