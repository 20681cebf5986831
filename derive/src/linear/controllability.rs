//! Controllability matrix and its numerical rank.

use nalgebra::{DMatrix, SVD};

use super::error::{check_pair, LinearError};

/// The controllability matrix of `(A, B)` and its SVD-based numerical rank.
#[derive(Debug, Clone, PartialEq)]
pub struct Controllability {
    /// `[B, AB, ..., A^(n-1) B]`, n x (n m).
    pub matrix: DMatrix<f64>,
    /// Number of singular values strictly above `tolerance`.
    pub rank: usize,
    /// Rank threshold `max(rows, cols) * eps * sigma_max` (the LAPACK/NumPy `matrix_rank` default).
    pub tolerance: f64,
    /// Singular values, descending.
    pub singular_values: Vec<f64>,
    /// `rank == n`.
    pub controllable: bool,
}

/// `[B, AB, ..., A^(n-1) B]` for A n x n, B n x m (shapes checked).
pub fn controllability_matrix(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
) -> Result<DMatrix<f64>, LinearError> {
    check_pair(a, b)?;
    let (n, m) = (a.nrows(), b.ncols());
    let mut c = DMatrix::zeros(n, n * m);
    let mut block = b.clone();
    for k in 0..n {
        c.columns_mut(k * m, m).copy_from(&block);
        if k + 1 < n {
            block = a * &block;
        }
    }
    Ok(c)
}

/// Singular values (descending) and the numerical rank of `m` with tolerance
/// `max(rows, cols) * eps * sigma_max`. Returns `(rank, tolerance, singular values)`.
pub fn numerical_rank(m: &DMatrix<f64>) -> Result<(usize, f64, Vec<f64>), LinearError> {
    let (rows, cols) = m.shape();
    let svd = SVD::try_new(
        m.clone(),
        false,
        false,
        f64::EPSILON,
        1000 + 100 * rows.max(cols),
    )
    .ok_or(LinearError::SvdFailed { rows, cols })?;
    let mut sv: Vec<f64> = svd.singular_values.iter().copied().collect();
    sv.sort_by(|x, y| y.total_cmp(x));
    let smax = sv.first().copied().unwrap_or(0.0);
    let tolerance = rows.max(cols) as f64 * f64::EPSILON * smax;
    let rank = sv.iter().filter(|&&s| s > tolerance).count();
    Ok((rank, tolerance, sv))
}

/// Controllability analysis of `(A, B)`.
pub fn controllability(a: &DMatrix<f64>, b: &DMatrix<f64>) -> Result<Controllability, LinearError> {
    let matrix = controllability_matrix(a, b)?;
    let (rank, tolerance, singular_values) = numerical_rank(&matrix)?;
    Ok(Controllability {
        controllable: rank == a.nrows(),
        matrix,
        rank,
        tolerance,
        singular_values,
    })
}
