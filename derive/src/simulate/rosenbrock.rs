//! A linearly implicit (Rosenbrock) integrator for stiff models: the
//! L-stable second-order method of Shampine & Reichelt (1997) behind
//! MATLAB's `ode23s`, with its third-order error estimate (designed to stay
//! small on stiff components, which an explicit-style estimate would keep
//! rejecting), and the same interface as [`super::rk::DormandPrince`] (lands
//! exactly on every requested end time).
//!
//! Per step, for an autonomous `x' = f(x)` (inputs change only between
//! [`Rosenbrock::advance`] calls in [`super::simulate`]): a Jacobian
//! `J = df/dx` by forward differences (`n + 1` right-hand sides), one LU
//! factorisation of `W = I - d h J` with `d = 1/(2 + sqrt 2)`, three solves:
//!
//! ```text
//! F0 = f(x)                       k1 = W^-1 F0
//! F1 = f(x + h k1 / 2)            k2 = W^-1 (F1 - k1) + k1
//! x+ = x + h k2                   F2 = f(x+)
//! k3 = W^-1 (F2 - e32 (k2 - F1) - 2 (k1 - F0)),  e32 = 6 + sqrt 2
//! error = h (k1 - 2 k2 + k3) / 6
//! ```
//!
//! A stiff mode (a tiny resistance or inertia: eigenvalues of `-1e8 /s`)
//! costs an explicit method `|lambda| / 3.3` steps per second; this one takes
//! steps set by accuracy alone.

use super::rk::{Dense, DenseKind, RkError, RkOptions, RkStats};

/// `d = 1 / (2 + sqrt 2)`.
const D: f64 = 0.292_893_218_813_452_5;
/// `e32 = 6 + sqrt 2`.
const E32: f64 = 7.414_213_562_373_095;
const SAFETY: f64 = 0.8;
const FAC_MIN: f64 = 0.2;
const FAC_MAX: f64 = 5.0;

/// The integrator state. Allocates only in [`Rosenbrock::new`].
#[derive(Clone, Debug)]
pub struct Rosenbrock {
    opts: RkOptions,
    n: usize,
    f0: Vec<f64>,
    fx: Vec<f64>,
    xt: Vec<f64>,
    k1: Vec<f64>,
    k2: Vec<f64>,
    k3: Vec<f64>,
    f1: Vec<f64>,
    f2: Vec<f64>,
    x1: Vec<f64>,
    /// `W = I - d h J`, row-major, factorised in place.
    m: Vec<f64>,
    jac: Vec<f64>,
    piv: Vec<usize>,
    h: f64,
    /// Counts since construction (`evaluations` includes the Jacobians').
    pub stats: RkStats,
}

impl Rosenbrock {
    /// An integrator for `n` states.
    pub fn new(n: usize, opts: RkOptions) -> Rosenbrock {
        Rosenbrock {
            opts,
            n,
            f0: vec![0.0; n],
            fx: vec![0.0; n],
            xt: vec![0.0; n],
            k1: vec![0.0; n],
            k2: vec![0.0; n],
            k3: vec![0.0; n],
            f1: vec![0.0; n],
            f2: vec![0.0; n],
            x1: vec![0.0; n],
            m: vec![0.0; n * n],
            jac: vec![0.0; n * n],
            piv: vec![0; n],
            h: 0.0,
            stats: RkStats::default(),
        }
    }

    /// Nothing is carried between steps but the step proposal (kept).
    pub fn restart(&mut self) {}

    fn norm(&self, x: &[f64], y: &[f64], v: &[f64]) -> f64 {
        let mut s = 0.0;
        for i in 0..v.len() {
            let sc = self.opts.atol + self.opts.rtol * x[i].abs().max(y[i].abs());
            let r = v[i] / sc;
            s += r * r;
        }
        (s / v.len().max(1) as f64).sqrt()
    }

    /// `J = df/dx` at `(t, x)` by forward differences; `f0 = f(t, x)`.
    fn jacobian<E, F>(&mut self, f: &mut F, t: f64, x: &[f64]) -> Result<(), E>
    where
        F: FnMut(f64, &[f64], &mut [f64]) -> Result<(), E>,
    {
        let n = self.n;
        self.xt.copy_from_slice(x);
        for (j, &xj) in x.iter().enumerate().take(n) {
            let d = f64::EPSILON.sqrt() * xj.abs().max(1.0);
            self.xt[j] = xj + d;
            f(t, &self.xt, &mut self.fx)?;
            self.xt[j] = xj;
            for i in 0..n {
                self.jac[i * n + j] = (self.fx[i] - self.f0[i]) / d;
            }
        }
        self.stats.evaluations += n;
        Ok(())
    }

