//! The exceptions the module raises and the failure type its workers return.

use plantc_derive::lang::diagnostic::{Diagnostic, Severity};
use plantc_derive::lang::source::SourceFile;
use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyValueError};
use pyo3::prelude::*;

pyo3::create_exception!(
    plantc,
    PlantcError,
    pyo3::exceptions::PyException,
    "A plantc computation failed (the message says why)."
);
pyo3::create_exception!(
    plantc,
    ModelError,
    PlantcError,
    "A model text has errors: `file`, `line`, `column` (1-based) of the first, `diagnostics` all of them."
);

/// One diagnostic with its position resolved (1-based line and column).
#[derive(Debug, Clone)]
pub struct Located {
    pub severity: &'static str,
    pub code: &'static str,
    pub message: String,
    pub line: usize,
    pub column: usize,
    pub help: Option<String>,
}

impl Located {
    pub fn new(source: &SourceFile, d: &Diagnostic) -> Located {
        let (line, column) = source.line_col(d.primary.start);
        Located {
            severity: d.severity.as_str(),
            code: d.code,
            message: d.message.clone(),
            line,
            column,
            help: d.help.clone(),
        }
    }
}

/// Why a call failed, carried out of the worker thread.
#[derive(Debug)]
pub enum Failure {
    /// The model has errors: file name, rendered text, the diagnostics.
    Model {
        file: String,
        rendered: String,
        diagnostics: Vec<Located>,
    },
    /// A file does not exist.
    NotFound(String),
    /// Another I/O failure.
    Io(String),
    /// Bad arguments (unknown name, wrong size, ...).
    Input(String),
    /// The computation failed.
    Compute(String),
}

impl Failure {
    /// The model errors of `diagnostics` on `source` (errors first).
    pub fn model(file: &str, source: &SourceFile, diagnostics: &[Diagnostic]) -> Failure {
        let mut located: Vec<Located> = diagnostics
            .iter()
            .filter(|d| d.severity == Severity::Error)
            .map(|d| Located::new(source, d))
            .collect();
        located.extend(
            diagnostics
                .iter()
                .filter(|d| d.severity != Severity::Error)
                .map(|d| Located::new(source, d)),
        );
        Failure::Model {
            file: file.to_string(),
            rendered: plantc_derive::lang::diagnostic::render(source, diagnostics),
            diagnostics: located,
        }
    }

    /// The Python exception.
    pub fn into_py(self, py: Python<'_>) -> PyErr {
        match self {
            Failure::Model {
                file,
                rendered,
                diagnostics,
            } => {
                let first = diagnostics.first();
                let err = ModelError::new_err(rendered.trim_end().to_string());
                let value = err.value(py);
                let set = || -> PyResult<()> {
                    value.setattr("file", &file)?;
                    value.setattr("line", first.map(|d| d.line))?;
                    value.setattr("column", first.map(|d| d.column))?;
                    let list: Vec<(String, String, String, usize, usize, Option<String>)> =
                        diagnostics
                            .iter()
                            .map(|d| {
                                (
                                    d.severity.to_string(),
                                    d.code.to_string(),
                                    d.message.clone(),
                                    d.line,
                                    d.column,
                                    d.help.clone(),
                                )
                            })
                            .collect();
                    value.setattr("diagnostics", list)?;
                    Ok(())
                };
                match set() {
                    Ok(()) => err,
                    Err(e) => e,
                }
            }
            Failure::NotFound(path) => {
                PyFileNotFoundError::new_err((2, "No such file or directory".to_string(), path))
            }
            Failure::Io(m) => PyOSError::new_err(m),
            Failure::Input(m) => PyValueError::new_err(m),
            Failure::Compute(m) => PlantcError::new_err(m),
        }
    }
}

/// `Failure::Input` from anything printable.
pub fn input(e: impl std::fmt::Display) -> Failure {
    Failure::Input(e.to_string())
}

/// `Failure::Compute` from anything printable.
pub fn compute(e: impl std::fmt::Display) -> Failure {
    Failure::Compute(e.to_string())
}
