//! Names of the temporaries next to a target: `.<name>.plantc-<kind>-<pid>-<n>`
//! (a file's) or inside an output directory: `.plantc-<kind>-<pid>-<n>`, and
//! the cleanup of those a killed process left behind.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::Error;

/// What a temporary next to a target is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    /// A file being written by [`crate::AtomicFile`].
    Tmp,
    /// A directory being built by [`crate::FreshDir`].
    New,
    /// The previous directory, moved aside during a swap (left by plantc
    /// versions that swapped whole directories).
    Old,
    /// The journal of entries carried from the old directory into the new
    /// (left by plantc versions that swapped whole directories).
    Carried,
    /// The journal of an output directory's commit ([`crate::FreshDir`]).
    Commit,
}

impl Kind {
    fn tag(self) -> &'static str {
        match self {
            Kind::Tmp => "tmp",
            Kind::New => "new",
            Kind::Old => "old",
            Kind::Carried => "carried",
            Kind::Commit => "commit",
        }
    }

    fn from_tag(t: &str) -> Option<Kind> {
        Some(match t {
            "tmp" => Kind::Tmp,
            "new" => Kind::New,
            "old" => Kind::Old,
            "carried" => Kind::Carried,
            "commit" => Kind::Commit,
            _ => return None,
        })
    }
}

/// The parent directory and the file name of a target (`.` for a bare name).
pub(crate) fn split(path: &Path) -> Result<(PathBuf, OsString), Error> {
    let name = path.file_name().ok_or_else(|| Error::NoFileName {
        path: path.to_path_buf(),
    })?;
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    Ok((parent, name.to_os_string()))
}

/// The prefix shared by every temporary of the target named `name`
/// (long names are shortened so the temporary stays under name limits).
fn prefix(name: &OsString) -> String {
    let lossy = name.to_string_lossy();
    let short: String = lossy.chars().take(80).collect();
    format!(".{short}.plantc-")
}

/// A fresh, unique id: `<pid>-<n>`.
pub(crate) fn fresh_id() -> String {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    format!(
        "{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    )
}

/// A fresh, unique temporary name for the target named `name`.
pub(crate) fn temporary(name: &OsString, kind: Kind) -> (String, String) {
    let id = fresh_id();
    (format!("{}{}-{id}", prefix(name), kind.tag()), id)
}

/// The name of a temporary of `kind` inside an output directory.
pub(crate) fn inside_with_id(kind: Kind, id: &str) -> String {
    format!(".plantc-{}-{id}", kind.tag())
}

/// The name of a temporary of `kind` with a known id.
pub(crate) fn with_id(name: &OsString, kind: Kind, id: &str) -> String {
    format!("{}{}-{id}", prefix(name), kind.tag())
}

/// A temporary of the target found in its directory.
pub(crate) struct Leftover {
    pub kind: Kind,
    pub id: String,
    pub path: PathBuf,
}

/// Temporaries of the target `name` in `parent` whose process is gone.
pub(crate) fn leftovers(parent: &Path, name: &OsString) -> Vec<Leftover> {
    leftovers_with_prefix(parent, &prefix(name))
}

/// Temporaries inside the output directory `dir` whose process is gone.
pub(crate) fn leftovers_inside(dir: &Path) -> Vec<Leftover> {
    leftovers_with_prefix(dir, ".plantc-")
}

fn leftovers_with_prefix(parent: &Path, pre: &str) -> Vec<Leftover> {
    let Ok(entries) = std::fs::read_dir(parent) else {
        return Vec::new();
    };
    let mut found = Vec::new();
    for e in entries.flatten() {
        let file = e.file_name();
        let Some(rest) = file.to_str().and_then(|f| f.strip_prefix(pre)) else {
            continue;
        };
        let Some((tag, id)) = rest.split_once('-') else {
            continue;
        };
        let Some(kind) = Kind::from_tag(tag) else {
            continue;
        };
        let pid = id.split('-').next().and_then(|p| p.parse::<u32>().ok());
        match pid {
            Some(pid) if !process_alive(pid) => found.push(Leftover {
                kind,
                id: id.to_string(),
                path: e.path(),
            }),
            _ => {}
        }
    }
    found.sort_by(|a, b| a.id.cmp(&b.id));
    found
}

/// Whether the process `pid` may still be running (and so may still be
/// using its temporaries). Our own process counts as running. On Linux this
/// asks /proc; elsewhere every other process is assumed gone (plantc does not
/// support two processes writing the same output at once).
fn process_alive(pid: u32) -> bool {
    if pid == std::process::id() {
        return true;
    }
    if cfg!(target_os = "linux") {
        Path::new("/proc").join(pid.to_string()).exists()
    } else {
        false
    }
}
