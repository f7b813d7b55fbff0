//! Writing a file so that no reader ever sees half of it: [`write_atomic`] writes a temporary file beside the
//! target, syncs it, and renames it over the target (a rename within one directory is atomic), so a reader
//! finds the old content or the new one, and an interrupted write leaves the old file in place. Every file the
//! project writes whole (weights, run summaries and curves, demonstrations, sweep records, reports) goes
//! through it.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// A failed atomic write: the file it was for and why.
#[derive(Debug, thiserror::Error)]
#[error("cannot write {}: {source}", path.display())]
pub struct WriteError {
    pub path: PathBuf,
    pub source: std::io::Error,
}

/// Writes `bytes` to `path` through a temporary file in the same directory (synced, then renamed over
/// `path`); the temporary file is removed if anything fails.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    let mut file = AtomicFile::create(path)?;
    file.write_all(bytes).map_err(|e| file.error(e))?;
    file.commit()
}

/// A file written in pieces in place of another, atomically: the bytes go to a temporary file beside the
/// target, and [`AtomicFile::commit`] syncs it and renames it over the target. Until then the target keeps its
/// old content; dropped without a commit (an error, a panic), the temporary file is removed.
pub(crate) struct AtomicFile {
    path: PathBuf,
    tmp: PathBuf,
    file: Option<BufWriter<File>>,
    committed: bool,
}

