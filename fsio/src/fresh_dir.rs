//! A fresh output directory: built aside, swapped in when complete.

use std::collections::BTreeSet;
use std::ffi::OsString;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::names::{self, Kind, Leftover};
use crate::sys::{exchange, sync_dir};
use crate::Error;

/// A new version of an output directory, written in a hidden sibling
/// (`.<name>.plantc-new-...`) and swapped in by [`FreshDir::commit`].
///
/// Until the swap the old directory is untouched, so a run killed at any
/// point leaves either the old complete directory or the new complete one
/// (never a mix, never an old `report.json` beside new figures), and files of
/// an earlier run never survive into the new one. On Linux the swap is one
/// `renameat2(RENAME_EXCHANGE)`; elsewhere two renames, and a run killed
/// between them is repaired by the next `FreshDir::create` of the same
/// target. Dropping an uncommitted `FreshDir` removes the staging directory.
#[derive(Debug)]
pub struct FreshDir {
    target: PathBuf,
    parent: PathBuf,
    name: OsString,
    id: String,
    staging: PathBuf,
    committed: bool,
}

fn write_err(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Write {
        path: path.to_path_buf(),
        source,
    }
}

fn replace_err(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Replace {
        path: path.to_path_buf(),
        source,
    }
}

/// Repairs what a killed run left next to `target`: a directory moved aside
/// but not replaced goes back; entries carried into an unfinished new
/// directory go back; unfinished new directories are removed.
fn recover(parent: &Path, name: &OsString, target: &Path) {
    let left = names::leftovers(parent, name);
    if left.is_empty() {
        return;
    }
    if !target.exists() {
        if let Some(old) = left.iter().find(|l| l.kind == Kind::Old) {
            let _ = fs::rename(&old.path, target);
        }
    }
    for j in left.iter().filter(|l| l.kind == Kind::Carried) {
        let staging = parent.join(names::with_id(name, Kind::New, &j.id));
        if let Ok(text) = fs::read_to_string(&j.path) {
            for entry in text.lines().filter(|l| !l.is_empty()) {
                let from = staging.join(entry);
                let to = target.join(entry);
                if from.symlink_metadata().is_ok() && to.symlink_metadata().is_err() {
                    let _ = fs::rename(&from, &to);
                }
            }
        }
        let _ = fs::remove_file(&j.path);
    }
    for l in &left {
        remove_any(l);
    }
}

fn remove_any(l: &Leftover) {
    match l.kind {
        Kind::Carried | Kind::Tmp => {
            let _ = fs::remove_file(&l.path);
        }
        Kind::New | Kind::Old => {
            if l.path.exists() {
                let _ = fs::remove_dir_all(&l.path);
            }
        }
    }
}

impl FreshDir {
    /// Starts a new version of the directory `target` (created with its
    /// parents if missing; an existing `target` must be a directory). Write
    /// everything into [`FreshDir::path`], then [`FreshDir::commit`].
    /// Refuses ([`Error::CurrentDirectory`]) a `target` that is the current
    /// directory or contains it.
    pub fn create(target: impl AsRef<Path>) -> Result<FreshDir, Error> {
        let given = target.as_ref().to_path_buf();
        let mut target = given.clone();
        if target.exists() {
            if !target.is_dir() {
                return Err(Error::WrongKind {
                    path: target,
                    expected: "a directory",
                });
            }
            // `.`, `..`, `out/.`: work on the real name
            let real = fs::canonicalize(&target).map_err(|source| Error::Read {
                path: given.clone(),
                source,
            })?;
            let cwd = std::env::current_dir().and_then(fs::canonicalize);
            if cwd.is_ok_and(|c| c.starts_with(&real)) {
                return Err(Error::CurrentDirectory { path: given });
            }
            if target.file_name().is_none() || target.ends_with(".") {
                target = real;
            }
        }
        let (parent, name) = names::split(&target)?;
        fs::create_dir_all(&parent).map_err(write_err(&target))?;
        recover(&parent, &name, &target);
        let (staging_name, id) = names::temporary(&name, Kind::New);
        let staging = parent.join(staging_name);
        fs::create_dir(&staging).map_err(write_err(&target))?;
        Ok(FreshDir {
            target,
            parent,
            name,
            id,
            staging,
            committed: false,
        })
    }

