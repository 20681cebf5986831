//! The safety supervisor: an explicit state machine
//! Idle -> Armed -> Engaged / SwingUp -> Fault.
//!
//! Only `Engaged` (balancing near upright) and `SwingUp` (a hybrid
//! controller's swing-up mode, the pendulum anywhere) let the controller
//! drive the motor; in every other state the loop writes 0 V. `SwingUp` is
//! entered from `Armed` with the pendulum hanging, or from `Engaged` when the
//! controller switches to a swing-up mode, and only if
//! [`SupervisorConfig::swing_up`] allows it; it is watched by the arm-angle
//! and speed limits instead of the fall angle. `Fault` is terminal for a run.

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
    /// An arm or pendulum speed passed its swing-up limit.
    SpeedLimit,
    /// The controller entered a swing-up mode, but swing-up is not allowed.
    SwingUpNotAllowed,
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
            FaultKind::SpeedLimit => "speed_limit",
            FaultKind::SwingUpNotAllowed => "swing_up_not_allowed",
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
    /// The controller drives the motor (balancing: the fall check applies).
    Engaged,
    /// A hybrid controller's swing-up mode drives the motor (arm-angle and
    /// speed limits apply, not the fall check).
    SwingUp,
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
            SupervisorState::SwingUp => "swing_up",
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
                FaultKind::SpeedLimit => "fault:speed_limit",
                FaultKind::SwingUpNotAllowed => "fault:swing_up_not_allowed",
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
    /// Allow swing-up (state `SwingUp`) with these limits; `None` (default)
    /// forbids it.
    pub swing_up: Option<SwingUpLimits>,
}

/// When and how a swing-up may drive the motor. The arm-angle limit is
/// [`SupervisorConfig::arm_limit_rad`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwingUpLimits {
    /// From `Armed`, swing-up starts only with the pendulum within this of
    /// hanging (default 20 deg) and both speeds within their limits.
    pub hanging_window_rad: f64,
    /// Fault in `SwingUp` once |arm speed| exceeds this (rad/s, default 30).
    pub max_arm_speed: f64,
    /// Fault in `SwingUp` once |pendulum speed| exceeds this (rad/s, default
    /// 25; a pendulum falling from upright reaches about 13.5 rad/s at the
    /// bottom with the Table 3 values).
    pub max_pendulum_speed: f64,
}

