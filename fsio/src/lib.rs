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
//! - [`FreshDir`] builds an output directory aside (a hidden sibling) and swaps
//!   it in when complete, so a killed run never leaves a directory that looks
//!   complete, and files of an earlier run never survive into the new one.
//! - [`probe_writable`] checks up front that a file can be created at a path,
//!   so a long computation does not end in "permission denied".
//!
//! Temporary names all start with `.<target name>.plantc-`; leftovers of a
//! killed process are cleaned by the next write to the same target.
//!
//! ```
//! let dir = std::env::temp_dir().join(format!("plantc-fsio-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! plantc_fsio::write_atomic(dir.join("model.plant"), b"model m\n")?;
//! let out = plantc_fsio::FreshDir::create(dir.join("out"))?;
//! plantc_fsio::write_atomic(out.path().join("report.json"), b"{}\n")?;
//! out.commit()?; // `out/` now holds exactly report.json
//! assert!(dir.join("out/report.json").exists());
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
pub use fresh_dir::FreshDir;
