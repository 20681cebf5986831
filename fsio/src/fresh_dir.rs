//! An output directory whose files plantc owns by a manifest: built aside,
//! moved in file by file when complete; the user's files never move.

use std::collections::BTreeSet;
use std::fs;
use std::io::Write;
use std::path::{Component, Path, PathBuf};

use crate::names::{self, Kind};
use crate::sys::sync_dir;
use crate::{write_atomic, Error};

/// Prefix of the manifest files: `.plantc-manifest-<owner>`.
const MANIFEST_PREFIX: &str = ".plantc-manifest-";

/// A new version of the files one command (the *owner*: `gen`, `identify`,
/// `synth`) writes into an output directory.
///
/// The rule: plantc replaces or deletes only files listed in the owner's
/// manifest (`DIR/.plantc-manifest-<owner>`, written by plantc itself at
/// each commit); every other entry of the directory (the user's files,
/// another command's) stays where it is, untouched, at every moment: it is
/// never moved, renamed or copied. A file of someone else's at a path the
/// new version writes is refused ([`Error::WouldReplace`]) unless
/// [`FreshDir::replace_unlisted`] was given (a command's `--force`).
///
/// The new files are written into a hidden staging directory inside the
/// target (`DIR/.plantc-new-<pid>-<n>/`; next to it, `.DIR.plantc-new-...`,
/// when `DIR` does not exist yet: it then appears whole at the commit, by one
/// rename); [`FreshDir::commit`] journals the
/// commit (`DIR/.plantc-commit-<pid>-<n>`, synced), renames each new file
/// over its place (one atomic rename per file; a file whose bytes did not
/// change is left alone, with its modification time), deletes the stale
/// files of the owner's previous version, writes the manifest and removes
/// the journal. A run killed before the commit leaves the previous version
/// as it was (the next run removes the staging directory); one killed during
/// the commit leaves each file old or new, and the next `FreshDir::create`
/// of the same directory finishes that commit from its journal before
/// anything else. Dropping an uncommitted `FreshDir` removes the staging
/// directory.
///
/// Refused: a target that is a symbolic link ([`Error::SymbolicLink`]: the
/// output would go somewhere else than named), a target that is a file, and
/// replacing or deleting a read-only file ([`Error::ReadOnly`]).
#[derive(Debug)]
pub struct FreshDir {
    target: PathBuf,
    owner: String,
    id: String,
    staging: PathBuf,
    replace_unlisted: bool,
    delete_stale: bool,
    adopted: Vec<PathBuf>,
    committed: bool,
}

fn write_err(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Write {
        path: path.to_path_buf(),
        source,
    }
}

fn read_err(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Read {
        path: path.to_path_buf(),
        source,
    }
}

/// The manifest of `owner` in `dir`: the files (relative paths) it lists,
/// or `None` when there is none.
pub fn manifest(dir: &Path, owner: &str) -> Option<BTreeSet<PathBuf>> {
    let text = fs::read_to_string(dir.join(format!("{MANIFEST_PREFIX}{owner}"))).ok()?;
    Some(
        text.lines()
            .filter(|l| !l.is_empty() && !l.starts_with('#'))
            .map(PathBuf::from)
            .filter(|p| is_plain_relative(p))
            .collect(),
    )
}

/// A relative path with only normal components (no `..`, no root): the only
/// kind a manifest may name, so a edited manifest cannot reach outside.
fn is_plain_relative(p: &Path) -> bool {
    p.components().count() > 0 && p.components().all(|c| matches!(c, Component::Normal(_)))
}

fn manifest_text(owner: &str, files: &BTreeSet<PathBuf>) -> String {
    let mut t = format!(
        "# plantc output manifest of `plantc {owner}`: the files it wrote here. plantc replaces \
         or deletes only the files listed here; everything else in this directory is left alone.\n"
    );
    for f in files {
        t.push_str(&f.to_string_lossy().replace('\\', "/"));
        t.push('\n');
    }
    t
}

/// The files below `dir` (relative), recursively, sorted.
fn files_below(dir: &Path) -> Result<BTreeSet<PathBuf>, Error> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeSet<PathBuf>) -> Result<(), Error> {
        for e in fs::read_dir(dir).map_err(read_err(dir))? {
            let e = e.map_err(read_err(dir))?;
            let p = e.path();
            let t = e.file_type().map_err(read_err(&p))?;
            if t.is_dir() {
                walk(root, &p, out)?;
            } else {
                out.insert(p.strip_prefix(root).unwrap_or(&p).to_path_buf());
            }
        }
        Ok(())
    }
    let mut out = BTreeSet::new();
    walk(dir, dir, &mut out)?;
    Ok(out)
}

