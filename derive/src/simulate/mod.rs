//! Closed- and open-loop simulation of a model's equations of motion.
//!
//! `x' = F(x, sat(u(t, x)))` is integrated by an adaptive Dormand-Prince 5(4)
//! method ([`rk::DormandPrince`]) that lands exactly on every output sample,
//! controller sample and input breakpoint. The controller is either evaluated
//! inside every integrator stage (continuous time, the default) or sampled at
//! [`SimOptions::sample_rate`] and held (zero-order hold; the integrator
//! restarts at every sample). Inputs are clipped to the model's limits.
//! A hybrid controller's switches are applied at every controller sample,
//! or, in continuous time, at every output instant (where the integrator
//! stops anyway); its mode is recorded in [`Trajectory::modes`].
//!
//! ```
//! use plantc_derive::control::{resolve, Derivation};
//! use plantc_derive::model::{load_model, ParameterValues};
//! use plantc_derive::simulate::{simulate, Control, ControllerEval, SimOptions, SimProblem};
//!
//! let model = load_model("../models/rotary_pendulum.plant".as_ref()).unwrap().model;
//! let values = ParameterValues::new(&model, Some("thesis"), &[]).unwrap();
//! let derivation = Derivation::new(&model).unwrap();
//! let ctrl = resolve(&model, &derivation, "feedback_linearization", &values).unwrap();
//! let control = Control::Feedback(ControllerEval::new(&model, &ctrl).unwrap());
//! let x0 = vec![0.0, 10f64.to_radians(), 0.0, 0.0];
//! let problem = SimProblem::new(&model, &derivation.equations, &values, control, x0, 1.0).unwrap();
//! let traj = simulate(&problem, &SimOptions::default()).unwrap();
//! let alpha = traj.state("alpha").unwrap();
//! assert!(alpha[traj.index_at(0.726)].abs() < 0.5f64.to_radians());
//! ```

mod controller;
pub mod rk;
pub mod rosenbrock;

use std::fmt;

pub use controller::{
    gain_names, set_gains, wrap_angle, ControllerEval, ControllerWorkspace, InputSignal, ModeInfo,
};
use std::cell::RefCell;

use rk::{Dense, DormandPrince, RkError, RkOptions, RkStats};
use rosenbrock::Rosenbrock;

use crate::mechanics::stick_slip::{first_crossing, Mode, StickSlip, MAX_EVENTS};
use crate::mechanics::{Equations, NumericDynamics, NumericError, Workspace};
use crate::model::{Model, ParameterValues};
use crate::sym::{Expr, Symbol, Tape};

/// Why a simulation could not be set up or failed.
#[derive(Clone, Debug, PartialEq)]
pub enum SimError {
    /// Inconsistent problem (sizes, non-finite values, options).
    Setup(String),
    /// The equations could not be compiled.
    Dynamics(NumericError),
    /// The mass matrix became singular.
    Singular {
        /// Time (s).
        t: f64,
    },
    /// The controller returned a non-finite input.
    NonFiniteControl {
        /// Time (s).
        t: f64,
        /// Input name.
        input: String,
    },
    /// The integrator failed (step too small, too many steps).
    Integrator(String),
    /// `--gain` names a gain the controller does not have.
    UnknownGain {
        /// Controller name.
        controller: String,
        /// Gain asked for.
        name: String,
        /// Gains it has.
        known: Vec<String>,
    },
}

impl fmt::Display for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SimError::Setup(s) => write!(f, "{s}"),
            SimError::Dynamics(e) => write!(f, "{e}"),
            SimError::Singular { t } => write!(f, "the mass matrix became singular at t = {t:.6} s"),
            SimError::NonFiniteControl { t, input } => write!(
                f,
                "the controller returned a non-finite `{input}` at t = {t:.6} s (singular law or diverged state)"
            ),
            SimError::Integrator(s) => write!(f, "{s}"),
            SimError::UnknownGain { controller, name, known } => {
                write!(f, "controller `{controller}` has no gain `{name}`")?;
                if known.is_empty() {
                    write!(f, " (it has no named gains)")
                } else {
                    write!(f, " (known: {})", known.join(", "))
                }
            }
        }
    }
}

impl std::error::Error for SimError {}

