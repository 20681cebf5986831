//! Fixed-step RK4 integration of a [`Plant`] with the input held constant.

use crate::plant::Plant;

/// Scratch space for [`rk4_step`], allocated once so stepping never allocates.
#[derive(Debug, Clone)]
pub struct Rk4Scratch {
    k1: Vec<f64>,
    k2: Vec<f64>,
    k3: Vec<f64>,
    k4: Vec<f64>,
    tmp: Vec<f64>,
}

impl Rk4Scratch {
    /// Scratch for a plant with `n` states.
    pub fn new(n: usize) -> Self {
        Self {
            k1: vec![0.0; n],
            k2: vec![0.0; n],
            k3: vec![0.0; n],
            k4: vec![0.0; n],
            tmp: vec![0.0; n],
        }
    }
}

/// Advances `x` by one classical Runge-Kutta step of length `h` with input `u`
/// held constant (zero-order hold). If the scratch is too small for `x`, `x`
/// is filled with NaN instead of panicking.
pub fn rk4_step<P: Plant + ?Sized>(
    plant: &P,
    x: &mut [f64],
    u: &[f64],
    h: f64,
    s: &mut Rk4Scratch,
) {
    let n = x.len();
    if s.k1.len() != n {
        x.fill(f64::NAN);
        return;
    }
    plant.derivatives(x, u, &mut s.k1);
    for ((t, xi), k) in s.tmp.iter_mut().zip(x.iter()).zip(&s.k1) {
        *t = xi + 0.5 * h * k;
    }
    plant.derivatives(&s.tmp, u, &mut s.k2);
    for ((t, xi), k) in s.tmp.iter_mut().zip(x.iter()).zip(&s.k2) {
        *t = xi + 0.5 * h * k;
    }
    plant.derivatives(&s.tmp, u, &mut s.k3);
    for ((t, xi), k) in s.tmp.iter_mut().zip(x.iter()).zip(&s.k3) {
        *t = xi + h * k;
    }
    plant.derivatives(&s.tmp, u, &mut s.k4);
    for (i, xi) in x.iter_mut().enumerate() {
        *xi += h / 6.0 * (s.k1[i] + 2.0 * s.k2[i] + 2.0 * s.k3[i] + s.k4[i]);
    }
}
