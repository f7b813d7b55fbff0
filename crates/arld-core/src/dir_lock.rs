//! The lock of a working directory: one `arld sweep` (or one shard of it) works in a sweep directory at a time,
//! and one `arld train` (a new run, `--resume`, `--restart`) in a run directory. The lock
//! is a file naming its holder (pid, host, start time), created atomically (written aside, then hard-linked into
//! place, which fails if it exists) and removed when the holder ends. A lock whose holder is gone (a process of
//! this host that no longer exists, e.g. after SIGKILL) is stale: it is taken over with a warning. A lock held
//! from another host cannot be checked from here and is never taken over.
//!
//! Taking over is serialised by an advisory lock (`flock`) on the directory itself: between reading a stale
//! holder and removing its file, no other taker can remove or replace the file, so that of several processes
//! taking over one stale lock at once exactly one holds it and every other is refused, naming it. The kernel
//! releases the advisory lock with its process, so it never goes stale itself.

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Who holds a lock (the lock file's contents).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Holder {
    pub pid: u32,
    pub host: String,
    /// Seconds since the Unix epoch when the lock was taken.
    pub since_unix: u64,
}

impl Holder {
    fn this_process() -> Self {
        Holder {
            pid: std::process::id(),
            host: host_name(),
            since_unix: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs()),
        }
    }

    /// Whether the holder is known to be gone: a process of this host that no longer exists.
    fn is_gone(&self) -> bool {
        self.host == host_name()
            && self.pid != std::process::id()
            && !Path::new(&format!("/proc/{}", self.pid)).exists()
    }
}

/// A held lock; dropping it releases it.
#[derive(Debug)]
pub struct DirLock {
    path: PathBuf,
}

impl DirLock {
    /// Takes the lock file `name` in `dir` (which must exist), taking over a stale one with a warning on stderr.
    /// Refuses, naming the holder, when a live process (or one on another host) holds it.
    pub fn acquire(dir: &Path, name: &str) -> Result<Self> {
        let path = dir.join(name);
        let me = Holder::this_process();
        // A name of this call's own: threads of one process take locks too.
        static CALLS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let temp = dir.join(format!("{name}.{}.{call}.tmp", me.pid));
        // Written without following a link someone put at the temporary name.
        crate::files::open_own_file(&temp, true)
            .and_then(|mut f| {
                std::io::Write::write_all(&mut f, serde_json::to_string(&me)?.as_bytes())
            })
            .with_context(|| format!("cannot write the lock file {}", temp.display()))?;
        let result = Self::link(&temp, &path);
        let _ = std::fs::remove_file(&temp);
        result
    }

    /// Links the written holder `temp` into place at `path`: `None` when a lock file is there already.
    fn try_link(temp: &Path, path: &Path) -> Result<Option<Self>> {
        match std::fs::hard_link(temp, path) {
            Ok(()) => Ok(Some(DirLock {
                path: path.to_path_buf(),
            })),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(None),
            Err(e) => {
                Err(e).with_context(|| format!("cannot create the lock file {}", path.display()))
            }
        }
    }

    fn link(temp: &Path, path: &Path) -> Result<Self> {
        // The usual case, with nobody holding the lock: taken at once.
        if let Some(lock) = Self::try_link(temp, path)? {
            return Ok(lock);
        }
        // Held, or stale: decided while no other taker looks at the file.
        let _takeover = Takeover::of(path.parent().unwrap_or(Path::new(".")))?;
        // Two attempts: the second after removing a stale lock.
        for _ in 0..2 {
            if let Some(lock) = Self::try_link(temp, path)? {
                return Ok(lock);
            }
            let text = crate::files::read_text_bounded(path, 1 << 20).unwrap_or_default();
            let holder: Option<Holder> = serde_json::from_str(&text).ok();
            match holder {
                Some(holder) if holder.is_gone() => {
                    eprintln!(
                        "warning: {} was left by process {} on {}, which no longer runs; taking it over",
                        path.display(),
                        holder.pid,
                        holder.host
                    );
                    std::fs::remove_file(path).with_context(|| {
                        format!("cannot remove the stale lock file {}", path.display())
                    })?;
                }
                Some(holder) => bail!(
                    "{} is in use by another arld process: process {} on host {} holds {} (since Unix time {}); \
                     wait for it to finish, or remove the lock file if that process is gone",
                    path.parent().unwrap_or(path).display(),
                    holder.pid,
                    holder.host,
                    path.display(),
                    holder.since_unix
                ),
                None => bail!(
                    "{} holds no readable holder (pid, host); if no arld process works in {}, remove it",
                    path.display(),
                    path.parent().unwrap_or(path).display()
                ),
            }
        }
        bail!(
            "cannot take the lock {}: another process keeps taking it",
            path.display()
        )
    }
}

