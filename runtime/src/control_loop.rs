//! The fixed-rate control loop: sample, estimate velocities, supervise,
//! control, write, log. Nothing allocates inside the loop after start.

use crate::backend::{Backend, BackendError, EncoderMap};
use crate::controller::Controller;
use crate::error::RuntimeError;
use crate::estimator::{DerivativeEstimator, VelocityEstimator};
use crate::histogram::Histogram;
use crate::log::LogWriter;
use crate::plant::Plant;
use crate::reference_pendulum::RotaryPendulumReference;
use crate::report::{ModeSwitch, RunReport};
use crate::rt_os::try_realtime;
use crate::supervisor::{FaultKind, NotEngaged, Supervisor, SupervisorConfig, Transition};
use crate::velocity_observer::ObserverSpec;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Highest supported loop rate (the Q2-USB's closed-loop limit).
pub const MAX_RATE_HZ: f64 = 2000.0;

/// Most samples of one run: 2^53, the largest count for which the sample
/// count and the loop time `k / rate` are exact in `f64` (a duration of 2e16 s
/// at 1 kHz overflowed the count to 0 samples and the run "ended" at once).
pub const MAX_SAMPLES: f64 = 9_007_199_254_740_992.0;

/// Settings of a run.
#[derive(Debug, Clone)]
pub struct RunConfig {
    /// Loop rate in Hz (default 1000, at most 2000).
    pub rate_hz: f64,
    /// Run length in seconds of loop time; `None` runs until the stop flag or a fault.
    pub duration_s: Option<f64>,
    /// State names (positions first, then their velocities), e.g. `theta, alpha, theta_dot, alpha_dot`.
    pub state_names: Vec<String>,
    /// The single input's name, e.g. `Vm` (the log also gets `<name>_cmd`).
    pub input_names: Vec<String>,
    /// Input limits; the output is always clamped to them.
    pub input_limits: Vec<(f64, f64)>,
    /// Supervisor limits.
    pub supervisor: SupervisorConfig,
    /// Bandwidth of the velocity-estimating filtered derivative (rad/s,
    /// default 50 as in Quanser's examples); used when `observer` is `None`.
    pub velocity_bandwidth: f64,
    /// Estimate velocities with a steady-state Kalman observer designed from
    /// this linear model instead of the filtered derivative (default `None`;
    /// `plantc run` uses it by default, see [`crate::velocity_observer`]).
    pub observer: Option<ObserverSpec>,
    /// Set to stop the run (e.g. by [`crate::stop_on_ctrl_c`]); ends in `fault:stopped`.
    pub stop: Arc<AtomicBool>,
    /// Try real-time priority and memory locking when the backend runs in real time (default true).
    pub os_realtime: bool,
    /// Real-time priority to request (Linux SCHED_FIFO 1..99, default 80).
    pub rt_priority: i32,
}

impl Default for RunConfig {
    /// 1 kHz, rotary-pendulum names and ±10 V limits, run until stopped.
    fn default() -> Self {
        Self::for_plant(&RotaryPendulumReference::default())
    }
}

impl RunConfig {
    /// A configuration taking names and input limits from `plant`.
    pub fn for_plant(plant: &dyn Plant) -> Self {
        Self {
            rate_hz: 1000.0,
            duration_s: None,
            state_names: plant.state_names().iter().map(|s| s.to_string()).collect(),
            input_names: plant.input_names().iter().map(|s| s.to_string()).collect(),
            input_limits: plant.input_limits().to_vec(),
            supervisor: SupervisorConfig::default(),
            velocity_bandwidth: 50.0,
            observer: None,
            stop: Arc::new(AtomicBool::new(false)),
            os_realtime: true,
            rt_priority: 80,
        }
    }

    fn validate(&self, n_encoders: usize) -> Result<(), RuntimeError> {
        let bad = |s: String| Err(RuntimeError::InvalidConfig(s));
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= MAX_RATE_HZ) {
            return bad(format!(
                "rate {} Hz not in (0, {MAX_RATE_HZ}]",
                self.rate_hz
            ));
        }
        if self.state_names.len() != 2 * n_encoders || n_encoders == 0 {
            return bad(format!(
                "{} state names for {} encoders (need positions then velocities)",
                self.state_names.len(),
                n_encoders
            ));
        }
        if self.input_names.len() != 1 || self.input_limits.len() != 1 {
            return bad("exactly one input (the motor voltage) and one limit are supported".into());
        }
        let (lo, hi) = self.input_limits[0];
        if !(lo.is_finite() && hi.is_finite() && lo <= 0.0 && 0.0 <= hi) {
            return bad(format!(
                "input limits ({lo}, {hi}) must be finite and contain 0"
            ));
        }
        if !(self.velocity_bandwidth.is_finite() && self.velocity_bandwidth > 0.0) {
            return bad("velocity bandwidth must be > 0".into());
        }
        if let Some(d) = self.duration_s {
            if !(d.is_finite() && d >= 0.0) {
                return bad(format!("duration {d} s"));
            }
            let samples = d * self.rate_hz;
            if samples >= MAX_SAMPLES {
                return bad(format!(
                    "duration {d} s at {} Hz is {samples:.3e} samples; a run counts at most \
                     2^53 samples ({:.2e} s at this rate), exactly, in its loop time",
                    self.rate_hz,
                    MAX_SAMPLES / self.rate_hz
                ));
            }
        }
        let s = &self.supervisor;
        if s.arm_index >= n_encoders || s.pendulum_index >= n_encoders {
            return bad("supervisor angle indices must name position states".into());
        }
        Ok(())
    }
}

