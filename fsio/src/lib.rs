//! plantc-fsio: crash-safe file output, shared by every plantc crate.
//!
//! Nothing the user has is lost, and nothing half-written is left behind:
//!
//! - [`write_atomic`] (and the streaming [`AtomicFile`]) writes a temporary
//!   file in the target's directory, flushes it to disk (`fsync`) and renames
//!   it over the target. A reader, a crash or a `kill -9` at any moment sees
//!   either the old complete file or the new complete one, never a truncated
//!   file. [`write_if_changed`] does the same but leaves an identical file (and
//!   its modification time) alone.
//! - [`FreshDir`] builds the files of an output directory aside (a hidden
//!   staging directory inside it) and moves them in when complete; it
//!   replaces or deletes only files listed in the manifest plantc wrote
//!   there, so the user's files in the directory never move, and stale files
//!   of an earlier run never survive into the new one.
//! - [`probe_writable`] checks up front that a file can be created at a path,
//!   so a long computation does not end in "permission denied".
//!
//! Temporary names all start with `.<target name>.plantc-` (next to a file)
//! or `.plantc-` (inside an output directory); leftovers of a killed process
//! are cleaned (or, for a journaled commit, finished) by the next write to
//! the same target. A read-only file is never replaced ([`Error::ReadOnly`]).
//!
//! ```
//! let dir = std::env::temp_dir().join(format!("plantc-fsio-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! plantc_fsio::write_atomic(dir.join("model.plant"), b"model m\n")?;
//! let out = plantc_fsio::FreshDir::create(dir.join("out"), "identify")?;
//! plantc_fsio::write_atomic(out.path().join("report.json"), b"{}\n")?;
//! out.commit()?; // `out/` holds report.json and the manifest listing it
//! assert!(dir.join("out/report.json").exists());
//! let listed = plantc_fsio::manifest(&dir.join("out"), "identify").unwrap();
//! assert!(listed.contains(std::path::Path::new("report.json")));
//! # std::fs::remove_dir_all(&dir)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod atomic_file;
mod error;
mod fresh_dir;
mod names;
mod sys;

pub use atomic_file::{probe_writable, write_atomic, write_if_changed, AtomicFile};
pub use error::Error;
pub use fresh_dir::{finish_interrupted, manifest, FreshDir};
