//! Replacing one file atomically: write a temporary next to it, sync, rename.

use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::names::{self, Kind};
use crate::sys::sync_dir;
use crate::Error;

/// A file being written aside; [`AtomicFile::commit`] puts it in place.
///
/// Until `commit` returns, the target is untouched (a previous version stays
/// complete); dropping an uncommitted `AtomicFile` removes the temporary. It
/// buffers, so many small writes (a CSV row at a time) are cheap.
#[derive(Debug)]
pub struct AtomicFile {
    target: PathBuf,
    tmp: PathBuf,
    file: Option<BufWriter<File>>,
}

/// Follows symbolic links, so that writing through a link replaces the file
/// it points to (and keeps the link).
fn resolve(path: &Path) -> Result<PathBuf, Error> {
    let mut p = path.to_path_buf();
    for _ in 0..40 {
        match fs::symlink_metadata(&p) {
            Ok(m) if m.file_type().is_symlink() => {
                let link = fs::read_link(&p).map_err(|source| Error::Read {
                    path: p.clone(),
                    source,
                })?;
                p = match p.parent() {
                    Some(parent) if link.is_relative() => parent.join(link),
                    _ => link,
                };
            }
            _ => return Ok(p),
        }
    }
    Err(Error::Read {
        path: path.to_path_buf(),
        source: io::Error::other("too many levels of symbolic links"),
    })
}

/// Removes temporary files a killed process left next to `name` in `parent`.
fn clean_leftovers(parent: &Path, name: &std::ffi::OsString) {
    for l in names::leftovers(parent, name) {
        if l.kind == Kind::Tmp {
            let _ = fs::remove_file(&l.path);
        }
    }
}

impl AtomicFile {
    /// Starts replacing (or creating) the file at `path`. The directory must
    /// exist; `path` must not be a directory nor a read-only file
    /// ([`Error::ReadOnly`]: a rename would replace it, permissions
    /// notwithstanding). A symbolic link is followed: the file it points to
    /// is replaced.
    pub fn create(path: impl AsRef<Path>) -> Result<AtomicFile, Error> {
        let target = resolve(path.as_ref())?;
        if target.is_dir() {
            return Err(Error::WrongKind {
                path: path.as_ref().to_path_buf(),
                expected: "a file",
            });
        }
        if fs::metadata(&target).is_ok_and(|m| m.permissions().readonly()) {
            return Err(Error::ReadOnly { path: target });
        }
        let (parent, name) = names::split(&target)?;
        clean_leftovers(&parent, &name);
        let (tmp_name, _) = names::temporary(&name, Kind::Tmp);
        let tmp = parent.join(tmp_name);
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(|source| Error::Write {
                path: path.as_ref().to_path_buf(),
                source,
            })?;
        // an existing file keeps its permissions
        if let Ok(m) = fs::metadata(&target) {
            let _ = file.set_permissions(m.permissions());
        }
        Ok(AtomicFile {
            target,
            tmp,
            file: Some(BufWriter::with_capacity(1 << 16, file)),
        })
    }

    /// The file this will replace (after following links).
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Flushes and syncs the temporary, renames it over the target and syncs
    /// the directory. On error the target is unchanged and the temporary is
    /// removed.
    pub fn commit(mut self) -> Result<(), Error> {
        let w = self.file.take().expect("AtomicFile used after commit");
        let write_err = |source| Error::Write {
            path: self.target.clone(),
            source,
        };
        let file = w.into_inner().map_err(|e| write_err(e.into_error()))?;
        file.sync_all().map_err(write_err)?;
        drop(file);
        fs::rename(&self.tmp, &self.target).map_err(|source| Error::Replace {
            path: self.target.clone(),
            source,
        })?;
        let (parent, _) = names::split(&self.target)?;
        sync_dir(&parent);
        Ok(())
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.file
            .as_mut()
            .ok_or_else(|| io::Error::other("AtomicFile already committed"))?
            .write(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        match self.file.as_mut() {
            Some(f) => f.flush(),
            None => Ok(()),
        }
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.file.take().is_some() {
            let _ = fs::remove_file(&self.tmp);
        }
    }
}

/// Replaces (or creates) the file at `path` with `bytes` atomically: a
/// reader or a crash sees the old complete file or the new complete one.
pub fn write_atomic(path: impl AsRef<Path>, bytes: impl AsRef<[u8]>) -> Result<(), Error> {
    let mut f = AtomicFile::create(path.as_ref())?;
    f.write_all(bytes.as_ref()).map_err(|source| Error::Write {
        path: path.as_ref().to_path_buf(),
        source,
    })?;
    f.commit()
}

/// Like [`write_atomic`], but leaves the file (and its modification time)
/// alone when it already holds exactly `bytes`. Returns whether it wrote.
pub fn write_if_changed(path: impl AsRef<Path>, bytes: impl AsRef<[u8]>) -> Result<bool, Error> {
    let path = path.as_ref();
    match fs::read(path) {
        Ok(old) if old == bytes.as_ref() => return Ok(false),
        _ => {}
    }
    write_atomic(path, bytes)?;
    Ok(true)
}

/// Checks that a file could be written at `path` (its directory exists and
/// accepts a new file; `path` is not a directory), by creating and removing
/// a temporary next to it. Nothing at `path` is touched. Call it before a long
/// computation whose result goes there.
pub fn probe_writable(path: impl AsRef<Path>) -> Result<(), Error> {
    let f = AtomicFile::create(path.as_ref())?;
    drop(f);
    Ok(())
}
