//! The controller interface (with the modes of hybrid controllers) and a
//! plain state-feedback controller.

/// A discrete-time controller called once per sample by the control loop.
///
/// Object safe. Implementations must not allocate in [`Controller::control`]:
/// the loop's zero-allocation guarantee depends on it.
pub trait Controller {
    /// Computes the inputs `u` at time `t` (seconds since the loop started) from
    /// the measured/estimated state `x`.
    fn control(&mut self, t: f64, x: &[f64], u: &mut [f64]);
    /// Clears internal state; called when the supervisor engages the controller.
    fn reset(&mut self) {}
    /// Names of a hybrid controller's modes, in mode order (empty for other
    /// controllers). Called once before the loop starts.
    fn mode_names(&self) -> Vec<String> {
        Vec::new()
    }
    /// The mode a hybrid controller is in after the last [`Controller::control`]
    /// call (`None` for other controllers). Must not allocate.
    fn mode(&self) -> Option<Mode> {
        None
    }
    /// Whether one of a hybrid controller's modes swings the pendulum up
    /// (a runner then lets the supervisor allow `SwingUp`). Called once
    /// before the loop starts.
    fn has_swing_up_mode(&self) -> bool {
        false
    }
}

/// The current mode of a hybrid controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mode {
    /// Index into [`Controller::mode_names`].
    pub index: usize,
    /// Whether this mode swings the pendulum up (it may drive the motor with
    /// the pendulum anywhere: the supervisor's `SwingUp` state); other modes
    /// balance it (the supervisor's `Engaged` state, with the fall check).
    pub swing_up: bool,
}

/// Single-input linear state feedback `u[0] = -K x`.
///
/// Other entries of `u`, if any, are set to zero. If `k` and `x` differ in
/// length the extra entries are ignored; a NaN gain produces a NaN output,
/// which the supervisor turns into a fault.
#[derive(Debug, Clone, PartialEq)]
pub struct StateFeedback {
    /// The gain row `K`, one entry per state.
    pub k: Vec<f64>,
}

impl StateFeedback {
    /// Creates the controller from a gain row.
    pub fn new(k: Vec<f64>) -> Self {
        Self { k }
    }
}

impl Controller for StateFeedback {
    fn control(&mut self, _t: f64, x: &[f64], u: &mut [f64]) {
        let v: f64 = self.k.iter().zip(x).map(|(k, x)| k * x).sum();
        if let Some((first, rest)) = u.split_first_mut() {
            *first = -v;
            rest.fill(0.0);
        }
    }
}
