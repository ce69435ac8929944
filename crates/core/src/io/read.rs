//! Bounded reads of the files a world or a command names.
//!
//! Every input file goes through [`open`] (or [`read_bytes`], [`read_text`], [`reader`],
//! which call it): the path must name a **regular file** — not a directory, a named pipe
//! (which would block the reader forever), a character device such as `/dev/zero` (which
//! never ends) or a socket — and the file must be no larger than the [`Limit`] of its kind,
//! both checked on the opened file before a byte is read. The read itself stops one byte
//! past the limit, so a file that grows while it is read (or a `/proc` file, whose size is
//! reported as 0) cannot exceed it either.
//!
//! The file is opened with `O_NONBLOCK` on Unix, so that a path swapped for a named pipe
//! between a check and the open cannot block the open; the type is then checked on the
//! open descriptor (`fstat`), which is the file that will be read.
//!
//! Messages do not repeat the path: callers put it in front (`FILE: message`), so each
//! operating-system error appears once.

use std::fs;
use std::io::{self, BufReader, Read};
use std::path::Path;

/// The largest file of one kind that hybridnav reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limit {
    /// What the file is, for messages ("world file").
    pub what: &'static str,
    /// Its size cap in bytes.
    pub max_bytes: u64,
}

const MIB: u64 = 1 << 20;
const GIB: u64 = 1 << 30;

/// World files: the largest shipped world is 12 kB; 16 MiB leaves room for scenes of
/// thousands of buildings written out by a script.
pub const WORLD: Limit = Limit {
    what: "world file",
    max_bytes: 16 * MIB,
};

/// RINEX navigation files: a daily multi-GNSS broadcast file (BRDM) is 5–8 MB; 256 MiB
/// holds a month of them concatenated.
pub const RINEX_NAV: Limit = Limit {
    what: "RINEX navigation file",
    max_bytes: 256 * MIB,
};

/// SP3 precise orbits: a daily 5-minute multi-GNSS file (IGS/MGEX) is 5–12 MB; 256 MiB
/// holds weeks of 30-s orbits.
pub const SP3: Limit = Limit {
    what: "SP3 orbit file",
    max_bytes: 256 * MIB,
};

/// FM fingerprint databases: a survey is capped at 10⁷ reference points (the world
/// loader's limit), but a database is JSON held in memory while it is parsed; 1 GiB is
/// about 4 million points of a dozen stations (≈ 250 bytes a point).
pub const FM_DATABASE: Limit = Limit {
    what: "FM fingerprint database",
    max_bytes: GIB,
};

/// Layout candidate files (CSV, one site a line): 64 MiB is about a million sites, far
/// beyond what the placement search can consider.
pub const CANDIDATES: Limit = Limit {
    what: "candidates file",
    max_bytes: 64 * MIB,
};

/// SigMF metadata (JSON): one annotation per frame, about 130 bytes each, so the longest
/// recording `dtmb iq` writes (10⁶ frames) has ≈ 130 MB; 256 MiB.
pub const SIGMF_META: Limit = Limit {
    what: "SigMF metadata file",
    max_bytes: 256 * MIB,
};

/// SigMF sample files, which hybridnav's own reader holds whole: 20 000 PN945 frames at
/// 4× oversampling in cf32 are 20 000 × 4 200 × 4 × 8 B ≈ 2.7 GB; 4 GiB. `dtmb iq`
/// streams recordings of up to 10⁶ frames; one larger than this cap is for other
/// receivers (GNU Radio, dtmb-sdr), not for reading back here.
pub const SIGMF_DATA: Limit = Limit {
    what: "SigMF data file",
    max_bytes: 4 * GIB,
};

/// Transport-stream payloads (`dtmb iq --payload`, a world transmitter's `payload`): read
/// in packets as the recording goes, never whole, so the cap only refuses what no
/// recording could use: 10⁶ frames (the recording limit) of the densest profile carry
/// ≈ 40 packets each, 7.5 GB; 64 GiB.
pub const TS_PAYLOAD: Limit = Limit {
    what: "transport-stream payload",
    max_bytes: 64 * GIB,
};

/// A run directory's manifest (`run.json`, < 1 kB).
pub const RUN_MANIFEST: Limit = Limit {
    what: "run manifest",
    max_bytes: MIB,
};

/// A stored trial (gzip'd JSON): a Beihang trial is 0.4 MB; the longest world allowed
/// (10 days at 100 Hz) would not fit, but neither would its trial in memory.
pub const TRIAL_FILE: Limit = Limit {
    what: "trial file",
    max_bytes: GIB,
};

/// What a path names, in words, for a refusal.
fn kind_of(t: fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a named pipe";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a directory"
    } else {
        "not a regular file"
    }
}

