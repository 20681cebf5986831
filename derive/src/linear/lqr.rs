//! Continuous-time LQR via the algebraic Riccati equation (CARE).

use nalgebra::{Cholesky, Complex, DMatrix, SymmetricEigen, SVD};

use super::balance::balance;
use super::error::{check_finite, check_pair, LinearError};
use super::poles::{poles, Pole};

/// Result of [`lqr`].
#[derive(Debug, Clone, PartialEq)]
pub struct Lqr {
    /// Gain, m x n, for the law `u = -K x`: `K = R^-1 B' P`.
    pub k: DMatrix<f64>,
    /// Stabilizing solution of `A'P + PA - P B R^-1 B' P + Q = 0` (symmetric).
    pub p: DMatrix<f64>,
    /// Eigenvalues of `A - B K` (canonical order, see [`poles`]).
    pub closed_loop_poles: Vec<Pole>,
    /// Relative residual, see [`care_residual`].
    pub care_residual: f64,
}

/// Largest state dimension for which the Newton-Kleinman refinement (a dense
/// n^2 x n^2 Kronecker solve) is performed.
const NEWTON_MAX_N: usize = 30;
/// Maximum number of sign-function iterations.
const SIGN_MAX_ITER: usize = 100;

/// Relative CARE residual of `p`:
///
/// `||A'P + PA - P G P + Q||_F / max(1, ||Q||_F + 2 ||A'P||_F + ||P G P||_F)`
/// with `G = B R^-1 B'`, i.e. the residual relative to the sum of the sizes of
/// its terms (absolute when all the terms are smaller than 1).
pub fn care_residual(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    p: &DMatrix<f64>,
) -> f64 {
    let (res, scale) = residual_and_scale(a, g, q, p);
    res.norm() / scale
}

fn residual_and_scale(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    p: &DMatrix<f64>,
) -> (DMatrix<f64>, f64) {
    let atp = a.transpose() * p;
    let pgp = p * g * p;
    let res = &atp + atp.transpose() - &pgp + q;
    let scale = (q.norm() + 2.0 * atp.norm() + pgp.norm()).max(1.0);
    (res, scale)
}

fn asymmetry(m: &DMatrix<f64>) -> f64 {
    (m - m.transpose()).amax()
}

fn symmetric_part(m: &DMatrix<f64>) -> DMatrix<f64> {
    (m + m.transpose()) * 0.5
}

fn check_weight(
    name: &'static str,
    m: &DMatrix<f64>,
    dim: usize,
) -> Result<DMatrix<f64>, LinearError> {
    if m.shape() != (dim, dim) {
        return Err(LinearError::DimensionMismatch {
            matrix: name,
            expected: (dim, dim),
            found: m.shape(),
        });
    }
    check_finite(name, m)?;
    let asym = asymmetry(m);
    if asym > 1e-10 * m.amax().max(f64::MIN_POSITIVE) {
        return Err(LinearError::NotSymmetric {
            matrix: name,
            asymmetry: asym,
        });
    }
    Ok(symmetric_part(m))
}

/// Smallest eigenvalue and the size-based tolerance `dim * eps * max|eig|`.
fn min_eig(m: &DMatrix<f64>) -> Result<(f64, f64), LinearError> {
    let n = m.nrows();
    let eig = SymmetricEigen::try_new(m.clone(), f64::EPSILON, 1000 + 100 * n)
        .ok_or(LinearError::EigenvaluesFailed { n })?;
    let min = eig.eigenvalues.min();
    let big = eig.eigenvalues.amax();
    Ok((min, n as f64 * f64::EPSILON * big))
}

/// PBH test: every eigenvalue with `Re >= -1e-8 max(|lambda|, 1)` must satisfy
/// `rank [A - lambda I, B] = n` (SVD rank, tolerance `max(rows, cols) eps sigma_max`).
fn check_stabilizable(a: &DMatrix<f64>, b: &DMatrix<f64>) -> Result<(), LinearError> {
    let n = a.nrows();
    let m = b.ncols();
    for lambda in poles(a)? {
        if lambda.re < -1e-8 * lambda.abs().max(1.0) {
            continue;
        }
        let z = lambda.to_complex();
        let pbh = DMatrix::<Complex<f64>>::from_fn(n, n + m, |i, j| {
            if j < n {
                let d = if i == j { z } else { Complex::new(0.0, 0.0) };
                Complex::new(a[(i, j)], 0.0) - d
            } else {
                Complex::new(b[(i, j - n)], 0.0)
            }
        });
        let svd = SVD::try_new(pbh, false, false, f64::EPSILON, 1000 + 100 * (n + m)).ok_or(
            LinearError::SvdFailed {
                rows: n,
                cols: n + m,
            },
        )?;
        let smax = svd.singular_values.max();
        let tol = (n + m) as f64 * f64::EPSILON * smax;
        let rank = svd.singular_values.iter().filter(|&&s| s > tol).count();
        if rank < n {
            return Err(LinearError::NotStabilizable { eigenvalue: lambda });
        }
    }
    Ok(())
}

