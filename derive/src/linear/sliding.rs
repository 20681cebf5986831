//! Linear sliding surfaces `s = c x` for a single input: design by
//! Ackermann's formula (Ackermann and Utkin, "Sliding mode control design
//! based on Ackermann's formula", IEEE TAC 43(2), 1998) and the reduced
//! (sliding) dynamics on `s = 0` under the equivalent control.

use nalgebra::DMatrix;

use super::error::{check_pair, LinearError};
use super::place::{
    char_poly, last_row_of_inverse_controllability, matrix_polynomial, pole_match_error,
};
use super::poles::{poles, Pole};

/// A designed surface.
#[derive(Debug, Clone, PartialEq)]
pub struct SlidingSurface {
    /// `c` (one entry per state); `c B = 1`.
    pub c: Vec<f64>,
    /// The sliding dynamics with this surface.
    pub reduced: ReducedDynamics,
    /// Largest distance between a desired and an achieved sliding pole,
    /// relative to `max(|desired|, 1)`.
    pub max_pole_error: f64,
}

/// `c = e_n' C^-1 p1(A)` with `p1` the monic polynomial of the `n - 1`
/// desired sliding poles: then `c B = 1` and the dynamics on `c x = 0` under
/// the equivalent control `u = -(c B)^-1 c A x` have exactly these poles.
pub fn sliding_surface(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    desired: &[Pole],
) -> Result<SlidingSurface, LinearError> {
    check_pair(a, b)?;
    if b.ncols() != 1 {
        return Err(LinearError::MultiInputUnsupported { inputs: b.ncols() });
    }
    let n = a.nrows();
    if n < 2 {
        return Err(LinearError::PoleCountMismatch {
            expected: 1,
            found: desired.len(),
        });
    }
    super::place::check_desired_poles(desired, n - 1)?;
    let w = last_row_of_inverse_controllability(a, b)?;
    let p1 = matrix_polynomial(a, &char_poly(desired));
    let c: Vec<f64> = (w.transpose() * p1).iter().copied().collect();
    if c.iter().any(|v| !v.is_finite()) {
        return Err(LinearError::SingularSystem {
            what: "sliding surface is not finite",
        });
    }
    let reduced = reduced_dynamics(a, b, &c)?;
    let max_pole_error = pole_match_error(desired, &reduced.poles);
    Ok(SlidingSurface {
        c,
        reduced,
        max_pole_error,
    })
}

/// The dynamics on `c x = 0` with the equivalent control.
#[derive(Debug, Clone, PartialEq)]
pub struct ReducedDynamics {
    /// `c B`: must be nonzero for the input to reach the surface in one step
    /// of differentiation (relative degree 1).
    pub cb: f64,
    /// `A_eq = (I - B (c B)^-1 c) A`: the closed loop under the equivalent
    /// control (`c A_eq = 0`, so `s` stays constant).
    pub a_eq: DMatrix<f64>,
    /// The state expressed by the others on the surface (largest `|c_k|`):
    /// `x_k = -(sum_{j != k} c_j x_j) / c_k`.
    pub eliminated: usize,
    /// `z' = A_r z` with `z` the states other than `eliminated`, in order.
    pub a_r: DMatrix<f64>,
    /// Eigenvalues of `A_r` (canonical order).
    pub poles: Vec<Pole>,
}

impl ReducedDynamics {
    /// Every sliding pole has a negative real part.
    pub fn asymptotically_stable(&self) -> bool {
        self.poles.iter().all(|p| p.re < 0.0)
    }
}

/// Reduced dynamics of `x' = A x + B u` on `c x = 0` under the equivalent control.
pub fn reduced_dynamics(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    c: &[f64],
) -> Result<ReducedDynamics, LinearError> {
    check_pair(a, b)?;
    if b.ncols() != 1 {
        return Err(LinearError::MultiInputUnsupported { inputs: b.ncols() });
    }
    let n = a.nrows();
    if c.len() != n || n < 2 {
        return Err(LinearError::DimensionMismatch {
            matrix: "c",
            expected: (1, n),
            found: (1, c.len()),
        });
    }
    let cr = DMatrix::from_row_slice(1, n, c);
    let cb = (&cr * b)[(0, 0)];
    let scale = c.iter().fold(0.0f64, |m, v| m.max(v.abs())) * b.amax();
    if cb.abs() <= 1e-12 * scale || !cb.is_finite() {
        return Err(LinearError::SingularSystem {
            what: "c B = 0: the input does not reach the surface (relative degree above 1)",
        });
    }
    let a_eq = (DMatrix::identity(n, n) - b * &cr / cb) * a;
    let eliminated = (0..n)
        .max_by(|&i, &j| c[i].abs().total_cmp(&c[j].abs()))
        .unwrap_or(n - 1);
    // x = T z: identity on the kept states, the surface for the eliminated one.
    let kept: Vec<usize> = (0..n).filter(|&i| i != eliminated).collect();
    let mut t = DMatrix::zeros(n, n - 1);
    for (col, &j) in kept.iter().enumerate() {
        t[(j, col)] = 1.0;
        t[(eliminated, col)] = -c[j] / c[eliminated];
    }
    let mut a_r = DMatrix::zeros(n - 1, n - 1);
    let full = &a_eq * &t;
    for (row, &i) in kept.iter().enumerate() {
        for col in 0..n - 1 {
            a_r[(row, col)] = full[(i, col)];
        }
    }
    let poles = poles(&a_r)?;
    Ok(ReducedDynamics {
        cb,
        a_eq,
        eliminated,
        a_r,
        poles,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn double_integrator_surface_by_hand() {
        // x1' = x2, x2' = u; s = lambda x1 + x2 gives x1' = -lambda x1 on s = 0.
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        let s = sliding_surface(&a, &b, &[Pole::new(-3.0, 0.0)]).unwrap();
        assert!((s.c[0] - 3.0).abs() < 1e-12 && (s.c[1] - 1.0).abs() < 1e-12);
        let r = reduced_dynamics(&a, &b, &[3.0, 1.0]).unwrap();
        assert_eq!(r.eliminated, 0);
        // keeping x2: x2' = -3 x2 on the surface as well
        assert!((r.a_r[(0, 0)] + 3.0).abs() < 1e-12);
        assert!(r.asymptotically_stable());
    }

    #[test]
    fn unreachable_surface_is_an_error() {
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, 0.0]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        assert!(reduced_dynamics(&a, &b, &[1.0, 0.0]).is_err());
    }
}