fn same_bytes(a: &Path, b: &Path) -> bool {
    match (fs::symlink_metadata(a), fs::symlink_metadata(b)) {
        (Ok(ma), Ok(mb)) if ma.is_file() && mb.is_file() && ma.len() == mb.len() => {
            matches!((fs::read(a), fs::read(b)), (Ok(x), Ok(y)) if x == y)
        }
        _ => false,
    }
}

/// Removes the now empty directories from `rel`'s parent up to (not
/// including) `root`.
fn remove_empty_parents(root: &Path, rel: &Path) {
    let mut p = rel.parent();
    while let Some(d) = p.filter(|d| !d.as_os_str().is_empty()) {
        if fs::remove_dir(root.join(d)).is_err() {
            break;
        }
        p = d.parent();
    }
}

/// The journal of a commit: every new file, every file to delete, the
/// manifest's final list.
struct Journal {
    owner: String,
    new: Vec<PathBuf>,
    delete: Vec<PathBuf>,
    listed: BTreeSet<PathBuf>,
}

impl Journal {
    fn text(&self) -> String {
        let mut t = format!("owner {}\n", self.owner);
        let line = |t: &mut String, tag: &str, p: &Path| {
            t.push_str(tag);
            t.push_str(&p.to_string_lossy());
            t.push('\n');
        };
        for p in &self.new {
            line(&mut t, "+ ", p);
        }
        for p in &self.delete {
            line(&mut t, "- ", p);
        }
        for p in &self.listed {
            line(&mut t, "= ", p);
        }
        t
    }

    fn parse(text: &str) -> Option<Journal> {
        let mut lines = text.lines();
        let owner = lines.next()?.strip_prefix("owner ")?.to_string();
        let mut j = Journal {
            owner,
            new: Vec::new(),
            delete: Vec::new(),
            listed: BTreeSet::new(),
        };
        for l in lines {
            let (tag, p) = l.split_at_checked(2)?;
            let p = PathBuf::from(p);
            if !is_plain_relative(&p) {
                return None;
            }
            match tag {
                "+ " => j.new.push(p),
                "- " => j.delete.push(p),
                "= " => {
                    j.listed.insert(p);
                }
                _ => return None,
            }
        }
        Some(j)
    }

    /// Carries the commit out (idempotent: a rerun after a kill finishes it).
    fn apply(&self, target: &Path, staging: &Path) -> Result<(), Error> {
        for n in &self.new {
            let from = staging.join(n);
            if fs::symlink_metadata(&from).is_err() {
                continue; // moved (or left as it was) already
            }
            let to = target.join(n);
            if same_bytes(&from, &to) {
                let _ = fs::remove_file(&from);
                continue;
            }
            if let Some(parent) = to.parent() {
                fs::create_dir_all(parent).map_err(write_err(&to))?;
            }
            fs::rename(&from, &to).map_err(|source| Error::Replace { path: to, source })?;
        }
        for d in &self.delete {
            match fs::remove_file(target.join(d)) {
                Ok(()) => remove_empty_parents(target, d),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(source) => {
                    return Err(Error::Replace {
                        path: target.join(d),
                        source,
                    })
                }
            }
        }
        write_atomic(
            target.join(format!("{MANIFEST_PREFIX}{}", self.owner)),
            manifest_text(&self.owner, &self.listed),
        )?;
        sync_dir(target);
        Ok(())
    }
}

/// Finishes the commits a killed process left in `target` (from their
/// journals) and removes its staging directories.
fn recover(target: &Path) {
    for l in names::leftovers_inside(target) {
        if l.kind != Kind::Commit {
            continue;
        }
        let staging = target.join(names::inside_with_id(Kind::New, &l.id));
        if let Some(j) = fs::read_to_string(&l.path)
            .ok()
            .and_then(|t| Journal::parse(&t))
        {
            if j.apply(target, &staging).is_err() {
                // leave the journal for a later run rather than lose it
                continue;
            }
        }
        let _ = fs::remove_file(&l.path);
    }
    for l in names::leftovers_inside(target) {
        if l.kind == Kind::New {
            let _ = fs::remove_dir_all(&l.path);
        }
    }
}

/// Finishes what killed runs left in the directory `target`, as
/// [`FreshDir::create`] does first: their journaled commits are carried out
/// (each file new, the manifest written), their staging directories removed.
/// Nothing for a path that is not a directory (a symbolic link included).
/// A command that decides from a directory's contents whether it may write
/// there (is it plantc's output? is it empty?) calls this before looking, so
/// a run killed half-way through its commit does not make the next run
/// refuse its own output.
pub fn finish_interrupted(target: &Path) {
    if let Ok(m) = fs::symlink_metadata(target) {
        if m.file_type().is_symlink() || !m.is_dir() {
            return;
        }
    }
    recover_swapped(target);
    if fs::symlink_metadata(target).is_ok() {
        recover(target);
    }
}