    /// Where to write the new contents.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// The directory this will replace.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Swaps the new directory in; the old one (if any) is removed.
    pub fn commit(self) -> Result<(), Error> {
        self.commit_keeping(|_| false)
    }

    /// Like [`FreshDir::commit`], but the top-level entries of the old
    /// directory for which `keep(name)` is true, and which the new directory
    /// lacks, are moved into the new one first (e.g. a generated crate's
    /// `target/` and `Cargo.lock`). A run killed while moving them leaves the
    /// old directory complete: the next `create` moves them back.
    pub fn commit_keeping(mut self, keep: impl Fn(&Path) -> bool) -> Result<(), Error> {
        sync_dir(&self.staging);
        if !self.target.exists() {
            fs::rename(&self.staging, &self.target).map_err(replace_err(&self.target))?;
            self.committed = true;
            sync_dir(&self.parent);
            return Ok(());
        }
        // carry the kept entries over, journaled so a kill can be undone
        let mut carried = BTreeSet::new();
        let journal = self
            .parent
            .join(names::with_id(&self.name, Kind::Carried, &self.id));
        let entries = fs::read_dir(&self.target).map_err(|source| Error::Read {
            path: self.target.clone(),
            source,
        })?;
        let mut kept: Vec<OsString> = entries
            .flatten()
            .map(|e| e.file_name())
            .filter(|n| keep(Path::new(n)) && !self.staging.join(n).exists())
            .collect();
        kept.sort();
        // (names that are not UTF-8 cannot be journaled: they stay behind)
        kept.retain(|n| n.to_str().is_some_and(|s| !s.contains('\n')));
        if !kept.is_empty() {
            // the journal first (one sync), then the moves: a kill at any
            // point is undone by `recover`
            let mut j = fs::File::create(&journal).map_err(write_err(&self.target))?;
            for n in &kept {
                writeln!(j, "{}", n.to_string_lossy()).map_err(write_err(&self.target))?;
            }
            j.sync_all().map_err(write_err(&self.target))?;
            for n in &kept {
                if let Err(e) = fs::rename(self.target.join(n), self.staging.join(n)) {
                    for c in &carried {
                        let _ = fs::rename(self.staging.join(c), self.target.join(c));
                    }
                    let _ = fs::remove_file(&journal);
                    return Err(Error::Replace {
                        path: self.target.clone(),
                        source: e,
                    });
                }
                carried.insert(n.clone());
            }
        }
        let result = self.swap(true);
        if result.is_err() {
            // put the carried entries back: the old directory stays complete
            for n in &carried {
                let _ = fs::rename(self.staging.join(n), self.target.join(n));
            }
        }
        let _ = fs::remove_file(&journal);
        result
    }

    /// The swap itself; afterwards `self.staging` holds the old directory.
    /// `try_exchange: false` forces the two-rename path (tested on Linux too).
    fn swap(&mut self, try_exchange: bool) -> Result<(), Error> {
        let swapped = try_exchange
            && exchange(&self.staging, &self.target).map_err(replace_err(&self.target))?;
        if !swapped {
            let old = self
                .parent
                .join(names::with_id(&self.name, Kind::Old, &self.id));
            fs::rename(&self.target, &old).map_err(replace_err(&self.target))?;
            if let Err(source) = fs::rename(&self.staging, &self.target) {
                let _ = fs::rename(&old, &self.target);
                return Err(Error::Replace {
                    path: self.target.clone(),
                    source,
                });
            }
            self.staging = old;
        }
        sync_dir(&self.parent);
        self.committed = true;
        let _ = fs::remove_dir_all(&self.staging);
        Ok(())
    }
}

impl Drop for FreshDir {
    fn drop(&mut self) {
        if !self.committed && self.staging.exists() {
            let _ = fs::remove_dir_all(&self.staging);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_rename_swap_replaces_and_cleans() {
        let d = std::env::temp_dir().join(format!("plantc-fsio-unit-{}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        let out = d.join("out");
        fs::create_dir_all(&out).unwrap();
        fs::write(out.join("stale.svg"), "old").unwrap();
        let mut fresh = FreshDir::create(&out).unwrap();
        fs::write(fresh.path().join("report.json"), "new").unwrap();
        fresh.swap(false).unwrap();
        drop(fresh);
        let names: Vec<_> = fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["report.json"]);
        assert_eq!(fs::read_dir(&d).unwrap().count(), 1, "only `out` left");
        fs::remove_dir_all(&d).unwrap();
    }
}