/// Runs the loop; see [`run_with_events`].
pub fn run(
    config: &RunConfig,
    backend: &mut dyn Backend,
    controller: &mut dyn Controller,
    log: Option<&mut LogWriter>,
) -> Result<RunReport, RuntimeError> {
    run_with_events(config, backend, controller, log, &mut |_| {})
}

struct Stats {
    jitter: Histogram,
    ctrl: Histogram,
    estimator: Histogram,
    path: Histogram,
    work: Histogram,
    overruns: u64,
    missed: u64,
    samples: u64,
}

/// The estimator `config` asks for: the observer designed from
/// `config.observer` (needs the `model` feature), else the filtered derivative.
fn configured_estimator(
    config: &RunConfig,
    maps: &[EncoderMap],
    period: f64,
) -> Result<Box<dyn VelocityEstimator>, RuntimeError> {
    match &config.observer {
        #[cfg(feature = "model")]
        Some(spec) => Ok(Box::new(
            crate::velocity_observer::VelocityObserver::design(spec, maps, period)?,
        )),
        #[cfg(not(feature = "model"))]
        Some(_) => Err(RuntimeError::InvalidConfig(
            "designing a velocity observer at start needs plantc-runtime's `model` feature; \
             pass a designed estimator (run_with_estimator) instead"
                .into(),
        )),
        None => Ok(Box::new(DerivativeEstimator::new(
            maps.len(),
            config.velocity_bandwidth,
            period,
        ))),
    }
}

struct Outcome {
    fault_detail: Option<BackendError>,
    not_engaged: Option<NotEngaged>,
    /// Every failed 0 V write of the loop (after a fault), in order.
    stop_errors: Vec<String>,
}

/// Closes the backend on a path that ends the run with `error`: a failed
/// close is attached to it, never dropped.
fn close_with(backend: &mut dyn Backend, error: RuntimeError) -> RuntimeError {
    match backend.close() {
        Ok(()) => error,
        Err(close) => RuntimeError::CloseFailed {
            cause: Some(Box::new(error)),
            close,
        },
    }
}

/// Runs the control loop with the velocity estimator `config` asks for; see
/// [`run_with_estimator`].
pub fn run_with_events(
    config: &RunConfig,
    backend: &mut dyn Backend,
    controller: &mut dyn Controller,
    log: Option<&mut LogWriter>,
    on_event: &mut dyn FnMut(&Transition),
) -> Result<RunReport, RuntimeError> {
    run_with_estimator(config, backend, controller, None, log, on_event)
}

/// A hybrid controller's mode names and the switches seen so far.
struct Modes<'a> {
    names: &'a [String],
    switches: &'a mut Vec<ModeSwitch>,
}