/// What drives the inputs.
#[derive(Clone, Debug)]
pub enum Control {
    /// A feedback controller `u(x)`.
    Feedback(ControllerEval),
    /// An input given as a function of time.
    OpenLoop(InputSignal),
}

/// Everything a simulation needs besides the options.
#[derive(Clone, Debug)]
pub struct SimProblem {
    /// Compiled equations of motion.
    pub dynamics: NumericDynamics,
    /// Full parameter vector ([`ParameterValues::full`]).
    pub params: Vec<f64>,
    /// Initial state.
    pub x0: Vec<f64>,
    /// Simulated time (s).
    pub duration: f64,
    /// Input source.
    pub control: Control,
    /// Input limits (clipped to when [`SimOptions::saturate`]).
    pub limits: Vec<Option<(f64, f64)>>,
    /// State names (`theta`, ..., `theta_dot`, ...).
    pub state_names: Vec<String>,
    /// Input names.
    pub input_names: Vec<String>,
    /// Output names (model outputs).
    pub output_names: Vec<String>,
    /// Parameter values the controller was designed with, when they differ
    /// from the plant's [`SimProblem::params`] (a robustness study); `None`:
    /// the plant's.
    pub controller_params: Option<Vec<f64>>,
    output_tape: Tape,
    /// Some `sign()` is not a dry friction of one coordinate and was
    /// smoothed (stiff).
    has_sign: bool,
}

impl SimProblem {
    /// Compile the dynamics and the model outputs for `model`.
    pub fn new(
        model: &Model,
        equations: &Equations,
        values: &ParameterValues,
        control: Control,
        x0: Vec<f64>,
        duration: f64,
    ) -> Result<SimProblem, SimError> {
        let dynamics = NumericDynamics::new(model, equations).map_err(SimError::Dynamics)?;
        let has_sign = !dynamics.notes().is_empty();
        let mut inputs: Vec<Symbol> = model.state_symbols();
        inputs.extend(model.input_symbols());
        inputs.extend(model.parameter_symbols());
        let outs: Vec<Expr> = model.outputs.iter().map(|o| o.expr).collect();
        let output_tape = Tape::compile(&outs, &inputs)
            .map_err(|e| SimError::Setup(format!("model outputs: {e}")))?;
        let p = SimProblem {
            dynamics,
            params: values.full.clone(),
            x0,
            duration,
            control,
            limits: model.inputs.iter().map(|i| i.limits).collect(),
            state_names: model.state_names(),
            input_names: model.inputs.iter().map(|i| i.name.clone()).collect(),
            output_names: model.outputs.iter().map(|o| o.name.clone()).collect(),
            controller_params: None,
            output_tape,
            has_sign,
        };
        p.check()?;
        Ok(p)
    }

    fn check(&self) -> Result<(), SimError> {
        let d = &self.dynamics;
        if self.x0.len() != d.n_states() || self.x0.iter().any(|v| !v.is_finite()) {
            return Err(SimError::Setup(format!(
                "the initial state needs {} finite values",
                d.n_states()
            )));
        }
        if let Some(c) = &self.controller_params {
            if c.len() != d.n_params() || c.iter().any(|v| !v.is_finite()) {
                return Err(SimError::Setup(format!(
                    "the controller's parameter vector needs {} finite values",
                    d.n_params()
                )));
            }
        }
        if self.params.len() != d.n_params() {
            return Err(SimError::Setup(format!(
                "{} parameter values given, the model has {}",
                self.params.len(),
                d.n_params()
            )));
        }
        if !(self.duration.is_finite() && self.duration > 0.0) {
            return Err(SimError::Setup(format!(
                "duration {} must be positive",
                self.duration
            )));
        }
        if self.limits.len() != d.n_inputs() {
            return Err(SimError::Setup("one limit entry per input".into()));
        }
        if let Control::OpenLoop(s) = &self.control {
            s.check(d.n_inputs())?;
        }
        Ok(())
    }
}

/// Integration and sampling options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimOptions {
    /// Relative tolerance of the integrator.
    pub rtol: f64,
    /// Absolute tolerance of the integrator.
    pub atol: f64,
    /// Largest integrator step (s).
    pub max_step: Option<f64>,
    /// Output samples per second (default 1000).
    pub output_rate: f64,
    /// Controller sample rate (Hz) with zero-order hold; `None` evaluates the
    /// controller inside every integrator stage.
    pub sample_rate: Option<f64>,
    /// Clip the inputs to the model's limits (default true).
    pub saturate: bool,
    /// Step budget between two consecutive events.
    pub max_steps: usize,
    /// Which integrator: explicit Dormand-Prince, implicit Rosenbrock, or
    /// chosen from the stiffness at the initial state (the default).
    pub integrator: Integrator,
}

