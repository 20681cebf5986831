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

use crate::error::RuntimeError;
use crate::estimator::VelocityEstimator;

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
/// correct (encoder angles). Allocates only when it is made.
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
    /// (s) with plantc-derive's `linear::design_velocity_observer`: ZOH
    /// discretisation of `(A, B)`; process noise `accel_std^2 G G^T` with
    /// `G = [T^2/2 I; T I]` (white acceleration on every joint); measurement
    /// noise the encoder quantisation, `(2 pi / counts_per_rev)^2 / 12`.
    /// Needs the `model` feature (the rig binaries of `plantc gen --rig` get
    /// the design as generated constants instead).
    #[cfg(feature = "model")]
    pub fn design(
        spec: &ObserverSpec,
        encoders: &[crate::backend::EncoderMap],
        period: f64,
    ) -> Result<Self, RuntimeError> {
        use plantc_derive::linear::{design_velocity_observer, encoder_variance};
        let variances: Vec<f64> = encoders
            .iter()
            .map(|m| encoder_variance(m.counts_per_rev))
            .collect();
        let d = design_velocity_observer(
            &spec.a,
            &spec.b,
            encoders.len(),
            period,
            spec.accel_std,
            &variances,
        )
        .map_err(|e| invalid(e.to_string()))?;
        Self::from_gains(
            d.n_positions,
            d.ad,
            d.bd,
            d.gain,
            (d.slowest_pole, d.fastest_pole),
        )
    }

    /// An observer from a finished design: `ad` (n x n), `bd` (n), `gain`
    /// (n x nq), all row-major with `n = 2 nq`, and the (slowest, fastest)
    /// pole real parts in rad/s for the report.
    pub fn from_gains(
        n_positions: usize,
        ad: Vec<f64>,
        bd: Vec<f64>,
        gain: Vec<f64>,
        poles: (f64, f64),
    ) -> Result<Self, RuntimeError> {
        let nq = n_positions;
        let n = 2 * nq;
        if nq == 0 || ad.len() != n * n || bd.len() != n || gain.len() != n * nq {
            return Err(invalid(format!(
                "Ad has {}, Bd {} and the gain {} entries for {nq} encoders",
                ad.len(),
                bd.len(),
                gain.len()
            )));
        }
        if !ad.iter().chain(&bd).chain(&gain).all(|v| v.is_finite()) {
            return Err(invalid("the design is not finite".into()));
        }
        Ok(Self {
            n,
            nq,
            ad,
            bd,
            gain,
            xh: vec![0.0; n],
            xp: vec![0.0; n],
            primed: false,
            slowest_pole: poles.0,
            fastest_pole: poles.1,
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

impl VelocityEstimator for VelocityObserver {
    fn update(&mut self, q: &[f64], _q_unwrapped: &[f64], u_prev: f64, velocities: &mut [f64]) {
        VelocityObserver::update(self, q, u_prev, velocities);
    }

    fn describe(&self) -> String {
        format!(
            "velocities: steady-state Kalman observer (poles {:.0} to {:.0} rad/s)",
            self.slowest_pole, self.fastest_pole
        )
    }
}

#[cfg(all(test, feature = "model"))]
mod tests {
    use super::*;
    use crate::backend::EncoderMap;

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
