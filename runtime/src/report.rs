//! The summary of a run: supervisor transitions and timing statistics.

use crate::supervisor::{NotEngaged, SupervisorState, Transition};
use std::fmt;

/// Percentiles of a latency distribution, in nanoseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Percentiles {
    /// Median.
    pub p50: u64,
    /// 99th percentile.
    pub p99: u64,
    /// Maximum.
    pub max: u64,
    /// Number of values.
    pub count: u64,
}

/// A hybrid controller's mode change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModeSwitch {
    /// Loop time of the sample whose control call changed the mode (s).
    pub t: f64,
    /// Previous mode (index into [`RunReport::mode_names`]).
    pub from: usize,
    /// New mode.
    pub to: usize,
}

/// What happened in a run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunReport {
    /// Supervisor transitions in order.
    pub transitions: Vec<Transition>,
    /// Why the controller had not engaged a second after the start, if it
    /// had not ([`crate::supervisor::NOT_ENGAGED_AFTER_S`]).
    pub not_engaged: Option<NotEngaged>,
    /// The state at the end of the loop.
    pub final_state: SupervisorState,
    /// The backend error behind a fault, if any (e.g. the HIL code and message).
    pub fault_detail: Option<String>,
    /// Failures of the safe stop: every 0 V write that failed after a fault
    /// and a failed close (with what holds the output). Not empty: the stop
    /// was not clean, whatever the final state (callers exit non-zero).
    pub stop_errors: Vec<String>,
    /// Samples executed.
    pub samples: u64,
    /// Rows written to the log.
    pub samples_logged: u64,
    /// Sample period (s).
    pub period_s: f64,
    /// Whether the backend ran in virtual time (then jitter is not meaningful).
    pub virtual_time: bool,
    /// |actual interval between sample instants - period| on the OS clock (ns).
    pub jitter_ns: Percentiles,
    /// Cycles whose work took longer than a period or that missed sample instants.
    pub overruns: u64,
    /// Sample instants skipped because the loop was late.
    pub missed_samples: u64,
    /// Time per controller call (ns).
    pub controller_ns: Percentiles,
    /// Time per velocity-estimator update (ns), every cycle.
    pub estimator_ns: Percentiles,
    /// Estimator update + controller call (ns), in the cycles the controller ran.
    pub control_path_ns: Percentiles,
    /// Time from the sample instant to the end of the output write (ns).
    pub cycle_work_ns: Percentiles,
    /// Notes (real-time setup, watchdog, log errors, fallbacks).
    pub notes: Vec<String>,
    /// A hybrid controller's mode names (empty for other controllers).
    pub mode_names: Vec<String>,
    /// Its mode changes in order (the first 4096).
    pub mode_switches: Vec<ModeSwitch>,
}

impl RunReport {
    /// Whether the controller drove the input at some point (the supervisor
    /// reached `engaged` or `swing_up`).
    pub fn engaged(&self) -> bool {
        self.transitions
            .iter()
            .any(|t| matches!(t.to, SupervisorState::Engaged | SupervisorState::SwingUp))
    }
}

fn us(ns: u64) -> f64 {
    ns as f64 / 1000.0
}

impl fmt::Display for RunReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "run: {} samples at {:.0} Hz ({}), {} logged, final state {}",
            self.samples,
            1.0 / self.period_s,
            if self.virtual_time {
                "virtual time"
            } else {
                "real time"
            },
            self.samples_logged,
            self.final_state
        )?;
        for t in &self.transitions {
            writeln!(f, "  {t}")?;
        }
        if let Some(n) = &self.not_engaged {
            if !self.engaged() {
                writeln!(f, "  never engaged; {n}")?;
            }
        }
        for m in &self.mode_switches {
            let name = |i: usize| self.mode_names.get(i).map_or("?", String::as_str);
            writeln!(f, "  t={:.3}s mode {} -> {}", m.t, name(m.from), name(m.to))?;
        }
        if let Some(d) = &self.fault_detail {
            writeln!(f, "  fault detail: {d}")?;
        }
        for e in &self.stop_errors {
            writeln!(f, "  SAFE STOP FAILED: {e}")?;
        }
        writeln!(
            f,
            "  period jitter: p50 {:.1} us, p99 {:.1} us, max {:.1} us{}",
            us(self.jitter_ns.p50),
            us(self.jitter_ns.p99),
            us(self.jitter_ns.max),
            if self.virtual_time {
                " (virtual time: not a timing measure)"
            } else {
                ""
            }
        )?;
        writeln!(
            f,
            "  overruns: {} (missed samples {})",
            self.overruns, self.missed_samples
        )?;
        writeln!(
            f,
            "  controller step: p50 {} ns, max {} ns ({} calls); cycle work p50 {:.1} us, max {:.1} us",
            self.controller_ns.p50,
            self.controller_ns.max,
            self.controller_ns.count,
            us(self.cycle_work_ns.p50),
            us(self.cycle_work_ns.max)
        )?;
        writeln!(
            f,
            "  velocity estimator: p50 {} ns, max {} ns; estimator + controller: p50 {} ns, p99 {} ns",
            self.estimator_ns.p50,
            self.estimator_ns.max,
            self.control_path_ns.p50,
            self.control_path_ns.p99
        )?;
        for n in &self.notes {
            writeln!(f, "  note: {n}")?;
        }
        Ok(())
    }
}
