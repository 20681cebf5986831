//! CSV sample log written through a preallocated buffer.
//!
//! Rows are formatted into a buffer allocated up front and handed to the
//! underlying writer in whole rows, at least every 100 ms of loop time and at
//! exit. The file is written unbuffered (straight to the OS), so a killed
//! process leaves a file that parses, at most its last line cut.

use std::fmt;
use std::fs::File;
use std::io::{self, Write};
use std::path::Path;

/// Errors of the log writer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LogError {
    /// An I/O error.
    Io {
        /// The error kind.
        kind: io::ErrorKind,
        /// The error text.
        message: String,
    },
}

impl From<io::Error> for LogError {
    fn from(e: io::Error) -> Self {
        LogError::Io {
            kind: e.kind(),
            message: e.to_string(),
        }
    }
}

impl fmt::Display for LogError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LogError::Io { message, .. } => write!(f, "log I/O error: {message}"),
        }
    }
}

impl std::error::Error for LogError {}

/// Default buffer size (bytes); rows are flushed long before it fills.
pub const DEFAULT_BUFFER_BYTES: usize = 1 << 20;

/// The CSV log of a run: one row per sample, header
/// `t,<states>,<positions>_counts,<input>,<input>_cmd,state,overrun` and,
/// for a hybrid controller ([`LogWriter::with_mode_column`]), `,mode`.
pub struct LogWriter {
    out: Box<dyn Write + Send>,
    buf: Vec<u8>,
    flush_interval_s: f64,
    last_flush_t: f64,
    rows: u64,
    error: Option<LogError>,
    mode_column: bool,
    full_precision: bool,
}