/// Repairs what a killed run of an earlier plantc (which swapped whole
/// directories) left next to `target`: a directory moved aside but not
/// replaced goes back; the user's entries it had carried into its unfinished
/// new directory go back; its unfinished new directories are removed.
fn recover_swapped(target: &Path) {
    let Ok((parent, name)) = names::split(target) else {
        return;
    };
    let left = names::leftovers(&parent, &name);
    if left.is_empty() {
        return;
    }
    if fs::symlink_metadata(target).is_err() {
        if let Some(old) = left.iter().find(|l| l.kind == Kind::Old) {
            let _ = fs::rename(&old.path, target);
        }
    }
    for j in left.iter().filter(|l| l.kind == Kind::Carried) {
        let staging = parent.join(names::with_id(&name, Kind::New, &j.id));
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
        match l.kind {
            Kind::Carried | Kind::Tmp => {
                let _ = fs::remove_file(&l.path);
            }
            Kind::New | Kind::Old => {
                // only what the old swap left: its carried entries went back above
                let _ = fs::remove_dir_all(&l.path);
            }
            Kind::Commit => {}
        }
    }
}

impl FreshDir {
    /// Starts a new version of `owner`'s files in the directory `target`
    /// (created with its parents if missing). Write the files under
    /// [`FreshDir::path`] (subdirectories allowed), then
    /// [`FreshDir::commit`]. Refuses a `target` that is a symbolic link or a
    /// file. First finishes a commit a killed run left in `target`.
    pub fn create(target: impl AsRef<Path>, owner: &str) -> Result<FreshDir, Error> {
        let target = target.as_ref().to_path_buf();
        if let Ok(m) = fs::symlink_metadata(&target) {
            if m.file_type().is_symlink() {
                return Err(Error::SymbolicLink {
                    to: fs::read_link(&target).unwrap_or_default(),
                    path: target,
                });
            }
            if !m.is_dir() {
                return Err(Error::WrongKind {
                    path: target,
                    expected: "a directory",
                });
            }
        }
        recover_swapped(&target);
        let id = names::fresh_id();
        let staging = if fs::symlink_metadata(&target).is_ok() {
            recover(&target);
            target.join(names::inside_with_id(Kind::New, &id))
        } else {
            // a new directory appears only at the commit, whole: staged
            // next to it (`.<name>.plantc-new-...`)
            let (parent, name) = names::split(&target)?;
            fs::create_dir_all(&parent).map_err(write_err(&target))?;
            parent.join(names::with_id(&name, Kind::New, &id))
        };
        fs::create_dir(&staging).map_err(write_err(&target))?;
        Ok(FreshDir {
            target,
            owner: owner.to_string(),
            id,
            staging,
            replace_unlisted: false,
            delete_stale: true,
            adopted: Vec::new(),
            committed: false,
        })
    }

    /// Where to write the new files.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// The directory the files go to.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Allows the commit to replace files at the new version's paths that
    /// the owner's manifest does not list (someone else's): a command's
    /// `--force`. Nothing else of theirs is touched either way.
    pub fn replace_unlisted(mut self, yes: bool) -> Self {
        self.replace_unlisted = yes;
        self
    }

    /// Keeps the owner's earlier files that the new version does not write
    /// (they stay listed) instead of deleting them.
    pub fn keep_earlier_files(mut self) -> Self {
        self.delete_stale = false;
        self
    }

    /// Declares `rel` (relative to the target) a file of the owner's when the
    /// directory has no manifest of the owner yet: the output of a plantc
    /// from before manifests, recognised by the caller (e.g. by its
    /// `@generated` header). Ignored once a manifest exists.
    pub fn adopt(mut self, rel: impl Into<PathBuf>) -> Self {
        self.adopted.push(rel.into());
        self
    }

