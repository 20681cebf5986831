//! The safety supervisor: an explicit state machine Idle -> Armed -> Engaged -> Fault.
//!
//! Only `Engaged` lets the controller drive the motor; in every other state the
//! loop writes 0 V. `Fault` is terminal for a run.

use crate::backend::wrap_pi;
use std::f64::consts::PI;
use std::fmt;

/// Why the supervisor stopped the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FaultKind {
    /// The pendulum left the fall window while engaged.
    PendulumFell,
    /// The arm passed its angle limit while engaged.
    ArmLimit,
    /// The controller produced NaN or infinity.
    NonFiniteOutput,
    /// The controller panicked.
    ControllerPanic,
    /// Too many consecutive overruns.
    Overrun,
    /// Reading the encoders (or waiting for the sample clock) failed.
    ReadError,
    /// Writing the motor voltage failed.
    WriteError,
    /// Reloading the watchdog failed.
    WatchdogError,
    /// The hardware watchdog had expired.
    WatchdogExpired,
    /// The encoders stopped changing while engaged for longer than plausible.
    EncoderStuck,
    /// The stop flag (Ctrl-C) was set.
    Stopped,
    /// The simulated plant diverged (its state is no longer finite): a
    /// modelling or parameter problem, not the encoder's.
    PlantDiverged,
}

impl FaultKind {
    /// Short snake_case name, as written in logs (`fault:<name>`).
    pub fn name(self) -> &'static str {
        match self {
            FaultKind::PendulumFell => "pendulum_fell",
            FaultKind::ArmLimit => "arm_limit",
            FaultKind::NonFiniteOutput => "non_finite_output",
            FaultKind::ControllerPanic => "controller_panic",
            FaultKind::Overrun => "overrun",
            FaultKind::ReadError => "read_error",
            FaultKind::WriteError => "write_error",
            FaultKind::WatchdogError => "watchdog_error",
            FaultKind::WatchdogExpired => "watchdog_expired",
            FaultKind::EncoderStuck => "encoder_stuck",
            FaultKind::Stopped => "stopped",
            FaultKind::PlantDiverged => "plant_diverged",
        }
    }
}

/// The supervisor's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SupervisorState {
    /// Not started.
    Idle,
    /// Running, output held at 0 V, waiting for the pendulum to enter the catch window.
    Armed,
    /// The controller drives the motor.
    Engaged,
    /// Stopped for the given reason; output 0 V.
    Fault(FaultKind),
}

impl SupervisorState {
    /// Label as written in the log's `state` column (`idle`, `armed`, `engaged`, `fault:<name>`).
    pub fn label(self) -> &'static str {
        match self {
            SupervisorState::Idle => "idle",
            SupervisorState::Armed => "armed",
            SupervisorState::Engaged => "engaged",
            SupervisorState::Fault(k) => match k {
                FaultKind::PendulumFell => "fault:pendulum_fell",
                FaultKind::ArmLimit => "fault:arm_limit",
                FaultKind::NonFiniteOutput => "fault:non_finite_output",
                FaultKind::ControllerPanic => "fault:controller_panic",
                FaultKind::Overrun => "fault:overrun",
                FaultKind::ReadError => "fault:read_error",
                FaultKind::WriteError => "fault:write_error",
                FaultKind::WatchdogError => "fault:watchdog_error",
                FaultKind::WatchdogExpired => "fault:watchdog_expired",
                FaultKind::EncoderStuck => "fault:encoder_stuck",
                FaultKind::Stopped => "fault:stopped",
                FaultKind::PlantDiverged => "fault:plant_diverged",
            },
        }
    }

    /// True for `Fault(_)`.
    pub fn is_fault(self) -> bool {
        matches!(self, SupervisorState::Fault(_))
    }
}

impl fmt::Display for SupervisorState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.label())
    }
}

/// A state change, reported to the caller as it happens and in the run report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition {
    /// Loop time of the change (s).
    pub t: f64,
    /// Previous state.
    pub from: SupervisorState,
    /// New state.
    pub to: SupervisorState,
}

impl fmt::Display for Transition {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "t={:.3}s {} -> {}", self.t, self.from, self.to)
    }
}

/// Supervisor limits. Angles in radians; `alpha = 0` is upright.
#[derive(Debug, Clone, PartialEq)]
pub struct SupervisorConfig {
    /// State index of the arm angle (default 0).
    pub arm_index: usize,
    /// State index of the pendulum angle (default 1).
    pub pendulum_index: usize,
    /// Engage only once |alpha| is within this of upright (default 10 deg).
    pub catch_window_rad: f64,
    /// Fault once engaged and |alpha| exceeds this (default 30 deg).
    pub fall_angle_rad: f64,
    /// Fault once engaged and |theta| exceeds this; also required to engage (default 180 deg).
    pub arm_limit_rad: f64,
    /// Fault after this many consecutive overrunning cycles (default 5).
    pub max_consecutive_overruns: u32,
    /// Fault if, while engaged, no encoder count changes for this long (s).
    /// An upright pendulum is unstable, so its encoders cannot be still for
    /// long; `None` disables the check. Default 2 s.
    pub encoder_stuck_s: Option<f64>,
}

impl Default for SupervisorConfig {
    fn default() -> Self {
        Self {
            arm_index: 0,
            pendulum_index: 1,
            catch_window_rad: 10f64.to_radians(),
            fall_angle_rad: 30f64.to_radians(),
            arm_limit_rad: PI,
            max_consecutive_overruns: 5,
            encoder_stuck_s: Some(2.0),
        }
    }
}

