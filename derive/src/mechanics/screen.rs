//! Numeric screening of symbolic facts: evaluate at a few random states (a
//! deterministic generator, nominal parameter values) before, or instead of,
//! an exact computation. A value well above rounding proves an expression
//! nonzero; only a vanishing one needs the exact test.

use std::collections::HashMap;

use nalgebra::DMatrix;

use super::Equations;
use crate::model::{Model, ParameterValues};
use crate::sym::{Expr, Symbol};

/// A small deterministic generator (xorshift) for screening states.
pub(crate) struct Rng(u64);

impl Rng {
    pub(crate) fn new(seed: u64) -> Rng {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    /// Uniform in `[lo, hi)`.
    pub(crate) fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
    }
}

/// `count` random states (coordinates in `[-1.5, 1.5]`, velocities in
/// `[-2, 2]`) with the nominal parameter values and zero inputs.
pub fn screening_points(model: &Model, eqs: &Equations, count: usize) -> Vec<HashMap<Symbol, f64>> {
    let values =
        ParameterValues::from_base(model, model.parameters.iter().map(|p| p.value).collect());
    let base = values.symbol_map(model);
    let mut rng = Rng::new(16);
    (0..count)
        .map(|_| {
            let mut p = base.clone();
            for c in &eqs.coords {
                p.insert(c.q, rng.uniform(-1.5, 1.5));
                p.insert(c.qd, rng.uniform(-2.0, 2.0));
            }
            for u in &eqs.inputs {
                p.insert(*u, 0.0);
            }
            p
        })
        .collect()
}

/// Smallest `lambda_min(M) / lambda_max(M)` over the screening states (0 if
/// `M` is singular or not finite at one of them).
pub fn mass_matrix_conditioning(model: &Model, eqs: &Equations, count: usize) -> f64 {
    let n = eqs.coords.len();
    let mut worst = f64::INFINITY;
    for p in screening_points(model, eqs, count) {
        let flat: Vec<Expr> = eqs.mass_matrix.iter().flatten().copied().collect();
        let v = Expr::eval_all(&flat, &p);
        let m = DMatrix::from_fn(n, n, |i, j| v[i * n + j]);
        if m.iter().any(|v| !v.is_finite()) {
            return 0.0;
        }
        let eig = m.symmetric_eigenvalues();
        let (lo, hi) = (eig.min(), eig.amax());
        worst = worst.min(if hi > 0.0 { lo / hi } else { 0.0 });
    }
    if n == 0 {
        1.0
    } else {
        worst.max(0.0)
    }
}