    /// Factorises `W = I - d h J` with partial pivoting; false if singular
    /// or not finite.
    fn factor(&mut self, h: f64) -> bool {
        let n = self.n;
        for i in 0..n {
            for j in 0..n {
                let id = if i == j { 1.0 } else { 0.0 };
                self.m[i * n + j] = id - D * h * self.jac[i * n + j];
            }
        }
        for c in 0..n {
            let mut p = c;
            for r in c + 1..n {
                if self.m[r * n + c].abs() > self.m[p * n + c].abs() {
                    p = r;
                }
            }
            self.piv[c] = p;
            if p != c {
                for j in 0..n {
                    self.m.swap(c * n + j, p * n + j);
                }
            }
            let d = self.m[c * n + c];
            if d == 0.0 || !d.is_finite() {
                return false;
            }
            for r in c + 1..n {
                let l = self.m[r * n + c] / d;
                self.m[r * n + c] = l;
                for j in c + 1..n {
                    self.m[r * n + j] -= l * self.m[c * n + j];
                }
            }
        }
        true
    }

    /// Solves with the factorisation, `b` overwritten by the solution.
    fn solve(m: &[f64], piv: &[usize], b: &mut [f64]) {
        let n = b.len();
        for c in 0..n {
            b.swap(c, piv[c]);
            for r in c + 1..n {
                b[r] -= m[r * n + c] * b[c];
            }
        }
        for c in (0..n).rev() {
            for j in c + 1..n {
                b[c] -= m[c * n + j] * b[j];
            }
            b[c] /= m[c * n + c];
        }
    }