/// Runs the control loop until the duration elapses, the stop flag is set or
/// a fault occurs, calling `on_event` for every supervisor transition.
/// `estimator` replaces the one `config` describes (`observer`,
/// `velocity_bandwidth`), e.g. a generated observer.
///
/// Returns `Err` only if the run could not start (bad configuration, backend
/// start failure) or the loop itself panicked; faults during the run end it
/// with `Ok(report)` whose `final_state` is `Fault(_)`. On every path the
/// backend is closed, which writes 0 V; a 0 V write or a close that failed
/// is in [`RunReport::stop_errors`] (or [`RuntimeError::CloseFailed`]),
/// never dropped.
pub fn run_with_estimator(
    config: &RunConfig,
    backend: &mut dyn Backend,
    controller: &mut dyn Controller,
    estimator: Option<&mut dyn VelocityEstimator>,
    log: Option<&mut LogWriter>,
    on_event: &mut dyn FnMut(&Transition),
) -> Result<RunReport, RuntimeError> {
    run_with_notes(
        config,
        backend,
        controller,
        estimator,
        log,
        on_event,
        &mut |_| {},
    )
}

/// [`run_with_estimator`], also calling `on_not_engaged` once when the
/// controller has not engaged [`crate::supervisor::NOT_ENGAGED_AFTER_S`]
/// after the start (the note is in the report too).
pub fn run_with_notes(
    config: &RunConfig,
    backend: &mut dyn Backend,
    controller: &mut dyn Controller,
    estimator: Option<&mut dyn VelocityEstimator>,
    mut log: Option<&mut LogWriter>,
    on_event: &mut dyn FnMut(&Transition),
    on_not_engaged: &mut dyn FnMut(&NotEngaged),
) -> Result<RunReport, RuntimeError> {
    let maps: Vec<EncoderMap> = backend.encoders().to_vec();
    let nq = maps.len();
    if let Err(e) = config.validate(nq) {
        return Err(close_with(backend, e));
    }
    let period = 1.0 / config.rate_hz;
    let mut notes = Vec::new();
    let mut own_estimator = None;
    let estimator: &mut dyn VelocityEstimator = match estimator {
        Some(e) => e,
        None => match configured_estimator(config, &maps, period) {
            Ok(e) => &mut **own_estimator.insert(e),
            Err(e) => return Err(close_with(backend, e)),
        },
    };
    notes.push(estimator.describe());
    let mode_names = controller.mode_names();
    let mut mode_switches: Vec<ModeSwitch> = Vec::with_capacity(4096);
    if let Some(l) = log.as_deref_mut() {
        if !mode_names.is_empty() {
            l.with_mode_column();
        }
        if let Err(e) = l.begin(&config.state_names, nq, &config.input_names) {
            return Err(close_with(backend, e.into()));
        }
    }
    let mut stats = Stats {
        jitter: Histogram::new(),
        ctrl: Histogram::new(),
        estimator: Histogram::new(),
        path: Histogram::new(),
        work: Histogram::new(),
        overruns: 0,
        missed: 0,
        samples: 0,
    };
    let mut transitions: Vec<Transition> = Vec::with_capacity(16);
    let mut sup = Supervisor::new(config.supervisor.clone(), nq);
    let virtual_time = backend.is_virtual_time();
    if let Err(e) = backend.start(period) {
        return Err(close_with(backend, e.into()));
    }
    let mut _rt_guard = None;
    if !virtual_time && config.os_realtime {
        let g = try_realtime(config.rt_priority);
        if g.setup.priority {
            notes.push("real-time priority (SCHED_FIFO) set for the loop".to_string());
        }
        if g.setup.memory_locked {
            notes.push("memory locked for the loop".to_string());
        }
        notes.extend(g.setup.notes.iter().cloned());
        _rt_guard = Some(g);
    } else if !virtual_time {
        notes.push("real-time priority and memory locking not requested".to_string());
    }

    let result = catch_unwind(AssertUnwindSafe(|| {
        cycle_loop(
            config,
            period,
            &maps,
            estimator,
            backend,
            controller,
            log.as_deref_mut(),
            &mut sup,
            &mut transitions,
            &mut stats,
            on_event,
            on_not_engaged,
            Modes {
                names: &mode_names,
                switches: &mut mode_switches,
            },
        )
    }));
    // Every exit path: close (writes 0 V) and flush the log.
    let close_result = backend.close();
    drop(_rt_guard);
    if let Some(l) = log.as_deref_mut() {
        l.flush();
        if let Some(e) = l.error() {
            notes.push(format!("log: {e}"));
        }
    }
    let mut outcome = match result {
        Ok(o) => o,
        Err(p) => {
            let msg = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".to_string());
            let panic = RuntimeError::Panic(msg);
            return Err(match close_result {
                Ok(()) => panic,
                Err(close) => RuntimeError::CloseFailed {
                    cause: Some(Box::new(panic)),
                    close,
                },
            });
        }
    };
    if let Err(e) = close_result {
        outcome.stop_errors.push(format!("close: {e}"));
    }
    Ok(RunReport {
        transitions,
        not_engaged: outcome.not_engaged,
        final_state: sup.state(),
        fault_detail: outcome.fault_detail.map(|e| e.to_string()),
        stop_errors: outcome.stop_errors,
        samples: stats.samples,
        samples_logged: log.as_deref().map_or(0, |l| l.rows()),
        period_s: period,
        virtual_time,
        jitter_ns: stats.jitter.percentiles(),
        overruns: stats.overruns,
        missed_samples: stats.missed,
        controller_ns: stats.ctrl.percentiles(),
        estimator_ns: stats.estimator.percentiles(),
        control_path_ns: stats.path.percentiles(),
        cycle_work_ns: stats.work.percentiles(),
        notes,
        mode_names,
        mode_switches,
    })
}

