//! The error of every fsio operation: what was being done, to which path.

use std::fmt;
use std::io;
use std::path::PathBuf;

/// Why a crash-safe write failed. `Display` reads `cannot <what> `<path>`:
/// <OS message>`; the target (old file or directory) is unchanged whenever
/// an error is returned.
#[derive(Debug)]
pub enum Error {
    /// The path names no file (`/`, `..`, empty).
    NoFileName {
        /// The path as given.
        path: PathBuf,
    },
    /// A file was expected but the path is a directory, or the reverse.
    WrongKind {
        /// The path.
        path: PathBuf,
        /// What was expected: "a file" or "a directory".
        expected: &'static str,
    },
    /// The output path is a symbolic link: plantc writes output directories
    /// only at their real path (the output would go elsewhere than named).
    SymbolicLink {
        /// The link.
        path: PathBuf,
        /// Where it points.
        to: PathBuf,
    },
    /// The file is read-only: plantc does not replace (or delete) a file the
    /// user made read-only.
    ReadOnly {
        /// The file.
        path: PathBuf,
    },
    /// A file plantc did not write (not in its manifest) is where a new
    /// output file goes; replacing it needs the command's `--force`.
    WouldReplace {
        /// The file.
        path: PathBuf,
    },
    /// Creating, writing or syncing the temporary file or directory failed.
    Write {
        /// The target the temporary belongs to.
        path: PathBuf,
        /// The operating system's error.
        source: io::Error,
    },
    /// Moving the finished file or directory into place failed.
    Replace {
        /// The target.
        path: PathBuf,
        /// The operating system's error.
        source: io::Error,
    },
    /// Reading the existing target (to compare it, or to follow a link) failed.
    Read {
        /// The path.
        path: PathBuf,
        /// The operating system's error.
        source: io::Error,
    },
}

impl Error {
    /// The path the error is about.
    pub fn path(&self) -> &std::path::Path {
        match self {
            Error::NoFileName { path }
            | Error::WrongKind { path, .. }
            | Error::SymbolicLink { path, .. }
            | Error::ReadOnly { path }
            | Error::WouldReplace { path }
            | Error::Write { path, .. }
            | Error::Replace { path, .. }
            | Error::Read { path, .. } => path,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::NoFileName { path } => {
                write!(f, "cannot write `{}`: not a file name", path.display())
            }
            Error::WrongKind { path, expected } => {
                write!(f, "cannot write `{}`: expected {expected}", path.display())
            }
            Error::SymbolicLink { path, to } => write!(
                f,
                "cannot write into `{}`: it is a symbolic link (to `{}`); plantc writes an output \
                 directory only at its real path: name `{}` itself, or remove the link",
                path.display(),
                to.display(),
                to.display()
            ),
            Error::ReadOnly { path } => write!(
                f,
                "cannot replace `{}`: the file is read-only; plantc does not replace a read-only \
                 file (make it writable first, e.g. `chmod u+w`)",
                path.display()
            ),
            Error::WouldReplace { path } => write!(
                f,
                "cannot replace `{}`: plantc did not write it (it is not in the directory's \
                 manifest); move it away, or pass --force to replace it",
                path.display()
            ),
            Error::Write { path, source } => {
                write!(f, "cannot write `{}`: {source}", path.display())
            }
            Error::Replace { path, source } => {
                write!(f, "cannot replace `{}`: {source}", path.display())
            }
            Error::Read { path, source } => {
                write!(f, "cannot read `{}`: {source}", path.display())
            }
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Write { source, .. }
            | Error::Replace { source, .. }
            | Error::Read { source, .. } => Some(source),
            _ => None,
        }
    }
}

impl From<Error> for io::Error {
    fn from(e: Error) -> io::Error {
        let kind = match &e {
            Error::Write { source, .. }
            | Error::Replace { source, .. }
            | Error::Read { source, .. } => source.kind(),
            _ => io::ErrorKind::InvalidInput,
        };
        io::Error::new(kind, e.to_string())
    }
}