impl LogWriter {
    /// Creates (truncates) a log file.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, LogError> {
        let f = File::create(path)?;
        Ok(Self::from_writer(Box::new(f)))
    }

    /// Creates a log file that must not exist yet (`O_EXCL`: of two runs
    /// started together with the same file, the second gets an
    /// [`io::ErrorKind::AlreadyExists`] error instead of writing into the
    /// first one's log).
    pub fn create_new(path: impl AsRef<Path>) -> Result<Self, LogError> {
        let f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(path)?;
        Ok(Self::from_writer(Box::new(f)))
    }

    /// [`LogWriter::create`] with `overwrite`, else [`LogWriter::create_new`].
    pub fn open(path: impl AsRef<Path>, overwrite: bool) -> Result<Self, LogError> {
        if overwrite {
            Self::create(path)
        } else {
            Self::create_new(path)
        }
    }

    /// A log writing to any writer (e.g. a `Vec<u8>` in tests).
    pub fn from_writer(out: Box<dyn Write + Send>) -> Self {
        Self {
            out,
            buf: Vec::with_capacity(DEFAULT_BUFFER_BYTES),
            flush_interval_s: 0.1,
            last_flush_t: 0.0,
            rows: 0,
            error: None,
            mode_column: false,
            full_precision: false,
        }
    }

    /// Adds a last column `mode` (a hybrid controller's mode name, see
    /// [`LogWriter::row_with_mode`]); call before [`LogWriter::begin`].
    pub fn with_mode_column(&mut self) {
        self.mode_column = true;
    }

    /// Sets the flush interval in loop time (default and maximum 0.1 s).
    pub fn set_flush_interval(&mut self, seconds: f64) {
        if seconds.is_finite() && seconds >= 0.0 {
            self.flush_interval_s = seconds.min(0.1);
        }
    }

    /// Writes every number with the shortest text that reads back to the
    /// same `f64` (e.g. `0.0012345678901234567`, `-3.1e-9`) instead of fixed
    /// decimals (6 for time and states, 4 for volts). For comparing runs
    /// bit for bit (`plantc run --compiled --compare`); the files are about
    /// twice as large. Default false.
    pub fn set_full_precision(&mut self, full: bool) {
        self.full_precision = full;
    }

    /// Writes the header. `n_counts` positions get a `<name>_counts` column.
    pub fn begin(
        &mut self,
        state_names: &[String],
        n_counts: usize,
        input_names: &[String],
    ) -> Result<(), LogError> {
        let mut h = String::from("t");
        for s in state_names {
            h.push(',');
            h.push_str(s);
        }
        for s in state_names.iter().take(n_counts) {
            h.push(',');
            h.push_str(s);
            h.push_str("_counts");
        }
        for s in input_names {
            h.push(',');
            h.push_str(s);
        }
        for s in input_names {
            h.push(',');
            h.push_str(s);
            h.push_str("_cmd");
        }
        h.push_str(",state,overrun");
        if self.mode_column {
            h.push_str(",mode");
        }
        h.push('\n');
        self.out.write_all(h.as_bytes())?;
        self.out.flush()?;
        self.last_flush_t = 0.0;
        Ok(())
    }

    /// Appends one sample row; flushes if 100 ms of loop time passed since the
    /// last flush or the buffer is nearly full. Never allocates. I/O errors are
    /// remembered (see [`LogWriter::error`]) and stop further logging.
    #[allow(clippy::too_many_arguments)]
    pub fn row(
        &mut self,
        t: f64,
        x: &[f64],
        counts: &[i32],
        u: &[f64],
        u_cmd: &[f64],
        state: &str,
        overrun: bool,
    ) {
        self.row_with_mode(t, x, counts, u, u_cmd, state, overrun, "");
    }

    /// [`LogWriter::row`] with the mode column's value (ignored without
    /// [`LogWriter::with_mode_column`]). Never allocates.
    #[allow(clippy::too_many_arguments)]
    pub fn row_with_mode(
        &mut self,
        t: f64,
        x: &[f64],
        counts: &[i32],
        u: &[f64],
        u_cmd: &[f64],
        state: &str,
        overrun: bool,
        mode: &str,
    ) {
        if self.error.is_some() {
            return;
        }
        // Writing into a Vec with spare capacity does not allocate; the
        // buffer is flushed well before it could grow.
        let b = &mut self.buf;
        if self.full_precision {
            let _ = write!(b, "{t:?}");
            for v in x {
                let _ = write!(b, ",{v:?}");
            }
        } else {
            let _ = write!(b, "{t:.6}");
            for v in x {
                let _ = write!(b, ",{v:.6}");
            }
        }
        for c in counts {
            let _ = write!(b, ",{c}");
        }
        for v in u.iter().chain(u_cmd) {
            if self.full_precision {
                let _ = write!(b, ",{v:?}");
            } else {
                let _ = write!(b, ",{v:.4}");
            }
        }
        let _ = write!(b, ",{state},{}", u8::from(overrun));
        if self.mode_column {
            let _ = write!(b, ",{mode}");
        }
        let _ = writeln!(b);
        self.rows += 1;
        if t - self.last_flush_t >= self.flush_interval_s
            || self.buf.len() + 4096 > self.buf.capacity()
        {
            self.last_flush_t = t;
            self.flush();
        }
    }

    /// Hands buffered rows to the writer.
    pub fn flush(&mut self) {
        if self.error.is_some() {
            self.buf.clear();
            return;
        }
        let r = self.out.write_all(&self.buf).and_then(|_| self.out.flush());
        self.buf.clear();
        if let Err(e) = r {
            self.error = Some(e.into());
        }
    }

    /// Rows written so far.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// The first I/O error, if any.
    pub fn error(&self) -> Option<&LogError> {
        self.error.as_ref()
    }
}

impl Drop for LogWriter {
    fn drop(&mut self) {
        self.flush();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn create_new_refuses_an_existing_log_and_leaves_it() {
        let p = std::env::temp_dir().join(format!("plantc-log-excl-{}.csv", std::process::id()));
        std::fs::write(&p, "t,x\n1,2\n").unwrap();
        match LogWriter::create_new(&p) {
            Err(LogError::Io { kind, .. }) => assert_eq!(kind, io::ErrorKind::AlreadyExists),
            Ok(_) => panic!("an existing log was opened"),
        }
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "t,x\n1,2\n");
        assert!(LogWriter::open(&p, true).is_ok(), "--force truncates");
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "");
        std::fs::remove_file(&p).unwrap();
    }
}
