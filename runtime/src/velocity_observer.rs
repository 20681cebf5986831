//! Model-based velocity estimation: a steady-state Kalman filter on the
//! plant linearized about upright, discretised by zero-order hold at the loop
//! period.
//!
//! Why: a feedback-linearizing law cancels the motor's back-EMF damping with a
//! large velocity gain (about 0.56 V per rad/s on the rotary pendulum, where
//! the net arm feedback `b theta'` is only ~0.5/35 V per rad/s). A filtered
//! derivative `wc s/(s + wc)` estimates `theta' - theta''/wc`, and that lag,
//! multiplied by the large cancelling gain, destabilises the slow arm mode
//! unless `wc` is several hundred rad/s. The observer predicts with the model
//! and the applied voltage, so it has no such lag on model-consistent motion.
//! See the runtime section of ARCHITECTURE.md for the measured margins.

use crate::backend::EncoderMap;
use crate::error::RuntimeError;
use nalgebra::DMatrix;

/// Default process noise: unmodelled angular acceleration, rad/s^2 (one
/// standard deviation per joint and sample). With 4096-count encoders at
/// 1 kHz this places the observer poles near -185 ± 185j rad/s.
pub const DEFAULT_ACCEL_STD: f64 = 30.0;

/// The linear model and noise level an observer is designed from.
#[derive(Debug, Clone, PartialEq)]
pub struct ObserverSpec {
    /// `A` of `x' = A x + B u` (n x n, row-major), about the upright
    /// equilibrium (zero state, zero input). States: positions, then velocities.
    pub a: Vec<f64>,
    /// `B` (n x 1): the single input (motor voltage).
    pub b: Vec<f64>,
    /// Process noise: standard deviation of unmodelled angular acceleration
    /// on every joint (rad/s^2, default [`DEFAULT_ACCEL_STD`]).
    pub accel_std: f64,
}

impl ObserverSpec {
    /// A spec from row-major `a` and `b` with the default process noise.
    pub fn new(a: Vec<f64>, b: Vec<f64>) -> Self {
        Self {
            a,
            b,
            accel_std: DEFAULT_ACCEL_STD,
        }
    }

    /// Linearizes a smooth plant about zero state and input by central
    /// differences (step 1e-6). Terms that are not differentiable at the
    /// operating point (e.g. `sign(v)` dry friction) make this meaningless:
    /// use an analytic linearization (plantc-derive's `linearize`) for those.
    pub fn from_smooth_plant(plant: &dyn crate::plant::Plant) -> Result<Self, RuntimeError> {
        let n = plant.state_names().len();
        let m = plant.input_names().len();
        if m != 1 {
            return Err(RuntimeError::InvalidConfig(format!(
                "observer: {m} inputs, exactly one supported"
            )));
        }
        let h = 1e-6;
        let mut a = vec![0.0; n * n];
        let mut b = vec![0.0; n];
        let mut dp = vec![0.0; n];
        let mut dm = vec![0.0; n];
        let mut x = vec![0.0; n];
        for j in 0..=n {
            let (mut up, mut um) = ([0.0], [0.0]);
            if j < n {
                x[j] = h;
            } else {
                up[0] = h;
            }
            plant.derivatives(&x, &up, &mut dp);
            if j < n {
                x[j] = -h;
            } else {
                um[0] = -h;
            }
            plant.derivatives(&x, &um, &mut dm);
            if j < n {
                x[j] = 0.0;
            }
            for i in 0..n {
                let d = (dp[i] - dm[i]) / (2.0 * h);
                if j < n {
                    a[i * n + j] = d;
                } else {
                    b[i] = d;
                }
            }
        }
        Ok(Self::new(a, b))
    }
}

/// The running observer: per-sample predict (model, applied voltage) and
/// correct (encoder angles). Allocates only in [`VelocityObserver::design`].
#[derive(Debug, Clone)]
pub struct VelocityObserver {
    n: usize,
    nq: usize,
    ad: Vec<f64>,
    bd: Vec<f64>,
    /// Steady-state Kalman gain, n x nq row-major.
    gain: Vec<f64>,
    xh: Vec<f64>,
    xp: Vec<f64>,
    primed: bool,
    slowest_pole: f64,
    fastest_pole: f64,
}

fn invalid(s: String) -> RuntimeError {
    RuntimeError::InvalidConfig(format!("observer: {s}"))
}