impl Default for SwingUpLimits {
    fn default() -> Self {
        Self {
            hanging_window_rad: 20f64.to_radians(),
            max_arm_speed: 30.0,
            max_pendulum_speed: 25.0,
        }
    }
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
            swing_up: None,
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
    armed_at: Option<f64>,
    /// While armed: the smallest |alpha| seen and when.
    closest: (f64, f64),
    waiting_told: bool,
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
            armed_at: None,
            closest: (f64::INFINITY, 0.0),
            waiting_told: false,
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
        matches!(
            self.state,
            SupervisorState::Engaged | SupervisorState::SwingUp
        )
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
            self.armed_at = Some(t);
            self.go(t, SupervisorState::Armed)
        } else {
            None
        }
    }

    /// Any non-fault state -> Fault(kind). The first fault wins.
    pub fn fault(&mut self, t: f64, kind: FaultKind) -> Option<Transition> {
        self.go(t, SupervisorState::Fault(kind))
    }

    /// Follows the controller's mode after its call: a swing-up mode moves
    /// `Engaged` to `SwingUp` (or faults if swing-up is not allowed), a
    /// balancing mode (or no mode) moves `SwingUp` to `Engaged`.
    pub fn follow_mode(&mut self, t: f64, swing_up: bool) -> Option<Transition> {
        match (self.state, swing_up) {
            (SupervisorState::Engaged, true) => {
                if self.config.swing_up.is_some() {
                    self.go(t, SupervisorState::SwingUp)
                } else {
                    self.fault(t, FaultKind::SwingUpNotAllowed)
                }
            }
            (SupervisorState::SwingUp, false) => self.go(t, SupervisorState::Engaged),
            _ => None,
        }
    }

    /// Checks the measured state and encoder counts of one sample.
    pub fn check(&mut self, t: f64, x: &[f64], counts: &[i32]) -> Option<Transition> {
        let theta = x.get(self.config.arm_index).copied().unwrap_or(f64::NAN);
        let alpha = wrap_pi(
            x.get(self.config.pendulum_index)
                .copied()
                .unwrap_or(f64::NAN),
        );
        let nq = x.len() / 2;
        let speed = |i: usize| x.get(nq + i).copied().unwrap_or(f64::NAN).abs();
        let (arm_speed, pendulum_speed) = (
            speed(self.config.arm_index),
            speed(self.config.pendulum_index),
        );
        let speeds_ok = |l: &SwingUpLimits| {
            arm_speed <= l.max_arm_speed && pendulum_speed <= l.max_pendulum_speed
        };
        let changed = counts != self.last_counts.as_slice();
        if changed {
            for (d, s) in self.last_counts.iter_mut().zip(counts) {
                *d = *s;
            }
            self.counts_changed_at = t;
        }
        match self.state {
            SupervisorState::Armed => {
                if alpha.abs() < self.closest.0 {
                    self.closest = (alpha.abs(), t);
                }
                if alpha.abs() <= self.config.catch_window_rad
                    && theta.abs() < self.config.arm_limit_rad
                {
                    self.counts_changed_at = t;
                    return self.go(t, SupervisorState::Engaged);
                }
                if let Some(l) = self.config.swing_up {
                    if alpha.abs() >= PI - l.hanging_window_rad
                        && theta.abs() < self.config.arm_limit_rad
                        && speeds_ok(&l)
                    {
                        self.counts_changed_at = t;
                        return self.go(t, SupervisorState::SwingUp);
                    }
                }
                None
            }
            SupervisorState::SwingUp => {
                if theta.is_nan() || theta.abs() > self.config.arm_limit_rad {
                    return self.fault(t, FaultKind::ArmLimit);
                }
                let ok = self.config.swing_up.is_some_and(|l| speeds_ok(&l));
                if !ok {
                    return self.fault(t, FaultKind::SpeedLimit);
                }
                if let Some(limit) = self.config.encoder_stuck_s {
                    if t - self.counts_changed_at > limit {
                        return self.fault(t, FaultKind::EncoderStuck);
                    }
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

    /// Once, [`NOT_ENGAGED_AFTER_S`] after arming, if still `Armed`: why the
    /// measured state `x` does not let the controller engage.
    pub fn not_engaged(&mut self, t: f64, x: &[f64]) -> Option<NotEngaged> {
        let armed_at = self.armed_at?;
        if self.waiting_told
            || self.state != SupervisorState::Armed
            || t - armed_at < NOT_ENGAGED_AFTER_S
        {
            return None;
        }
        self.waiting_told = true;
        Some(NotEngaged {
            t,
            closest_alpha: self.closest.0,
            closest_t: self.closest.1,
            theta: x.get(self.config.arm_index).copied().unwrap_or(f64::NAN),
            alpha: wrap_pi(
                x.get(self.config.pendulum_index)
                    .copied()
                    .unwrap_or(f64::NAN),
            ),
            catch_window_rad: self.config.catch_window_rad,
            fall_angle_rad: self.config.fall_angle_rad,
            arm_limit_rad: self.config.arm_limit_rad,
            hanging_window_rad: self.config.swing_up.map(|l| l.hanging_window_rad),
        })
    }
}

/// How long after arming a run that has not engaged says why (s). A
/// pendulum started inside the catch window engages on the first sample; one
/// outside it falls away from upright within about a second (the rotary
/// pendulum's unstable pole is at 7.37 rad/s, `plantc linearize
/// models/rotary_pendulum.plant`: an e-folding time of 0.14 s, so 10 deg grows
/// past 90 deg in 0.3 s), so after a second waiting longer rarely helps and
/// the user should hear why.
pub const NOT_ENGAGED_AFTER_S: f64 = 1.0;

/// Why a run has not engaged its controller yet ([`Supervisor::not_engaged`]),
/// with the `plantc run` options (also the rig binaries') that widen the
/// windows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NotEngaged {
    /// Loop time of the note (s).
    pub t: f64,
    /// Arm angle (rad).
    pub theta: f64,
    /// Pendulum angle from upright, wrapped into [-pi, pi) (rad).
    pub alpha: f64,
    /// The smallest |alpha| since the start (rad): the widest catch window
    /// needed to engage.
    pub closest_alpha: f64,
    /// When it was seen (s).
    pub closest_t: f64,
    /// The catch window (rad).
    pub catch_window_rad: f64,
    /// The fall angle (rad); the catch window must stay below it.
    pub fall_angle_rad: f64,
    /// The arm limit (rad).
    pub arm_limit_rad: f64,
    /// The hanging window when swing-up is allowed (rad).
    pub hanging_window_rad: Option<f64>,
}

impl fmt::Display for NotEngaged {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let deg = f64::to_degrees;
        write!(f, "t={:.3}s not engaged: ", self.t)?;
        if !(self.alpha.is_finite() && self.theta.is_finite()) {
            return write!(f, "the measured angles are not finite");
        }
        let mut reasons = Vec::new();
        if self.alpha.abs() > self.catch_window_rad {
            // the next whole degree past the closest approach, with one to
            // spare: the window that would have engaged then
            let closest = if self.closest_alpha.is_finite() {
                self.closest_alpha
            } else {
                self.alpha.abs()
            };
            let wider = deg(closest).ceil() + 1.0;
            // a catch window is a neighbourhood of upright: past the
            // horizontal the pendulum needs a swing-up, not a wider window
            let how = if wider >= 90.0 {
                "it never rose above the horizontal: a balancing controller engages only near upright, so start it near upright or use a controller with a swing-up mode (`mode name = controller swing_up`)".to_string()
            } else if wider.to_radians() >= self.fall_angle_rad {
                format!(
                    "widen it with --catch-window {wider:.0}deg and --fall-angle above it (now {:.1}deg; the catch window must be smaller), or start it closer to upright",
                    deg(self.fall_angle_rad)
                )
            } else {
                format!("widen it with --catch-window {wider:.0}deg, or start it closer to upright")
            };
            let hanging = match self.hanging_window_rad {
                Some(h) => format!(
                    ", nor within the hanging window of {:.1}deg for swing-up (--hanging-window)",
                    deg(h)
                ),
                None => String::new(),
            };
            reasons.push(format!(
                "the pendulum came no closer to upright than {:.2}deg (at t={:.3}s; now alpha = {:.1}deg), outside the catch window of {:.2}deg{hanging}; {how}",
                deg(closest),
                self.closest_t,
                deg(self.alpha),
                deg(self.catch_window_rad),
            ));
        }
        if self.theta.abs() >= self.arm_limit_rad {
            reasons.push(format!(
                "the arm is at theta = {:.1}deg, beyond the arm limit of {:.1}deg (--arm-limit)",
                deg(self.theta),
                deg(self.arm_limit_rad)
            ));
        }
        if reasons.is_empty() {
            // inside both windows now (it moved there this sample, or the
            // swing-up speeds are exceeded)
            return write!(
                f,
                "alpha = {:.1}deg, theta = {:.1}deg (within the catch window of {:.1}deg)",
                deg(self.alpha),
                deg(self.theta),
                deg(self.catch_window_rad)
            );
        }
        f.write_str(&reasons.join("; "))
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
    fn says_once_why_it_has_not_engaged_after_a_second() {
        let mut s = Supervisor::new(SupervisorConfig::default(), 2);
        s.arm(0.0);
        // released at 10.5 deg (closest), falling away
        let x = |a: f64| [0.0, a.to_radians(), 0.0, 0.0];
        assert!(s.check(0.0, &x(10.5), &[0, 1]).is_none());
        assert!(s.not_engaged(0.0, &x(10.5)).is_none());
        assert!(s.check(0.5, &x(20.0), &[0, 2]).is_none());
        assert!(s.not_engaged(0.5, &x(20.0)).is_none());
        assert!(s.check(1.0, &x(40.0), &[0, 3]).is_none());
        let n = s.not_engaged(1.0, &x(40.0)).expect("a note after 1 s");
        assert!(s.not_engaged(1.1, &x(41.0)).is_none(), "said once");
        let text = n.to_string();
        // the window that would have caught it at its closest: ceil(10.5) + 1
        assert!(
            text.contains("no closer to upright than 10.50deg (at t=0.000s; now alpha = 40.0deg)"),
            "{text}"
        );
        assert!(text.contains("catch window of 10.00deg"), "{text}");
        assert!(text.contains("--catch-window 12deg"), "{text}");
        assert!(!text.contains("--fall-angle"), "{text}");
        // a window that would need to reach the fall angle says so
        let mut s = Supervisor::new(SupervisorConfig::default(), 2);
        s.arm(0.0);
        s.check(0.0, &x(35.0), &[0, 1]);
        let text = s.not_engaged(1.0, &x(35.0)).unwrap().to_string();
        assert!(
            text.contains("--catch-window 36deg and --fall-angle above it"),
            "{text}"
        );
        // hanging: no window advice, a swing-up
        let mut s = Supervisor::new(SupervisorConfig::default(), 2);
        s.arm(0.0);
        s.check(0.0, &x(177.0), &[0, 1]);
        let text = s.not_engaged(1.0, &x(178.0)).unwrap().to_string();
        assert!(text.contains("never rose above the horizontal"), "{text}");
        assert!(!text.contains("--catch-window"), "{text}");
        // an engaged run has nothing to say
        let mut s = Supervisor::new(SupervisorConfig::default(), 2);
        s.arm(0.0);
        s.check(0.0, &x(5.0), &[0, 1]);
        assert!(s.not_engaged(1.0, &x(5.0)).is_none());
    }

    #[test]
    fn swing_up_from_hanging_and_back() {
        let cfg = SupervisorConfig {
            swing_up: Some(SwingUpLimits::default()),
            ..SupervisorConfig::default()
        };
        let mut s = Supervisor::new(cfg, 2);
        s.arm(0.0);
        // pendulum half way up: neither window
        assert!(s.check(0.0, &[0.0, 1.5, 0.0, 0.0], &[0, 1]).is_none());
        // hanging but swinging too fast to start
        assert!(s.check(0.0, &[0.0, 3.1, 0.0, 26.0], &[0, 2]).is_none());
        let tr = s.check(0.1, &[0.0, -3.1, 0.0, 0.5], &[0, 3]).unwrap();
        assert_eq!(tr.to, SupervisorState::SwingUp);
        assert!(s.output_enabled());
        // no fall check while swinging up
        assert!(s.check(0.2, &[1.0, 1.5, 5.0, 10.0], &[1, 4]).is_none());
        // the controller catches: balancing, fall check back on
        assert_eq!(
            s.follow_mode(0.3, false).unwrap().to,
            SupervisorState::Engaged
        );
        assert!(s.follow_mode(0.3, false).is_none());
        assert_eq!(
            s.follow_mode(0.4, true).unwrap().to,
            SupervisorState::SwingUp
        );
        let tr = s.check(0.5, &[1.0, 2.0, 31.0, 0.0], &[2, 5]).unwrap();
        assert_eq!(tr.to, SupervisorState::Fault(FaultKind::SpeedLimit));
    }

    #[test]
    fn swing_up_needs_permission_and_respects_the_arm_limit() {
        let mut s = Supervisor::new(SupervisorConfig::default(), 2);
        s.arm(0.0);
        assert!(s.check(0.0, &[0.0, 3.1, 0.0, 0.0], &[0, 1]).is_none());
        s.check(0.1, &[0.0, 0.1, 0.0, 0.0], &[0, 2]);
        let tr = s.follow_mode(0.1, true).unwrap();
        assert_eq!(tr.to, SupervisorState::Fault(FaultKind::SwingUpNotAllowed));
        let cfg = SupervisorConfig {
            swing_up: Some(SwingUpLimits::default()),
            ..SupervisorConfig::default()
        };
        let mut s = Supervisor::new(cfg, 2);
        s.arm(0.0);
        s.check(0.0, &[0.0, 3.1, 0.0, 0.0], &[0, 1]);
        let tr = s.check(0.1, &[3.2, 1.0, 0.0, 0.0], &[1, 1]).unwrap();
        assert_eq!(tr.to, SupervisorState::Fault(FaultKind::ArmLimit));
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
