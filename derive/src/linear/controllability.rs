//! Controllability: the decision by a scale-aware PBH test on the balanced
//! realisation (with its margin), and the controllability matrix with its
//! numerical rank (informative only: its columns span many orders of
//! magnitude from a handful of states on, so its rank says "not
//! controllable" for systems that are).

use nalgebra::{Complex, DMatrix, SVD};

use super::balance::balance;
use super::error::{check_pair, LinearError};
use super::poles::poles;

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
    /// PBH margin: `min over eigenvalues lambda of sigma_min([A - lambda I, B]) / ||A||_F`
    /// on the balanced realisation (`D^-1 A D`, `D^-1 B`, see [`super::balance`]) with each
    /// column of `B` scaled to norm `||A||_F` (inputs in the system's own units). 0 when
    /// a mode is uncontrollable.
    pub pbh_margin: f64,
    /// The eigenvalue `(re, im)` where the margin is attained.
    pub pbh_eigenvalue: (f64, f64),
    /// Decision threshold of the margin: `n sqrt(eps)` (eigenvalues of a
    /// nonnormal `A` are accurate to about `sqrt(eps)`).
    pub pbh_tolerance: f64,
    /// `pbh_margin > pbh_tolerance`: the decision.
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

/// PBH margin of `(A, B)` on the balanced realisation: `(margin, eigenvalue)`,
/// see [`Controllability::pbh_margin`].
pub fn pbh_margin(a: &DMatrix<f64>, b: &DMatrix<f64>) -> Result<(f64, (f64, f64)), LinearError> {
    check_pair(a, b)?;
    let (n, m) = (a.nrows(), b.ncols());
    if n == 0 {
        return Ok((f64::INFINITY, (0.0, 0.0)));
    }
    let (ab, mut bb, _) = balance(a, b);
    let na = ab.norm();
    let scale = if na > 0.0 { na } else { 1.0 };
    for mut col in bb.column_iter_mut() {
        let c = col.norm();
        if c > 0.0 {
            col *= scale / c;
        }
    }
    let mut worst = (f64::INFINITY, (0.0, 0.0));
    for lambda in poles(&ab)? {
        let z = lambda.to_complex();
        let pbh = DMatrix::<Complex<f64>>::from_fn(n, n + m, |i, j| {
            if j < n {
                let d = if i == j { z } else { Complex::new(0.0, 0.0) };
                Complex::new(ab[(i, j)], 0.0) - d
            } else {
                Complex::new(bb[(i, j - n)], 0.0)
            }
        });
        let svd = SVD::try_new(pbh, false, false, f64::EPSILON, 1000 + 100 * (n + m)).ok_or(
            LinearError::SvdFailed {
                rows: n,
                cols: n + m,
            },
        )?;
        // the n-th largest singular value of the n x (n + m) matrix
        let mut sv: Vec<f64> = svd.singular_values.iter().copied().collect();
        sv.sort_by(|x, y| y.total_cmp(x));
        let smin = sv.get(n - 1).copied().unwrap_or(0.0) / scale;
        if smin < worst.0 {
            worst = (smin, (lambda.re, lambda.im));
        }
    }
    Ok(worst)
}

/// Controllability analysis of `(A, B)`: decided by the PBH margin on the
/// balanced realisation; the controllability matrix and its rank alongside.
pub fn controllability(a: &DMatrix<f64>, b: &DMatrix<f64>) -> Result<Controllability, LinearError> {
    let matrix = controllability_matrix(a, b)?;
    let (rank, tolerance, singular_values) = numerical_rank(&matrix)?;
    let (pbh_margin, pbh_eigenvalue) = pbh_margin(a, b)?;
    let pbh_tolerance = a.nrows().max(1) as f64 * f64::EPSILON.sqrt();
    Ok(Controllability {
        controllable: pbh_margin > pbh_tolerance,
        matrix,
        rank,
        tolerance,
        singular_values,
        pbh_margin,
        pbh_eigenvalue,
        pbh_tolerance,
    })
}