/// The integration method of [`simulate`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Integrator {
    /// Explicit unless the model is stiff at the initial state (an explicit
    /// method would need more than [`STIFF_STEPS`] steps): then implicit.
    #[default]
    Auto,
    /// Dormand-Prince 5(4) ([`rk::DormandPrince`]).
    Explicit,
    /// Rosenbrock ROS2 ([`rosenbrock::Rosenbrock`]), for stiff models.
    Implicit,
}

/// Above this many explicit steps (estimated from the fastest mode at the
/// initial state) [`Integrator::Auto`] integrates implicitly.
pub const STIFF_STEPS: f64 = 1e6;

/// How stiff a problem is at its initial state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stiffness {
    /// Largest |eigenvalue| of the closed-loop Jacobian `df/dx` (1/s).
    pub fastest_mode: f64,
    /// Steps an explicit method needs for the whole duration (its stability
    /// bound, `|lambda| h < 3.3`).
    pub explicit_steps: f64,
}

impl Stiffness {
    /// Whether [`Integrator::Auto`] integrates it implicitly.
    pub fn is_stiff(&self) -> bool {
        self.explicit_steps > STIFF_STEPS
    }
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            rtol: 1e-8,
            atol: 1e-10,
            max_step: None,
            output_rate: 1000.0,
            sample_rate: None,
            saturate: true,
            max_steps: 100_000,
            integrator: Integrator::Auto,
        }
    }
}

/// A simulated trajectory sampled at the output rate.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    /// Sample times (s).
    pub t: Vec<f64>,
    /// State at each sample.
    pub states: Vec<Vec<f64>>,
    /// Applied (saturated) input at each sample.
    pub inputs: Vec<Vec<f64>>,
    /// Model outputs at each sample.
    pub outputs: Vec<Vec<f64>>,
    /// Whether any input was clipped at each sample.
    pub saturated: Vec<bool>,
    /// State names.
    pub state_names: Vec<String>,
    /// Input names.
    pub input_names: Vec<String>,
    /// Output names.
    pub output_names: Vec<String>,
    /// Integrator counts.
    pub stats: RkStats,
    /// A hybrid controller's mode names (empty otherwise).
    pub mode_names: Vec<String>,
    /// The mode (index into `mode_names`) at each sample; empty if not hybrid.
    pub modes: Vec<usize>,
    /// Mode switches `(t, from, to)` in time order.
    pub switches: Vec<(f64, usize, usize)>,
    /// The method used (never `Auto`).
    pub integrator: Integrator,
    /// The stiffness at the initial state (estimated for `Auto`).
    pub stiffness: Option<Stiffness>,
}

impl Trajectory {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// A state's time series by name.
    pub fn state(&self, name: &str) -> Option<Vec<f64>> {
        let i = self.state_names.iter().position(|n| n == name)?;
        Some(self.states.iter().map(|x| x[i]).collect())
    }

    /// An input's time series by name.
    pub fn input(&self, name: &str) -> Option<Vec<f64>> {
        let i = self.input_names.iter().position(|n| n == name)?;
        Some(self.inputs.iter().map(|x| x[i]).collect())
    }

    /// Index of the sample nearest to `t`.
    pub fn index_at(&self, t: f64) -> usize {
        match self.t.binary_search_by(|s| s.total_cmp(&t)) {
            Ok(i) => i,
            Err(0) => 0,
            Err(i) if i >= self.t.len() => self.t.len() - 1,
            Err(i) => {
                if (self.t[i] - t).abs() < (t - self.t[i - 1]).abs() {
                    i
                } else {
                    i - 1
                }
            }
        }
    }

    /// Share of samples with a clipped input (0..1).
    pub fn saturation_share(&self) -> f64 {
        if self.saturated.is_empty() {
            return 0.0;
        }
        self.saturated.iter().filter(|s| **s).count() as f64 / self.saturated.len() as f64
    }
}