    /// Moves the new files in and deletes the owner's stale ones (see the
    /// type's documentation). On an error before the first rename nothing
    /// in the target changed.
    pub fn commit(mut self) -> Result<(), Error> {
        let new = files_below(&self.staging)?;
        let inside = self.target.join(names::inside_with_id(Kind::New, &self.id));
        if self.staging != inside {
            // staged next to a directory that did not exist
            if fs::symlink_metadata(&self.target).is_err() {
                let listed: BTreeSet<PathBuf> = new.clone();
                write_atomic(
                    self.staging
                        .join(format!("{MANIFEST_PREFIX}{}", self.owner)),
                    manifest_text(&self.owner, &listed),
                )?;
                sync_dir(&self.staging);
                fs::rename(&self.staging, &self.target).map_err(|source| Error::Replace {
                    path: self.target.clone(),
                    source,
                })?;
                self.committed = true;
                if let Ok((parent, _)) = names::split(&self.target) {
                    sync_dir(&parent);
                }
                return Ok(());
            }
            // it appeared meanwhile: stage inside it, as for an existing one
            fs::rename(&self.staging, &inside).map_err(write_err(&self.target))?;
            self.staging = inside;
        }
        for n in &new {
            if n.to_str().is_none_or(|s| s.contains('\n')) || !is_plain_relative(n) {
                return Err(Error::NoFileName {
                    path: self.target.join(n),
                });
            }
        }
        let listed_before = match manifest(&self.target, &self.owner) {
            Some(m) => m,
            None => self
                .adopted
                .iter()
                .filter(|p| is_plain_relative(p))
                .filter(|p| self.target.join(p).is_file())
                .cloned()
                .collect(),
        };
        // everything is checked before anything moves
        for n in &new {
            let to = self.target.join(n);
            let mut parent = n.parent();
            while let Some(d) = parent.filter(|d| !d.as_os_str().is_empty()) {
                let p = self.target.join(d);
                if fs::symlink_metadata(&p).is_ok_and(|m| !m.is_dir()) {
                    return Err(Error::WrongKind {
                        path: p,
                        expected: "a directory",
                    });
                }
                parent = d.parent();
            }
            let Ok(m) = fs::symlink_metadata(&to) else {
                continue;
            };
            if m.is_dir() {
                return Err(Error::WrongKind {
                    path: to,
                    expected: "a file",
                });
            }
            if same_bytes(&self.staging.join(n), &to) {
                continue;
            }
            if !listed_before.contains(n) && !self.replace_unlisted {
                return Err(Error::WouldReplace { path: to });
            }
            if m.permissions().readonly() {
                return Err(Error::ReadOnly { path: to });
            }
        }
        let delete: Vec<PathBuf> = if self.delete_stale {
            listed_before.difference(&new).cloned().collect()
        } else {
            Vec::new()
        };
        for d in &delete {
            let p = self.target.join(d);
            if fs::symlink_metadata(&p).is_ok_and(|m| m.permissions().readonly()) {
                return Err(Error::ReadOnly { path: p });
            }
        }
        let mut listed: BTreeSet<PathBuf> = new.clone();
        if !self.delete_stale {
            listed.extend(listed_before.iter().cloned());
        }
        let journal = Journal {
            owner: self.owner.clone(),
            new: new.into_iter().collect(),
            delete,
            listed,
        };
        sync_dir(&self.staging);
        let jpath = self
            .target
            .join(names::inside_with_id(Kind::Commit, &self.id));
        {
            let mut f = fs::File::create(&jpath).map_err(write_err(&jpath))?;
            f.write_all(journal.text().as_bytes())
                .and_then(|()| f.sync_all())
                .map_err(write_err(&jpath))?;
        }
        sync_dir(&self.target);
        // from here on a kill is finished by the next run's `recover`
        let applied = journal.apply(&self.target, &self.staging);
        if applied.is_ok() {
            let _ = fs::remove_file(&jpath);
            self.committed = true;
            let _ = fs::remove_dir_all(&self.staging);
        }
        // on an error the journal stays: the next run finishes the commit
        applied
    }
}

impl Drop for FreshDir {
    fn drop(&mut self) {
        let journaled = self
            .target
            .join(names::inside_with_id(Kind::Commit, &self.id))
            .exists();
        if !self.committed && !journaled && self.staging.exists() {
            let _ = fs::remove_dir_all(&self.staging);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn journals_round_trip_and_refuse_escaping_paths() {
        let j = Journal {
            owner: "gen".into(),
            new: vec!["src/lib.rs".into(), "Cargo.toml".into()],
            delete: vec!["src/main.rs".into()],
            listed: ["src/lib.rs".into(), "Cargo.toml".into()].into(),
        };
        let back = Journal::parse(&j.text()).unwrap();
        assert_eq!(back.owner, "gen");
        assert_eq!(back.new, j.new);
        assert_eq!(back.delete, j.delete);
        assert_eq!(back.listed, j.listed);
        assert!(Journal::parse("owner gen\n- ../../etc/passwd\n").is_none());
        assert!(Journal::parse("owner gen\n- /etc/passwd\n").is_none());
        assert!(!is_plain_relative(Path::new("a/../b")));
        assert!(is_plain_relative(Path::new("1-nominal/driven.svg")));
    }
}