impl AtomicFile {
    /// Starts writing the file that will replace `path`.
    pub fn create(path: &Path) -> Result<Self, WriteError> {
        // Distinct temporary names for concurrent writers in one process (sweep threads) and across processes.
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let error = |source| WriteError {
            path: path.to_path_buf(),
            source,
        };
        let name = path
            .file_name()
            .ok_or_else(|| error(std::io::Error::other("the path has no file name")))?;
        check_replaceable(path).map_err(error)?;
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let tmp = dir.join(format!(
            "{TEMP_PREFIX}{}.tmp{}-{}",
            name.to_string_lossy(),
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let file = File::create(&tmp).map_err(error)?;
        Ok(Self {
            path: path.to_path_buf(),
            tmp,
            file: Some(BufWriter::new(file)),
            committed: false,
        })
    }

    /// The error of a failed write to this file, naming the target.
    pub fn error(&self, source: std::io::Error) -> WriteError {
        WriteError {
            path: self.path.clone(),
            source,
        }
    }

    /// Writes what is buffered to the temporary file (into the operating system's cache: a process killed from
    /// now on leaves the whole content there, though still under the temporary name).
    pub(crate) fn flush_buffer(&mut self) -> Result<(), WriteError> {
        let result = self.writer().flush();
        result.map_err(|e| self.error(e))
    }

    /// Makes the new content the target's: flushes, syncs the temporary file to the disk, then renames it over
    /// the target, so that even a machine that loses power after the rename finds the whole new content.
    pub fn commit(mut self) -> Result<(), WriteError> {
        let writer = self
            .file
            .take()
            .expect("an uncommitted file has its writer");
        let done = writer
            .into_inner()
            .map_err(|e| e.into_error())
            .and_then(|file| file.sync_all())
            .and_then(|()| std::fs::rename(&self.tmp, &self.path));
        self.committed = done.is_ok();
        done.map_err(|e| self.error(e))
    }

    fn writer(&mut self) -> &mut BufWriter<File> {
        self.file
            .as_mut()
            .expect("an uncommitted file has its writer")
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.writer().write(buf)
    }

    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        self.writer().write_all(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.writer().flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Refuses a target that exists and is not a regular file: renaming over a directory fails late, and renaming
/// over a device (`/dev/null`), a pipe or a symbolic link would replace the node itself, not write into it.
fn check_replaceable(path: &Path) -> std::io::Result<()> {
    let meta = match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        meta => meta?,
    };
    let kind = meta.file_type();
    if kind.is_file() {
        return Ok(());
    }
    Err(std::io::Error::other(format!(
        "it is {}; arld writes its outputs only to new or regular files",
        kind_name(kind)
    )))
}

/// What a file system entry is, for messages: "a symbolic link", "a directory", "a device", ...
pub fn kind_name(kind: std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if kind.is_file() {
        "a regular file"
    } else if kind.is_symlink() {
        "a symbolic link"
    } else if kind.is_dir() {
        "a directory"
    } else if kind.is_char_device() || kind.is_block_device() {
        "a device"
    } else if kind.is_fifo() {
        "a named pipe"
    } else if kind.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

/// Whether a regular file is at `path` (`false`: nothing is), without following a symbolic link: anything else
/// there (a link, a directory, a device, a pipe) is an error naming the path and what it is. For the files a
/// program owns in its own directory, which it must never read or write through a link.
pub(crate) fn own_file_exists(path: &Path) -> std::io::Result<bool> {
    match std::fs::symlink_metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(false),
        Err(e) => Err(std::io::Error::new(
            e.kind(),
            format!("cannot inspect {}: {e}", path.display()),
        )),
        Ok(meta) if meta.file_type().is_file() => Ok(true),
        Ok(meta) => Err(std::io::Error::other(format!(
            "{} is {}, where arld keeps a regular file of its own; move it away",
            path.display(),
            kind_name(meta.file_type())
        ))),
    }
}

/// Opens a file the program owns for writing (see [`own_file_exists`]): created (and emptied) when `create`,
/// else it must exist. Never through a symbolic link, never a device or a pipe.
pub(crate) fn open_own_file(path: &Path, create: bool) -> std::io::Result<File> {
    use std::os::unix::fs::OpenOptionsExt;
    own_file_exists(path)?;
    let file = std::fs::OpenOptions::new()
        .write(true)
        .create(create)
        .truncate(create)
        // A link or pipe put there between the check and the open is refused too (no blocking on a pipe).
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", path.display())))?;
    if !file.metadata()?.is_file() {
        return Err(std::io::Error::other(format!(
            "{} is not a regular file",
            path.display()
        )));
    }
    Ok(file)
}

/// Reads a whole input file of at most `max_bytes` (opened by `open_bounded`: a file, or what a link names,
/// that is no regular file, or is longer, is an error naming it): every whole-file read of input has a bound, so
/// that `/dev/zero` or a pipe that never ends cannot exhaust the memory, nor a pipe without a writer hang.
pub fn read_bounded(path: &Path, max_bytes: u64) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let named =
        |e: std::io::Error| std::io::Error::new(e.kind(), format!("{}: {e}", path.display()));
    let (file, len) = open_bounded(path, max_bytes)?;
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(max_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(named)?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_long(path, max_bytes));
    }
    Ok(bytes)
}

/// Reads a whole input text file of at most `max_bytes` ([`read_bounded`]); bytes that are not UTF-8 are an
/// error ([`std::io::ErrorKind::InvalidData`]) naming it.
pub fn read_text_bounded(path: &Path, max_bytes: u64) -> std::io::Result<String> {
    String::from_utf8(read_bounded(path, max_bytes)?).map_err(|_| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("{} is not UTF-8 text", path.display()),
        )
    })
}

/// Opens an input file to be read in pieces ([`open_regular`]), with its length, which is at most `max_bytes`
/// (a longer file is an error naming it); the reader reads at most that many bytes (a file that grows while
/// it is read is cut there). Every input arld reads (configurations, tables, demonstrations, datasets, weights,
/// grids) is opened here or by [`read_bounded`], which builds on it.
pub(crate) fn open_bounded(path: &Path, max_bytes: u64) -> std::io::Result<(File, u64)> {
    let named =
        |e: std::io::Error| std::io::Error::new(e.kind(), format!("{}: {e}", path.display()));
    let file = open_regular(path)?;
    let len = file.metadata().map_err(named)?.len();
    if len > max_bytes {
        return Err(too_long(path, max_bytes));
    }
    Ok((file, len))
}

