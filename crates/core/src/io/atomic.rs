//! Atomic file output: write to a temporary file in the destination's directory, flush it
//! to disk, rename it over the destination, then flush the directory. A reader (or a
//! resumed run) sees either the old file or the complete new one, never a torn write; and
//! once [`AtomicFile::commit`] returns, the new name survives a power loss too (POSIX
//! makes a rename durable only when the directory holding it is synced: `fsync(2)`).

use std::fs;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

/// Writes `bytes` to `path` atomically.
///
/// # Errors
/// Any I/O error, with the path in the message. The temporary file is removed on failure.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let mut f = AtomicFile::create(path)?;
    f.write_all(bytes).map_err(|e| f.error(e))?;
    f.commit()
}

/// A file written as a stream and published atomically: the bytes go to a temporary file
/// beside `path`, and [`AtomicFile::commit`] flushes it to disk and renames it over `path`.
/// Dropped without a commit (an error, a panic, an interrupted run), it removes the
/// temporary file and leaves `path` as it was.
#[derive(Debug)]
pub struct AtomicFile {
    path: PathBuf,
    tmp: PathBuf,
    w: Option<BufWriter<fs::File>>,
}

impl AtomicFile {
    /// Creates the temporary file for `path`.
    ///
    /// # Errors
    /// When the directory is missing or not writable (the message names `path`).
    pub fn create(path: &Path) -> io::Result<Self> {
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let name = path.file_name().ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("{}: not a file path", path.display()),
            )
        })?;
        let tmp = dir.join(format!(
            ".{}.{}.tmp",
            name.to_string_lossy(),
            std::process::id()
        ));
        let f = fs::File::create(&tmp).map_err(|e| named(path, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            tmp,
            w: Some(BufWriter::with_capacity(1 << 16, f)),
        })
    }

    /// The destination.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// `e` with the destination's name in its message.
    pub fn error(&self, e: io::Error) -> io::Error {
        named(&self.path, e)
    }

    /// Flushes the file to disk, renames it over the destination and flushes the
    /// directory (so the rename itself is on disk when this returns).
    ///
    /// # Errors
    /// Any I/O error (a full disk shows here at the latest), naming the destination; the
    /// temporary file is then removed.
    pub fn commit(mut self) -> io::Result<()> {
        let w = self.w.take().expect("an AtomicFile is committed once");
        let result = w
            .into_inner()
            .map_err(|e| e.into_error())
            .and_then(|f| f.sync_all())
            .and_then(|()| fs::rename(&self.tmp, &self.path));
        if let Err(e) = result {
            let _ = fs::remove_file(&self.tmp);
            return Err(named(&self.path, e));
        }
        sync_dir(&self.path).map_err(|e| named(&self.path, e))
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.w.as_mut().expect("not yet committed").write(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.w.as_mut().expect("not yet committed").flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.w.take().is_some() {
            let _ = fs::remove_file(&self.tmp);
        }
    }
}

/// Removes the temporary files that processes killed mid-write left in `dir`: this
/// module's `.NAME.PID.tmp` files and the external sort's `.hybridnav-spill-PID-…` runs,
/// when process PID is no longer alive. A live process's files (another shard writing
/// into the same directory) are left alone. Only where `/proc` tells which processes are
/// alive (Linux); elsewhere nothing is removed. Returns how many files were removed.
///
/// # Errors
/// When `dir` cannot be listed or a stale file cannot be removed.
pub fn remove_stale_temporaries(dir: &Path) -> io::Result<usize> {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return Ok(0);
    }
    let own = std::process::id();
    let mut removed = 0;
    let entries = match fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(named(dir, e)),
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        let pid = if let Some(rest) = name.strip_prefix(".hybridnav-spill-") {
            rest.split('-').next()
        } else if let Some(rest) = name.strip_prefix('.').and_then(|n| n.strip_suffix(".tmp")) {
            rest.rsplit_once('.').map(|(_, pid)| pid)
        } else {
            None
        };
        let Some(pid) = pid.and_then(|p| p.parse::<u32>().ok()) else {
            continue;
        };
        if pid != own && !proc.join(pid.to_string()).exists() {
            let path = entry.path();
            fs::remove_file(&path).map_err(|e| named(&path, e))?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// Flushes the directory that holds `path` to disk, making a rename or a new name in it
/// durable. Where directories cannot be opened for this (not Unix), nothing is done.
///
/// # Errors
/// The OS error of opening or syncing the directory.
pub fn sync_dir(path: &Path) -> io::Result<()> {
    #[cfg(unix)]
    {
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        fs::File::open(dir)?.sync_all()?;
    }
    #[cfg(not(unix))]
    let _ = path;
    Ok(())
}

fn named(path: &Path, e: io::Error) -> io::Error {
    if e.to_string().contains(&path.display().to_string()) {
        return e;
    }
    io::Error::new(e.kind(), format!("writing {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_and_replaces() {
        let dir = std::env::temp_dir().join(format!("hybridnav-atomic-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.json");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"two");
        // No temporary files are left behind.
        assert_eq!(fs::read_dir(&dir).unwrap().count(), 1);
        // A stream dropped before its commit leaves the old file and no temporary file.
        let mut f = AtomicFile::create(&p).unwrap();
        f.write_all(b"three").unwrap();
        drop(f);
        assert_eq!(fs::read(&p).unwrap(), b"two");
        assert_eq!(fs::read_dir(&dir).unwrap().count(), 1);
        let mut f = AtomicFile::create(&p).unwrap();
        f.write_all(b"four").unwrap();
        f.commit().unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"four");
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn stale_temporaries_of_dead_processes_are_removed() {
        let dir = std::env::temp_dir().join(format!("hybridnav-stale-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        // PID 0x7fff_fff0 is above Linux's pid_max, so no process has it.
        let dead = 0x7fff_fff0u32;
        let own = std::process::id();
        for n in [
            format!(".epochs.csv.{dead}.tmp"),
            format!(".hybridnav-spill-{dead}-3-0.f64"),
            format!(".epochs.csv.{own}.tmp"),
            format!(".hybridnav-spill-{own}-0-0.f64"),
            "summary.json".to_string(),
            ".hidden.tmp".to_string(),
        ] {
            fs::write(dir.join(n), b"x").unwrap();
        }
        let removed = remove_stale_temporaries(&dir).unwrap();
        let mut left: Vec<String> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        if Path::new("/proc/self").exists() {
            assert_eq!(removed, 2);
            assert_eq!(
                left,
                [
                    format!(".epochs.csv.{own}.tmp"),
                    ".hidden.tmp".to_string(),
                    format!(".hybridnav-spill-{own}-0-0.f64"),
                    "summary.json".to_string()
                ]
            );
        } else {
            assert_eq!(removed, 0);
        }
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn unwritable_directory_names_the_path() {
        let e = write_atomic(Path::new("/nonexistent-dir-hybridnav/x.json"), b"x").unwrap_err();
        assert!(
            e.to_string().contains("/nonexistent-dir-hybridnav/x.json"),
            "{e}"
        );
    }
}
