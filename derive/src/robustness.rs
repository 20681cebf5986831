//! Robustness study: controllers designed on a model's parameter values,
//! each run against plants whose parameters differ (e.g. J1, l2, b1 +-20 %,
//! dry friction added), reporting which hold and how much they chatter.
//!
//! Every case is a sampled simulation ([`crate::simulate`], zero-order hold
//! at the controller rate, exact states, inputs saturated at the model's
//! limits) of the mismatched plant, whose `sign()` terms (dry friction) are
//! regularised by `tanh(v / smooth_sign)` so the integrator does not stall; the
//! controller keeps the design values ([`crate::simulate::SimProblem::controller_params`]).
//! A case holds when the pendulum coordinate never leaves the fall window,
//! the arm never passes its limit, and the pendulum settles (largest
//! |angle| over the last `settle_window` seconds below `settle_angle`).
//! Chattering is the total variation of the applied input, `sum |u_k - u_(k-1)|`.
//! Cases run in parallel on `threads` scoped std threads.

use std::fmt;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use crate::control::{resolve, ControlError, Derivation, ResolvedController};
use crate::mechanics::smooth_signs;
use crate::model::{Model, ParameterValues, ValuesError};
use crate::simulate::{
    simulate, wrap_angle, Control, ControllerEval, SimError, SimOptions, SimProblem,
};

/// How a plant parameter differs from the design value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Change {
    /// The design value times this factor.
    Scale(f64),
    /// This value (SI), e.g. dry friction the design model lacks.
    Value(f64),
}

/// One plant of the study: parameter changes against the design values.
#[derive(Clone, Debug, PartialEq)]
pub struct Mismatch {
    /// Label, e.g. `J1 +20%` or `Fg1 = 0.01`.
    pub label: String,
    /// The changes (parameter name, change).
    pub changes: Vec<(String, Change)>,
}

impl Mismatch {
    /// The design values themselves.
    pub fn nominal() -> Mismatch {
        Mismatch {
            label: "nominal".into(),
            changes: Vec::new(),
        }
    }

    /// `parameter` times `1 + fraction` (label `J1 +20%`).
    pub fn relative(parameter: &str, fraction: f64) -> Mismatch {
        Mismatch {
            label: format!("{parameter} {:+}%", (fraction * 100.0 * 1e6).round() / 1e6),
            changes: vec![(parameter.into(), Change::Scale(1.0 + fraction))],
        }
    }

    /// `parameter = value` (label `Fg1 = 0.01`).
    pub fn value(parameter: &str, value: f64) -> Mismatch {
        Mismatch {
            label: format!("{parameter} = {value}"),
            changes: vec![(parameter.into(), Change::Value(value))],
        }
    }

    /// The usual list: nominal, each of `vary` by `-fraction` and
    /// `+fraction`, then each `set` value.
    pub fn standard(vary: &[String], fraction: f64, set: &[(String, f64)]) -> Vec<Mismatch> {
        let mut v = vec![Mismatch::nominal()];
        for p in vary {
            v.push(Mismatch::relative(p, -fraction));
            v.push(Mismatch::relative(p, fraction));
        }
        v.extend(set.iter().map(|(p, x)| Mismatch::value(p, *x)));
        v
    }
}

/// Settings of a study.
#[derive(Clone, Debug, PartialEq)]
pub struct StudyOptions {
    /// Initial state (model state order).
    pub x0: Vec<f64>,
    /// Simulated time per case (s).
    pub duration: f64,
    /// Controller rate (Hz); the input is held between samples.
    pub sample_rate: f64,
    /// The coordinate that must stay up (index), e.g. the pendulum.
    pub pendulum: usize,
    /// The coordinate with an angle limit (index), e.g. the arm.
    pub arm: usize,
    /// The pendulum coordinate must stay within this of 0 (wrapped), rad.
    pub fall_angle: f64,
    /// The arm must stay within this of 0, rad (or m).
    pub arm_limit: f64,
    /// Largest |pendulum| allowed over the last `settle_window` s.
    pub settle_angle: f64,
    /// Length of the settling window at the end (s).
    pub settle_window: f64,
    /// Width of `tanh(v / w)` replacing `sign(v)` in the plant.
    pub smooth_sign: f64,
    /// Worker threads (at least 1).
    pub threads: usize,
}