/// Opens an input file for reading: a regular file, or what a link names if that is one. Anything else (a named
/// pipe, a device, a directory, a socket) is an error naming the path and what it is, at once: opening a named
/// pipe without a writer would wait for one forever.
pub(crate) fn open_regular(path: &Path) -> std::io::Result<File> {
    use std::os::unix::fs::OpenOptionsExt;
    let named =
        |e: std::io::Error| std::io::Error::new(e.kind(), format!("{}: {e}", path.display()));
    let file = std::fs::OpenOptions::new()
        .read(true)
        // Opening a pipe does not wait for a writer; a regular file reads as without the flag.
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(named)?;
    let meta = file.metadata().map_err(named)?;
    if !meta.is_file() {
        return Err(std::io::Error::other(format!(
            "{} is {}, not a regular file",
            path.display(),
            kind_name(meta.file_type())
        )));
    }
    Ok(file)
}

fn too_long(path: &Path, max_bytes: u64) -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::InvalidData,
        format!(
            "{} is longer than {max_bytes} bytes, more than arld reads from such a file",
            path.display()
        ),
    )
}

/// Reads one line (without its `\n`, and a `\r` before it) of at most `max_bytes` into `line`; `false` at the
/// end of the input. A longer line is an error ([`std::io::ErrorKind::InvalidData`]): a stream that never
/// sends a line break cannot exhaust the memory.
pub(crate) fn read_line_bounded(
    reader: &mut impl std::io::BufRead,
    line: &mut Vec<u8>,
    max_bytes: usize,
) -> std::io::Result<bool> {
    use std::io::{BufRead, Read};
    line.clear();
    let read = reader
        .by_ref()
        .take(max_bytes as u64 + 1)
        .read_until(b'\n', line)?;
    if read == 0 {
        return Ok(false);
    }
    if line.last() == Some(&b'\n') {
        line.pop();
        if line.last() == Some(&b'\r') {
            line.pop();
        }
    } else if line.len() > max_bytes {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("a line is longer than {max_bytes} bytes"),
        ));
    }
    Ok(true)
}

/// Every temporary file's name begins with this (then the target's name), so that what a killed process left
/// behind can be recognised ([`remove_leftovers`]).
const TEMP_PREFIX: &str = ".";

/// Whether `name` is the name of a temporary file that a writer of the file named `target` makes
/// ([`AtomicFile::create`]: `.TARGET.tmpPID-N`), exactly: a user's `.TARGET.tmp.bak` is not one. With the
/// writer's process id.
fn temporary_of(name: &str, target: &str) -> Option<u32> {
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    let rest = name
        .strip_prefix(TEMP_PREFIX)?
        .strip_prefix(target)?
        .strip_prefix(".tmp")?;
    let (pid, counter) = rest.split_once('-')?;
    (digits(pid) && digits(counter)).then(|| pid.parse().ok())?
}

/// Whether `name` is a temporary file of a writer of `target` (see [`AtomicFile`]), exactly by its form.
pub(crate) fn is_temporary_of(name: &str, target: &str) -> bool {
    temporary_of(name, target).is_some()
}

