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
/// `t,<states>,<positions>_counts,<input>,<input>_cmd,state,overrun`.
pub struct LogWriter {
    out: Box<dyn Write + Send>,
    buf: Vec<u8>,
    flush_interval_s: f64,
    last_flush_t: f64,
    rows: u64,
    error: Option<LogError>,
    full_precision: bool,
}

impl LogWriter {
    /// Creates (truncates) a log file.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, LogError> {
        let f = File::create(path)?;
        Ok(Self::from_writer(Box::new(f)))
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
            full_precision: false,
        }
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
        h.push_str(",state,overrun\n");
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
        let _ = writeln!(b, ",{state},{}", u8::from(overrun));
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