/// Evaluation state of the closed loop.
struct Plant<'a> {
    p: &'a SimProblem,
    saturate: bool,
    ws: Workspace,
    cws: Option<ControllerWorkspace>,
    u_raw: Vec<f64>,
    u: Vec<f64>,
    held: bool,
    stick: Stick,
}

/// The stick-slip state of a simulation with sticking dry friction: the
/// mode of the current integration stretch (fixed between events) and the
/// rules' buffers.
struct Stick {
    dry: bool,
    rules: StickSlip,
    mode: Mode,
    m: Vec<f64>,
    b: Vec<f64>,
    d: Vec<f64>,
    a: Vec<f64>,
    f: Vec<f64>,
    g: Vec<f64>,
    g_end: Vec<f64>,
    xt: Vec<f64>,
    /// The state at the start of an integration stretch.
    start: Vec<f64>,
    /// The event located in the last step: the joint and whether it was
    /// stuck.
    event: Option<(usize, bool)>,
}

impl Stick {
    fn new(d: &NumericDynamics) -> Stick {
        let n = d.n_coordinates();
        let dry = d.dry_coordinates();
        Stick {
            dry: d.has_dry_friction(),
            rules: StickSlip::new(&dry),
            mode: Mode::new(n),
            m: vec![0.0; n * n],
            b: vec![0.0; n],
            d: vec![0.0; n],
            a: vec![0.0; n],
            f: vec![0.0; n],
            g: vec![0.0; n],
            g_end: vec![0.0; n],
            xt: vec![0.0; 2 * n],
            start: vec![0.0; 2 * n],
            event: None,
        }
    }
}

