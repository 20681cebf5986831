//! Savitzky-Golay kernels: value and derivatives of a local least-squares
//! polynomial, as convolution weights.
//!
//! For a window of `2h + 1` uniformly spaced samples and a polynomial of
//! degree `order`, the fit `c = (A'A)^-1 A' y` with `A_jp = x_j^p`,
//! `x_j = j / h` (`j = -h..h`, scaled for conditioning) is linear in `y`, so
//! the `d`-th time derivative of the fitted polynomial at the window centre is
//! `sum_j w_j y_j` with `w = d! e_d' (A'A)^-1 A' / (h T)^d`. The kernels are
//! derived here rather than tabulated, for any window and order.
//!
//! Used by the equation-error ranking to estimate velocities and
//! accelerations from quantised angles (identification notes, trap 1: 61
//! samples, order 5 at 500 Hz).

use std::fmt;

/// Why a kernel cannot be built.
#[derive(Clone, Debug, PartialEq)]
pub enum KernelError {
    /// The window has fewer points than the polynomial has coefficients.
    WindowTooShort {
        /// Half width `h` (window `2h + 1`).
        half_width: usize,
        /// Polynomial degree.
        order: usize,
    },
    /// The derivative order exceeds the polynomial degree.
    DerivativeTooHigh {
        /// Derivative asked for.
        derivative: usize,
        /// Polynomial degree.
        order: usize,
    },
    /// The sample time is not positive and finite.
    BadSampleTime(f64),
}

impl fmt::Display for KernelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            KernelError::WindowTooShort { half_width, order } => write!(
                f,
                "a Savitzky-Golay window of {} samples cannot fit a degree-{order} polynomial",
                2 * half_width + 1
            ),
            KernelError::DerivativeTooHigh { derivative, order } => write!(
                f,
                "derivative {derivative} of a degree-{order} polynomial is not estimable"
            ),
            KernelError::BadSampleTime(t) => write!(f, "sample time must be positive, got {t}"),
        }
    }
}

impl std::error::Error for KernelError {}

/// Weights `w_{-h..h}` (index `j + h`) of the `derivative`-th time
/// derivative at the window centre, for sample time `dt`.
pub fn kernel(
    half_width: usize,
    order: usize,
    derivative: usize,
    dt: f64,
) -> Result<Vec<f64>, KernelError> {
    if 2 * half_width < order {
        return Err(KernelError::WindowTooShort { half_width, order });
    }
    if derivative > order {
        return Err(KernelError::DerivativeTooHigh { derivative, order });
    }
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(KernelError::BadSampleTime(dt));
    }
    let np = order + 1;
    let h = half_width as f64;
    let xs: Vec<f64> = (0..=2 * half_width)
        .map(|j| (j as f64 - h) / h.max(1.0))
        .collect();
    // Gram matrix G_pq = sum_j x^(p+q); solve G c = e_d for row d of G^-1
    let mut g = vec![0.0; np * np];
    for &x in &xs {
        let mut pows = vec![1.0; 2 * np];
        for k in 1..2 * np {
            pows[k] = pows[k - 1] * x;
        }
        for p in 0..np {
            for q in 0..np {
                g[p * np + q] += pows[p + q];
            }
        }
    }
    let mut e = vec![0.0; np];
    e[derivative] = 1.0;
    let row = solve(g, np, e);
    let fact: f64 = (1..=derivative).map(|k| k as f64).product();
    let scale = fact / (h.max(1.0) * dt).powi(derivative as i32);
    Ok(xs
        .iter()
        .map(|&x| {
            let mut s = 0.0;
            let mut xp = 1.0;
            for c in &row {
                s += c * xp;
                xp *= x;
            }
            s * scale
        })
        .collect())
}

/// Gaussian elimination with partial pivoting of the small SPD Gram system.
fn solve(mut a: Vec<f64>, n: usize, mut b: Vec<f64>) -> Vec<f64> {
    for c in 0..n {
        let p = (c..n)
            .max_by(|&i, &j| a[i * n + c].abs().total_cmp(&a[j * n + c].abs()))
            .unwrap_or(c);
        if p != c {
            for k in 0..n {
                a.swap(c * n + k, p * n + k);
            }
            b.swap(c, p);
        }
        let d = a[c * n + c];
        for r in c + 1..n {
            let f = a[r * n + c] / d;
            for k in c..n {
                a[r * n + k] -= f * a[c * n + k];
            }
            b[r] -= f * b[c];
        }
    }
    for c in (0..n).rev() {
        let mut s = b[c];
        for k in c + 1..n {
            s -= a[c * n + k] * b[k];
        }
        b[c] = s / a[c * n + c];
    }
    b
}

/// Convolve `y` with a centred kernel of odd length `2h + 1`: the result
/// has `y.len() - 2h` values, entry `k` belonging to sample `k + h` (empty
/// when `y` is shorter than the kernel).
pub fn apply(w: &[f64], y: &[f64]) -> Vec<f64> {
    let len = w.len();
    if y.len() < len {
        return Vec::new();
    }
    (0..=y.len() - len)
        .map(|k| w.iter().zip(&y[k..k + len]).map(|(a, b)| a * b).sum())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernels_are_exact_on_polynomials() {
        let dt = 0.002;
        let h = 30;
        let f = |t: f64| 0.3 - 1.2 * t + 2.0 * t * t - 4.0 * t.powi(3) + 7.0 * t.powi(5);
        let df = |t: f64| -1.2 + 4.0 * t - 12.0 * t * t + 35.0 * t.powi(4);
        let ddf = |t: f64| 4.0 - 24.0 * t + 140.0 * t.powi(3);
        let y: Vec<f64> = (0..200).map(|k| f(k as f64 * dt)).collect();
        for (d, g) in [(0usize, &f as &dyn Fn(f64) -> f64), (1, &df), (2, &ddf)] {
            let w = kernel(h, 5, d, dt).unwrap();
            let z = apply(&w, &y);
            assert_eq!(z.len(), 200 - 2 * h);
            for (k, v) in z.iter().enumerate() {
                let t = (k + h) as f64 * dt;
                assert!(
                    (v - g(t)).abs() < 1e-8 * (1.0 + g(t).abs()),
                    "d{d} {v} {}",
                    g(t)
                );
            }
        }
    }

    #[test]
    fn bad_arguments_are_errors() {
        assert!(matches!(
            kernel(1, 5, 0, 1.0),
            Err(KernelError::WindowTooShort { .. })
        ));
        assert!(matches!(
            kernel(10, 2, 3, 1.0),
            Err(KernelError::DerivativeTooHigh { .. })
        ));
        assert!(kernel(10, 2, 1, 0.0).is_err());
    }
}