impl StudyOptions {
    /// Defaults for a model: 10 s at 1 kHz, pendulum = coordinate 1, arm =
    /// coordinate 0, fall at 30 deg, arm limit 180 deg, settled within 1 deg
    /// over the last 2 s, friction regularised at 1e-3 rad/s, threads = the
    /// available parallelism.
    pub fn new(model: &Model, x0: Vec<f64>) -> StudyOptions {
        let n = model.coordinates.len();
        StudyOptions {
            x0,
            duration: 10.0,
            sample_rate: 1000.0,
            pendulum: 1.min(n.saturating_sub(1)),
            arm: 0,
            fall_angle: 30f64.to_radians(),
            arm_limit: std::f64::consts::PI,
            settle_angle: 1f64.to_radians(),
            settle_window: 2.0,
            smooth_sign: 1e-3,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        }
    }
}

/// How a case ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// Stayed up, arm within its limit, settled.
    Holds,
    /// The pendulum left the fall window at `t`.
    Fell {
        /// Time (s).
        t: f64,
    },
    /// The arm passed its limit at `t`.
    ArmLimit {
        /// Time (s).
        t: f64,
    },
    /// Stayed up but did not settle.
    NotSettled,
    /// The simulation failed (e.g. a singular law).
    Failed {
        /// Why.
        message: String,
    },
}

impl Outcome {
    /// Whether the case holds.
    pub fn holds(&self) -> bool {
        *self == Outcome::Holds
    }
}

impl fmt::Display for Outcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Outcome::Holds => write!(f, "holds"),
            Outcome::Fell { t } => write!(f, "fell@{t:.2}"),
            Outcome::ArmLimit { t } => write!(f, "arm@{t:.2}"),
            Outcome::NotSettled => write!(f, "unsettled"),
            Outcome::Failed { .. } => write!(f, "failed"),
        }
    }
}

/// One controller against one plant.
#[derive(Clone, Debug, PartialEq)]
pub struct CaseResult {
    /// Controller name.
    pub controller: String,
    /// Mismatch label.
    pub mismatch: String,
    /// How it ended.
    pub outcome: Outcome,
    /// Largest |pendulum| (wrapped) over the settling window (rad).
    pub tail_angle: f64,
    /// Largest |arm| over the run (rad or m).
    pub max_arm: f64,
    /// Total variation of the applied input over the run.
    pub total_variation: f64,
    /// Total variation per second over the settling window (steady chattering).
    pub tail_variation_rate: f64,
}

/// Why a study could not run.
#[derive(Clone, Debug, PartialEq)]
pub enum StudyError {
    /// A controller could not be resolved with the design values.
    Control(ControlError),
    /// A controller could not be compiled.
    Setup(SimError),
    /// A mismatch names an unknown parameter or gives a bad value.
    Values {
        /// The mismatch.
        mismatch: String,
        /// The error.
        error: ValuesError,
    },
    /// Bad options.
    Options(String),
}

impl fmt::Display for StudyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StudyError::Control(e) => write!(f, "{e}"),
            StudyError::Setup(e) => write!(f, "{e}"),
            StudyError::Values { mismatch, error } => write!(f, "`{mismatch}`: {error}"),
            StudyError::Options(s) => write!(f, "{s}"),
        }
    }
}

impl std::error::Error for StudyError {}

