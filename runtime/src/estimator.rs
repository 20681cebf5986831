//! The velocity-estimator interface of the control loop, and the filtered
//! derivative bank behind `--velocity derivative`.
//!
//! The loop measures angles only; an estimator turns them (and the voltage
//! applied during the last period) into velocities. The runtime's own
//! estimators are [`DerivativeEstimator`] and
//! [`crate::velocity_observer::VelocityObserver`]; a generated rig binary
//! passes its generated observer (constants computed at generation time)
//! through the same trait.

use crate::velocity_filter::VelocityFilter;

/// Estimates the velocities of the measured positions, once per sample.
///
/// Implementations must not allocate in [`VelocityEstimator::update`].
pub trait VelocityEstimator {
    /// Feeds this sample's angles: `q` as the controller sees them (wrapped
    /// into `(-pi, pi]` where the encoder map wraps), `q_unwrapped` continuous
    /// (for differentiation), and the voltage applied during the previous
    /// period `u_prev`; writes one velocity per position. The first call
    /// initialises the estimator.
    fn update(&mut self, q: &[f64], q_unwrapped: &[f64], u_prev: f64, velocities: &mut [f64]);
    /// One line for the run report, e.g. `velocities: filtered derivative, bandwidth 50 rad/s`.
    fn describe(&self) -> String;
}

/// One filtered derivative `wc s / (s + wc)` per encoder (Quanser's examples).
#[derive(Debug, Clone)]
pub struct DerivativeEstimator {
    filters: Vec<VelocityFilter>,
    bandwidth: f64,
}

impl DerivativeEstimator {
    /// `n_positions` filters of bandwidth `wc` (rad/s) at sample period `period` (s).
    pub fn new(n_positions: usize, wc: f64, period: f64) -> Self {
        Self {
            filters: vec![VelocityFilter::new(wc, period); n_positions],
            bandwidth: wc,
        }
    }
}

impl VelocityEstimator for DerivativeEstimator {
    fn update(&mut self, _q: &[f64], q_unwrapped: &[f64], _u_prev: f64, velocities: &mut [f64]) {
        for ((v, f), q) in velocities
            .iter_mut()
            .zip(self.filters.iter_mut())
            .zip(q_unwrapped)
        {
            *v = f.update(*q);
        }
    }

    fn describe(&self) -> String {
        format!(
            "velocities: filtered derivative, bandwidth {} rad/s",
            self.bandwidth
        )
    }
}
