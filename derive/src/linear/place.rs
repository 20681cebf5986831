//! Single-input pole placement (Ackermann's formula with a scaled linear solve).

use nalgebra::{Complex, DMatrix};

use super::controllability::{controllability_matrix, numerical_rank};
use super::error::{check_pair, LinearError};
use super::poles::{poles, Pole};

/// Result of [`place`].
#[derive(Debug, Clone, PartialEq)]
pub struct Placement {
    /// Gain, 1 x n, for the law `u = -K x`.
    pub k: DMatrix<f64>,
    /// Eigenvalues of `A - B K` as computed (canonical order, see [`poles`]).
    pub closed_loop_poles: Vec<Pole>,
    /// Largest distance between a desired pole and its nearest achieved pole,
    /// relative to `max(|desired|, 1)` (greedy matching).
    /// Near `1e-15..1e-10` for well-conditioned problems; repeated desired
    /// poles are intrinsically sensitive (error ~ eps^(1/multiplicity)).
    pub max_pole_error: f64,
}

/// Relative tolerance for recognising a conjugate partner in the desired poles.
const CONJ_TOL: f64 = 1e-9;

/// Checks that the desired pole list is finite, has `n` entries and is closed under
/// conjugation (each non-real pole has a partner within `1e-9 * max(|p|, 1)`).
pub fn check_desired_poles(desired: &[Pole], n: usize) -> Result<(), LinearError> {
    if desired.len() != n {
        return Err(LinearError::PoleCountMismatch {
            expected: n,
            found: desired.len(),
        });
    }
    if let Some(index) = desired
        .iter()
        .position(|p| !(p.re.is_finite() && p.im.is_finite()))
    {
        return Err(LinearError::NonFinitePole { index });
    }
    let mut used = vec![false; n];
    for i in 0..n {
        if desired[i].im == 0.0 || used[i] {
            continue;
        }
        let tol = CONJ_TOL * desired[i].abs().max(1.0);
        let partner = (0..n).find(|&j| {
            j != i
                && !used[j]
                && (desired[j].re - desired[i].re).abs() <= tol
                && (desired[j].im + desired[i].im).abs() <= tol
        });
        match partner {
            Some(j) => {
                used[i] = true;
                used[j] = true;
            }
            None => return Err(LinearError::ComplexPolesNotConjugate { pole: desired[i] }),
        }
    }
    Ok(())
}

/// Monic characteristic polynomial coefficients `c[0] + c[1] s + ... + s^n`
/// of a conjugation-closed pole list (imaginary rounding discarded).
pub fn char_poly(desired: &[Pole]) -> Vec<f64> {
    let mut c = vec![Complex::new(1.0, 0.0)];
    for p in desired {
        let z = p.to_complex();
        // multiply by (s - z)
        let mut next = vec![Complex::new(0.0, 0.0); c.len() + 1];
        for (k, ck) in c.iter().enumerate() {
            next[k + 1] += ck;
            next[k] -= ck * z;
        }
        c = next;
    }
    c.iter().map(|z| z.re).collect()
}

/// Greedy matching distance between desired and achieved poles, each
/// relative to `max(|desired|, 1)`.
pub fn pole_match_error(desired: &[Pole], achieved: &[Pole]) -> f64 {
    let mut used = vec![false; achieved.len()];
    let mut worst: f64 = 0.0;
    for d in desired {
        let best = (0..achieved.len())
            .filter(|&j| !used[j])
            .map(|j| (j, (achieved[j].re - d.re).hypot(achieved[j].im - d.im)))
            .min_by(|x, y| x.1.total_cmp(&y.1));
        match best {
            Some((j, dist)) => {
                used[j] = true;
                worst = worst.max(dist / d.abs().max(1.0));
            }
            None => return f64::INFINITY,
        }
    }
    worst
}

/// Single-input pole placement: K (1 x n) with `eig(A - B K) = desired` for `u = -K x`.
///
/// Method: Ackermann's formula `K = e_n' C^-1 p(A)` where `C` is the
/// controllability matrix and `p` the desired characteristic polynomial;
/// `e_n' C^-1` is obtained by an LU solve of `C' w = e_n` after scaling the
/// columns of `C` to unit norm (no explicit inverse). Adequate for n up to
/// about 10; the achieved poles are recomputed and returned with their error.
///
/// Errors: shape problems, [`LinearError::MultiInputUnsupported`],
/// [`LinearError::PoleCountMismatch`], [`LinearError::ComplexPolesNotConjugate`],
/// [`LinearError::NotControllable`].
pub fn place(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    desired: &[Pole],
) -> Result<Placement, LinearError> {
    check_pair(a, b)?;
    if b.ncols() != 1 {
        return Err(LinearError::MultiInputUnsupported { inputs: b.ncols() });
    }
    let n = a.nrows();
    check_desired_poles(desired, n)?;

    let w = last_row_of_inverse_controllability(a, b)?;
    let p_of_a = matrix_polynomial(a, &char_poly(desired));
    let k = DMatrix::from_row_slice(1, n, (w.transpose() * p_of_a).as_slice());
    if k.iter().any(|v| !v.is_finite()) {
        return Err(LinearError::SingularSystem {
            what: "gain is not finite",
        });
    }

    let closed = a - b * &k;
    let closed_loop_poles = poles(&closed)?;
    let max_pole_error = pole_match_error(desired, &closed_loop_poles);
    Ok(Placement {
        k,
        closed_loop_poles,
        max_pole_error,
    })
}

/// `w = C^-T e_n` (the last row of the inverse controllability matrix, as a
/// column), by an LU solve after scaling the columns of `C` to unit norm.
pub(super) fn last_row_of_inverse_controllability(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
) -> Result<nalgebra::DVector<f64>, LinearError> {
    let n = a.nrows();
    let c = controllability_matrix(a, b)?;
    let (rank, tolerance, _) = numerical_rank(&c)?;
    if rank < n {
        return Err(LinearError::NotControllable { rank, n, tolerance });
    }
    // Scale columns: C = Cs D, so C' w = e_n  <=>  Cs' w = D^-1 e_n.
    let mut cs = c.clone();
    let mut rhs = nalgebra::DVector::zeros(n);
    for j in 0..n {
        let norm = cs.column(j).norm();
        if norm == 0.0 {
            return Err(LinearError::NotControllable { rank, n, tolerance });
        }
        cs.column_mut(j).unscale_mut(norm);
        if j == n - 1 {
            rhs[j] = 1.0 / norm;
        }
    }
    cs.transpose()
        .lu()
        .solve(&rhs)
        .ok_or(LinearError::SingularSystem {
            what: "controllability matrix in Ackermann's formula",
        })
}

/// `p(A)` for the monic polynomial `coeffs[0] + coeffs[1] s + ... + s^d`
/// (`coeffs` of length `d + 1`, the last entry ignored as 1), by Horner's rule.
pub(super) fn matrix_polynomial(a: &DMatrix<f64>, coeffs: &[f64]) -> DMatrix<f64> {
    let n = a.nrows();
    let identity = DMatrix::<f64>::identity(n, n);
    let mut p_of_a = identity.clone();
    for k in (0..coeffs.len().saturating_sub(1)).rev() {
        p_of_a = &p_of_a * a + &identity * coeffs[k];
    }
    p_of_a
}
