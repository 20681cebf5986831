//! The few operating-system calls std does not offer: syncing a directory
//! and exchanging two directories atomically.

use std::io;
use std::path::Path;

/// Flushes a directory's entries (a rename in it) to disk. Best effort:
/// some file systems refuse to sync a directory, which is not an error.
pub(crate) fn sync_dir(dir: &Path) {
    #[cfg(unix)]
    {
        if let Ok(f) = std::fs::File::open(dir) {
            let _ = f.sync_all();
        }
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
    }
}

/// Atomically exchanges `a` and `b` (both must exist). `Ok(false)` when the
/// platform or file system cannot (the caller then renames in two steps).
pub(crate) fn exchange(a: &Path, b: &Path) -> io::Result<bool> {
    imp::exchange(a, b)
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
mod imp {
    use std::ffi::{c_char, c_int, c_uint, CString};
    use std::io;
    use std::os::unix::ffi::OsStrExt;
    use std::path::Path;

    const AT_FDCWD: c_int = -100;
    const RENAME_EXCHANGE: c_uint = 2;
    const EINVAL: i32 = 22;
    const ENOSYS: i32 = 38;
    const EOPNOTSUPP: i32 = 95;

    extern "C" {
        // glibc >= 2.28
        fn renameat2(
            olddirfd: c_int,
            oldpath: *const c_char,
            newdirfd: c_int,
            newpath: *const c_char,
            flags: c_uint,
        ) -> c_int;
    }

    pub fn exchange(a: &Path, b: &Path) -> io::Result<bool> {
        let ca = CString::new(a.as_os_str().as_bytes())?;
        let cb = CString::new(b.as_os_str().as_bytes())?;
        // SAFETY: both pointers are valid NUL-terminated strings for the call.
        let r = unsafe {
            renameat2(
                AT_FDCWD,
                ca.as_ptr(),
                AT_FDCWD,
                cb.as_ptr(),
                RENAME_EXCHANGE,
            )
        };
        if r == 0 {
            return Ok(true);
        }
        let e = io::Error::last_os_error();
        match e.raw_os_error() {
            Some(EINVAL | ENOSYS | EOPNOTSUPP) => Ok(false),
            _ => Err(e),
        }
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
mod imp {
    use std::io;
    use std::path::Path;

    pub fn exchange(_a: &Path, _b: &Path) -> io::Result<bool> {
        Ok(false)
    }
}
