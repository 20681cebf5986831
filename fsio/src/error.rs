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
    /// A fresh directory cannot replace the current directory (or one of its
    /// ancestors): the process (and the user's shell) would be left in a
    /// removed directory.
    CurrentDirectory {
        /// The directory.
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
            | Error::CurrentDirectory { path }
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
            Error::CurrentDirectory { path } => write!(
                f,
                "cannot replace `{}`: it is the current directory (or contains it); choose a subdirectory",
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