/// Runs every controller (by name, designed with `design`) against every
/// mismatched plant; results in controller-major order.
pub fn study(
    model: &Model,
    derivation: &Derivation,
    design: &ParameterValues,
    controllers: &[String],
    mismatches: &[Mismatch],
    options: &StudyOptions,
) -> Result<Vec<CaseResult>, StudyError> {
    let nq = model.coordinates.len();
    if options.pendulum >= nq || options.arm >= nq {
        return Err(StudyError::Options(
            "pendulum and arm must be coordinate indices".into(),
        ));
    }
    if !(options.duration > options.settle_window && options.settle_window > 0.0) {
        return Err(StudyError::Options(
            "the duration must exceed the settling window, which must be positive".into(),
        ));
    }
    if !(options.smooth_sign.is_finite() && options.smooth_sign > 0.0) {
        return Err(StudyError::Options("smooth_sign must be positive".into()));
    }
    let evals: Vec<ControllerEval> = controllers
        .iter()
        .map(|c| {
            let rc: ResolvedController =
                resolve(model, derivation, c, design).map_err(StudyError::Control)?;
            ControllerEval::new(model, &rc).map_err(StudyError::Setup)
        })
        .collect::<Result<_, _>>()?;
    let plants: Vec<ParameterValues> = mismatches
        .iter()
        .map(|m| {
            let overrides: Vec<(String, f64)> = m
                .changes
                .iter()
                .map(|(p, ch)| {
                    let Some(v) = design
                        .get(model, p)
                        .filter(|_| model.parameter(p).is_some())
                    else {
                        return Err(StudyError::Values {
                            mismatch: m.label.clone(),
                            error: ValuesError::UnknownParameter {
                                name: p.clone(),
                                suggestions: Vec::new(),
                            },
                        });
                    };
                    Ok((
                        p.clone(),
                        match ch {
                            Change::Scale(f) => v * f,
                            Change::Value(x) => *x,
                        },
                    ))
                })
                .collect::<Result<_, _>>()?;
            let base: Vec<(String, f64)> = model
                .parameters
                .iter()
                .zip(&design.base)
                .map(|(p, v)| (p.name.clone(), *v))
                .chain(overrides)
                .collect();
            ParameterValues::new(model, None, &base).map_err(|error| StudyError::Values {
                mismatch: m.label.clone(),
                error,
            })
        })
        .collect::<Result<_, _>>()?;
    let equations = smooth_signs(&derivation.equations, options.smooth_sign);
    let cases: Vec<(usize, usize)> = (0..evals.len())
        .flat_map(|c| (0..plants.len()).map(move |p| (c, p)))
        .collect();
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<CaseResult>>> = Mutex::new(vec![None; cases.len()]);
    std::thread::scope(|scope| {
        for _ in 0..options.threads.clamp(1, cases.len().max(1)) {
            scope.spawn(|| loop {
                let k = next.fetch_add(1, Ordering::Relaxed);
                let Some(&(c, p)) = cases.get(k) else {
                    break;
                };
                let r = run_case(
                    model,
                    &equations,
                    &evals[c],
                    design,
                    &plants[p],
                    &mismatches[p].label,
                    options,
                );
                results.lock().unwrap_or_else(|e| e.into_inner())[k] = Some(r);
            });
        }
    });
    Ok(results
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .flatten()
        .collect())
}

fn run_case(
    model: &Model,
    equations: &crate::mechanics::Equations,
    eval: &ControllerEval,
    design: &ParameterValues,
    plant: &ParameterValues,
    label: &str,
    o: &StudyOptions,
) -> CaseResult {
    let mut result = CaseResult {
        controller: eval.name().to_string(),
        mismatch: label.to_string(),
        outcome: Outcome::Holds,
        tail_angle: f64::NAN,
        max_arm: f64::NAN,
        total_variation: f64::NAN,
        tail_variation_rate: f64::NAN,
    };
    let traj = SimProblem::new(
        model,
        equations,
        plant,
        Control::Feedback(eval.clone()),
        o.x0.clone(),
        o.duration,
    )
    .and_then(|mut p| {
        p.controller_params = Some(design.full.clone());
        simulate(
            &p,
            &SimOptions {
                sample_rate: Some(o.sample_rate),
                output_rate: o.sample_rate,
                ..SimOptions::default()
            },
        )
    });
    let traj = match traj {
        Ok(t) => t,
        Err(e) => {
            result.outcome = Outcome::Failed {
                message: e.to_string(),
            };
            return result;
        }
    };
    let t_end = traj.t.last().copied().unwrap_or(0.0);
    let tail_from = t_end - o.settle_window;
    let (mut tail, mut arm, mut tv, mut tail_tv) = (0.0f64, 0.0f64, 0.0, 0.0);
    let mut fell = None;
    let mut arm_at = None;
    for k in 0..traj.len() {
        let x = &traj.states[k];
        let a = wrap_angle(x[o.pendulum]).abs();
        let th = x[o.arm].abs();
        arm = arm.max(th);
        if fell.is_none() && (a > o.fall_angle || a.is_nan()) {
            fell = Some(traj.t[k]);
        }
        if arm_at.is_none() && (th > o.arm_limit || th.is_nan()) {
            arm_at = Some(traj.t[k]);
        }
        if traj.t[k] >= tail_from {
            tail = tail.max(a);
        }
        if k > 0 {
            let d: f64 = traj.inputs[k]
                .iter()
                .zip(&traj.inputs[k - 1])
                .map(|(u, v)| (u - v).abs())
                .sum();
            tv += d;
            if traj.t[k - 1] >= tail_from {
                tail_tv += d;
            }
        }
    }
    result.tail_angle = tail;
    result.max_arm = arm;
    result.total_variation = tv;
    result.tail_variation_rate = tail_tv / o.settle_window;
    result.outcome = match (fell, arm_at) {
        (Some(t), Some(u)) if u < t => Outcome::ArmLimit { t: u },
        (Some(t), _) => Outcome::Fell { t },
        (None, Some(t)) => Outcome::ArmLimit { t },
        (None, None) if tail > o.settle_angle || tail.is_nan() => Outcome::NotSettled,
        (None, None) => Outcome::Holds,
    };
    result
}
