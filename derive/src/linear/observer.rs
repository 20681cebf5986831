//! Steady-state Kalman velocity observer for encoder-only measurements.
//!
//! The design used by `plantc run` at start-up (plantc-runtime's
//! `VelocityObserver`) and by `plantc gen --rig` at generation time (the rig
//! binary gets the result as constants and does no linear algebra): the
//! linear model `x' = A x + B u` (positions, then velocities; one input) is
//! discretised by zero-order hold at the loop period `T`; the process noise
//! is white angular acceleration of standard deviation `accel_std` on every
//! joint, `Q = accel_std^2 G G^T` with `G = [T^2/2 I; T I]`; the measurement
//! noise of each encoder is given as a variance (quantisation:
//! [`encoder_variance`]). The gain comes from iterating the Riccati recursion
//! to convergence; the design is refused if it does not converge or the
//! observer is unstable.
//!
//! The observer this designs runs as: predict `xp = Ad xh + Bd u_prev`,
//! correct `xh = xp + L (q - xp[..nq])`.

use std::fmt;

use nalgebra::DMatrix;

/// Why an observer could not be designed.
#[derive(Debug, Clone, PartialEq)]
pub enum ObserverError {
    /// `A` or `B` does not fit `n_positions` (need `2 nq x 2 nq` and `2 nq x 1`),
    /// or the measurement variances are not one per position.
    Dimensions {
        /// Positions (encoders).
        n_positions: usize,
        /// Entries of `A` given.
        a_len: usize,
        /// Entries of `B` given.
        b_len: usize,
        /// Measurement variances given.
        variances: usize,
    },
    /// `A` or `B` has a NaN or infinite entry.
    NonFinite,
    /// A design setting is out of range (`what` names it).
    Setting {
        /// Which setting (`"period"`, `"acceleration noise"`, `"measurement variance"`).
        what: &'static str,
        /// Its value.
        value: f64,
    },
    /// The innovation covariance became singular.
    Singular,
    /// The Riccati recursion did not converge (the model is not detectable
    /// from the encoders, or diverges).
    NotConverged,
    /// The resulting observer is unstable.
    Unstable {
        /// Spectral radius of the error dynamics `(I - L C) Ad`.
        spectral_radius: f64,
    },
}

impl fmt::Display for ObserverError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ObserverError::Dimensions {
                n_positions,
                a_len,
                b_len,
                variances,
            } => {
                let n = 2 * n_positions;
                write!(
                    f,
                    "A has {a_len} and B {b_len} entries, {variances} measurement variances \
                     for {n_positions} encoders (need {}, {n} and {n_positions})",
                    n * n
                )
            }
            ObserverError::NonFinite => write!(f, "A or B is not finite"),
            ObserverError::Setting { what, value } => write!(f, "{what} {value} must be > 0"),
            ObserverError::Singular => write!(f, "innovation covariance singular"),
            ObserverError::NotConverged => write!(
                f,
                "the Riccati recursion did not converge (is the model detectable from the encoders?)"
            ),
            ObserverError::Unstable { spectral_radius } => {
                write!(f, "observer unstable (spectral radius {spectral_radius})")
            }
        }
    }
}

impl std::error::Error for ObserverError {}

/// A designed observer: the discrete model and the steady-state gain, all
/// row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct ObserverDesign {
    /// Number of measured positions `nq`; the state has `n = 2 nq` entries.
    pub n_positions: usize,
    /// Sample period (s) the design is for.
    pub period: f64,
    /// `Ad = exp(A T)`, `n x n`.
    pub ad: Vec<f64>,
    /// `Bd = int_0^T exp(A s) ds B`, `n` entries.
    pub bd: Vec<f64>,
    /// Steady-state Kalman gain `L`, `n x nq`.
    pub gain: Vec<f64>,
    /// Real part (rad/s) of the slowest observer pole (continuous-time equivalent).
    pub slowest_pole: f64,
    /// Real part (rad/s) of the fastest observer pole.
    pub fastest_pole: f64,
}

/// Why a linearization cannot carry the velocity observer.
#[derive(Debug, Clone, PartialEq)]
pub enum ObserverPlantError {
    /// Not exactly one input (the observer's model has one: the motor
    /// voltage).
    Inputs {
        /// Inputs of the linearization.
        count: usize,
    },
    /// The operating point is not an equilibrium (the observer is designed
    /// about it).
    NotEquilibrium {
        /// Largest |acceleration| there.
        residual: f64,
    },
}

/// `(A, B)` of `lin`, row-major, for [`design_velocity_observer`]: the
/// model `plantc run` designs its observer on at start-up and `plantc gen
/// --rig` at generation time, so both check it here. Refused without
/// exactly one input, then unless the operating point is an equilibrium
/// (largest acceleration below 1e-9).
pub fn observer_plant(
    lin: &crate::analysis::Linearization,
) -> Result<(Vec<f64>, Vec<f64>), ObserverPlantError> {
    if lin.b.ncols() != 1 {
        return Err(ObserverPlantError::Inputs {
            count: lin.b.ncols(),
        });
    }
    let residual = lin.equilibrium_residual;
    if residual.is_nan() || residual.abs() >= 1e-9 {
        return Err(ObserverPlantError::NotEquilibrium { residual });
    }
    let n = lin.a.nrows();
    let a = (0..n * n).map(|k| lin.a[(k / n, k % n)]).collect();
    let b = (0..n).map(|i| lin.b[(i, 0)]).collect();
    Ok((a, b))
}