impl VelocityObserver {
    /// Designs the steady-state Kalman filter for sample period `period`
    /// (s): ZOH discretisation of `(A, B)`; process noise `accel_std^2 G G^T`
    /// with `G = [T^2/2 I; T I]` (white acceleration on every joint);
    /// measurement noise the encoder quantisation, `(2 pi / counts_per_rev)^2 / 12`.
    /// The gain comes from iterating the Riccati recursion to convergence;
    /// the design is refused if it does not converge or the observer is unstable.
    pub fn design(
        spec: &ObserverSpec,
        encoders: &[EncoderMap],
        period: f64,
    ) -> Result<Self, RuntimeError> {
        let nq = encoders.len();
        let n = 2 * nq;
        if nq == 0 || spec.a.len() != n * n || spec.b.len() != n {
            return Err(invalid(format!(
                "A has {} and B {} entries for {nq} encoders (need {} and {n})",
                spec.a.len(),
                spec.b.len(),
                n * n
            )));
        }
        if !spec.a.iter().chain(&spec.b).all(|v| v.is_finite()) {
            return Err(invalid("A or B is not finite".into()));
        }
        if !(spec.accel_std.is_finite() && spec.accel_std > 0.0) {
            return Err(invalid(format!(
                "acceleration noise {} must be > 0",
                spec.accel_std
            )));
        }
        if !(period.is_finite() && period > 0.0) {
            return Err(invalid(format!("period {period}")));
        }
        // ZOH: exp([[A, B], [0, 0]] T) = [[Ad, Bd], [0, 1]].
        let mut aug = DMatrix::<f64>::zeros(n + 1, n + 1);
        for i in 0..n {
            for j in 0..n {
                aug[(i, j)] = spec.a[i * n + j] * period;
            }
            aug[(i, n)] = spec.b[i] * period;
        }
        let e = aug.exp();
        let ad = e.view((0, 0), (n, n)).into_owned();
        let bd: Vec<f64> = (0..n).map(|i| e[(i, n)]).collect();
        let mut c = DMatrix::<f64>::zeros(nq, n);
        for i in 0..nq {
            c[(i, i)] = 1.0;
        }
        let mut g = DMatrix::<f64>::zeros(n, nq);
        for i in 0..nq {
            g[(i, i)] = period * period / 2.0;
            g[(nq + i, i)] = period;
        }
        let q = &g * g.transpose() * (spec.accel_std * spec.accel_std);
        let mut r = DMatrix::<f64>::zeros(nq, nq);
        for (i, m) in encoders.iter().enumerate() {
            let step = 2.0 * std::f64::consts::PI / m.counts_per_rev.abs();
            if !(step.is_finite() && step > 0.0) {
                return Err(invalid(format!("encoder {i}: counts per revolution")));
            }
            r[(i, i)] = (step * step / 12.0).max(1e-18);
        }
        let identity = DMatrix::<f64>::identity(n, n);
        let mut p = q.clone() * 1e3 + &identity * 1e-6;
        let mut gain = DMatrix::<f64>::zeros(n, nq);
        let mut converged = false;
        for _ in 0..200_000 {
            let pp = &ad * &p * ad.transpose() + &q;
            let s = &c * &pp * c.transpose() + &r;
            let s_inv = s
                .try_inverse()
                .ok_or_else(|| invalid("innovation covariance singular".into()))?;
            gain = &pp * c.transpose() * s_inv;
            let pn = (&identity - &gain * &c) * &pp;
            let pn = (&pn + pn.transpose()) * 0.5;
            let scale = pn.amax().max(f64::MIN_POSITIVE);
            let change = (&pn - &p).amax();
            p = pn;
            if !p.iter().all(|v| v.is_finite()) {
                break;
            }
            if change <= 1e-12 * scale {
                converged = true;
                break;
            }
        }
        if !converged {
            return Err(invalid(
                "the Riccati recursion did not converge (is the model detectable from the encoders?)"
                    .into(),
            ));
        }
        let err_dyn = (&identity - &gain * &c) * &ad;
        let eig = err_dyn.complex_eigenvalues();
        let radius = eig.iter().map(|z| z.norm()).fold(0.0, f64::max);
        if radius.is_nan() || radius >= 1.0 {
            return Err(invalid(format!(
                "observer unstable (spectral radius {radius})"
            )));
        }
        // Continuous-time equivalents of the observer poles, rad/s (real parts).
        let re: Vec<f64> = eig.iter().map(|z| z.norm().ln() / period).collect();
        let slowest_pole = re.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let fastest_pole = re.iter().copied().fold(f64::INFINITY, f64::min);
        Ok(Self {
            n,
            nq,
            ad: (0..n * n).map(|k| ad[(k / n, k % n)]).collect(),
            bd,
            gain: (0..n * nq).map(|k| gain[(k / nq, k % nq)]).collect(),
            xh: vec![0.0; n],
            xp: vec![0.0; n],
            primed: false,
            slowest_pole,
            fastest_pole,
        })
    }