    /// Integrate `x' = f(t, x)` from `t0` to exactly `t1` (`x` updated in
    /// place). `f` must not depend on `t` within the call (inputs change only
    /// between calls, as in [`super::simulate`]).
    pub fn advance<E, F>(
        &mut self,
        f: &mut F,
        t0: f64,
        t1: f64,
        x: &mut [f64],
    ) -> Result<(), RkError<E>>
    where
        F: FnMut(f64, &[f64], &mut [f64]) -> Result<(), E>,
    {
        self.advance_until(f, &mut |_: &Dense<'_>| Ok(None), t0, t1, x)
            .map(|_| ())
    }

    /// [`Rosenbrock::advance`], stopping at an event as
    /// [`super::rk::DormandPrince::advance_until`] does; the step's dense
    /// output is the cubic Hermite interpolant of its ends.
    pub fn advance_until<E, F, S>(
        &mut self,
        f: &mut F,
        stop: &mut S,
        t0: f64,
        t1: f64,
        x: &mut [f64],
    ) -> Result<Option<f64>, RkError<E>>
    where
        F: FnMut(f64, &[f64], &mut [f64]) -> Result<(), E>,
        S: FnMut(&Dense<'_>) -> Result<Option<f64>, E>,
    {
        if t1 <= t0 {
            return Ok(None);
        }
        let n = self.n;
        if self.h <= 0.0 {
            self.h = (t1 - t0).min(1e-3);
        }
        let mut t = t0;
        let mut steps = 0usize;
        let mut fresh = false; // f0 and the Jacobian belong to (t, x)
        loop {
            let remaining = t1 - t;
            let mut h = self.h.min(self.opts.max_step);
            let last = h >= remaining * (1.0 - 1e-12);
            if last {
                h = remaining;
            }
            steps += 1;
            if steps > self.opts.max_steps {
                return Err(RkError::TooManySteps { t });
            }
            if !fresh {
                f(t, x, &mut self.f0).map_err(RkError::Rhs)?;
                self.stats.evaluations += 1;
                self.jacobian(f, t, x).map_err(RkError::Rhs)?;
                fresh = true;
            }
            let mut ok = self.factor(h);
            if ok {
                // k1 = W^-1 F0
                self.k1.copy_from_slice(&self.f0);
                Self::solve(&self.m, &self.piv, &mut self.k1);
                // F1 = f(x + h k1 / 2); k2 = W^-1 (F1 - k1) + k1
                for ((xt, &xi), &k1) in self.xt.iter_mut().zip(x.iter()).zip(&self.k1) {
                    *xt = xi + 0.5 * h * k1;
                }
                f(t + 0.5 * h, &self.xt, &mut self.f1).map_err(RkError::Rhs)?;
                for i in 0..n {
                    self.k2[i] = self.f1[i] - self.k1[i];
                }
                Self::solve(&self.m, &self.piv, &mut self.k2);
                for ((k2, x1), (&xi, &k1)) in self
                    .k2
                    .iter_mut()
                    .zip(self.x1.iter_mut())
                    .zip(x.iter().zip(&self.k1))
                {
                    *k2 += k1;
                    *x1 = xi + h * *k2;
                }
                // F2 = f(x+); k3 = W^-1 (F2 - e32 (k2 - F1) - 2 (k1 - F0))
                f(t + h, &self.x1, &mut self.k3).map_err(RkError::Rhs)?;
                self.f2.copy_from_slice(&self.k3);
                self.stats.evaluations += 2;
                for i in 0..n {
                    self.k3[i] -= E32 * (self.k2[i] - self.f1[i]) + 2.0 * (self.k1[i] - self.f0[i]);
                }
                Self::solve(&self.m, &self.piv, &mut self.k3);
                for i in 0..n {
                    self.xt[i] = h / 6.0 * (self.k1[i] - 2.0 * self.k2[i] + self.k3[i]);
                }
                ok = self.x1.iter().all(|v| v.is_finite());
            }
            let err = if ok {
                self.norm(x, &self.x1, &self.xt)
            } else {
                f64::INFINITY
            };
            if err.is_finite() && err <= 1.0 {
                self.stats.accepted += 1;
                let fac = (SAFETY * err.max(1e-10).powf(-1.0 / 3.0)).clamp(FAC_MIN, FAC_MAX);
                let proposal = h * fac;
                if !(last && h < self.h && fac >= 1.0) {
                    self.h = proposal;
                }
                let dense = Dense {
                    t,
                    h,
                    y0: x,
                    y1: &self.x1,
                    kind: DenseKind::Hermite {
                        f0: &self.f0,
                        f1: &self.f2,
                    },
                };
                if let Some(theta) = stop(&dense).map_err(RkError::Rhs)? {
                    let theta = theta.clamp(0.0, 1.0);
                    dense.at(theta, &mut self.xt);
                    x.copy_from_slice(&self.xt);
                    return Ok(Some(if theta == 1.0 { t + h } else { t + theta * h }));
                }
                x.copy_from_slice(&self.x1);
                fresh = false;
                if last {
                    return Ok(None);
                }
                t += h;
            } else {
                self.stats.rejected += 1;
                let fac = if err.is_finite() {
                    (SAFETY * err.powf(-1.0 / 3.0)).max(FAC_MIN)
                } else {
                    FAC_MIN
                };
                self.h = h * fac;
                if self.h < self.opts.min_step.max(1e-15 * t.abs()) {
                    return Err(RkError::StepTooSmall { t, h: self.h });
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `x' = lambda (x - cos s) - sin s, s' = 1`: the solution is `x = cos s`
    /// after a transient decaying like `exp(lambda t)`; autonomous.
    fn rhs(lambda: f64) -> impl FnMut(f64, &[f64], &mut [f64]) -> Result<(), ()> {
        move |_t, x, dx| {
            dx[0] = lambda * (x[0] - x[1].cos()) - x[1].sin();
            dx[1] = 1.0;
            Ok(())
        }
    }

    #[test]
    fn stiff_problem_in_few_steps() {
        // lambda = -1e8 would need ~6e7 explicit steps for 2 s
        let mut r = Rosenbrock::new(
            2,
            RkOptions {
                rtol: 1e-6,
                atol: 1e-9,
                ..RkOptions::default()
            },
        );
        let mut x = [2.0, 0.0]; // off the slow manifold: a fast transient first
        let mut f = rhs(-1e8);
        for k in 0..200 {
            let (a, b) = (k as f64 * 0.01, (k + 1) as f64 * 0.01);
            r.advance(&mut f, a, b, &mut x).unwrap();
        }
        assert!((x[0] - 2f64.cos()).abs() < 1e-5, "{}", x[0]);
        assert!(r.stats.accepted < 5_000, "{:?}", r.stats);
    }

    #[test]
    fn accurate_on_a_smooth_problem() {
        // x' = -x, x(0) = 1 -> e^-1 at t = 1
        let mut r = Rosenbrock::new(
            1,
            RkOptions {
                rtol: 1e-8,
                atol: 1e-12,
                ..RkOptions::default()
            },
        );
        let mut x = [1.0];
        r.advance(
            &mut |_t: f64, x: &[f64], dx: &mut [f64]| -> Result<(), ()> {
                dx[0] = -x[0];
                Ok(())
            },
            0.0,
            1.0,
            &mut x,
        )
        .unwrap();
        assert!((x[0] - (-1f64).exp()).abs() < 1e-6, "{}", x[0]);
    }
}