/// Opens `path` for reading after checking that it is a regular file of at most
/// `limit.max_bytes`; returns the file and its size.
///
/// # Errors
/// The OS error of the open, or `InvalidInput` ("is a named pipe; expected a regular
/// …"), or `FileTooLarge` naming the cap. The path is not in the message.
pub fn open(path: &Path, limit: Limit) -> io::Result<(fs::File, u64)> {
    let mut opts = fs::OpenOptions::new();
    opts.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        opts.custom_flags(libc::O_NONBLOCK);
    }
    let f = opts.open(path)?;
    let meta = f.metadata()?;
    if !meta.file_type().is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "is {}; expected a regular file (a {})",
                kind_of(meta.file_type()),
                limit.what
            ),
        ));
    }
    check_size(meta.len(), limit)?;
    Ok((f, meta.len()))
}

fn check_size(bytes: u64, limit: Limit) -> io::Result<()> {
    if bytes > limit.max_bytes {
        return Err(io::Error::new(
            io::ErrorKind::FileTooLarge,
            format!(
                "is {}, more than the {} a {} may have (the cap is documented in docs/reliability.md)",
                size_text(bytes),
                size_text(limit.max_bytes),
                limit.what
            ),
        ));
    }
    Ok(())
}

/// `bytes` as a short human figure ("22.5 GB", "256 MiB").
fn size_text(bytes: u64) -> String {
    if bytes >= GIB && bytes % GIB == 0 {
        format!("{} GiB", bytes / GIB)
    } else if bytes >= MIB && bytes % MIB == 0 {
        format!("{} MiB", bytes / MIB)
    } else if bytes >= 1_000_000 {
        format!("{:.1} MB ({bytes} bytes)", bytes as f64 / 1e6)
    } else {
        format!("{bytes} bytes")
    }
}

/// A streaming reader of `path` (checked as [`open`] does) that never yields more than
/// the cap: a file grown past it since the check reads as an error, not more data.
///
/// # Errors
/// As [`open`].
pub fn reader(path: &Path, limit: Limit) -> io::Result<BufReader<Capped>> {
    let (f, _) = open(path, limit)?;
    Ok(BufReader::with_capacity(
        1 << 16,
        Capped {
            inner: f,
            left: limit.max_bytes,
            limit,
        },
    ))
}

/// A file that errors instead of reading past its [`Limit`].
#[derive(Debug)]
pub struct Capped {
    inner: fs::File,
    left: u64,
    limit: Limit,
}

impl Read for Capped {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.left == 0 {
            // One byte more than the cap means the file grew past it.
            let mut one = [0u8; 1];
            return match self.inner.read(&mut one)? {
                0 => Ok(0),
                _ => Err(check_size(self.limit.max_bytes + 1, self.limit).unwrap_err()),
            };
        }
        let want = buf
            .len()
            .min(usize::try_from(self.left).unwrap_or(usize::MAX));
        let n = self.inner.read(&mut buf[..want])?;
        self.left -= n as u64;
        Ok(n)
    }
}

/// The whole of `path` (checked as [`open`] does).
///
/// # Errors
/// As [`open`], and the OS error of the read.
pub fn read_bytes(path: &Path, limit: Limit) -> io::Result<Vec<u8>> {
    let (f, size) = open(path, limit)?;
    let mut bytes = Vec::with_capacity(usize::try_from(size).unwrap_or(0));
    // `take(cap + 1)`: a file that grew since the check is read one byte past the cap
    // at most, and refused.
    f.take(limit.max_bytes + 1).read_to_end(&mut bytes)?;
    check_size(bytes.len() as u64, limit)?;
    Ok(bytes)
}

/// Why bytes are not the text a reader expects, and where (1-based line and column in
/// characters, counting LF as the line break).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NotText {
    pub line: usize,
    pub column: usize,
    /// Byte offset from the start of the file.
    pub offset: usize,
    pub message: String,
}

impl std::fmt::Display for NotText {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "line {}, column {} (byte offset {}): {}",
            self.line, self.column, self.offset, self.message
        )
    }
}

/// Line and column (1-based, columns in characters) of byte `offset` of `valid`, which
/// is valid UTF-8 up to `offset`.
fn position(valid: &[u8], offset: usize) -> (usize, usize) {
    let before = &valid[..offset];
    let line_start = before
        .iter()
        .rposition(|&b| b == b'\n')
        .map_or(0, |k| k + 1);
    let line = 1 + before.iter().filter(|&&b| b == b'\n').count();
    let column = 1 + String::from_utf8_lossy(&before[line_start..])
        .chars()
        .count();
    (line, column)
}

