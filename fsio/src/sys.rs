//! The operating-system call std does not offer: syncing a directory.

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