/// Solves `F' X + X F = -C` (C symmetric) by a dense Kronecker system; returns
/// `None` if that system is singular.
fn lyapunov(f: &DMatrix<f64>, c: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = f.nrows();
    let id = DMatrix::<f64>::identity(n, n);
    let ft = f.transpose();
    // vec(F' X) = (I kron F') vec X, vec(X F) = (F' kron I) vec X (column-major vec).
    let op = id.kronecker(&ft) + ft.kronecker(&id);
    let rhs = -DMatrix::from_column_slice(n * n, 1, c.as_slice());
    let x = op.lu().solve(&rhs)?;
    Some(symmetric_part(&DMatrix::from_column_slice(
        n,
        n,
        x.as_slice(),
    )))
}

/// Matrix sign function of `h` by Newton's iteration with determinant scaling.
fn sign_function(h: &DMatrix<f64>) -> Result<DMatrix<f64>, LinearError> {
    let dim = h.nrows();
    let mut z = h.clone();
    let mut scaling = true;
    for _ in 0..SIGN_MAX_ITER {
        let lu = z.clone().lu();
        let zinv = lu.try_inverse().ok_or(LinearError::CareFailed {
            reason: "Hamiltonian matrix has eigenvalues on the imaginary axis (singular iterate)",
            residual: f64::NAN,
        })?;
        let c = if scaling {
            let log_det: f64 = lu.u().diagonal().iter().map(|u| u.abs().ln()).sum();
            (log_det / dim as f64).exp()
        } else {
            1.0
        };
        let next = (&z / c + zinv * c) * 0.5;
        if next.iter().any(|v| !v.is_finite()) {
            return Err(LinearError::CareFailed {
                reason: "sign iteration overflowed",
                residual: f64::NAN,
            });
        }
        let diff = (&next - &z).norm() / next.norm();
        z = next;
        if diff < 1e-2 {
            scaling = false;
        }
        if diff <= 1e-12 {
            return Ok(z);
        }
    }
    Err(LinearError::CareFailed {
        reason: "sign iteration did not converge (eigenvalues near the imaginary axis?)",
        residual: f64::NAN,
    })
}

/// Stabilizing CARE solution of `(a, g, q)` by the sign function of the
/// Hamiltonian, refined by Newton-Kleinman.
fn care_balanced(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
) -> Result<DMatrix<f64>, LinearError> {
    let n = a.nrows();
    // Hamiltonian and its sign.
    let mut h = DMatrix::<f64>::zeros(2 * n, 2 * n);
    h.view_mut((0, 0), (n, n)).copy_from(a);
    h.view_mut((0, n), (n, n)).copy_from(&(-g));
    h.view_mut((n, 0), (n, n)).copy_from(&(-q));
    h.view_mut((n, n), (n, n)).copy_from(&(-a.transpose()));
    let w = sign_function(&h)?;

    // (W + I) [I; P] = 0  =>  [W12; W22 + I] P = -[W11 + I; W21].
    let id = DMatrix::<f64>::identity(n, n);
    let mut lhs = DMatrix::<f64>::zeros(2 * n, n);
    lhs.view_mut((0, 0), (n, n))
        .copy_from(&w.view((0, n), (n, n)));
    lhs.view_mut((n, 0), (n, n))
        .copy_from(&(w.view((n, n), (n, n)) + &id));
    let mut rhs = DMatrix::<f64>::zeros(2 * n, n);
    rhs.view_mut((0, 0), (n, n))
        .copy_from(&(-(w.view((0, 0), (n, n)) + &id)));
    rhs.view_mut((n, 0), (n, n))
        .copy_from(&(-w.view((n, 0), (n, n))));
    let svd = SVD::try_new(lhs, true, true, f64::EPSILON, 2000 + 200 * n).ok_or(
        LinearError::SvdFailed {
            rows: 2 * n,
            cols: n,
        },
    )?;
    let smax = svd.singular_values.max();
    let smin = svd.singular_values.min();
    if smin.is_nan() || smin <= 2.0 * n as f64 * f64::EPSILON * smax * 1e3 {
        return Err(LinearError::CareFailed {
            reason: "stable invariant subspace of the Hamiltonian is not a graph [I; P]",
            residual: f64::NAN,
        });
    }
    let p = svd.solve(&rhs, 0.0).map_err(|_| LinearError::CareFailed {
        reason: "least-squares solve for P failed",
        residual: f64::NAN,
    })?;
    let mut p = symmetric_part(&p);
    let mut res = care_residual(a, g, q, &p);
    if n <= NEWTON_MAX_N {
        newton_kleinman(a, g, q, &mut p, &mut res);
    }
    Ok(p)
}