/// `bytes` as text with LF or CRLF line endings: refuses invalid UTF-8 and a carriage
/// return not followed by a line feed (classic Mac OS line endings, which TOML and the
/// line-oriented readers would otherwise see as one long line), naming the first offending
/// byte's line and column.
///
/// # Errors
/// [`NotText`] at the first offending byte.
pub fn text_of(bytes: Vec<u8>) -> Result<String, NotText> {
    let text = match String::from_utf8(bytes) {
        Ok(t) => t,
        Err(e) => {
            let offset = e.utf8_error().valid_up_to();
            let bytes = e.into_bytes();
            let (line, column) = position(&bytes, offset);
            return Err(NotText {
                line,
                column,
                offset,
                message: format!(
                    "not UTF-8 text (byte 0x{:02x}); save the file as UTF-8",
                    bytes[offset]
                ),
            });
        }
    };
    let b = text.as_bytes();
    if let Some(offset) = (0..b.len()).find(|&k| b[k] == b'\r' && b.get(k + 1) != Some(&b'\n')) {
        let (line, column) = position(b, offset);
        return Err(NotText {
            line,
            column,
            offset,
            message: "a carriage return without a line feed (classic Mac OS line endings); \
                      expected LF or CRLF line endings"
                .into(),
        });
    }
    Ok(text)
}

/// Why a text file could not be read: the file itself, or its content.
#[derive(Debug)]
pub enum TextError {
    Io(io::Error),
    NotText(NotText),
}

impl std::fmt::Display for TextError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TextError::Io(e) => e.fmt(f),
            TextError::NotText(e) => e.fmt(f),
        }
    }
}

impl std::error::Error for TextError {}

/// The whole of `path` as text (checked as [`open`] and [`text_of`] do).
///
/// # Errors
/// [`TextError::Io`] as [`read_bytes`]; [`TextError::NotText`] with the position.
pub fn read_text(path: &Path, limit: Limit) -> Result<String, TextError> {
    text_of(read_bytes(path, limit).map_err(TextError::Io)?).map_err(TextError::NotText)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("hybridnav-read-{}-{name}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        fs::create_dir_all(&d).unwrap();
        d
    }

    const SMALL: Limit = Limit {
        what: "test file",
        max_bytes: 10,
    };

    #[test]
    fn regular_files_within_the_cap_are_read_and_others_refused() {
        let d = tmp("cap");
        fs::write(d.join("ok"), b"0123456789").unwrap();
        assert_eq!(read_bytes(&d.join("ok"), SMALL).unwrap(), b"0123456789");
        fs::write(d.join("big"), b"0123456789A").unwrap();
        let e = read_bytes(&d.join("big"), SMALL).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::FileTooLarge);
        assert!(
            e.to_string()
                .contains("11 bytes, more than the 10 bytes a test file"),
            "{e}"
        );
        let e = read_bytes(&d, SMALL).unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
        if Path::new("/dev/zero").exists() {
            let e = read_bytes(Path::new("/dev/zero"), WORLD).unwrap_err();
            assert!(e.to_string().contains("is a character device"), "{e}");
        }
        // The streaming reader stops at the cap too.
        let mut s = String::new();
        reader(&d.join("ok"), SMALL)
            .unwrap()
            .read_to_string(&mut s)
            .unwrap();
        assert_eq!(s, "0123456789");
        let e = read_bytes(&d.join("missing"), SMALL).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::NotFound);
        // The message does not repeat the path (callers put it in front).
        assert!(!e.to_string().contains("missing"), "{e}");
        fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_file_growing_past_the_cap_while_read_is_refused() {
        // A `/proc` file reports size 0 and reads more: the read stops one byte past the
        // cap and refuses.
        let p = Path::new("/proc/self/maps");
        if p.exists() {
            let tiny = Limit {
                what: "test file",
                max_bytes: 16,
            };
            let e = read_bytes(p, tiny).unwrap_err();
            assert_eq!(e.kind(), io::ErrorKind::FileTooLarge, "{e}");
            let mut s = Vec::new();
            let e = reader(p, tiny).unwrap().read_to_end(&mut s).unwrap_err();
            assert_eq!(e.kind(), io::ErrorKind::FileTooLarge, "{e}");
        }
    }

    #[test]
    fn not_text_is_located() {
        let e = text_of(b"a = 1\nb = \"\xff\"\n".to_vec()).unwrap_err();
        assert_eq!((e.line, e.column, e.offset), (2, 6, 11));
        assert!(e.message.contains("0xff"), "{e}");
        // Multi-byte characters count as one column.
        let e = text_of("é = 1\rb = 2\r".as_bytes().to_vec()).unwrap_err();
        assert_eq!((e.line, e.column, e.offset), (1, 6, 6));
        assert!(e.message.contains("carriage return"), "{e}");
        assert_eq!(text_of(b"a\r\nb\n".to_vec()).unwrap(), "a\r\nb\n");
    }
}