#[allow(clippy::too_many_arguments)]
fn cycle_loop(
    config: &RunConfig,
    period: f64,
    maps: &[EncoderMap],
    estimator: &mut dyn VelocityEstimator,
    backend: &mut dyn Backend,
    controller: &mut dyn Controller,
    mut log: Option<&mut LogWriter>,
    sup: &mut Supervisor,
    transitions: &mut Vec<Transition>,
    stats: &mut Stats,
    on_event: &mut dyn FnMut(&Transition),
    on_not_engaged: &mut dyn FnMut(&NotEngaged),
    modes: Modes<'_>,
) -> Outcome {
    let nq = maps.len();
    let n = 2 * nq;
    let mut x = vec![0.0; n];
    let mut counts = vec![0i32; nq];
    let mut u_cmd = vec![0.0; 1];
    let mut u_out = [0.0f64; 1];
    let mut q_unwrapped = vec![0.0; nq];
    let mut velocities = vec![0.0; nq];
    let (lo, hi) = config.input_limits[0];
    // (validated: below 2^53, so the count and its + 1 are exact)
    let total = config
        .duration_s
        .map(|d| ((d * config.rate_hz).round().max(0.0) as u64).saturating_add(1));
    let period_ns = (period * 1e9) as u64;
    let mut fault_detail = None;
    let mut not_engaged = None;
    let mut stop_errors = Vec::new();
    let mut prev_wake: Option<Instant> = None;
    // a hybrid controller starts (reset) in its first mode
    let mut last_mode: Option<usize> = None;

    let mut emit = |tr: Option<Transition>, transitions: &mut Vec<Transition>| {
        if let Some(tr) = tr {
            if transitions.len() < transitions.capacity() {
                transitions.push(tr);
            }
            on_event(&tr);
        }
    };
    emit(sup.arm(0.0), transitions);

    loop {
        if let Some(total) = total {
            if stats.samples >= total {
                break;
            }
        }
        let mut t = stats.samples as f64 * period;
        let mut overran = false;
        match backend.wait_next_period() {
            Ok(tick) => {
                t = tick.t;
                if tick.missed > 0 {
                    stats.missed += u64::from(tick.missed);
                    overran = true;
                }
            }
            Err(e) => {
                emit(sup.fault(t, FaultKind::ReadError), transitions);
                fault_detail = Some(e);
            }
        }
        let wake = Instant::now();
        if let Some(prev) = prev_wake {
            let dt = wake.duration_since(prev).as_nanos() as u64;
            stats.jitter.record(dt.abs_diff(period_ns));
        }
        prev_wake = Some(wake);
        stats.samples += 1;

        if !sup.state().is_fault() {
            if let Err(e) = backend.read_encoders(&mut counts) {
                let kind = match e {
                    BackendError::PlantDiverged { .. } => FaultKind::PlantDiverged,
                    _ => FaultKind::ReadError,
                };
                emit(sup.fault(t, kind), transitions);
                fault_detail = Some(e);
            }
        }
        for i in 0..nq {
            (x[i], q_unwrapped[i]) = maps[i].angles(counts[i]);
        }
        // An observer's model holds about upright: it takes the state
        // angles; u_out still holds the voltage applied since the previous sample.
        let e0 = Instant::now();
        estimator.update(&x[..nq], &q_unwrapped, u_out[0], &mut velocities);
        let estimator_ns = e0.elapsed().as_nanos() as u64;
        stats.estimator.record(estimator_ns);
        x[nq..].copy_from_slice(&velocities);
        if config.stop.load(Ordering::Relaxed) {
            emit(sup.fault(t, FaultKind::Stopped), transitions);
        }
        let was_engaged = sup.output_enabled();
        emit(sup.check(t, &x, &counts), transitions);
        if let Some(n) = sup.not_engaged(t, &x) {
            on_not_engaged(&n);
            not_engaged = Some(n);
        }

        u_cmd[0] = 0.0;
        if sup.output_enabled() {
            if !was_engaged {
                controller.reset();
                last_mode = controller.mode().map(|m| m.index);
            }
            let c0 = Instant::now();
            let r = catch_unwind(AssertUnwindSafe(|| controller.control(t, &x, &mut u_cmd)));
            let ctrl_ns = c0.elapsed().as_nanos() as u64;
            stats.ctrl.record(ctrl_ns);
            stats.path.record(estimator_ns + ctrl_ns);
            if r.is_err() {
                emit(sup.fault(t, FaultKind::ControllerPanic), transitions);
            } else if !u_cmd.iter().all(|v| v.is_finite()) {
                emit(sup.fault(t, FaultKind::NonFiniteOutput), transitions);
            } else {
                let mode = controller.mode();
                if let (Some(m), Some(prev)) = (mode, last_mode) {
                    if m.index != prev && modes.switches.len() < modes.switches.capacity() {
                        modes.switches.push(ModeSwitch {
                            t,
                            from: prev,
                            to: m.index,
                        });
                    }
                }
                last_mode = mode.map(|m| m.index);
                emit(
                    sup.follow_mode(t, mode.is_some_and(|m| m.swing_up)),
                    transitions,
                );
            }
        }

        if !sup.state().is_fault() {
            if let Err(e) = backend.reload_watchdog() {
                let kind = if e == BackendError::WatchdogExpired {
                    FaultKind::WatchdogExpired
                } else {
                    FaultKind::WatchdogError
                };
                emit(sup.fault(t, kind), transitions);
                fault_detail = Some(e);
            }
        }

        u_out[0] = if sup.output_enabled() {
            u_cmd[0].clamp(lo, hi)
        } else {
            0.0
        };
        if let Err(e) = backend.write_voltage(u_out[0]) {
            if sup.state().is_fault() {
                // u_out was 0 V: a failed write of the safe state.
                stop_errors.push(format!("t={t:.3} s: the 0 V write after the fault: {e}"));
            } else {
                emit(sup.fault(t, FaultKind::WriteError), transitions);
                fault_detail = Some(e);
            }
            u_out[0] = 0.0;
            if let Err(e) = backend.write_voltage(0.0) {
                stop_errors.push(format!("t={t:.3} s: the 0 V write after the fault: {e}"));
            }
        }
        let work = wake.elapsed().as_nanos() as u64;
        stats.work.record(work);
        if work > period_ns {
            overran = true;
        }
        if overran {
            stats.overruns += 1;
        }
        if !sup.state().is_fault() {
            emit(sup.overrun(t, overran), transitions);
            if sup.state().is_fault() {
                u_out[0] = 0.0;
                if let Err(e) = backend.write_voltage(0.0) {
                    stop_errors.push(format!("t={t:.3} s: the 0 V write after the fault: {e}"));
                }
            }
        }
        if let Some(l) = log.as_deref_mut() {
            let mode = last_mode
                .and_then(|i| modes.names.get(i))
                .map_or("", String::as_str);
            l.row_with_mode(
                t,
                &x,
                &counts,
                &u_out,
                &u_cmd,
                sup.state().label(),
                overran,
                mode,
            );
        }
        if sup.state().is_fault() {
            break;
        }
    }
    Outcome {
        fault_detail,
        not_engaged,
        stop_errors,
    }
}