impl Plant<'_> {
    /// Demand and applied input from the controller at `(t, x)`.
    fn demand(&mut self, t: f64, x: &[f64]) -> Result<(), SimError> {
        let Control::Feedback(c) = &self.p.control else {
            return Ok(());
        };
        let cws = self.cws.as_mut().expect("controller workspace");
        let params = self
            .p
            .controller_params
            .as_deref()
            .unwrap_or(&self.p.params);
        c.eval(x, params, &mut self.u_raw, cws);
        if let Some(i) = self.u_raw.iter().position(|v| !v.is_finite()) {
            return Err(SimError::NonFiniteControl {
                t,
                input: self.p.input_names[i].clone(),
            });
        }
        self.apply_limits();
        Ok(())
    }

    /// Applies a hybrid controller's switches at `(t, x)`; true if the mode changed.
    fn update_mode(&mut self, t: f64, x: &[f64], switches: &mut Vec<(f64, usize, usize)>) -> bool {
        let Control::Feedback(c) = &self.p.control else {
            return false;
        };
        let cws = self.cws.as_mut().expect("controller workspace");
        let params = self
            .p
            .controller_params
            .as_deref()
            .unwrap_or(&self.p.params);
        match c.update_mode(x, params, cws) {
            Some((from, to)) => {
                switches.push((t, from, to));
                true
            }
            None => false,
        }
    }

    fn mode(&self) -> Option<usize> {
        match (&self.p.control, &self.cws) {
            (Control::Feedback(c), Some(ws)) if !c.modes().is_empty() => Some(c.mode(ws)),
            _ => None,
        }
    }

    fn apply_limits(&mut self) {
        for (i, (u, raw)) in self.u.iter_mut().zip(&self.u_raw).enumerate() {
            *u = match (self.saturate, self.p.limits[i]) {
                (true, Some((lo, hi))) => raw.clamp(lo, hi),
                _ => *raw,
            };
        }
    }

    fn rhs(&mut self, t: f64, x: &[f64], dx: &mut [f64]) -> Result<(), SimError> {
        if !self.held {
            self.demand(t, x)?;
        }
        if self.stick.dry {
            self.split(t, x)?;
            let st = &mut self.stick;
            if !st
                .rules
                .accelerations(&st.m, &st.b, &st.d, &st.mode, &mut st.a)
            {
                return Err(SimError::Singular { t });
            }
            let n = st.a.len();
            dx[..n].copy_from_slice(&x[n..2 * n]);
            dx[n..2 * n].copy_from_slice(&st.a);
            return Ok(());
        }
        self.p
            .dynamics
            .derivatives(x, &self.u, &self.p.params, dx, &mut self.ws)
            .map_err(|_| SimError::Singular { t })
    }

    /// `M`, `b` and the levels at `(t, x)` with the current input.
    fn split(&mut self, t: f64, x: &[f64]) -> Result<(), SimError> {
        let st = &mut self.stick;
        if self.p.dynamics.split(
            x,
            &self.u,
            &self.p.params,
            (&mut st.m, &mut st.b, &mut st.d),
            &mut self.ws,
        ) {
            Ok(())
        } else {
            Err(SimError::Singular { t })
        }
    }

    /// Decide the stick-slip mode at `(t, x)` (`release`: a stuck joint
    /// breaking away there); true when it changed.
    fn classify(&mut self, t: f64, x: &[f64], release: Option<usize>) -> Result<bool, SimError> {
        if !self.held {
            self.demand(t, x)?;
        }
        let n = self.stick.a.len();
        let before = self.stick.mode.clone();
        let st = &mut self.stick;
        if !st.rules.slide(&x[n..2 * n], &mut st.mode) {
            self.split(t, x)?;
            let st = &mut self.stick;
            if !st
                .rules
                .classify(&st.m, &st.b, &st.d, &x[n..2 * n], release, &mut st.mode)
            {
                return Err(SimError::Singular { t });
            }
        }
        Ok(before != self.stick.mode)
    }

    /// The guards of the current mode at `(t, x)` into `stick.g`.
    fn guards(&mut self, t: f64, x: &[f64]) -> Result<(), SimError> {
        if !self.held {
            self.demand(t, x)?;
        }
        let n = self.stick.a.len();
        if self.stick.mode.any_stuck() {
            self.split(t, x)?;
            let st = &mut self.stick;
            if !st
                .rules
                .accelerations(&st.m, &st.b, &st.d, &st.mode, &mut st.a)
            {
                return Err(SimError::Singular { t });
            }
            st.rules
                .holding_forces(&st.m, &st.b, &st.a, &st.mode, &mut st.f);
        }
        let st = &mut self.stick;
        st.rules
            .guards(&x[n..2 * n], &st.d, &st.f, &st.mode, &mut st.g);
        Ok(())
    }

    /// After an accepted step: where in it (fraction of the step) the
    /// first guard crosses zero, by [`first_crossing`] on the dense output;
    /// the joint is kept in `stick.event`.
    fn locate(&mut self, step: &Dense<'_>) -> Result<Option<f64>, SimError> {
        let t1 = step.t + step.h;
        self.guards(t1, step.end())?;
        if self.stick.g.iter().all(|g| *g >= 0.0) {
            return Ok(None);
        }
        let g_end = std::mem::take(&mut self.stick.g_end);
        let mut g_end = g_end;
        g_end.copy_from_slice(&self.stick.g);
        let mut xt = std::mem::take(&mut self.stick.xt);
        let (mut hi, mut which) = (1.0, None);
        let mut failed = None;
        for (i, &ge) in g_end.iter().enumerate() {
            if ge >= 0.0 {
                continue;
            }
            let mut guard = |theta: f64| -> Option<f64> {
                step.at(theta, &mut xt);
                match self.guards(step.t + theta * step.h, &xt) {
                    Ok(()) => Some(self.stick.g[i]),
                    Err(e) => {
                        failed = Some(e);
                        None
                    }
                }
            };
            match first_crossing(&mut guard, hi) {
                Ok(Some(theta)) => (hi, which) = (theta, Some(i)),
                Ok(None) => {}
                Err(_) => {
                    return Err(failed.take().unwrap_or(SimError::Singular { t: step.t }));
                }
            }
        }
        self.stick.g_end = g_end;
        self.stick.xt = xt;
        Ok(which.map(|j| {
            self.stick.event = Some((j, self.stick.mode.stuck[j]));
            hi
        }))
    }
}

fn event_times(rate: f64, end: f64, what: &str) -> Result<Vec<f64>, SimError> {
    if !(rate.is_finite() && rate > 0.0) {
        return Err(SimError::Setup(format!("{what} {rate} must be positive")));
    }
    let count = (end * rate * (1.0 + 1e-12)).floor() as usize;
    if count > 50_000_000 {
        return Err(SimError::Setup(format!(
            "{what} {rate} Hz gives too many samples"
        )));
    }
    Ok((0..=count).map(|i| i as f64 / rate).collect())
}