/// The advisory lock on a directory that serialises taking over its lock files; released when dropped (or when
/// the process ends).
struct Takeover(std::fs::File);

impl Takeover {
    fn of(dir: &Path) -> Result<Self> {
        let file = std::fs::File::open(dir)
            .with_context(|| format!("cannot open the directory {}", dir.display()))?;
        loop {
            // SAFETY: `flock` on a descriptor this function owns; it touches no memory.
            let rc = unsafe { libc::flock(std::os::fd::AsRawFd::as_raw_fd(&file), libc::LOCK_EX) };
            if rc == 0 {
                return Ok(Takeover(file));
            }
            let err = std::io::Error::last_os_error();
            if err.kind() != std::io::ErrorKind::Interrupted {
                return Err(err).with_context(|| {
                    format!(
                        "cannot lock the directory {} to take over its lock",
                        dir.display()
                    )
                });
            }
        }
    }
}

impl Drop for Takeover {
    fn drop(&mut self) {
        // SAFETY: as in `of`; closing the file would release it too.
        unsafe { libc::flock(std::os::fd::AsRawFd::as_raw_fd(&self.0), libc::LOCK_UN) };
    }
}

impl Drop for DirLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// This machine's short host name (as Slurm's node names are).
pub fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|h| h.trim().split('.').next().unwrap_or("").to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "unknown".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Many takers of one stale lock at once: exactly one holds it, every other is refused naming the holder
    /// (before the takeover was serialised, one taker could remove another's fresh lock, so that two held it, or
    /// find the stale file gone and refuse, so that none did).
    #[test]
    fn a_stale_lock_taken_over_by_many_at_once_has_one_holder() {
        let stale = Holder {
            pid: u32::MAX,
            host: host_name(),
            since_unix: 0,
        };
        for round in 0..300 {
            let dir = tempfile::tempdir().unwrap();
            std::fs::write(
                dir.path().join(".lock"),
                serde_json::to_string(&stale).unwrap(),
            )
            .unwrap();
            let takers = 6;
            let barrier = std::sync::Barrier::new(takers);
            let outcomes: Vec<Result<DirLock, String>> = std::thread::scope(|scope| {
                let handles: Vec<_> = (0..takers)
                    .map(|_| {
                        scope.spawn(|| {
                            barrier.wait();
                            DirLock::acquire(dir.path(), ".lock").map_err(|e| format!("{e:#}"))
                        })
                    })
                    .collect();
                handles.into_iter().map(|h| h.join().unwrap()).collect()
            });
            let held = outcomes.iter().filter(|o| o.is_ok()).count();
            let refusals: Vec<&String> = outcomes.iter().filter_map(|o| o.as_ref().err()).collect();
            assert_eq!(
                held, 1,
                "round {round}: {held} holders; refusals: {refusals:?}"
            );
            for refusal in refusals {
                assert!(
                    refusal.contains("is in use by another arld process"),
                    "round {round}: {refusal}"
                );
            }
        }
    }

    #[test]
    fn a_held_lock_is_refused_and_a_stale_one_taken_over() {
        let dir = tempfile::tempdir().unwrap();
        let lock = DirLock::acquire(dir.path(), ".lock").unwrap();
        // This process holds it: a second acquisition is refused and names this pid.
        let err = format!("{:#}", DirLock::acquire(dir.path(), ".lock").unwrap_err());
        assert!(
            err.contains(&format!("process {}", std::process::id())),
            "{err}"
        );
        drop(lock);
        assert!(!dir.path().join(".lock").exists());
        // A lock of a process that does not exist on this host (pid beyond the kernel's maximum) is stale.
        let stale = Holder {
            pid: u32::MAX,
            host: host_name(),
            since_unix: 0,
        };
        std::fs::write(
            dir.path().join(".lock"),
            serde_json::to_string(&stale).unwrap(),
        )
        .unwrap();
        let lock = DirLock::acquire(dir.path(), ".lock").unwrap();
        let holder: Holder =
            serde_json::from_str(&std::fs::read_to_string(dir.path().join(".lock")).unwrap())
                .unwrap();
        assert_eq!(holder.pid, std::process::id());
        drop(lock);
        // Another host's lock is never taken over.
        let remote = Holder {
            host: "some-other-host".into(),
            ..stale
        };
        std::fs::write(
            dir.path().join(".lock"),
            serde_json::to_string(&remote).unwrap(),
        )
        .unwrap();
        let err = format!("{:#}", DirLock::acquire(dir.path(), ".lock").unwrap_err());
        assert!(err.contains("some-other-host"), "{err}");
    }
}
