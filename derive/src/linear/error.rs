//! The error type shared by the linear analysis and design functions.

use std::fmt;

use super::poles::Pole;

/// Everything that can go wrong in [`crate::linear`]. Variants carry the data
/// needed to explain the problem; none of the functions in this module panic
/// on bad input.
#[derive(Debug, Clone, PartialEq)]
pub enum LinearError {
    /// The JSON text could not be parsed into the expected shape.
    Json {
        /// serde_json's message.
        message: String,
        /// 1-based line of the error (0 if unknown).
        line: usize,
        /// 1-based column of the error (0 if unknown).
        column: usize,
    },
    /// A matrix has no rows or no columns.
    EmptyMatrix {
        /// Which matrix (`"A"`, `"B"`, ...).
        matrix: &'static str,
    },
    /// A row of a matrix given as a list of rows has the wrong length.
    RaggedRows {
        /// Which matrix.
        matrix: &'static str,
        /// 0-based index of the offending row.
        row: usize,
        /// Length of the first row.
        expected: usize,
        /// Length of the offending row.
        found: usize,
    },
    /// A matrix that must be square is not.
    NotSquare {
        /// Which matrix.
        matrix: &'static str,
        /// Its row count.
        rows: usize,
        /// Its column count.
        cols: usize,
    },
    /// Matrix dimensions do not fit together.
    DimensionMismatch {
        /// Which matrix has the wrong shape.
        matrix: &'static str,
        /// Expected `(rows, cols)`.
        expected: (usize, usize),
        /// Actual `(rows, cols)`.
        found: (usize, usize),
    },
    /// A matrix entry is NaN or infinite.
    NonFinite {
        /// Which matrix.
        matrix: &'static str,
        /// 0-based row.
        row: usize,
        /// 0-based column.
        col: usize,
    },
    /// The number of state or input names does not match the matrices.
    NameCountMismatch {
        /// `"state"` or `"inputs"`.
        names: &'static str,
        /// Number implied by the matrices.
        expected: usize,
        /// Number of names given.
        found: usize,
    },
    /// The eigenvalue iteration did not converge.
    EigenvaluesFailed {
        /// Order of the matrix.
        n: usize,
    },
    /// The singular value decomposition did not converge.
    SvdFailed {
        /// Shape of the matrix.
        rows: usize,
        /// Shape of the matrix.
        cols: usize,
    },
    /// An item of a pole list could not be parsed.
    InvalidPole {
        /// 0-based position of the item in the comma-separated list.
        index: usize,
        /// The item as written (trimmed).
        item: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// The pole list is empty.
    NoPoles,
    /// The pair (A, B) is not controllable (rank test on the controllability matrix).
    NotControllable {
        /// Numerical rank of the controllability matrix.
        rank: usize,
        /// State dimension (full rank).
        n: usize,
        /// Singular value threshold used for the rank decision.
        tolerance: f64,
    },
    /// Wrong number of desired poles.
    PoleCountMismatch {
        /// The state dimension.
        expected: usize,
        /// The number of poles given.
        found: usize,
    },
    /// A complex pole has no matching conjugate in the list, so no real gain can place it.
    ComplexPolesNotConjugate {
        /// The pole without partner.
        pole: Pole,
    },
    /// A desired pole is NaN or infinite.
    NonFinitePole {
        /// 0-based index in the list.
        index: usize,
    },
    /// The method only handles a single input.
    MultiInputUnsupported {
        /// Number of inputs of the system.
        inputs: usize,
    },
    /// The controllability matrix is numerically singular in the linear solve.
    SingularSystem {
        /// What was being solved.
        what: &'static str,
    },
    /// A matrix that must be symmetric is not.
    NotSymmetric {
        /// Which matrix.
        matrix: &'static str,
        /// `max |M - M'|` .
        asymmetry: f64,
    },
    /// Q is not positive semidefinite.
    QNotPositiveSemidefinite {
        /// Smallest eigenvalue of Q.
        min_eigenvalue: f64,
    },
    /// R is not positive definite.
    RNotPositiveDefinite {
        /// Smallest eigenvalue of R.
        min_eigenvalue: f64,
    },
    /// An eigenvalue of A in the closed right half plane is uncontrollable.
    NotStabilizable {
        /// The uncontrollable unstable (or marginal) eigenvalue.
        eigenvalue: Pole,
    },
    /// The Riccati solver did not produce a stabilizing solution.
    CareFailed {
        /// Why.
        reason: &'static str,
        /// Relative residual of the best iterate, if one was computed (NaN otherwise).
        residual: f64,
    },
}

impl fmt::Display for LinearError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use LinearError::*;
        match self {
            Json { message, .. } => write!(f, "invalid model JSON: {message}"),
            EmptyMatrix { matrix } => write!(f, "matrix {matrix} is empty"),
            RaggedRows {
                matrix,
                row,
                expected,
                found,
            } => write!(
                f,
                "matrix {matrix}: row {row} has {found} entries, expected {expected}"
            ),
            NotSquare { matrix, rows, cols } => {
                write!(f, "matrix {matrix} must be square, it is {rows}x{cols}")
            }
            DimensionMismatch {
                matrix,
                expected,
                found,
            } => write!(
                f,
                "matrix {matrix} must be {}x{}, it is {}x{}",
                expected.0, expected.1, found.0, found.1
            ),
            NonFinite { matrix, row, col } => {
                write!(f, "matrix {matrix}: entry ({row}, {col}) is not finite")
            }
            NameCountMismatch {
                names,
                expected,
                found,
            } => {
                write!(
                    f,
                    "{found} {names} names given, the matrices need {expected}"
                )
            }
            EigenvaluesFailed { n } => {
                write!(f, "eigenvalue iteration did not converge ({n}x{n} matrix)")
            }
            SvdFailed { rows, cols } => write!(f, "SVD did not converge ({rows}x{cols} matrix)"),
            InvalidPole {
                index,
                item,
                reason,
            } => {
                write!(f, "pole #{} `{item}`: {reason}", index + 1)
            }
            NoPoles => write!(f, "no poles given"),
            NotControllable { rank, n, tolerance } => write!(
                f,
                "(A, B) is not controllable: controllability matrix has rank {rank} < {n} \
                 (singular value tolerance {tolerance:e})"
            ),
            PoleCountMismatch { expected, found } => {
                write!(f, "{found} poles given, the system has {expected} states")
            }
            ComplexPolesNotConjugate { pole } => write!(
                f,
                "complex pole {}{:+}i has no conjugate partner",
                pole.re, pole.im
            ),
            NonFinitePole { index } => write!(f, "pole #{} is not finite", index + 1),
            MultiInputUnsupported { inputs } => write!(
                f,
                "pole placement supports a single input, the system has {inputs}"
            ),
            SingularSystem { what } => write!(f, "numerically singular: {what}"),
            NotSymmetric { matrix, asymmetry } => {
                write!(
                    f,
                    "matrix {matrix} is not symmetric (max |M - M'| = {asymmetry:e})"
                )
            }
            QNotPositiveSemidefinite { min_eigenvalue } => write!(
                f,
                "Q is not positive semidefinite (smallest eigenvalue {min_eigenvalue:e})"
            ),
            RNotPositiveDefinite { min_eigenvalue } => write!(
                f,
                "R is not positive definite (smallest eigenvalue {min_eigenvalue:e})"
            ),
            NotStabilizable { eigenvalue } => write!(
                f,
                "(A, B) is not stabilizable: eigenvalue {}{:+}i is uncontrollable",
                eigenvalue.re, eigenvalue.im
            ),
            CareFailed { reason, residual } => {
                write!(
                    f,
                    "Riccati equation solve failed: {reason} (residual {residual:e})"
                )
            }
        }
    }
}