/// The supervisor state machine. Allocates only in [`Supervisor::new`].
#[derive(Debug, Clone)]
pub struct Supervisor {
    config: SupervisorConfig,
    state: SupervisorState,
    consecutive_overruns: u32,
    last_counts: Vec<i32>,
    counts_changed_at: f64,
}

impl Supervisor {
    /// A supervisor in `Idle` for `n_encoders` encoders.
    pub fn new(config: SupervisorConfig, n_encoders: usize) -> Self {
        Self {
            config,
            state: SupervisorState::Idle,
            consecutive_overruns: 0,
            last_counts: vec![0; n_encoders],
            counts_changed_at: 0.0,
        }
    }

    /// The current state.
    pub fn state(&self) -> SupervisorState {
        self.state
    }

    /// The configuration.
    pub fn config(&self) -> &SupervisorConfig {
        &self.config
    }

    /// Whether the controller may drive the output.
    pub fn output_enabled(&self) -> bool {
        self.state == SupervisorState::Engaged
    }

    fn go(&mut self, t: f64, to: SupervisorState) -> Option<Transition> {
        if self.state == to || self.state.is_fault() {
            return None;
        }
        let from = self.state;
        self.state = to;
        Some(Transition { t, from, to })
    }

    /// Idle -> Armed (the loop has started).
    pub fn arm(&mut self, t: f64) -> Option<Transition> {
        if self.state == SupervisorState::Idle {
            self.go(t, SupervisorState::Armed)
        } else {
            None
        }
    }

    /// Any non-fault state -> Fault(kind). The first fault wins.
    pub fn fault(&mut self, t: f64, kind: FaultKind) -> Option<Transition> {
        self.go(t, SupervisorState::Fault(kind))
    }

    /// Checks the measured state and encoder counts of one sample.
    pub fn check(&mut self, t: f64, x: &[f64], counts: &[i32]) -> Option<Transition> {
        let theta = x.get(self.config.arm_index).copied().unwrap_or(f64::NAN);
        let alpha = wrap_pi(
            x.get(self.config.pendulum_index)
                .copied()
                .unwrap_or(f64::NAN),
        );
        let changed = counts != self.last_counts.as_slice();
        if changed {
            for (d, s) in self.last_counts.iter_mut().zip(counts) {
                *d = *s;
            }
            self.counts_changed_at = t;
        }
        match self.state {
            SupervisorState::Armed => {
                if alpha.abs() <= self.config.catch_window_rad
                    && theta.abs() < self.config.arm_limit_rad
                {
                    self.counts_changed_at = t;
                    return self.go(t, SupervisorState::Engaged);
                }
                None
            }
            SupervisorState::Engaged => {
                if alpha.is_nan() || alpha.abs() > self.config.fall_angle_rad {
                    return self.fault(t, FaultKind::PendulumFell);
                }
                if theta.is_nan() || theta.abs() > self.config.arm_limit_rad {
                    return self.fault(t, FaultKind::ArmLimit);
                }
                if let Some(limit) = self.config.encoder_stuck_s {
                    if t - self.counts_changed_at > limit {
                        return self.fault(t, FaultKind::EncoderStuck);
                    }
                }
                None
            }
            _ => None,
        }
    }

    /// Counts an overrunning (or not) cycle; faults after too many in a row.
    pub fn overrun(&mut self, t: f64, overran: bool) -> Option<Transition> {
        if !overran {
            self.consecutive_overruns = 0;
            return None;
        }
        self.consecutive_overruns = self.consecutive_overruns.saturating_add(1);
        if self.consecutive_overruns >= self.config.max_consecutive_overruns {
            return self.fault(t, FaultKind::Overrun);
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn engages_only_in_window_and_faults_on_fall() {
        let mut s = Supervisor::new(SupervisorConfig::default(), 2);
        assert!(s.arm(0.0).is_some());
        assert!(s.check(0.0, &[0.0, 0.5, 0.0, 0.0], &[0, 1]).is_none());
        assert_eq!(s.state(), SupervisorState::Armed);
        let tr = s.check(0.1, &[0.0, 0.1, 0.0, 0.0], &[0, 2]).unwrap();
        assert_eq!(tr.to, SupervisorState::Engaged);
        let tr = s.check(0.2, &[0.0, 0.6, 0.0, 0.0], &[0, 3]).unwrap();
        assert_eq!(tr.to, SupervisorState::Fault(FaultKind::PendulumFell));
        // Fault is terminal.
        assert!(s.fault(0.3, FaultKind::Stopped).is_none());
        assert_eq!(s.state().label(), "fault:pendulum_fell");
    }

    #[test]
    fn nan_angles_fault() {
        let mut s = Supervisor::new(SupervisorConfig::default(), 2);
        s.arm(0.0);
        s.check(0.0, &[0.0, 0.0, 0.0, 0.0], &[0, 0]);
        let tr = s.check(0.1, &[f64::NAN, 0.0, 0.0, 0.0], &[1, 0]).unwrap();
        assert_eq!(tr.to, SupervisorState::Fault(FaultKind::ArmLimit));
    }

    #[test]
    fn consecutive_overruns() {
        let mut s = Supervisor::new(SupervisorConfig::default(), 2);
        s.arm(0.0);
        for _ in 0..4 {
            assert!(s.overrun(0.0, true).is_none());
        }
        s.overrun(0.0, false);
        for _ in 0..4 {
            assert!(s.overrun(0.0, true).is_none());
        }
        assert!(s.overrun(0.0, true).is_some());
    }
}