/// Removes the temporary files that writers of `path` killed before their commit left beside it (nothing if
/// its directory does not exist): the files of exactly their form ([`is_temporary_of`]) made by another process
/// than this one (whose writers may be at work).
pub(crate) fn remove_leftovers(path: &Path) -> std::io::Result<()> {
    let (Some(dir), Some(name)) = (path.parent(), path.file_name()) else {
        return Ok(());
    };
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let name = name.to_string_lossy();
    let entries = match std::fs::read_dir(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        entries => entries?,
    };
    for entry in entries {
        let entry = entry?;
        let pid = temporary_of(&entry.file_name().to_string_lossy(), &name);
        if pid.is_some_and(|pid| pid != std::process::id()) {
            match std::fs::remove_file(entry.path()) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(e),
                _ => {}
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_replaces_the_whole_file_and_leaves_nothing_behind() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.txt");
        write_atomic(&path, b"first version, longer").unwrap();
        write_atomic(&path, b"second").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "second");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        // A failed write (no such directory) names the file and leaves no temporary file.
        let missing = dir.path().join("no/such/dir/b.txt");
        let err = write_atomic(&missing, b"x").unwrap_err();
        assert!(err.to_string().contains("b.txt"), "{err}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn an_uncommitted_file_leaves_the_target_alone_and_leftovers_are_found() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.bin");
        write_atomic(&path, b"old").unwrap();
        let mut file = AtomicFile::create(&path).unwrap();
        file.write_all(b"new, in pieces").unwrap();
        file.flush_buffer().unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        drop(file);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        // What a killed writer leaves: its temporary file (forgotten here, as a killed process would); a
        // process's own writers' files are left to them, another (killed) process's are removed.
        let mut killed = AtomicFile::create(&path).unwrap();
        killed.write_all(b"half").unwrap();
        killed.flush_buffer().unwrap();
        std::mem::forget(killed);
        let ours = format!(".s.bin.tmp{}-", std::process::id());
        std::fs::write(dir.path().join(".s.bin.tmp4194305-7"), b"x").unwrap();
        std::fs::write(dir.path().join("other.bin"), b"x").unwrap();
        std::fs::write(dir.path().join(".s.bin.other"), b"x").unwrap();
        // A user's files whose names only look like temporary ones.
        std::fs::write(dir.path().join(".s.bin.tmp.bak"), b"x").unwrap();
        std::fs::write(dir.path().join(".s.bin.tmp12-3.bak"), b"x").unwrap();
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 7);
        remove_leftovers(&path).unwrap();
        let mut left: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|name| !name.starts_with(&ours))
            .collect();
        left.sort();
        assert_eq!(
            left,
            [
                ".s.bin.other",
                ".s.bin.tmp.bak",
                ".s.bin.tmp12-3.bak",
                "other.bin",
                "s.bin"
            ]
        );
        assert!(is_temporary_of(".s.bin.tmp12-3", "s.bin"));
        assert!(!is_temporary_of(".s.bin.tmp12-", "s.bin"));
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        remove_leftovers(&dir.path().join("missing/s.bin")).unwrap();
    }

    #[test]
    fn lines_and_files_are_read_with_a_bound_and_own_files_never_through_a_link() {
        let mut input = std::io::Cursor::new(b"ab\r\ncde\nxyz".to_vec());
        let mut line = Vec::new();
        let mut lines = Vec::new();
        while read_line_bounded(&mut input, &mut line, 3).unwrap() {
            lines.push(String::from_utf8(line.clone()).unwrap());
        }
        assert_eq!(lines, ["ab", "cde", "xyz"]);
        let mut long = std::io::Cursor::new(b"abcd\n".to_vec());
        let err = read_line_bounded(&mut long, &mut line, 3).unwrap_err();
        assert!(err.to_string().contains("longer than 3 bytes"), "{err}");
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("f.txt");
        std::fs::write(&file, b"12345").unwrap();
        assert_eq!(read_bounded(&file, 5).unwrap(), b"12345");
        assert!(read_bounded(&file, 4).is_err());
        let err = read_bounded(Path::new("/dev/zero"), 1 << 20).unwrap_err();
        assert!(err.to_string().contains("a device"), "{err}");
        let link = dir.path().join("link.txt");
        std::os::unix::fs::symlink(&file, &link).unwrap();
        assert!(own_file_exists(&file).unwrap());
        assert!(!own_file_exists(&dir.path().join("none")).unwrap());
        for err in [
            own_file_exists(&link).unwrap_err(),
            open_own_file(&link, true).unwrap_err(),
        ] {
            assert!(err.to_string().contains("symbolic link"), "{err}");
        }
        assert_eq!(std::fs::read(&file).unwrap(), b"12345");
    }

    #[test]
    fn a_target_that_is_not_a_regular_file_is_refused_and_left_alone() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real.txt");
        std::fs::write(&real, b"kept").unwrap();
        let link = dir.path().join("link.txt");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).unwrap();
        for (target, what) in [
            (link.as_path(), "symbolic link"),
            (sub.as_path(), "directory"),
            (Path::new("/dev/null"), "device"),
        ] {
            let err = write_atomic(target, b"x").unwrap_err().to_string();
            assert!(err.contains(what), "{target:?}: {err}");
        }
        // Nothing replaced, nothing left behind.
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(std::fs::read(&real).unwrap(), b"kept");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);
        use std::os::unix::fs::FileTypeExt;
        assert!(
            std::fs::metadata("/dev/null")
                .unwrap()
                .file_type()
                .is_char_device()
        );
    }
}