/// One of the two integrators.
enum Stepper {
    Explicit(DormandPrince),
    Implicit(Rosenbrock),
}

impl Stepper {
    fn restart(&mut self) {
        match self {
            Stepper::Explicit(r) => r.restart(),
            Stepper::Implicit(r) => r.restart(),
        }
    }

    fn advance<E, F>(
        &mut self,
        f: &mut F,
        t0: f64,
        t1: f64,
        x: &mut [f64],
    ) -> Result<(), RkError<E>>
    where
        F: FnMut(f64, &[f64], &mut [f64]) -> Result<(), E>,
    {
        match self {
            Stepper::Explicit(r) => r.advance(f, t0, t1, x),
            Stepper::Implicit(r) => r.advance(f, t0, t1, x),
        }
    }

    fn stats(&self) -> RkStats {
        match self {
            Stepper::Explicit(r) => r.stats,
            Stepper::Implicit(r) => r.stats,
        }
    }
}

/// The stiffness of `problem` at its initial state: the spectral radius of
/// the Jacobian of the closed loop (the controller inside, as in continuous
/// time; the plant alone with the initial input held when sampled or open
/// loop), by forward differences. Velocities below 1e-3 are taken as 1e-3:
/// at exactly 0 the jump of dry friction's `sign()` would read as an
/// infinitely fast mode.
pub fn stiffness(problem: &SimProblem, options: &SimOptions) -> Result<Stiffness, SimError> {
    problem.check()?;
    let d = &problem.dynamics;
    let (n, m) = (d.n_states(), d.n_inputs());
    let mut plant = Plant {
        p: problem,
        saturate: options.saturate,
        ws: d.workspace(),
        cws: match &problem.control {
            Control::Feedback(c) => Some(c.workspace(problem.params.len())),
            Control::OpenLoop(_) => None,
        },
        u_raw: vec![0.0; m],
        u: vec![0.0; m],
        held: !matches!(problem.control, Control::Feedback(_)) || options.sample_rate.is_some(),
        stick: Stick::new(d),
    };
    match &problem.control {
        Control::OpenLoop(sig) => {
            plant.u_raw.copy_from_slice(sig.sample(None));
            plant.apply_limits();
        }
        Control::Feedback(_) => plant.demand(0.0, &problem.x0)?,
    }
    let mut x0 = problem.x0.clone();
    for v in &mut x0[n / 2..] {
        if v.abs() < 1e-3 {
            *v = if *v < 0.0 { -1e-3 } else { 1e-3 };
        }
    }
    let x0 = &x0;
    if plant.stick.dry {
        plant.classify(0.0, x0, None)?;
    }
    let mut f0 = vec![0.0; n];
    plant.rhs(0.0, x0, &mut f0)?;
    let mut jac = nalgebra::DMatrix::<f64>::zeros(n, n);
    let (mut xt, mut fx) = (x0.clone(), vec![0.0; n]);
    for j in 0..n {
        let h = f64::EPSILON.sqrt() * x0[j].abs().max(1.0);
        xt[j] = x0[j] + h;
        plant.rhs(0.0, &xt, &mut fx)?;
        xt[j] = x0[j];
        for i in 0..n {
            jac[(i, j)] = (fx[i] - f0[i]) / h;
        }
    }
    let fastest_mode = if jac.iter().all(|v| v.is_finite()) {
        jac.complex_eigenvalues()
            .iter()
            .map(|l| l.norm())
            .fold(0.0, f64::max)
    } else {
        f64::INFINITY
    };
    Ok(Stiffness {
        fastest_mode,
        explicit_steps: problem.duration * fastest_mode / 3.3,
    })
}

