//! A continuous-time linear state-space model `x' = A x + B u` and its JSON form.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use super::error::{check_finite, check_pair, LinearError};

/// A linear model `x' = A x + B u` with named states and inputs.
///
/// JSON form (names optional on input, default `x1..xn`, `u1..um`):
/// `{"state": ["theta", ...], "inputs": ["Vm"], "A": [[...], ...], "B": [[...], ...]}`,
/// matrices as lists of rows.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearModel {
    /// State names, one per row of A.
    pub state: Vec<String>,
    /// Input names, one per column of B.
    pub inputs: Vec<String>,
    /// State matrix, n x n.
    pub a: DMatrix<f64>,
    /// Input matrix, n x m.
    pub b: DMatrix<f64>,
}

#[derive(Serialize, Deserialize)]
struct ModelJson {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    state: Option<Vec<String>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    inputs: Option<Vec<String>>,
    #[serde(rename = "A")]
    a: Vec<Vec<f64>>,
    #[serde(rename = "B")]
    b: Vec<Vec<f64>>,
}

/// Builds a matrix from a list of rows, checking that it is rectangular,
/// non-empty and finite.
pub fn matrix_from_rows(
    matrix: &'static str,
    rows: &[Vec<f64>],
) -> Result<DMatrix<f64>, LinearError> {
    let ncols = rows.first().map_or(0, Vec::len);
    if rows.is_empty() || ncols == 0 {
        return Err(LinearError::EmptyMatrix { matrix });
    }
    for (row, r) in rows.iter().enumerate() {
        if r.len() != ncols {
            return Err(LinearError::RaggedRows {
                matrix,
                row,
                expected: ncols,
                found: r.len(),
            });
        }
    }
    let m = DMatrix::from_fn(rows.len(), ncols, |i, j| rows[i][j]);
    check_finite(matrix, &m)?;
    Ok(m)
}

/// A matrix as a list of rows (the JSON layout used throughout plantc).
pub fn matrix_to_rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| m.row(i).iter().copied().collect())
        .collect()
}

fn default_names(prefix: &str, count: usize) -> Vec<String> {
    (1..=count).map(|k| format!("{prefix}{k}")).collect()
}

impl LinearModel {
    /// A model with default names `x1..xn`, `u1..um`, after validating shapes
    /// and finiteness.
    pub fn new(a: DMatrix<f64>, b: DMatrix<f64>) -> Result<Self, LinearError> {
        check_pair(&a, &b)?;
        Ok(LinearModel {
            state: default_names("x", a.nrows()),
            inputs: default_names("u", b.ncols()),
            a,
            b,
        })
    }

    /// A model with explicit names; the name counts must match the matrices.
    pub fn with_names(
        state: Vec<String>,
        inputs: Vec<String>,
        a: DMatrix<f64>,
        b: DMatrix<f64>,
    ) -> Result<Self, LinearError> {
        let mut m = Self::new(a, b)?;
        if state.len() != m.n_states() {
            return Err(LinearError::NameCountMismatch {
                names: "state",
                expected: m.n_states(),
                found: state.len(),
            });
        }
        if inputs.len() != m.n_inputs() {
            return Err(LinearError::NameCountMismatch {
                names: "inputs",
                expected: m.n_inputs(),
                found: inputs.len(),
            });
        }
        m.state = state;
        m.inputs = inputs;
        Ok(m)
    }

    /// Number of states n.
    pub fn n_states(&self) -> usize {
        self.a.nrows()
    }

    /// Number of inputs m.
    pub fn n_inputs(&self) -> usize {
        self.b.ncols()
    }

    /// Parses and validates the JSON form.
    pub fn from_json(text: &str) -> Result<Self, LinearError> {
        let raw: ModelJson = serde_json::from_str(text).map_err(|e| LinearError::Json {
            message: e.to_string(),
            line: e.line(),
            column: e.column(),
        })?;
        let a = matrix_from_rows("A", &raw.a)?;
        let b = matrix_from_rows("B", &raw.b)?;
        let n = b.nrows();
        let m = b.ncols();
        let model = Self::new(a, b)?;
        Self::with_names(
            raw.state.unwrap_or_else(|| default_names("x", n)),
            raw.inputs.unwrap_or_else(|| default_names("u", m)),
            model.a,
            model.b,
        )
    }

    /// The JSON form, with names and matrices as lists of rows.
    pub fn to_json(&self) -> String {
        let raw = ModelJson {
            state: Some(self.state.clone()),
            inputs: Some(self.inputs.clone()),
            a: matrix_to_rows(&self.a),
            b: matrix_to_rows(&self.b),
        };
        // Serialising plain strings and finite floats cannot fail.
        serde_json::to_string_pretty(&raw).unwrap_or_default()
    }
}
