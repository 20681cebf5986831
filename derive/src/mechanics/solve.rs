//! Symbolic solves that never expand an inverse.
//!
//! The results are expressions in the hash-consed DAG built with the plain
//! constructors (no canonical form): a solve of size `n` adds `O(n^3)` small
//! nodes (`a - b*c`, one reciprocal per pivot) and shares everything it can,
//! so it stays cheap to build, differentiate, evaluate and compile at sizes
//! where `adj(M)/det(M)` in expanded form is out of reach (the 10-link chain).
//!
//! * [`ldl_solve`]: `M y = b` for a symmetric positive-definite `M` (a mass
//!   matrix) by `M = L D L^T` without pivoting: every pivot is a ratio of
//!   leading principal minors of `M`, positive wherever `M` is, so the
//!   expressions are valid at every state.
//! * [`lu_solve_at`]: `A y = b` for a general square `A`, with the pivots
//!   chosen by their numeric size at a given point (the expressions are valid
//!   near it, wherever those pivots do not vanish).

use std::collections::HashMap;
use std::fmt;

use crate::sym::{Expr, Symbol};

/// Why a symbolic solve failed.
#[derive(Clone, Debug, PartialEq)]
pub enum SolveError {
    /// The matrix is singular (or not finite) at the pivoting point.
    Singular {
        /// Elimination step at which no usable pivot was found.
        step: usize,
    },
}

impl fmt::Display for SolveError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SolveError::Singular { step } => write!(
                f,
                "the linear system is singular at the point used to choose pivots (step {step})"
            ),
        }
    }
}

impl std::error::Error for SolveError {}

/// `y = M^-1 b` for each right-hand side `b` of `rhs`, `M` symmetric positive
/// definite (only the lower triangle is read), by an `L D L^T` factorisation.
pub fn ldl_solve(m: &[Vec<Expr>], rhs: &[Vec<Expr>]) -> Vec<Vec<Expr>> {
    let n = m.len();
    let zero = Expr::zero();
    let mut l = vec![vec![zero; n]; n];
    let mut e = vec![vec![zero; n]; n]; // e_ij = L_ij d_j
    let mut dinv = vec![zero; n];
    for j in 0..n {
        let mut dj = vec![m[j][j]];
        for k in 0..j {
            dj.push(-(l[j][k] * e[j][k]));
        }
        dinv[j] = Expr::add_all(dj).recip();
        for i in j + 1..n {
            let mut v = vec![m[i][j]];
            for k in 0..j {
                v.push(-(l[i][k] * e[j][k]));
            }
            let v = Expr::add_all(v);
            e[i][j] = v;
            l[i][j] = v * dinv[j];
        }
    }
    rhs.iter()
        .map(|b| {
            let mut z = vec![zero; n];
            for i in 0..n {
                let mut v = vec![b[i]];
                for k in 0..i {
                    v.push(-(l[i][k] * z[k]));
                }
                z[i] = Expr::add_all(v);
            }
            let mut y = vec![zero; n];
            for i in (0..n).rev() {
                let mut v = vec![z[i] * dinv[i]];
                for k in i + 1..n {
                    v.push(-(l[k][i] * y[k]));
                }
                y[i] = Expr::add_all(v);
            }
            y
        })
        .collect()
}

/// `y = A^-1 b` by Gaussian elimination with partial pivoting, the pivot of
/// each column chosen by its absolute value at `point` (symbol values).
#[allow(clippy::needless_range_loop)] // row/column index loops over a matrix
pub fn lu_solve_at(
    a: &[Vec<Expr>],
    b: &[Expr],
    point: &HashMap<Symbol, f64>,
) -> Result<Vec<Expr>, SolveError> {
    let n = a.len();
    let mut a: Vec<Vec<Expr>> = a.to_vec();
    let mut b: Vec<Expr> = b.to_vec();
    let mut ev = crate::sym::Evaluator::new(point);
    let mut value = |e: Expr| -> f64 { ev.eval(e) };
    let scale: f64 = a
        .iter()
        .flatten()
        .map(|e| value(*e).abs())
        .fold(0.0, f64::max);
    for k in 0..n {
        let (p, pv) = (k..n)
            .map(|i| (i, value(a[i][k]).abs()))
            .fold((k, -1.0), |acc, x| if x.1 > acc.1 { x } else { acc });
        if pv.is_nan() || pv <= 1e-12 * scale.max(f64::MIN_POSITIVE) || !pv.is_finite() {
            return Err(SolveError::Singular { step: k });
        }
        a.swap(k, p);
        b.swap(k, p);
        let inv = a[k][k].recip();
        for i in k + 1..n {
            if a[i][k].is_zero() {
                continue;
            }
            let f = a[i][k] * inv;
            for j in k + 1..n {
                if !a[k][j].is_zero() {
                    a[i][j] = a[i][j] - f * a[k][j];
                }
            }
            b[i] = b[i] - f * b[k];
            a[i][k] = Expr::zero();
        }
    }
    let mut y = vec![Expr::zero(); n];
    for i in (0..n).rev() {
        let mut v = vec![b[i]];
        for j in i + 1..n {
            if !a[i][j].is_zero() {
                v.push(-(a[i][j] * y[j]));
            }
        }
        y[i] = Expr::add_all(v) / a[i][i];
    }
    Ok(y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_agree_with_the_matrix() {
        let (x, y) = (Expr::sym("x"), Expr::sym("y"));
        let m = vec![
            vec![2 + x.cos().powi(2), y.sin(), Expr::one()],
            vec![y.sin(), 3 + x.powi(2), x * y],
            vec![Expr::one(), x * y, 5 + y.powi(2)],
        ];
        let b = vec![x, Expr::one(), y.cos()];
        let mut point = HashMap::new();
        point.insert(Symbol::new("x"), 0.3);
        point.insert(Symbol::new("y"), -1.1);
        let s1 = ldl_solve(&m, std::slice::from_ref(&b)).remove(0);
        let s2 = lu_solve_at(&m, &b, &point).unwrap();
        for s in [s1, s2] {
            for i in 0..3 {
                let r: f64 = (0..3)
                    .map(|j| m[i][j].eval_map(&point) * s[j].eval_map(&point))
                    .sum::<f64>()
                    - b[i].eval_map(&point);
                assert!(r.abs() < 1e-12, "residual {r}");
            }
        }
    }
}