/// Simulate `problem`.
pub fn simulate(problem: &SimProblem, options: &SimOptions) -> Result<Trajectory, SimError> {
    problem.check()?;
    if !(options.rtol > 0.0 && options.atol > 0.0) {
        return Err(SimError::Setup("tolerances must be positive".into()));
    }
    let d = &problem.dynamics;
    let (n, m) = (d.n_states(), d.n_inputs());
    let mut outs = event_times(options.output_rate, problem.duration, "output rate")?;
    if problem.duration - outs[outs.len() - 1] > 1e-9 / options.output_rate {
        outs.push(problem.duration);
    }
    let t_end = outs[outs.len() - 1];
    let samples = match (options.sample_rate, &problem.control) {
        (Some(r), Control::Feedback(_)) => Some(event_times(r, t_end, "sample rate")?),
        _ => None,
    };
    let breakpoints: &[f64] = match &problem.control {
        Control::OpenLoop(s) => s.breakpoints(),
        Control::Feedback(_) => &[],
    };
    let mut plant = Plant {
        p: problem,
        saturate: options.saturate,
        ws: d.workspace(),
        cws: match &problem.control {
            Control::Feedback(c) => Some(c.workspace(problem.params.len())),
            Control::OpenLoop(_) => None,
        },
        u_raw: vec![0.0; m],
        u: vec![0.0; m],
        held: !matches!(problem.control, Control::Feedback(_)) || samples.is_some(),
        stick: Stick::new(d),
    };
    let rk_opts = RkOptions {
        rtol: options.rtol,
        atol: options.atol,
        max_step: options.max_step.unwrap_or(f64::INFINITY),
        max_steps: options.max_steps,
        ..RkOptions::default()
    };
    let stiff = match options.integrator {
        Integrator::Auto => Some(stiffness(problem, options)?),
        _ => None,
    };
    let method = match (options.integrator, stiff) {
        (Integrator::Auto, Some(s)) if s.is_stiff() => Integrator::Implicit,
        (Integrator::Auto, _) => Integrator::Explicit,
        (m, _) => m,
    };
    let mut rk = match method {
        Integrator::Implicit => Stepper::Implicit(Rosenbrock::new(n, rk_opts)),
        _ => Stepper::Explicit(DormandPrince::new(n, rk_opts)),
    };
    let mut traj = Trajectory {
        t: Vec::with_capacity(outs.len()),
        states: Vec::with_capacity(outs.len()),
        inputs: Vec::with_capacity(outs.len()),
        outputs: Vec::with_capacity(outs.len()),
        saturated: Vec::with_capacity(outs.len()),
        state_names: problem.state_names.clone(),
        input_names: problem.input_names.clone(),
        output_names: problem.output_names.clone(),
        stats: RkStats::default(),
        mode_names: match &problem.control {
            Control::Feedback(c) => c.modes().iter().map(|m| m.name.clone()).collect(),
            Control::OpenLoop(_) => Vec::new(),
        },
        modes: Vec::new(),
        switches: Vec::new(),
        integrator: method,
        stiffness: stiff,
    };
    let mut switches = Vec::new();
    let n_y = problem.output_tape.n_outputs();
    let mut y_in = vec![0.0; n + m + problem.params.len()];
    let mut y_scratch = vec![0.0; problem.output_tape.scratch_len()];
    let mut x = problem.x0.clone();
    let mut t = 0.0f64;
    let (mut i_out, mut k_samp, mut next_bp) = (0usize, 0usize, 0usize);
    let mut segment: Option<usize> = None;
    let mut first = true;
    loop {
        let tol = 1e-10 * t.abs().max(1.0);
        // Input changes at t.
        let mut changed = first;
        while next_bp < breakpoints.len() && breakpoints[next_bp] <= t + tol {
            segment = Some(next_bp);
            next_bp += 1;
            changed = true;
        }
        if let Control::OpenLoop(sig) = &problem.control {
            if changed {
                plant.u_raw.copy_from_slice(sig.sample(segment));
                plant.apply_limits();
            }
        }
        if let Some(st) = &samples {
            let mut due = false;
            while k_samp < st.len() && st[k_samp] <= t + tol {
                k_samp += 1;
                due = true;
            }
            if due {
                plant.update_mode(t, &x, &mut switches);
                plant.demand(t, &x)?;
                changed = true;
            }
        } else if plant.update_mode(t, &x, &mut switches) {
            // continuous control: switches are checked at every output
            // instant (and input breakpoint), where the integrator stops
            changed = true;
        }
        if changed && !first {
            rk.restart();
        }
        first = false;
        // Output samples at t.
        while i_out < outs.len() && outs[i_out] <= t + tol {
            if !plant.held {
                plant.demand(t, &x)?;
            }
            y_in[..n].copy_from_slice(&x);
            y_in[n..n + m].copy_from_slice(&plant.u);
            y_in[n + m..].copy_from_slice(&problem.params);
            let mut y = vec![0.0; n_y];
            problem.output_tape.eval(&y_in, &mut y, &mut y_scratch);
            traj.t.push(outs[i_out]);
            traj.states.push(x.clone());
            traj.inputs.push(plant.u.clone());
            traj.outputs.push(y);
            traj.saturated
                .push(plant.u.iter().zip(&plant.u_raw).any(|(a, b)| a != b));
            if let Some(m) = plant.mode() {
                traj.modes.push(m);
            }
            i_out += 1;
        }
        if i_out >= outs.len() {
            break;
        }
        let mut next = outs[i_out];
        if let Some(st) = &samples {
            if k_samp < st.len() {
                next = next.min(st[k_samp]);
            }
        }
        if next_bp < breakpoints.len() {
            next = next.min(breakpoints[next_bp]);
        }
        let t0 = t;
        let advanced = if plant.stick.dry {
            advance_sticking(&mut rk, &mut plant, t0, next, &mut x)
        } else {
            rk.advance(
                &mut |tt: f64, xx: &[f64], dx: &mut [f64]| plant.rhs(tt, xx, dx),
                t0,
                next,
                &mut x,
            )
        };
        advanced.map_err(|e| match e {
            RkError::Rhs(e) => e,
            other if problem.has_sign => SimError::Integrator(format!(
                "{other}; the equations contain a sign() that is not a dry friction of one \
                 coordinate, smoothed as tanh(v/1e-3), which is stiff: smooth every dry \
                 friction wider (`mechanics::smooth_signs`, `plantc sim --smooth-sign WIDTH`)"
            )),
            other if method == Integrator::Explicit && stiff.is_none() => {
                SimError::Integrator(format!(
                    "{other}; if the model is stiff (a tiny resistance, mass or inertia), \
                     try the implicit integrator (`plantc sim --integrator implicit`)"
                ))
            }
            other => SimError::Integrator(other.to_string()),
        })?;
        t = next;
    }
    traj.stats = rk.stats();
    traj.switches = switches;
    Ok(traj)
}

