//! Advisory whole-file locks (`flock(2)`), which the kernel releases when the process
//! ends, however it ends — so a killed process never leaves a stale lock behind.

use std::fs::File;
use std::io;

/// Tries to lock `f`, exclusively or shared, without waiting: `Ok(true)` when taken,
/// `Ok(false)` when another open file description holds a conflicting lock. Where
/// `flock` does not exist (not Unix), the lock is always "taken".
///
/// # Errors
/// OS errors other than "would block".
// The crate denies unsafe code; this one call is the system call itself (std's
// `File::try_lock` would do, but needs Rust 1.89, above the workspace's MSRV).
#[allow(unsafe_code)]
pub fn try_lock(f: &File, exclusive: bool) -> io::Result<bool> {
    #[cfg(unix)]
    {
        use std::os::unix::io::AsRawFd;
        let op = if exclusive {
            libc::LOCK_EX
        } else {
            libc::LOCK_SH
        } | libc::LOCK_NB;
        // SAFETY: `flock` only reads the descriptor, which `f` keeps open for the call.
        if unsafe { libc::flock(f.as_raw_fd(), op) } == 0 {
            return Ok(true);
        }
        let e = io::Error::last_os_error();
        if e.kind() == io::ErrorKind::WouldBlock {
            Ok(false)
        } else {
            Err(e)
        }
    }
    #[cfg(not(unix))]
    {
        let _ = (f, exclusive);
        Ok(true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_exclusive_lock_is_refused_until_the_first_is_dropped() {
        let p = std::env::temp_dir().join(format!("hybridnav-lock-{}", std::process::id()));
        let open = || {
            std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&p)
                .unwrap()
        };
        let a = open();
        assert!(try_lock(&a, true).unwrap());
        let b = open();
        if cfg!(unix) {
            assert!(!try_lock(&b, true).unwrap());
            assert!(!try_lock(&b, false).unwrap());
        }
        drop(a);
        assert!(try_lock(&b, false).unwrap());
        let c = open();
        assert!(try_lock(&c, false).unwrap(), "shared locks coexist");
        std::fs::remove_file(&p).unwrap();
    }
}