    /// Real part (rad/s) of the slowest observer pole (e.g. -185).
    pub fn slowest_pole(&self) -> f64 {
        self.slowest_pole
    }

    /// Real part (rad/s) of the fastest observer pole.
    pub fn fastest_pole(&self) -> f64 {
        self.fastest_pole
    }

    /// Feeds this sample's angles `q` (the state angles, wrapped into
    /// `(-pi, pi]` where the encoder map wraps) and the voltage applied during
    /// the previous period `u_prev`; writes the velocity estimates. The first
    /// call initialises the state to `(q, 0)`. No allocation.
    ///
    /// The linear model holds about upright (angle 0), so the observer works
    /// on the wrapped angle the controller sees: when an angle wraps by a
    /// multiple of 2 pi between samples, the estimate is shifted with it.
    pub fn update(&mut self, q: &[f64], u_prev: f64, velocities: &mut [f64]) {
        let (n, nq) = (self.n, self.nq);
        if q.len() != nq || velocities.len() != nq {
            velocities.fill(f64::NAN);
            return;
        }
        if !self.primed {
            self.primed = true;
            self.xh[..nq].copy_from_slice(q);
            self.xh[nq..].fill(0.0);
        } else {
            for (xh, q) in self.xh[..nq].iter_mut().zip(q) {
                let turns = ((q - *xh) / std::f64::consts::TAU).round();
                if turns != 0.0 && turns.is_finite() {
                    *xh += turns * std::f64::consts::TAU;
                }
            }
            for i in 0..n {
                let row = &self.ad[i * n..(i + 1) * n];
                let mut s = self.bd[i] * u_prev;
                for (a, x) in row.iter().zip(&self.xh) {
                    s += a * x;
                }
                self.xp[i] = s;
            }
            for i in 0..n {
                let gains = &self.gain[i * nq..(i + 1) * nq];
                let mut s = self.xp[i];
                for ((g, q), p) in gains.iter().zip(q).zip(&self.xp[..nq]) {
                    s += g * (q - p);
                }
                self.xh[i] = s;
            }
        }
        velocities.copy_from_slice(&self.xh[nq..]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A double integrator per joint (A = [[0, I], [0, 0]], B = [0, 0, 1, 1]).
    fn double_integrator() -> ObserverSpec {
        let mut a = vec![0.0; 16];
        a[2] = 1.0;
        a[4 + 3] = 1.0;
        ObserverSpec::new(a, vec![0.0, 0.0, 1.0, 1.0])
    }

    #[test]
    fn tracks_a_model_consistent_motion_without_lag() {
        let enc = [EncoderMap::plain(4096.0); 2];
        let mut obs = VelocityObserver::design(&double_integrator(), &enc, 1e-3).unwrap();
        assert!(obs.slowest_pole() < -50.0, "{}", obs.slowest_pole());
        // u = 2 rad/s^2 on both joints from rest: q = t^2, v = 2 t.
        let mut v = [0.0; 2];
        for k in 0..=1000 {
            let t = k as f64 * 1e-3;
            obs.update(&[t * t, t * t], 2.0, &mut v);
        }
        // A filtered derivative with wc = 50 rad/s lags a ramp by slope/wc = 0.04 rad/s.
        assert!((v[0] - 2.0).abs() < 1e-3, "{v:?}");
    }

    #[test]
    fn a_wrapping_angle_does_not_disturb_the_velocity() {
        let enc = [EncoderMap::plain(4096.0); 2];
        let mut obs = VelocityObserver::design(&double_integrator(), &enc, 1e-3).unwrap();
        // Both joints turn at 1 rad/s through +-pi at t = 0.5 s (no input).
        let mut v = [0.0; 2];
        for k in 0..=1000 {
            let t = k as f64 * 1e-3;
            let q = crate::backend::wrap_pi(std::f64::consts::PI - 0.5 + t);
            obs.update(&[q, q], 0.0, &mut v);
            // After the start-up transient (observer poles near -100 rad/s).
            if t >= 0.3 {
                assert!((v[0] - 1.0).abs() < 1e-6, "t = {t}: {v:?}");
            }
        }
    }

    #[test]
    fn refuses_bad_dimensions_and_non_finite_models() {
        let enc = [EncoderMap::plain(4096.0); 2];
        let mut bad = double_integrator();
        bad.b.pop();
        assert!(VelocityObserver::design(&bad, &enc, 1e-3).is_err());
        let mut nan = double_integrator();
        nan.a[0] = f64::NAN;
        assert!(VelocityObserver::design(&nan, &enc, 1e-3).is_err());
    }
}