/// Integrate from `t0` to `t1` with sticking dry friction: the mode is
/// decided at `t0` and at every event, each event located in the step's
/// dense output ([`Plant::locate`]: Dormand-Prince's own, the Rosenbrock
/// method's cubic Hermite); a sliding joint's velocity reaching zero is set
/// to 0.0 there, a stuck joint's breakaway releases it.
fn advance_sticking(
    rk: &mut Stepper,
    plant: &mut Plant<'_>,
    t0: f64,
    t1: f64,
    x: &mut [f64],
) -> Result<(), RkError<SimError>> {
    let n = x.len() / 2;
    let mut t = t0;
    let mut release = None;
    for _ in 0..=MAX_EVENTS {
        if plant.classify(t, x, release.take()).map_err(RkError::Rhs)? {
            rk.restart();
        }
        let mut start = std::mem::take(&mut plant.stick.start);
        start.copy_from_slice(x);
        let cell = RefCell::new(&mut *plant);
        let mut f = |tt: f64, xx: &[f64], dx: &mut [f64]| cell.borrow_mut().rhs(tt, xx, dx);
        let mut stop = |step: &Dense<'_>| cell.borrow_mut().locate(step);
        let reached = match rk {
            Stepper::Explicit(dp) => dp.advance_until(&mut f, &mut stop, t, t1, x)?,
            Stepper::Implicit(ro) => ro.advance_until(&mut f, &mut stop, t, t1, x)?,
        };
        // a stuck joint keeps its angle and zero speed exactly (the explicit
        // method's stages keep them by arithmetic, the implicit method's
        // solves only to rounding)
        for j in 0..n {
            if plant.stick.mode.stuck[j] {
                x[j] = start[j];
                x[n + j] = 0.0;
            }
        }
        plant.stick.start = start;
        let Some(te) = reached else {
            return Ok(());
        };
        match plant.stick.event.take() {
            Some((j, true)) => release = Some(j),
            Some((j, false)) => x[n + j] = 0.0,
            None => {}
        }
        t = te;
    }
    Err(RkError::Rhs(SimError::Integrator(format!(
        "the dry friction switched between sticking and sliding more than {MAX_EVENTS} times \
         between t = {t0:.6} s and {t1:.6} s"
    ))))
}