/// Newton-Kleinman refinement in correction form:
/// `(A - G P)' E + E (A - G P) = -Res(P)`, `P <- P + E`, up to four steps,
/// each kept only if it lowers the residual.
fn newton_kleinman(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    p: &mut DMatrix<f64>,
    res: &mut f64,
) {
    for _ in 0..4 {
        if *res < 1e-15 {
            break;
        }
        let (r_mat, _) = residual_and_scale(a, g, q, p);
        let f = a - g * &*p;
        let Some(e) = lyapunov(&f, &r_mat) else { break };
        let candidate = symmetric_part(&(&*p + e));
        let cres = care_residual(a, g, q, &candidate);
        if cres.is_finite() && cres < *res {
            *p = candidate;
            *res = cres;
        } else {
            break;
        }
    }
}

/// Continuous-time LQR: minimises `integral x'Qx + u'Ru dt` for `x' = Ax + Bu`,
/// `u = -K x`.
///
/// Method: the stabilizing CARE solution is read off the sign function of the
/// Hamiltonian `[[A, -G], [-Q, -A']]` (`G = B R^-1 B'`, Newton iteration with
/// determinant scaling, stable subspace by a least-squares solve) on the
/// balanced realisation (see [`super::balance`]), then refined
/// by up to four Newton-Kleinman steps (Lyapunov equations solved as Kronecker
/// systems, n <= 30), each kept only if it lowers the residual.
///
/// Q must be symmetric positive semidefinite (n x n), R symmetric positive
/// definite (m x m), (A, B) stabilizable (PBH test). The result is checked:
/// the closed loop must be asymptotically stable, otherwise
/// [`LinearError::CareFailed`] (e.g. (Q, A) has unobservable modes on the
/// imaginary axis).
pub fn lqr(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> Result<Lqr, LinearError> {
    check_pair(a, b)?;
    let n = a.nrows();
    let m = b.ncols();
    let q = check_weight("Q", q, n)?;
    let r = check_weight("R", r, m)?;
    let (qmin, qtol) = min_eig(&q)?;
    if qmin < -qtol {
        return Err(LinearError::QNotPositiveSemidefinite {
            min_eigenvalue: qmin,
        });
    }
    let (rmin, rtol) = min_eig(&r)?;
    if rmin <= rtol {
        return Err(LinearError::RNotPositiveDefinite {
            min_eigenvalue: rmin,
        });
    }
    let chol = Cholesky::new(r.clone()).ok_or(LinearError::RNotPositiveDefinite {
        min_eigenvalue: rmin,
    })?;
    check_stabilizable(a, b)?;

    let rinv_bt = chol.solve(&b.transpose()); // m x n
    let g = symmetric_part(&(b * &rinv_bt));

    // Solved on the balanced realisation x = D z (D^-1 A D, D^-1 B, D Q D):
    // the same problem with P = D^-1 P_z D^-1, in the system's own scales.
    let (az, bz, d) = balance(a, b);
    let qz = DMatrix::from_fn(n, n, |i, j| q[(i, j)] * d[i] * d[j]);
    let gz = symmetric_part(&(&bz * chol.solve(&bz.transpose())));
    let pz = care_balanced(&az, &gz, &qz)?;
    let mut p = symmetric_part(&DMatrix::from_fn(n, n, |i, j| pz[(i, j)] / (d[i] * d[j])));
    let mut res = care_residual(a, &g, &q, &p);
    // Newton-Kleinman refinement on the original realisation (kept only if
    // it lowers the residual reported).
    if n <= NEWTON_MAX_N {
        newton_kleinman(a, &g, &q, &mut p, &mut res);
    }

    let k = &rinv_bt * &p;
    let closed_loop_poles = poles(&(a - b * &k))?;
    if closed_loop_poles
        .iter()
        .any(|z| z.re.is_nan() || z.re >= 0.0)
    {
        return Err(LinearError::CareFailed {
            reason: "solution is not stabilizing (closed loop has eigenvalues with Re >= 0)",
            residual: res,
        });
    }
    if !res.is_finite() {
        return Err(LinearError::CareFailed {
            reason: "residual is not finite",
            residual: res,
        });
    }
    Ok(Lqr {
        k,
        p,
        closed_loop_poles,
        care_residual: res,
    })
}