impl std::error::Error for LinearError {}

/// Checks that every entry of `m` is finite.
pub(crate) fn check_finite(
    matrix: &'static str,
    m: &nalgebra::DMatrix<f64>,
) -> Result<(), LinearError> {
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            if !m[(i, j)].is_finite() {
                return Err(LinearError::NonFinite {
                    matrix,
                    row: i,
                    col: j,
                });
            }
        }
    }
    Ok(())
}

/// Checks that `a` is square and non-empty and `b` has as many rows as `a`
/// and at least one column; both finite.
pub(crate) fn check_pair(
    a: &nalgebra::DMatrix<f64>,
    b: &nalgebra::DMatrix<f64>,
) -> Result<(), LinearError> {
    if a.nrows() == 0 || a.ncols() == 0 {
        return Err(LinearError::EmptyMatrix { matrix: "A" });
    }
    if a.nrows() != a.ncols() {
        return Err(LinearError::NotSquare {
            matrix: "A",
            rows: a.nrows(),
            cols: a.ncols(),
        });
    }
    if b.ncols() == 0 {
        return Err(LinearError::EmptyMatrix { matrix: "B" });
    }
    if b.nrows() != a.nrows() {
        return Err(LinearError::DimensionMismatch {
            matrix: "B",
            expected: (a.nrows(), b.ncols()),
            found: (b.nrows(), b.ncols()),
        });
    }
    check_finite("A", a)?;
    check_finite("B", b)
}