/// Variance of the quantisation error of an encoder with `counts_per_rev`
/// counts per revolution: `(2 pi / counts_per_rev)^2 / 12` (rad^2).
pub fn encoder_variance(counts_per_rev: f64) -> f64 {
    let step = 2.0 * std::f64::consts::PI / counts_per_rev.abs();
    step * step / 12.0
}

/// Designs the steady-state Kalman velocity observer (see the module
/// documentation). `a` is `n x n` and `b` `n x 1`, row-major, with
/// `n = 2 n_positions`; `measurement_variance` has one entry per position.
pub fn design_velocity_observer(
    a: &[f64],
    b: &[f64],
    n_positions: usize,
    period: f64,
    accel_std: f64,
    measurement_variance: &[f64],
) -> Result<ObserverDesign, ObserverError> {
    let nq = n_positions;
    let n = 2 * nq;
    if nq == 0 || a.len() != n * n || b.len() != n || measurement_variance.len() != nq {
        return Err(ObserverError::Dimensions {
            n_positions,
            a_len: a.len(),
            b_len: b.len(),
            variances: measurement_variance.len(),
        });
    }
    if !a.iter().chain(b).all(|v| v.is_finite()) {
        return Err(ObserverError::NonFinite);
    }
    if !(accel_std.is_finite() && accel_std > 0.0) {
        return Err(ObserverError::Setting {
            what: "acceleration noise",
            value: accel_std,
        });
    }
    if !(period.is_finite() && period > 0.0) {
        return Err(ObserverError::Setting {
            what: "period",
            value: period,
        });
    }
    if let Some(v) = measurement_variance
        .iter()
        .find(|v| !(v.is_finite() && **v > 0.0))
    {
        return Err(ObserverError::Setting {
            what: "measurement variance",
            value: *v,
        });
    }
    // ZOH: exp([[A, B], [0, 0]] T) = [[Ad, Bd], [0, 1]].
    let mut aug = DMatrix::<f64>::zeros(n + 1, n + 1);
    for i in 0..n {
        for j in 0..n {
            aug[(i, j)] = a[i * n + j] * period;
        }
        aug[(i, n)] = b[i] * period;
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
    let q = &g * g.transpose() * (accel_std * accel_std);
    let mut r = DMatrix::<f64>::zeros(nq, nq);
    for (i, v) in measurement_variance.iter().enumerate() {
        r[(i, i)] = v.max(1e-18);
    }
    let identity = DMatrix::<f64>::identity(n, n);
    let mut p = q.clone() * 1e3 + &identity * 1e-6;
    let mut gain = DMatrix::<f64>::zeros(n, nq);
    let mut converged = false;
    for _ in 0..200_000 {
        let pp = &ad * &p * ad.transpose() + &q;
        let s = &c * &pp * c.transpose() + &r;
        let s_inv = s.try_inverse().ok_or(ObserverError::Singular)?;
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
        return Err(ObserverError::NotConverged);
    }
    let err_dyn = (&identity - &gain * &c) * &ad;
    let eig = err_dyn.complex_eigenvalues();
    let radius = eig.iter().map(|z| z.norm()).fold(0.0, f64::max);
    if radius.is_nan() || radius >= 1.0 {
        return Err(ObserverError::Unstable {
            spectral_radius: radius,
        });
    }
    // Continuous-time equivalents of the observer poles, rad/s (real parts).
    let re: Vec<f64> = eig.iter().map(|z| z.norm().ln() / period).collect();
    let slowest_pole = re.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let fastest_pole = re.iter().copied().fold(f64::INFINITY, f64::min);
    Ok(ObserverDesign {
        n_positions: nq,
        period,
        ad: (0..n * n).map(|k| ad[(k / n, k % n)]).collect(),
        bd,
        gain: (0..n * nq).map(|k| gain[(k / nq, k % nq)]).collect(),
        slowest_pole,
        fastest_pole,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A double integrator per joint.
    fn double_integrator() -> (Vec<f64>, Vec<f64>) {
        let mut a = vec![0.0; 16];
        a[2] = 1.0;
        a[4 + 3] = 1.0;
        (a, vec![0.0, 0.0, 1.0, 1.0])
    }

    #[test]
    fn zoh_of_a_double_integrator_is_exact() {
        // Ad = [[I, T I], [0, I]], Bd = [T^2/2; T] per joint (closed form).
        let (a, b) = double_integrator();
        let v = encoder_variance(4096.0);
        let d = design_velocity_observer(&a, &b, 2, 1e-3, 30.0, &[v, v]).unwrap();
        assert!((d.ad[2] - 1e-3).abs() < 1e-15, "{:?}", d.ad);
        assert!((d.bd[0] - 0.5e-6).abs() < 1e-18 && (d.bd[2] - 1e-3).abs() < 1e-15);
        assert!(d.slowest_pole < -50.0 && d.fastest_pole <= d.slowest_pole);
    }

    #[test]
    fn bad_settings_are_errors() {
        let (a, b) = double_integrator();
        let v = encoder_variance(4096.0);
        assert!(matches!(
            design_velocity_observer(&a, &b[..3], 2, 1e-3, 30.0, &[v, v]),
            Err(ObserverError::Dimensions { .. })
        ));
        assert!(matches!(
            design_velocity_observer(&a, &b, 2, 0.0, 30.0, &[v, v]),
            Err(ObserverError::Setting { what: "period", .. })
        ));
        let mut nan = a.clone();
        nan[0] = f64::NAN;
        assert_eq!(
            design_velocity_observer(&nan, &b, 2, 1e-3, 30.0, &[v, v]),
            Err(ObserverError::NonFinite)
        );
    }
}
