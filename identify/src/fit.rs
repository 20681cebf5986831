//! Bounded simulation-error fit that never lies.
//!
//! **Unknowns** ([`crate::problem`]): the free model parameters (in their
//! `estimate [lo, hi]` boxes), per-experiment nuisance unknowns (initial
//! velocities by default, initial positions on request, sensor zero
//! offsets where the data call for them) and, in multiple shooting, the
//! initial state of every segment.
//!
//! **Residuals**: simulated minus measured coordinates, each channel
//! divided by its scale ([`crate::weights`]), so no channel decides alone.
//!
//! **Solver**: Levenberg-Marquardt with Marquardt's scale-invariant damping,
//! Nielsen's damping update and box constraints handled by projection with
//! an active set (a parameter at a bound is held only while the gradient
//! pushes it outwards, so a friction that reached its zero bound can grow
//! again). The normal equations come from exact forward sensitivities and
//! are solved with the nuisance unknowns eliminated block by block
//! ([`crate::lm`]).
//!
//! **Stages**:
//! 1. *Horizon*: by default each experiment is simulated whole (single
//!    shooting). When the replay at the start values diverges or ends far
//!    from the data (an unstable plant replayed open loop), the records are
//!    cut into segments of [`AUTO_SEGMENTS`] seconds (the longest that
//!    follows the data), each with its own estimated initial state
//!    (multiple shooting without continuity constraints: k-step-ahead
//!    prediction error); `--horizon S` sets the segment length. With a
//!    recorded controller in the loop the replay is closed loop and
//!    usually stays whole.
//! 2. *Global scan*: a parameter that moves an input delay or a sensor
//!    offset is scanned over its box (delays at a quarter of the sample
//!    period) before the local solver: such objectives have kinks or
//!    several minima.
//! 3. *Nuisance*: the nuisance unknowns are fitted at the start parameters;
//!    the cost there is the honest "before".
//! 4. *Growing horizons* (single shooting): 3 s, 8 s, everything; a
//!    shorter stage is nearly linear in the parameters and brings them into
//!    the basin. After every stage the point is evaluated on the whole
//!    record and the best one is kept.
//! 5. *Multi-start* when the local solver stalled far above the noise
//!    floor with a parameter at a bound.
//! 6. *Offsets*: per-experiment offsets that are not significant (all
//!    within two standard errors of zero) are dropped.
//! 7. *Identifiability* ([`crate::identifiability`]): parameters the data do
//!    not determine are fixed at their start values and the fit repeated;
//!    kept when the cost does not rise by more than 1 %.
//!
//! The result is the best point evaluated on the whole record, never worse
//! than the start; its statistics are computed there.
//!
//! Standard errors come from `sigma^2 S^-1`, `S` the parameters' information
//! with the nuisance unknowns marginalised, `sigma^2 = SSR/(N - unknowns)`.
//! Simulation residuals are correlated in time, so these are lower bounds;
//! the identifiability analysis and correlations are more telling.

use std::cell::OnceCell;
use std::fmt;

use plantc_derive::model::{Model, ParameterValues};
use serde::Serialize;

use crate::closed_loop::LoopLaw;
use crate::data::Experiment;
use crate::experiment_sim::{
    dynamics_outputs, DryFriction, InitialVelocity, Signals, SimError, SimOptions, Simulator,
};
use crate::identifiability::{analyse, to_fix, Fixed, Identifiability, ParamInfo};
use crate::initial_state::{prior_bound, velocity_prior, Prior};
use crate::lm::{global_information, local_variances, predicted_reduction, Damped};
use crate::problem::{BlockLayout, Point, Problem};
use crate::sensitivity::{estimated_parameters, SensitivitySimulator};
use crate::weights::{channel_weights, with_simulation_error, ChannelWeight};

/// How records are cut for the fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Horizon {
    /// Whole records unless the replay at the start diverges; then segments
    /// (the longest of [`AUTO_SEGMENTS`] that follows the data).
    Auto,
    /// Single shooting over each whole record.
    Whole,
    /// Multiple shooting: segments of this many seconds, each starting from
    /// its own estimated state.
    Segments(f64),
}

/// Which coordinates get a per-experiment sensor offset (an encoder zero
/// of its own in each file).
#[derive(Clone, Debug, PartialEq)]
pub enum Offsets {
    /// The coordinates whose measured value matters (the dynamics or a
    /// recorded controller depend on it) and that have no `sensor_offset`
    /// in the model; dropped again when not significant.
    Auto,
    /// None.
    None,
    /// These coordinates.
    On(Vec<String>),
}

/// Which recorded controller, if any, is simulated in the loop.
#[derive(Clone, Debug, PartialEq)]
pub enum ClosedLoop {
    /// The model's recorded controller when it has exactly one and every
    /// experiment holds the columns it reads; open loop otherwise.
    Auto,
    /// Open loop: the logged inputs are replayed.
    Off,
    /// This recorded controller (an error when the data lack its columns).
    Named(String),
}

/// Options of [`fit`].
#[derive(Clone, Debug, PartialEq)]
pub struct FitOptions {
    /// Free parameters; `None` means those marked `estimate` in the model.
    pub free: Option<Vec<String>>,
    /// Starting base values (model order); `None` means the nominal values.
    pub start: Option<Vec<f64>>,
    /// Growing horizons in s for single shooting; the last should be
    /// `f64::INFINITY` (everything).
    pub horizons: Vec<f64>,
    /// Whole records or segments.
    pub horizon: Horizon,
    /// Most LM iterations per stage.
    pub max_iterations: usize,
    /// Simulation options (`initial_velocity` gives the velocities that are
    /// not estimated).
    pub sim: SimOptions,
    /// Pairs of estimates with `|corr|` above this are reported.
    pub correlation_threshold: f64,
    /// Channel weights set by the user `(coordinate, weight per SI unit)`;
    /// the others are estimated from the data.
    pub weights: Vec<(String, f64)>,
    /// Estimate each experiment's initial velocities (on by default).
    pub estimate_velocities: bool,
    /// Estimate each experiment's initial positions (on by default, within
    /// each channel's noise: a quantised first sample is up to half a
    /// quantum off, and a sensor zero standing in for that error biases
    /// the whole record, or the observed velocities make up for it over
    /// the observer's window, a start a long simulation amplifies; segments
    /// always estimate theirs).
    pub estimate_positions: bool,
    /// Per-experiment sensor offsets.
    pub offsets: Offsets,
    /// Closed-loop simulation.
    pub closed_loop: ClosedLoop,
    /// Scan delay and offset parameters over their box before the local
    /// solver.
    pub scan: bool,
    /// Extra starts tried when the local solver stalls (0: none).
    pub multistart: usize,
    /// Fix parameters the data do not determine and refit.
    pub act_on_identifiability: bool,
    /// On the whole records, LM stops when an accepted step lowers the SSR
    /// by less than this fraction ([`FINAL_TOLERANCE`]; a screening fit,
    /// which only compares costs, can stop earlier).
    pub tolerance: f64,
    /// On the final horizon (the whole records, or the segments), stop at
    /// the screening tolerance ([`crate::diagnose::SCREENING_TOLERANCE`])
    /// while the weighted RMS stays more than [`FAR_ABOVE_FLOOR`] times the
    /// noise floor estimate: for a diagnosis' baseline, which is compared
    /// with screening refits of candidate effects and replaced by the model
    /// with the effect it lacks. Near the floor (nothing missing: the
    /// baseline is the answer) [`FitOptions::tolerance`] holds; a story
    /// whose first round finds no effect far above the floor fits its
    /// baseline on to that tolerance.
    pub coarse_far_above_floor: bool,
    /// Start the nuisance (initial states of every block, per-experiment
    /// offsets) where an earlier fit of the same experiments ended
    /// ([`FitResult::warm`]), and, when the whole records (or, on segments,
    /// the same segments) follow the data from there, skip the growing
    /// horizons and the nuisance-only start: for a refit near a fitted
    /// point (a candidate effect added to a fitted baseline).
    pub warm: Option<WarmStart>,
    /// Other starts (base values, model order) for a warm fit: the fit
    /// starts from whichever of `start` and these the whole records, from
    /// the warm nuisance, fit best (the first on a tie; one more simulation
    /// each). A lower cost is no proof of a better basin: the diagnosis'
    /// refits, which offer these, say where that costs them.
    pub alternative_starts: Vec<Vec<f64>>,
    /// Keep the simulation at the start ([`FitResult::simulated_start`]):
    /// one more nuisance fit and simulation, for a caller that shows the
    /// start values as a stage of their own (the identify story's nominal
    /// stage).
    pub simulate_start: bool,
    /// The first sample of each record the model is asked to follow (see
    /// [`crate::release`]); `None`: found from the data at the start values
    /// (or taken from [`FitOptions::warm`]). A diagnosis passes its
    /// baseline's to every refit so that all are judged on the same
    /// samples.
    pub starts: Option<Vec<usize>>,
    /// Stop short where the fit cannot reach a cost ([`GiveUp`]); `None`
    /// (the default) never gives up.
    pub give_up: Option<GiveUp>,
    /// The simulation's own error per channel `(coordinate, RMS in SI)`,
    /// added to its noise floor ([`crate::weights::with_simulation_error`];
    /// a diagnosis measures it on its baseline, [`simulation_error`]).
    /// Empty (the default): the floor is the sensor's noise alone.
    pub simulation_error: Vec<(String, f64)>,
}

/// When a fit stops short ([`FitOptions::give_up`]): on the final horizon,
/// once its weighted RMS is at most `once_at` and the Gauss-Newton model at
/// the iterate cannot bring it below `unless_below` (the residual's part
/// outside the span of the sensitivities is above it: no step, however
/// long, reaches lower to first order). A diagnosis' screening refit of a
/// candidate effect gets the baseline's cost as `once_at` (a refit that
/// ends above it was trapped and is started again, see `diagnose`) and the
/// cost the decision rule needs for the candidate to pass as
/// `unless_below`: it cannot pass, and its cost is not refined further.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct GiveUp {
    /// The weighted RMS at or below which the fit may stop.
    pub once_at: f64,
    /// The weighted RMS the fit must be able to reach to go on.
    pub unless_below: f64,
}

/// Where a fit's nuisance ended: per experiment its sensor offsets by
/// coordinate, and the initial state (positions then velocities) of every
/// block it was fitted in (one per experiment on whole records, one per
/// segment on segments). See [`FitOptions::warm`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WarmStart {
    /// Per experiment: its offsets as `(coordinate, value)`.
    offsets: Vec<Vec<(usize, f64)>>,
    /// Per block: experiment, first sample, initial state.
    blocks: Vec<(usize, usize, Vec<f64>)>,
    /// Per experiment: the first sample the model follows.
    starts: Vec<usize>,
}

impl WarmStart {
    /// Per experiment: the first sample the model was asked to follow
    /// ([`crate::release`]).
    pub fn starts(&self) -> &[usize] {
        &self.starts
    }
}

/// Per experiment, the first sample `model` (at `opts.start`, or its
/// nominal values) is asked to follow under `opts` (see
/// [`crate::release`]) at those values, or what `opts.starts` gives.
pub fn record_starts(
    model: &Model,
    experiments: &[Experiment],
    opts: &FitOptions,
) -> Result<Vec<usize>, FitError> {
    Ok(Setup::new(model, experiments, opts, &[])?.starts)
}

impl FitOptions {
    /// The names of the parameters fitted on `model`: [`FitOptions::free`],
    /// or every `estimate` parameter.
    pub fn free_names(&self, model: &Model) -> Vec<String> {
        self.free
            .clone()
            .unwrap_or_else(|| estimated_parameters(model))
    }
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            free: None,
            start: None,
            horizons: vec![3.0, 8.0, f64::INFINITY],
            horizon: Horizon::Auto,
            max_iterations: 30,
            sim: SimOptions::default(),
            correlation_threshold: 0.95,
            weights: Vec::new(),
            estimate_velocities: true,
            estimate_positions: true,
            offsets: Offsets::Auto,
            closed_loop: ClosedLoop::Auto,
            scan: true,
            multistart: 4,
            act_on_identifiability: true,
            tolerance: FINAL_TOLERANCE,
            coarse_far_above_floor: false,
            warm: None,
            alternative_starts: Vec::new(),
            simulate_start: false,
            starts: None,
            give_up: None,
            simulation_error: Vec::new(),
        }
    }
}

/// Segment lengths tried (longest first) when the whole-record replay at the
/// start diverges.
pub const AUTO_SEGMENTS: [f64; 4] = [2.0, 1.0, 0.5, 0.25];

/// A replay whose residuals, each channel divided by its spread (how much
/// it moves), have an RMS above this counts as diverged: residuals twice
/// the channels' own motion, a fit % below -100 (the prediction is worse
/// than the mean of the data by more than the data's own variation).
pub const DIVERGED_COST: f64 = 2.0;

/// A segment length is accepted when the residuals with the segments'
/// states fitted, each channel divided by its spread, have an RMS below
/// this: a fit % above 50, the segments follow the data better than they
/// miss it.
pub const SEGMENT_COST: f64 = 0.5;

/// An intermediate horizon stage is skipped when the cost over the whole
/// record is at most this multiple of the cost the previous (shorter) stage
/// ended with.
pub const SKIP_RATIO: f64 = 1.5;

/// On the whole record, LM stops when an accepted step lowers the SSR by
/// less than this fraction.
pub const FINAL_TOLERANCE: f64 = 5e-5;

/// See [`FitOptions::coarse_far_above_floor`]: above the floor there is
/// something for an effect to explain ([`crate::decision::at_floor`]: a
/// weighted RMS of `sqrt(2)` times the noise's). A misspecified model
/// creeps down a long valley there at a few 1e-4 of its SSR per iteration
/// (a spring missing on the arm: the last 13 of 35 iterations took 0.15 %
/// off the RMSE; 28 iterations at the screening tolerance), which moves no
/// decision (see [`crate::diagnose::SCREENING_TOLERANCE`]).
pub const FAR_ABOVE_FLOOR: f64 = std::f64::consts::SQRT_2;

/// The identifiability-reduced fit is kept when its cost is at most this
/// factor above the full one.
pub const REDUCED_TOLERANCE: f64 = 1.01;

/// Why a fit could not be done.
#[derive(Clone, Debug, PartialEq)]
pub enum FitError {
    /// Setting up or running the simulation failed (at the start values).
    Sim(SimError),
    /// No experiments were given.
    NoExperiments,
    /// No free parameters.
    NoFreeParameters,
    /// A free parameter has no `estimate [lo, hi]` bounds (or they are empty).
    NoBounds {
        /// Parameter name.
        name: String,
    },
    /// The start vector has the wrong length or a non-finite value.
    BadStart {
        /// Expected length.
        expected: usize,
    },
    /// Fewer residuals than unknowns.
    NotEnoughData {
        /// Number of residuals.
        residuals: usize,
        /// Number of unknowns.
        parameters: usize,
    },
    /// An option names something the model does not have, or is out of
    /// range.
    BadOption(String),
}

impl fmt::Display for FitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FitError::Sim(e) => write!(f, "{e}"),
            FitError::NoExperiments => write!(f, "no experiments to fit"),
            FitError::NoFreeParameters => write!(
                f,
                "no free parameters (mark some `estimate [lo, hi]` or name them)"
            ),
            FitError::NoBounds { name } => write!(
                f,
                "parameter `{name}` has no usable `estimate [lo, hi]` bounds"
            ),
            FitError::BadStart { expected } => write!(
                f,
                "start values must be {expected} finite numbers (one per parameter)"
            ),
            FitError::NotEnoughData {
                residuals,
                parameters,
            } => write!(
                f,
                "{residuals} residuals cannot determine {parameters} unknowns"
            ),
            FitError::BadOption(m) => write!(f, "{m}"),
        }
    }
}

impl std::error::Error for FitError {}

impl From<SimError> for FitError {
    fn from(e: SimError) -> Self {
        FitError::Sim(e)
    }
}

/// One estimated parameter.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Estimate {
    /// Parameter name.
    pub name: String,
    /// Estimated value (SI).
    pub value: f64,
    /// Standard error (NaN when it cannot be computed, e.g. fixed).
    pub std_error: f64,
    /// Starting value.
    pub start: f64,
    /// True when the estimate sits within 0.1 % of the box width of a bound.
    pub at_bound: bool,
    /// True when the fit fixed it at its start (not identifiable).
    pub fixed: bool,
}

/// A nuisance estimate of one experiment.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct NuisanceValue {
    /// What: `theta(0)`, `theta'(0)`, `offset theta`.
    pub name: String,
    /// Value (SI).
    pub value: f64,
    /// Standard error (NaN when not estimated).
    pub std_error: f64,
    /// Whether it was estimated (else taken from the data or fixed).
    pub estimated: bool,
}

/// What the fit found per experiment.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ExperimentEstimate {
    /// Experiment name.
    pub name: String,
    /// Initial state (of its first block), positions then velocities.
    pub initial_state: Vec<NuisanceValue>,
    /// Per-experiment sensor offsets.
    pub offsets: Vec<NuisanceValue>,
    /// RMSE per coordinate at the start and at the result (SI).
    pub rmse_before: Vec<f64>,
    /// RMSE per coordinate at the result (SI).
    pub rmse_after: Vec<f64>,
    /// Fit % per coordinate (as MATLAB's `compare`) at the start (None
    /// when it could not be simulated or the channel is constant).
    pub fit_before: Vec<Option<f64>>,
    /// Fit % per coordinate at the result.
    pub fit_after: Vec<Option<f64>>,
    /// When the record follows the model only from a later sample (a
    /// release transient at its start, [`crate::release`]): that sample's
    /// time from the record's first, in s. The initial state is the state
    /// there; the samples before it are in no cost, simulation or fit %.
    pub release: Option<f64>,
}

impl ExperimentEstimate {
    /// The release transient in words, when the record has one.
    pub fn release_line(&self) -> Option<String> {
        self.release.map(|t| {
            format!(
                "{}: followed from t = {t:.3} s: before it, a release transient the model cannot follow (an outside force, such as a hand letting go: the first prediction windows miss by more than the data move, and by more than any later window); those samples are in no cost or fit %",
                self.name
            )
        })
    }
}

/// The result of [`fit`].
#[derive(Clone, PartialEq)]
pub struct FitResult {
    /// Estimates of the free parameters, in the order they were given.
    pub parameters: Vec<Estimate>,
    /// All base parameter values after the fit (model order).
    pub base: Vec<f64>,
    /// The fit's cost (weighted RMS of the residuals, dimensionless) at the
    /// start (nuisance fitted) and at the result, over the same records,
    /// horizon and weights: after <= before always.
    pub before_cost: f64,
    /// See [`FitResult::before_cost`].
    pub after_cost: f64,
    /// Unweighted RMSE over all coordinates and experiments (SI) at the
    /// start and at the result.
    pub before_rmse: f64,
    /// See [`FitResult::before_rmse`].
    pub after_rmse: f64,
    /// Pairs of estimates with `|corr|` above the threshold: `(a, b, corr)`.
    pub correlations: Vec<(String, String, f64)>,
    /// LM iterations over all stages (each one sensitivity simulation).
    pub iterations: usize,
    /// Other simulations: trial steps, cost evaluations, and the
    /// sensitivity simulations of the final statistics.
    pub simulations: usize,
    /// Per experiment: nuisance estimates and RMSE.
    pub experiments: Vec<ExperimentEstimate>,
    /// The channel weights used.
    pub weights: Vec<ChannelWeight>,
    /// Segment length in s when the fit used multiple shooting.
    pub segments: Option<f64>,
    /// The recorded controller simulated in the loop, if any.
    pub closed_loop: Option<String>,
    /// Identifiability of the parameters (and what was fixed).
    pub identifiability: Identifiability,
    /// What the fit did beyond the plain solve, in words.
    pub notes: Vec<String>,
    /// The simulated measurements at the result, per experiment and
    /// coordinate (whole records; segments stitched).
    pub simulated: Vec<Vec<Vec<f64>>>,
    /// Where the nuisance ended, to warm-start another fit from.
    pub warm: WarmStart,
    /// The simulated measurements at the start (the free parameters at
    /// their `start` values, the nuisance fitted there to the final
    /// tolerance, as [`crate::validate()`] fits it), as
    /// [`FitResult::simulated`], when [`FitOptions::simulate_start`] asks;
    /// `None` for a warm fit, when the fit ended
    /// on segments (each from its own estimated state), the delay and
    /// offset scan moved the start, or the start could not be simulated.
    pub simulated_start: Option<Vec<Vec<Vec<f64>>>>,
    /// Nuisance estimates at the edge of what the data allow (an initial
    /// state at its prior's bound, an offset at its bound): the model
    /// needed a start or a zero the data do not show, so it is not
    /// adequate however low its cost.
    pub nuisance_flags: Vec<NuisanceFlag>,
    /// The fit stopped short where it could not reach
    /// [`GiveUp::unless_below`] (a screening refit of a candidate that
    /// cannot pass): its cost is above what a full refit would reach.
    pub gave_up: bool,
}

/// A nuisance estimate at the edge of what the data allow (see
/// [`FitResult::nuisance_flags`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct NuisanceFlag {
    /// Experiment name.
    pub experiment: String,
    /// What: `theta'(0)`, `alpha(2.000 s)` (a segment's start), `offset
    /// alpha`.
    pub name: String,
    /// The estimate (SI).
    pub value: f64,
    /// For an initial state, its prior from the data: `(mean, sigma)`.
    pub prior: Option<(f64, f64)>,
    /// The bound it sits at (SI).
    pub bound: f64,
}

impl NuisanceFlag {
    /// One line naming the estimate, its value and what the data allow.
    pub fn message(&self) -> String {
        match self.prior {
            Some((m, s)) => format!(
                "{} of {} = {:.4e}, at the edge of its prior from the data {:.4e} +- {:.2e} ({:.1} standard deviations)",
                self.name,
                self.experiment,
                self.value,
                m,
                s,
                (self.value - m) / s
            ),
            None => format!(
                "{} of {} = {:.4e}, at its bound {:.4e}",
                self.name, self.experiment, self.value, self.bound
            ),
        }
    }
}

impl fmt::Debug for FitResult {
    /// Everything but the simulated samples (their shape only).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("FitResult")
            .field("parameters", &self.parameters)
            .field("base", &self.base)
            .field("before_cost", &self.before_cost)
            .field("after_cost", &self.after_cost)
            .field("before_rmse", &self.before_rmse)
            .field("after_rmse", &self.after_rmse)
            .field("correlations", &self.correlations)
            .field("iterations", &self.iterations)
            .field("simulations", &self.simulations)
            .field("experiments", &self.experiments)
            .field("weights", &self.weights)
            .field("segments", &self.segments)
            .field("closed_loop", &self.closed_loop)
            .field("identifiability", &self.identifiability)
            .field("notes", &self.notes)
            .field(
                "simulated",
                &format_args!(
                    "[{} experiments x {} coordinates]",
                    self.simulated.len(),
                    self.simulated.first().map_or(0, Vec::len)
                ),
            )
            .finish()
    }
}

impl FitResult {
    /// The JSON form.
    pub fn to_json(&self) -> serde_json::Value {
        let mut params = serde_json::Map::new();
        for e in &self.parameters {
            params.insert(
                e.name.clone(),
                serde_json::json!({
                    "value": e.value,
                    "std_error": e.std_error,
                    "start": e.start,
                    "at_bound": e.at_bound,
                    "fixed": e.fixed,
                }),
            );
        }
        let corr: Vec<serde_json::Value> = self
            .correlations
            .iter()
            .map(|(a, b, c)| serde_json::json!({"a": a, "b": b, "corr": c}))
            .collect();
        serde_json::json!({
            "parameters": params,
            "before": {"cost": self.before_cost, "rmse": self.before_rmse},
            "after": {"cost": self.after_cost, "rmse": self.after_rmse},
            "correlations": corr,
            "identifiable": self.identifiability.is_identifiable(),
            "identifiability": self.identifiability,
            "messages": self.identifiability.messages(),
            "experiments": self.experiments,
            "weights": self.weights,
            "segments": self.segments,
            "closed_loop": self.closed_loop,
            "notes": self.notes,
            "nuisance_flags": self.nuisance_flags,
            "iterations": self.iterations,
            "simulations": self.simulations,
        })
    }
}

impl Serialize for FitResult {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.to_json().serialize(s)
    }
}

/// Where a running fit is, reported once per LM iteration by
/// [`fit_with_progress`].
#[derive(Clone, Debug, PartialEq)]
pub struct FitProgress {
    /// Stage (0-based).
    pub stage: usize,
    /// Number of stages planned.
    pub stages: usize,
    /// The stage's horizon in s (`INFINITY` = the whole record).
    pub horizon: f64,
    /// LM iterations so far, over all stages.
    pub iteration: usize,
    /// Weighted RMS over the stage's horizon at the current estimates.
    pub rmse: f64,
}

/// Fit the free parameters of `model` to `experiments` (see the module docs).
pub fn fit(
    model: &Model,
    experiments: &[Experiment],
    opts: &FitOptions,
) -> Result<FitResult, FitError> {
    fit_with_progress(model, experiments, opts, &mut |_| {})
}

/// The recorded controller to simulate in the loop, by the options and the
/// data.
pub fn resolve_closed_loop(
    model: &Model,
    experiments: &[Experiment],
    how: &ClosedLoop,
) -> Result<Option<LoopLaw>, FitError> {
    match how {
        ClosedLoop::Off => Ok(None),
        ClosedLoop::Named(name) => Ok(Some(LoopLaw::new(model, name)?)),
        ClosedLoop::Auto => {
            let usable: Vec<&str> = model
                .recorded
                .iter()
                .filter(|r| {
                    experiments
                        .iter()
                        .all(|e| r.signals.iter().all(|s| e.channel(&s.name).is_some()))
                })
                .map(|r| r.name.as_str())
                .collect();
            match usable.as_slice() {
                [] => Ok(None),
                [one] => Ok(Some(LoopLaw::new(model, one)?)),
                many => Err(FitError::BadOption(format!(
                    "the data fit several recorded controllers ({}); choose one with --closed-loop NAME",
                    many.join(", ")
                ))),
            }
        }
    }
}

/// The signals of every experiment, for a closed loop with `law` if given.
pub fn signals_for(
    model: &Model,
    experiments: &[Experiment],
    law: Option<&LoopLaw>,
) -> Result<Vec<Signals>, SimError> {
    experiments
        .iter()
        .map(|e| match law {
            Some(l) => Signals::from_experiment_closed(model, e, l),
            None => Signals::from_experiment(model, e),
        })
        .collect()
}

/// Coordinates that get per-experiment offsets under `how`.
fn offset_coordinates(
    model: &Model,
    how: &Offsets,
    law: Option<&LoopLaw>,
    friction: DryFriction,
) -> Result<Vec<usize>, FitError> {
    match how {
        Offsets::None => Ok(Vec::new()),
        Offsets::On(names) => names
            .iter()
            .map(|n| {
                model
                    .coordinates
                    .iter()
                    .position(|c| &c.name == n)
                    .ok_or_else(|| {
                        FitError::BadOption(format!("offsets: the model has no coordinate `{n}`"))
                    })
            })
            .collect(),
        Offsets::Auto => {
            let outs = dynamics_outputs(model, friction)?.outs;
            let outs: Vec<_> = outs.iter().map(|e| model.expand_derived(*e)).collect();
            Ok((0..model.coordinates.len())
                .filter(|&i| {
                    let q = model.coordinates[i].symbols.q;
                    let has_model_offset = model.sensors.iter().any(|s| s.coordinate == i);
                    let in_dynamics = outs.iter().any(|e| e.contains(q));
                    let read_by_law = law.is_some_and(|l| l.reads_coordinate(model, i));
                    !has_model_offset && (in_dynamics || read_by_law)
                })
                .collect())
        }
    }
}

/// Counters and progress of a fit.
struct Run<'a> {
    /// Whether the LM keeps the locals within their priors' bounds (only
    /// the answer is bounded: see [`bounded_polish`]).
    bounded: bool,
    /// Whether the LM holds every local (initial state) where it is.
    hold_locals: bool,
    /// [`FitOptions::tolerance`].
    tolerance: f64,
    /// The weighted RMS above which the screening tolerance suffices
    /// ([`FitOptions::coarse_far_above_floor`]; infinite when not).
    coarse_above: f64,
    /// [`FitOptions::give_up`].
    give_up: Option<GiveUp>,
    /// Whether an LM run stopped at [`Stop::CannotReach`].
    gave_up: bool,
    /// The normal equations over the whole records at the point where the
    /// last LM run on them ended, when it had them (a stop without a step,
    /// or a last step taken with its sensitivities): the fit's final
    /// statistics use them instead of simulating that point again (the
    /// same numbers: the two simulators agree to the bit).
    last_normal: Option<(Point, crate::lm::Normal)>,
    iterations: usize,
    simulations: usize,
    stage: usize,
    stages: usize,
    progress: &'a mut dyn FnMut(&FitProgress),
}

impl<'a> Run<'a> {
    /// A run from nothing done yet, at `tolerance`, over `stages` stages
    /// (for progress), reporting to `progress`; nothing bounded or held,
    /// no give-up, the screening tolerance never taken.
    fn new(tolerance: f64, stages: usize, progress: &'a mut dyn FnMut(&FitProgress)) -> Self {
        Run {
            bounded: false,
            hold_locals: false,
            tolerance,
            coarse_above: f64::INFINITY,
            give_up: None,
            gave_up: false,
            last_normal: None,
            iterations: 0,
            simulations: 0,
            stage: 0,
            stages,
            progress,
        }
    }
}

/// How an LM run ended.
#[derive(Copy, Clone, Debug, PartialEq)]
enum Stop {
    Converged,
    NoDescent,
    MaxIterations,
    /// The Gauss-Newton model cannot reach [`GiveUp::unless_below`].
    CannotReach,
}

/// LM on `pb` from `pt` over `horizon` with the globals where `frozen` is
/// true held. Returns the SSR and count at the end and why it stopped.
#[allow(clippy::too_many_arguments)]
fn lm(
    pb: &Problem<'_>,
    pt: &mut Point,
    horizon: f64,
    frozen: &[bool],
    max_iterations: usize,
    final_stage: bool,
    lambda: &mut f64,
    run: &mut Run<'_>,
) -> Result<(f64, usize, Stop), SimError> {
    let ng = pb.n_globals();
    let n_unknowns = frozen.iter().filter(|f| !**f).count() + pb.n_locals();
    let mut nu = 2.0;
    let mut last = (f64::NAN, 0usize);
    // The normal equations at the next point, when the trial that found it
    // was simulated with its sensitivities. That is done when the last step
    // was taken at its first trial, well predicted and far from convergence:
    // the next first trial is then likely taken too and its plain
    // simulation would only be repeated with sensitivities (a third of a
    // fit's simulation time). The same points, costs and equations either
    // way (the two simulators agree to the bit).
    let mut cached: Option<crate::lm::Normal> = None;
    let mut eager = false;
    if run.bounded {
        for (blk, l) in pb.blocks.iter().zip(pt.l.iter_mut()) {
            blk.clamp(l);
        }
    }
    for _ in 0..max_iterations {
        let nrm = match cached.take() {
            Some(n) => n,
            None => pb.normal(pt, horizon)?,
        };
        run.iterations += 1;
        (run.progress)(&FitProgress {
            stage: run.stage,
            stages: run.stages,
            horizon,
            iteration: run.iterations,
            rmse: (nrm.ssr / nrm.count.max(1) as f64).sqrt(),
        });
        let tol = if final_stage {
            let tol = (0.1 / nrm.count.saturating_sub(n_unknowns).max(1) as f64).max(run.tolerance);
            if rms(nrm.ssr, nrm.count) > run.coarse_above {
                tol.max(crate::diagnose::SCREENING_TOLERANCE)
            } else {
                tol
            }
        } else {
            1e-3
        };
        let held: Vec<bool> = (0..ng)
            .map(|j| {
                frozen[j]
                    || (pt.g[j] <= pb.lo[j] && nrm.g_g[j] > 0.0)
                    || (pt.g[j] >= pb.hi[j] && nrm.g_g[j] < 0.0)
            })
            .collect();
        if held.iter().all(|h| *h) && pb.n_locals() == 0 {
            let out = (nrm.ssr, nrm.count, Stop::Converged);
            keep_normal(run, horizon, pt, nrm);
            return Ok(out);
        }
        // on the final stage, locals at a bound of their prior that the
        // gradient pushes outwards are held too (the step `-J'r` direction
        // leaves the box)
        let held_l: Vec<Vec<bool>> = pb
            .blocks
            .iter()
            .zip(&pt.l)
            .zip(&nrm.blocks)
            .map(|((blk, l), bn)| {
                (0..l.len())
                    .map(|j| {
                        run.hold_locals
                            || run.bounded
                                && ((l[j] <= blk.lo[j] && bn.g_l[j] > 0.0)
                                    || (l[j] >= blk.hi[j] && bn.g_l[j] < 0.0))
                    })
                    .collect()
            })
            .collect();
        let holding = held_l.iter().flatten().any(|h| *h);
        let solve_nrm;
        let nrm_step: &crate::lm::Normal = if holding {
            solve_nrm = nrm.holding_locals(&held_l);
            &solve_nrm
        } else {
            &nrm
        };
        if final_stage
            && run.give_up.is_some_and(|g| {
                rms(nrm.ssr, nrm.count) <= g.once_at
                    && rms(nrm.ssr - gauss_newton_reduction(nrm_step, &held), nrm.count)
                        > g.unless_below
            })
        {
            run.gave_up = true;
            let out = (nrm.ssr, nrm.count, Stop::CannotReach);
            keep_normal(run, horizon, pt, nrm);
            return Ok(out);
        }
        let mut accepted = None;
        let mut first_trial = true;
        while *lambda < 1e12 {
            let Some(d) = Damped::solve(nrm_step, *lambda, &held) else {
                *lambda *= 10.0;
                continue;
            };
            let g_new: Vec<f64> = (0..ng)
                .map(|j| (pt.g[j] + d.dg[j]).clamp(pb.lo[j], pb.hi[j]))
                .collect();
            let dg: Vec<f64> = (0..ng).map(|j| g_new[j] - pt.g[j]).collect();
            let dl = d.locals(&dg);
            let pred = predicted_reduction(nrm_step, &dg, &dl);
            let trial = Point {
                g: g_new,
                l: pt
                    .l
                    .iter()
                    .zip(&dl)
                    .zip(&pb.blocks)
                    .map(|((l, d), blk)| {
                        let mut v: Vec<f64> = l.iter().zip(d).map(|(a, b)| a + b).collect();
                        if run.bounded {
                            blk.clamp(&mut v);
                        }
                        v
                    })
                    .collect(),
            };
            run.simulations += 1;
            // (not when the sensitivity simulation had to refine its
            // substep: the plain one may not have, and its cost decides).
            // On the final stage a first trial the model predicts to be
            // the last step is simulated with its sensitivities too: the
            // fit's final statistics need them there.
            let last_expected = final_stage && horizon.is_infinite() && pred < tol * nrm.ssr;
            let with_normal = if (eager || last_expected) && first_trial {
                pb.normal(&trial, horizon).ok().filter(|n| !n.refined)
            } else {
                None
            };
            let outcome = match &with_normal {
                Some(n) => Ok((n.ssr, n.count)),
                None => pb.cost(&trial, horizon),
            };
            let at_first = first_trial;
            first_trial = false;
            match outcome {
                Ok((s, _)) if s < nrm.ssr => {
                    let rho = if pred > 0.0 {
                        (nrm.ssr - s) / pred
                    } else {
                        1.0
                    };
                    *lambda =
                        (*lambda * (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3))).max(1e-12);
                    nu = 2.0;
                    eager = at_first && rho > 0.5 && (nrm.ssr - s) > 10.0 * tol * nrm.ssr;
                    accepted = Some((trial, s, with_normal));
                    break;
                }
                _ => {
                    *lambda *= nu;
                    nu *= 2.0;
                }
            }
        }
        let Some((trial, s, next)) = accepted else {
            let out = (nrm.ssr, nrm.count, Stop::NoDescent);
            keep_normal(run, horizon, pt, nrm);
            return Ok(out);
        };
        let small = (nrm.ssr - s) < tol * nrm.ssr;
        *pt = trial;
        cached = next;
        last = (s, nrm.count);
        if small {
            if let Some(n) = cached.take() {
                keep_normal(run, horizon, pt, n);
            }
            return Ok((s, nrm.count, Stop::Converged));
        }
    }
    Ok((last.0, last.1, Stop::MaxIterations))
}

/// Keep `nrm`, the normal equations at `pt` over `horizon`, as the last
/// LM run's ([`Run::last_normal`]; only over the whole records).
fn keep_normal(run: &mut Run<'_>, horizon: f64, pt: &Point, nrm: crate::lm::Normal) {
    run.last_normal = horizon.is_infinite().then(|| (pt.clone(), nrm));
}

/// The reduction of the SSR the Gauss-Newton model at `nrm` predicts for
/// its full step (the globals where `held` is true kept), bounds ignored:
/// the residual's projection on the span of the sensitivities, the most
/// any step can remove to first order. Solved with the smallest damping
/// that keeps the system positive definite (from 1e-10 of each diagonal:
/// the prediction of a damped step only falls short of the full one).
fn gauss_newton_reduction(nrm: &crate::lm::Normal, held: &[bool]) -> f64 {
    let mut lambda = 1e-10;
    while lambda < 1e12 {
        if let Some(d) = Damped::solve(nrm, lambda, held) {
            let dl = d.locals(&d.dg);
            return predicted_reduction(nrm, &d.dg, &dl).max(0.0);
        }
        lambda *= 10.0;
    }
    0.0
}

/// Weighted RMS from an SSR and count.
fn rms(ssr: f64, count: usize) -> f64 {
    (ssr / count.max(1) as f64).sqrt()
}

/// The nuisance of a fit's start (model parameters held): the observer
/// ([`lm_nuisance`]), the one estimator validation and compare use, with
/// the sensor zeros at their prior's mean (0): the start values need not
/// follow the whole record, and a zero fitted over a record the model does
/// not follow goes anywhere its bound lets it (a cart-pole's hanging
/// pendulum, 10 % off in length, got a zero of -pi); the fit's own steps
/// refine states and zeros jointly with the parameters. Whole-record LM
/// steps on the states alone do not serve as a start: on a closed-loop
/// replay they lead the states and zeros where the parameters then follow
/// (eight QUBE episodes with clipped starts, fitted from the data's smoothed
/// states with 10 such steps, ended with a hanging pendulum and zeros of
/// half a turn, every held-out simulation diverged; after 10 such steps
/// from the observer's start, at bounds with every held-out simulation
/// diverged too; from the observer's start alone, 0.5 s ahead 92-96 % /
/// 87-91 % on the other eight).
fn start_nuisance(setup: &Setup<'_>, pb: &Problem<'_>, pt: &mut Point, run: &mut Run<'_>) {
    run.simulations += 1;
    let _ = observe_nuisance(setup, pb, pt, false);
}

/// Refit `q` on the whole record with the globals where `frozen` is true
/// held (fresh damping, final tolerance); its SSR there, None when the fit
/// or the cost could not be simulated. With `kept_at`, the refit stops
/// where the Gauss-Newton model cannot reach it ([`GiveUp`]) and the fit's
/// own give-up is left as it was.
fn refit_whole(
    pb: &Problem<'_>,
    q: &mut Point,
    frozen: &[bool],
    max_iterations: usize,
    run: &mut Run<'_>,
    kept_at: Option<GiveUp>,
) -> Option<f64> {
    let mut lambda = 1e-3;
    let own = kept_at.map(|g| (run.give_up.replace(g), run.gave_up));
    // (from a point within the priors' bounds, near the optimum: kept there)
    run.bounded = true;
    let out = lm(
        pb,
        q,
        f64::INFINITY,
        frozen,
        max_iterations,
        true,
        &mut lambda,
        run,
    );
    run.bounded = false;
    if let Some((give_up, gave_up)) = own {
        (run.give_up, run.gave_up) = (give_up, gave_up);
    }
    out.ok()?;
    pb.cost(q, f64::INFINITY).ok().map(|(s, _)| s)
}

/// Everything fixed for one fit: model, data, simulators, layout choices.
pub(crate) struct Setup<'a> {
    model: &'a Model,
    pub(crate) sigs: Vec<Signals>,
    pub(crate) sim: Simulator,
    sens: SensitivitySimulator,
    /// Sensitivities to the nuisance unknowns only (the parameters held).
    sens_nuisance: SensitivitySimulator,
    weights: Vec<ChannelWeight>,
    free: Vec<usize>,
    free_names: Vec<String>,
    base: Vec<f64>,
    bounds: Vec<(f64, f64)>,
    offset_coords: Vec<usize>,
    /// Per experiment: the first sample the model is asked to follow
    /// ([`crate::release`]).
    pub(crate) starts: Vec<usize>,
    opts: &'a FitOptions,
}

impl<'a> Setup<'a> {
    /// Check the options, resolve the closed loop, compile the simulators
    /// with sensitivities to `free_names` (may be empty: nuisance only),
    /// read the signals and estimate the weights.
    pub(crate) fn new(
        model: &'a Model,
        experiments: &[Experiment],
        opts: &'a FitOptions,
        free_names: &[String],
    ) -> Result<Setup<'a>, FitError> {
        let n_base = model.parameters.len();
        let base = match &opts.start {
            Some(s) if s.len() == n_base && s.iter().all(|v| v.is_finite()) => s.clone(),
            Some(_) => return Err(FitError::BadStart { expected: n_base }),
            None => model.parameters.iter().map(|p| p.value).collect(),
        };
        let law = resolve_closed_loop(model, experiments, &opts.closed_loop)?;
        let mut sens = SensitivitySimulator::new(model, free_names, opts.sim)?;
        let mut sens_nuisance = SensitivitySimulator::new(model, &[], opts.sim)?;
        let mut sim = Simulator::new(model, opts.sim)?;
        if let Some(l) = &law {
            sens = sens.with_loop(l.clone());
            sens_nuisance = sens_nuisance.with_loop(l.clone());
            sim = sim.with_loop(l.clone());
        }
        let free = sens.free_indices().to_vec();
        let mut bounds = Vec::with_capacity(free.len());
        for (&i, name) in free.iter().zip(free_names) {
            match model.parameters[i].estimate {
                Some((lo, hi)) if lo < hi && lo.is_finite() && hi.is_finite() => {
                    bounds.push((lo, hi))
                }
                _ => return Err(FitError::NoBounds { name: name.clone() }),
            }
        }
        for (name, w) in &opts.weights {
            if !model.coordinates.iter().any(|c| &c.name == name) {
                return Err(FitError::BadOption(format!(
                    "weight for `{name}`: the model has no coordinate `{name}`"
                )));
            }
            if !(*w > 0.0 && w.is_finite()) {
                return Err(FitError::BadOption(format!(
                    "the weight of `{name}` must be a positive number, got {w}"
                )));
            }
        }
        let sigs = signals_for(model, experiments, law.as_ref())?;
        let names: Vec<String> = model.coordinates.iter().map(|c| c.name.clone()).collect();
        let records: Vec<Vec<&[f64]>> = (0..names.len())
            .map(|i| sigs.iter().map(|s| s.q[i].as_slice()).collect())
            .collect();
        let mut weights = channel_weights(&names, &records, &opts.weights);
        with_simulation_error(&mut weights, &opts.simulation_error);
        let offset_coords =
            offset_coordinates(model, &opts.offsets, law.as_ref(), opts.sim.dry_friction)?;
        let given = opts
            .starts
            .clone()
            .or_else(|| opts.warm.as_ref().map(|w| w.starts.clone()))
            .filter(|s| s.len() == sigs.len() && s.iter().zip(&sigs).all(|(&k, g)| k < g.len()));
        let mut setup = Setup {
            model,
            sigs,
            sim,
            sens,
            sens_nuisance,
            weights,
            free,
            free_names: free_names.to_vec(),
            base,
            bounds,
            offset_coords,
            starts: Vec::new(),
            opts,
        };
        setup.starts = match given {
            Some(s) => s,
            None => crate::release::record_starts(&setup),
        };
        Ok(setup)
    }

    /// The model.
    pub(crate) fn model(&self) -> &'a Model {
        self.model
    }

    /// The free parameters' start values.
    pub(crate) fn free_start(&self) -> Vec<f64> {
        self.free.iter().map(|&i| self.base[i]).collect()
    }

    /// [`Setup::problem`] with sensitivities to the nuisance unknowns only
    /// (for stages that hold the parameters: cheaper).
    pub(crate) fn nuisance_problem(&self, segments: Option<f64>) -> Problem<'_> {
        Problem {
            sens: &self.sens_nuisance,
            ..self.problem(segments)
        }
    }

    /// The problem with blocks cut at `segments` s (None: whole records).
    pub(crate) fn problem(&self, segments: Option<f64>) -> Problem<'_> {
        let n = self.model.coordinates.len();
        let mut blocks = Vec::new();
        for (e, sig) in self.sigs.iter().enumerate() {
            let first = self.starts.get(e).copied().unwrap_or(0);
            let cuts: Vec<usize> = match segments {
                None => vec![first, sig.len()],
                Some(h) => {
                    let mut c = vec![first];
                    let mut k = first;
                    while k < sig.len() {
                        let t0 = sig.t[k];
                        let next = k + sig.t[k..].partition_point(|&t| t < t0 + h - 1e-12);
                        let next = next.max(k + 2).min(sig.len());
                        // a short tail joins the previous segment
                        if sig.len() - next < 2 || sig.t[sig.len() - 1] - sig.t[next] < 0.5 * h {
                            c.push(sig.len());
                            break;
                        }
                        c.push(next);
                        k = next;
                    }
                    c
                }
            };
            for w in cuts.windows(2) {
                let free_state: Vec<usize> = if segments.is_some() {
                    (0..2 * n).collect()
                } else {
                    let mut v = Vec::new();
                    if self.opts.estimate_positions {
                        v.extend(0..n);
                    }
                    if self.opts.estimate_velocities {
                        v.extend(n..2 * n);
                    }
                    v
                };
                let mut fixed = vec![0.0; 2 * n];
                if let InitialVelocity::Estimate { .. } = self.opts.sim.initial_velocity {
                    let x = crate::experiment_sim::initial_state(
                        sig,
                        self.opts.sim.initial_velocity,
                        &vec![0.0; n],
                    );
                    fixed[n..].copy_from_slice(&x[n..]);
                }
                let priors: Vec<Prior> = free_state
                    .iter()
                    .map(|&c| {
                        let noise = self.weights[c % n].noise;
                        if c < n {
                            Prior {
                                mean: 0.0,
                                sigma: noise,
                            }
                        } else {
                            velocity_prior(&sig.t, &sig.q[c - n], w[0], noise)
                        }
                    })
                    .collect();
                blocks.push(BlockLayout {
                    exp: e,
                    range: w[0]..w[1],
                    free_state,
                    fixed,
                    priors,
                    lo: Vec::new(),
                    hi: Vec::new(),
                });
            }
        }
        // every prior bounds its unknown at the Bonferroni 99 % point over
        // all of them
        let count: usize = blocks
            .iter()
            .map(|b| b.priors.iter().filter(|p| p.sigma.is_finite()).count())
            .sum();
        let z = prior_bound(count);
        for b in &mut blocks {
            let (lo, hi): (Vec<f64>, Vec<f64>) = b
                .priors
                .iter()
                .map(|p| {
                    if p.sigma.is_finite() {
                        p.interval(z)
                    } else {
                        (f64::NEG_INFINITY, f64::INFINITY)
                    }
                })
                .unzip();
            b.lo = lo;
            b.hi = hi;
        }
        let offsets: Vec<(usize, usize)> = (0..self.sigs.len())
            .flat_map(|e| self.offset_coords.iter().map(move |&i| (e, i)))
            .collect();
        let mut lo: Vec<f64> = self.bounds.iter().map(|b| b.0).collect();
        let mut hi: Vec<f64> = self.bounds.iter().map(|b| b.1).collect();
        for &(e, i) in &offsets {
            let d = self.offset_bound(e, i);
            lo.push(-d);
            hi.push(d);
        }
        Problem {
            model: self.model,
            sim: &self.sim,
            sens: &self.sens,
            sigs: &self.sigs,
            weights: self.weights.iter().map(|w| w.weight).collect(),
            spreads: self.weights.iter().map(|w| w.spread).collect(),
            free: self.free.clone(),
            base: self.base.clone(),
            offsets,
            blocks,
            lo,
            hi,
        }
    }

    /// How far experiment `e`'s offset on coordinate `i` may go: the
    /// largest magnitude its record measures on it, and on an angle at
    /// most half a turn (an encoder zero beyond it is the same zero on the
    /// other side). A sensor zero is a calibration error of the model's
    /// landmark (upright, hanging, the track's centre): a pendulum swings
    /// about it or a controller holds it, so a record passes it, and a
    /// zero beyond every value it measured would put the landmark where
    /// the rig never went. Without this bound a closed-loop fit whose
    /// replay fell found the pendulum hanging with a zero of half a turn
    /// (QUBE, offsets near +-pi).
    fn offset_bound(&self, e: usize, i: usize) -> f64 {
        let visited = self.sigs[e].q[i]
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()))
            .max(f64::MIN_POSITIVE);
        match self.model.coordinates[i].kind {
            plantc_derive::model::CoordinateKind::Angle => visited.min(std::f64::consts::PI),
            _ => visited,
        }
    }

    /// The start point of `pb` at model parameters `g_model`: offsets zero,
    /// estimated initial states at their priors' means (measured
    /// positions, smoothed velocities).
    pub(crate) fn start_point(&self, pb: &Problem<'_>, g_model: &[f64]) -> Point {
        let n = self.model.coordinates.len();
        let mut g = g_model.to_vec();
        g.extend(std::iter::repeat_n(0.0, pb.offsets.len()));
        let l = pb
            .blocks
            .iter()
            .map(|b| {
                b.free_state
                    .iter()
                    .zip(&b.priors)
                    .map(|(&c, p)| {
                        if c < n || !p.mean.is_finite() {
                            0.0
                        } else {
                            p.mean
                        }
                    })
                    .collect()
            })
            .collect();
        Point { g, l }
    }

    /// The channel weights (and noise floors) of the records.
    pub(crate) fn weights(&self) -> &[ChannelWeight] {
        &self.weights
    }

    /// The free parameters' values in `base` (model order).
    fn free_values(&self, base: &[f64]) -> Vec<f64> {
        self.free.iter().map(|&i| base[i]).collect()
    }

    /// Where the nuisance of `pt` on `pb` is: offsets per experiment,
    /// initial state per block (see [`WarmStart`]).
    fn warm_at(&self, pb: &Problem<'_>, pt: &Point) -> WarmStart {
        let n = self.model.coordinates.len();
        let full = pb.full_at(&pt.g);
        let model_off = self
            .sim
            .model_offsets(&full)
            .unwrap_or_else(|_| vec![0.0; n]);
        let p = self.free.len();
        let offsets = (0..self.sigs.len())
            .map(|e| {
                pb.offsets
                    .iter()
                    .enumerate()
                    .filter(|(_, o)| o.0 == e)
                    .map(|(k, o)| (o.1, pt.g[p + k]))
                    .collect()
            })
            .collect();
        let blocks = pb
            .blocks
            .iter()
            .enumerate()
            .map(|(b, blk)| {
                let x0 = pb.block_start(b, pt, &model_off, blk.range.clone()).x0;
                (blk.exp, blk.range.start, x0)
            })
            .collect();
        WarmStart {
            offsets,
            blocks,
            starts: self.starts.clone(),
        }
    }

    /// `pt` with the nuisance of [`FitOptions::warm`] where it applies: the
    /// offsets, the initial state of each block that starts where a block
    /// of the warm start did. False when there is no warm start for these
    /// experiments, or on segments when a block has none (a fit on other
    /// segments).
    fn apply_warm(&self, pb: &Problem<'_>, pt: &mut Point) -> bool {
        let Some(w) = &self.opts.warm else {
            return false;
        };
        if w.offsets.len() != self.sigs.len() {
            return false;
        }
        let p = self.free.len();
        for (k, &(e, c)) in pb.offsets.iter().enumerate() {
            if let Some(&(_, v)) = w.offsets[e].iter().find(|o| o.0 == c) {
                pt.g[p + k] = v;
            }
        }
        let n = self.model.coordinates.len();
        let full = pb.full_at(&pt.g);
        let model_off = self
            .sim
            .model_offsets(&full)
            .unwrap_or_else(|_| vec![0.0; n]);
        let mut all = true;
        for (b, blk) in pb.blocks.iter().enumerate() {
            let Some((_, _, x0)) = w
                .blocks
                .iter()
                .find(|(e, k0, _)| *e == blk.exp && *k0 == blk.range.start)
            else {
                all = false;
                continue;
            };
            // (a position's local is its deviation from the measurement
            // minus the offsets)
            let exp_off = pb.exp_offsets(&pt.g, blk.exp);
            let sig = &self.sigs[blk.exp];
            for (j, &c) in blk.free_state.iter().enumerate() {
                if let Some(v) = x0.get(c) {
                    pt.l[b][j] = if c < n {
                        v - (sig.q[c][blk.range.start] - model_off[c] - exp_off[c])
                    } else {
                        *v
                    };
                }
            }
            blk.clamp(&mut pt.l[b]);
        }
        all || pb.blocks.len() == self.sigs.len()
    }
}

/// [`fit`], calling `progress` after each LM iteration's linearisation (for
/// progress bars on long fits).
///
/// A record is fitted from the sample its model follows ([`crate::release`]),
/// judged at the start values unless [`FitOptions::starts`] gives it; when
/// the fitted model draws that line elsewhere (a start so far off that every
/// window misses, a hand's hold only the fitted model tells from the rest),
/// the fit is refined once more on the samples the fitted model follows,
/// from its result (no extra starts: the first fit had them; the
/// simulation at the start values, when asked, is the first fit's).
pub fn fit_with_progress(
    model: &Model,
    experiments: &[Experiment],
    opts: &FitOptions,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<FitResult, FitError> {
    let r = fit_on_starts(model, experiments, opts, progress)?;
    if opts.starts.is_some() || opts.warm.is_some() {
        return Ok(r);
    }
    let at_result = FitOptions {
        start: Some(r.base.clone()),
        ..opts.clone()
    };
    let starts = record_starts(model, experiments, &at_result)?;
    if starts == r.warm.starts {
        return Ok(r);
    }
    let again = FitOptions {
        starts: Some(starts),
        multistart: 0,
        simulate_start: false,
        ..at_result
    };
    let mut out = fit_on_starts(model, experiments, &again, progress)?;
    // the start values are the first fit's: so are the figures at them
    // (over that fit's samples)
    out.simulated_start = r.simulated_start;
    out.before_cost = r.before_cost.max(out.after_cost);
    out.before_rmse = r.before_rmse;
    for (o, f) in out.experiments.iter_mut().zip(r.experiments) {
        o.fit_before = f.fit_before;
        o.rmse_before = f.rmse_before;
    }
    out.iterations += r.iterations;
    out.simulations += r.simulations;
    Ok(out)
}

/// [`fit_with_progress`] on the samples `opts` gives or the start values
/// find.
fn fit_on_starts(
    model: &Model,
    experiments: &[Experiment],
    opts: &FitOptions,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<FitResult, FitError> {
    if experiments.is_empty() {
        return Err(FitError::NoExperiments);
    }
    let free_names = opts.free_names(model);
    if free_names.is_empty() {
        return Err(FitError::NoFreeParameters);
    }
    if let Horizon::Segments(h) = opts.horizon {
        if !(h > 0.0 && h.is_finite()) {
            return Err(FitError::BadOption(format!(
                "the horizon must be a positive number of seconds, got {h}"
            )));
        }
    }
    let setup = Setup::new(model, experiments, opts, &free_names)?;
    let law = setup.sim.law().cloned();
    let free = setup.free.clone();
    let floor = crate::weights::noise_cost(&setup.weights);
    let mut run = Run {
        coarse_above: if opts.coarse_far_above_floor && floor > 0.0 {
            FAR_ABOVE_FLOOR * floor
        } else {
            f64::INFINITY
        },
        give_up: opts.give_up,
        ..Run::new(opts.tolerance, 1, progress)
    };
    let g0 = better_start(&setup, &mut run);
    let mut notes = Vec::new();
    if let Some(l) = &law {
        notes.push(format!(
            "closed loop: recorded controller `{}` simulated in the loop, fed by {}",
            l.name,
            if l.signal_names().is_empty() {
                "the measured coordinates".to_string()
            } else {
                format!("the columns {}", l.signal_names().join(", "))
            }
        ));
    }

    // 1. horizon: whole records unless the replay diverges; then segments,
    // and back to whole records when the segments' estimates follow the data
    // (the simulator at half the step, compiled when first asked)
    let fine_sim = OnceCell::new();
    let whole_follows = |g: &[f64], locals: Option<&Outcome>, run: &mut Run<'_>| -> bool {
        let pb = setup.problem(None);
        let mut pt = setup.start_point(&pb, g);
        if let Some(o) = locals {
            carry_over(&setup, &pb, &mut pt, o);
        } else {
            setup.apply_warm(&pb, &mut pt);
        }
        run.simulations += 1;
        // the replay within the data's spread, and one that agrees with
        // itself at half the step (not chaotic at those values: the spread
        // of a tumbling angle is so large that a replay that has lost every
        // revolution still lies within it, and a whole-record fit from
        // there moves to damped values where the motion is regular and no
        // test can tell any more)
        follows(&pb, &pt) && {
            run.simulations += 2;
            predictable(&setup, &pb, &pt, experiments, &fine_sim)
        }
    };
    let out = match opts.horizon {
        Horizon::Whole => solve(&setup, None, &g0, None, true, &mut run, &mut notes)?,
        Horizon::Segments(h) => solve(&setup, Some(h), &g0, None, true, &mut run, &mut notes)?,
        Horizon::Auto if whole_follows(&g0, None, &mut run) => {
            solve(&setup, None, &g0, None, true, &mut run, &mut notes)?
        }
        Horizon::Auto => {
            let h = choose_segments(&setup, &g0, &mut run);
            let seg = solve(&setup, Some(h), &g0, None, true, &mut run, &mut notes)?;
            let g1 = seg.pt.g[..free.len()].to_vec();
            if whole_follows(&g1, Some(&seg), &mut run) {
                notes.push(format!(
                    "the replay of the whole records at the start values diverged or left the data: fitted first on {h} s segments (each from its own estimated state), then on the whole records from there"
                ));
                let (before_pt, before) = whole_before(&setup, &g0, &mut run);
                let mut whole = solve(&setup, None, &g1, Some(&seg), false, &mut run, &mut notes)?;
                whole.before = before;
                whole.start_pt = before_pt;
                whole
            } else {
                notes.push(format!(
                    "the replay of the whole records diverges or leaves the data, also at the fitted values: the fit is on {h} s segments, each from its own estimated state (multiple shooting; set the length with --horizon)"
                ));
                seg
            }
        }
    };
    let segments = out.segments;
    let pb = setup.problem(segments);
    let ng = pb.n_globals();
    let p = free.len();
    let unknowns = pb.n_unknowns();
    let (ssr0, count) = out.before;
    let before_cost = rms(ssr0, count);
    let start_pt = out.start_pt;
    let mut frozen = vec![false; ng];
    let mut pt = out.pt;
    let mut best = (pt.clone(), out.ssr);
    // a refit with some globals fixed is kept when its cost stays within
    // the tolerance of the best and below the start's
    let acceptable =
        |s: f64, best: f64| s <= REDUCED_TOLERANCE * REDUCED_TOLERANCE * best && s <= ssr0;

    // the normal equations at the best point (reused below when the point
    // does not move)
    let mut nrm = match run.last_normal.take() {
        Some((at, n)) if at == pt => n,
        _ => {
            run.simulations += 1;
            pb.normal(&pt, f64::INFINITY)?
        }
    };
    // 6. per-experiment offsets that are not significant are dropped (not
    // from a fit that gave up: dropping nuisance refines a cost that is
    // not to be refined, see [`GiveUp`])
    if matches!(opts.offsets, Offsets::Auto) && !pb.offsets.is_empty() && !run.gave_up {
        let (cov, _) = covariance(&nrm, &frozen, unknowns);
        let mut dropped = Vec::new();
        let mut q = pt.clone();
        let mut fz = frozen.clone();
        for &i in &setup.offset_coords {
            let idx: Vec<usize> = pb
                .offsets
                .iter()
                .enumerate()
                .filter(|(_, o)| o.1 == i)
                .map(|(k, _)| p + k)
                .collect();
            // an offset the data cannot determine (NaN standard error, e.g.
            // the arm's zero under a controller that regulates the measured
            // angle) is not significant either
            let significant = idx.iter().any(|&j| {
                let se = cov[j * ng + j].sqrt();
                se.is_finite() && pt.g[j].abs() > 2.0 * se
            });
            if !significant {
                for &j in &idx {
                    q.g[j] = 0.0;
                    fz[j] = true;
                }
                dropped.push(model.coordinates[i].name.clone());
            }
        }
        if !dropped.is_empty() {
            // (a yes-or-no question, kept or not: the refit stops once the
            // Gauss-Newton model cannot bring it to where it would be kept,
            // as `refine_to_floor`'s does in a diagnosis; the cogging
            // candidate of two_hidden, whose arm offset was not significant,
            // started again at 1.86 times its weighted RMS and took 21
            // iterations to end 3.6 % above it, not kept)
            let kept_at = GiveUp {
                once_at: f64::INFINITY,
                unless_below: REDUCED_TOLERANCE * rms(best.1, count),
            };
            let refit = refit_whole(
                &pb,
                &mut q,
                &fz,
                opts.max_iterations,
                &mut run,
                Some(kept_at),
            );
            run.simulations += 1;
            if let Some(s2) = refit {
                if acceptable(s2, best.1) {
                    best = (q, s2);
                    frozen = fz;
                    nrm = pb.normal(&best.0, f64::INFINITY)?;
                    run.simulations += 1;
                    notes.push(format!(
                        "per-experiment offsets on {} were dropped: not significant (within 2 standard errors of zero) or not determined by the data",
                        dropped.join(", ")
                    ));
                }
            }
        }
        pt = best.0.clone();
    }

    // 7. identifiability: fix what the data do not determine, refit
    let mut ident = identifiability(&setup, &pb, &pt, &nrm, &frozen, unknowns);
    if opts.act_on_identifiability {
        let fix = to_fix(&ident);
        if !fix.is_empty() {
            let mut q = pt.clone();
            let mut fz = frozen.clone();
            for (name, _) in &fix {
                if let Some(j) = setup.free_names.iter().position(|n| n == name) {
                    q.g[j] = g0[j];
                    fz[j] = true;
                }
            }
            let reduced = refit_whole(&pb, &mut q, &fz, opts.max_iterations, &mut run, None);
            if let Some(s) = reduced {
                if acceptable(s, best.1) {
                    notes.push(format!(
                        "{} fixed at start value(s) (not identifiable); cost {:.4e} against {:.4e} with all free",
                        fix.iter().map(|f| format!("`{}`", f.0)).collect::<Vec<_>>().join(", "),
                        rms(s, count),
                        rms(best.1, count)
                    ));
                    best = (q.clone(), s);
                    frozen = fz;
                    pt = q;
                    nrm = pb.normal(&pt, f64::INFINITY)?;
                    run.simulations += 1;
                    let fixed: Vec<Fixed> = fix
                        .iter()
                        .map(|(name, reason)| Fixed {
                            name: name.clone(),
                            value: setup
                                .free_names
                                .iter()
                                .position(|n| n == name)
                                .map_or(f64::NAN, |j| g0[j]),
                            reason: reason.clone(),
                        })
                        .collect();
                    ident = identifiability(&setup, &pb, &pt, &nrm, &frozen, unknowns);
                    ident.fixed = fixed;
                } else {
                    let rise = s / best.1 - 1.0;
                    for (name, _) in &fix {
                        ident.kept_free.push((name.clone(), rise));
                    }
                }
            }
        }
    }

    // final statistics at the best point
    let (cov, sigma2) = covariance(&nrm, &frozen, unknowns);
    let lv = local_variances(&nrm);
    let base_after = pb.base_at(&pt.g);
    let parameters: Vec<Estimate> = (0..p)
        .map(|j| {
            let (lo, hi) = setup.bounds[j];
            let v = pt.g[j];
            Estimate {
                name: free_names[j].clone(),
                value: v,
                std_error: if frozen[j] {
                    f64::NAN
                } else {
                    cov[j * ng + j].sqrt()
                },
                start: g0[j],
                at_bound: crate::identifiability::at_bound(v, lo, hi),
                fixed: frozen[j],
            }
        })
        .collect();
    let mut correlations = Vec::new();
    for j in 0..p {
        for l in j + 1..p {
            let c = cov[j * ng + l] / (cov[j * ng + j] * cov[l * ng + l]).sqrt();
            if c.abs() > opts.correlation_threshold {
                correlations.push((free_names[j].clone(), free_names[l].clone(), c));
            }
        }
    }
    let simulated = pb.predict(&pt)?;
    let warm = setup.warm_at(&pb, &pt);
    let simulated_before = pb.predict(&start_pt).ok();
    run.simulations += 2;
    // the start as a comparison of the start values: its nuisance fitted
    // to the final tolerance as `validate` fits it (the fit's own start
    // stops at 1e-3), from where the fit's start left it; not for a warm
    // fit (its start kept the warm nuisance), on segments, or when the
    // scan moved a free parameter off its start value
    let simulated_start = if opts.simulate_start
        && segments.is_none()
        && opts.warm.is_none()
        && start_pt.g[..p] == g0[..p]
    {
        let pbn = setup.nuisance_problem(None);
        let mut q = start_pt.clone();
        run.simulations += 1;
        if lm_nuisance(&setup, &pbn, &mut q) {
            pb.predict(&q).ok()
        } else {
            None
        }
    } else {
        None
    };
    let experiments_out = experiment_estimates(
        &setup,
        &pb,
        &pt,
        &cov,
        &lv,
        sigma2,
        &simulated,
        simulated_before.as_ref(),
    );
    let (before_rmse, after_rmse) = (
        simulated_before
            .as_ref()
            .map_or(f64::INFINITY, |b| unweighted_rmse(&setup.sigs, b)),
        unweighted_rmse(&setup.sigs, &simulated),
    );
    Ok(FitResult {
        parameters,
        base: base_after,
        before_cost,
        after_cost: rms(best.1, count),
        before_rmse,
        after_rmse,
        correlations,
        iterations: run.iterations,
        simulations: run.simulations,
        experiments: experiments_out,
        weights: setup.weights.clone(),
        segments,
        closed_loop: law.map(|l| l.name.clone()),
        identifiability: ident,
        notes,
        simulated,
        warm,
        simulated_start,
        nuisance_flags: nuisance_flags(&setup, &pb, &pt),
        gave_up: run.gave_up,
    })
}

/// Do the whole records, replayed from the start values with the nuisance
/// at its data estimates, follow the data (the weighted RMS within
/// [`DIVERGED_COST`])? What [`Horizon::Auto`] asks before choosing segments.
pub fn replay_follows(
    model: &Model,
    experiments: &[Experiment],
    opts: &FitOptions,
) -> Result<bool, FitError> {
    at_start_values(model, experiments, opts, |_, pb, pt| follows(pb, pt))
}

/// `what` of the whole records' problem at the start values, the nuisance
/// at its data estimates (the replay [`replay_follows`] and
/// [`replay_predictable`] judge).
fn at_start_values<T>(
    model: &Model,
    experiments: &[Experiment],
    opts: &FitOptions,
    what: impl FnOnce(&Setup, &Problem<'_>, &Point) -> T,
) -> Result<T, FitError> {
    let free_names = opts.free_names(model);
    let setup = Setup::new(model, experiments, opts, &free_names)?;
    let pb = setup.problem(None);
    let pt = setup.start_point(&pb, &setup.free_values(&setup.base));
    Ok(what(&setup, &pb, &pt))
}

/// Does the simulation of `pb` at `pt` over everything follow the data
/// (simulates, weighted RMS within [`DIVERGED_COST`])?
fn follows(pb: &Problem<'_>, pt: &Point) -> bool {
    pb.relative_cost(pt, f64::INFINITY)
        .is_ok_and(|(s, c)| rms(s, c) <= DIVERGED_COST)
}

/// The free values of the start of a fit: those of [`FitOptions::start`],
/// or of the [`FitOptions::alternative_starts`] whose whole records, with
/// the warm nuisance, fit best when the fit is warm (the first on a tie;
/// a simulation per distinct start).
fn better_start(setup: &Setup<'_>, run: &mut Run<'_>) -> Vec<f64> {
    let g0 = setup.free_values(&setup.base);
    // (the alternatives are weighed on whole records)
    let warm = setup.opts.warm.is_some() && !matches!(setup.opts.horizon, Horizon::Segments(_));
    if !warm {
        return g0;
    }
    let mut starts = vec![g0];
    for a in &setup.opts.alternative_starts {
        if a.len() != setup.base.len() {
            continue;
        }
        let g = setup.free_values(a);
        if g.iter().all(|v| v.is_finite()) && !starts.contains(&g) {
            starts.push(g);
        }
    }
    if starts.len() == 1 {
        return starts.swap_remove(0);
    }
    let pb = setup.problem(None);
    let mut best = (f64::INFINITY, 0);
    for (k, g) in starts.iter().enumerate() {
        let mut pt = setup.start_point(&pb, g);
        setup.apply_warm(&pb, &mut pt);
        run.simulations += 1;
        let cost = pb
            .cost(&pt, f64::INFINITY)
            .map_or(f64::INFINITY, |(s, _)| s);
        if cost < best.0 {
            best = (cost, k);
        }
    }
    starts.swap_remove(best.1)
}

/// Where a fit on one layout (whole records or segments) ended.
struct Outcome {
    /// Segment length, None for whole records.
    segments: Option<f64>,
    /// The best point on the layout's whole objective.
    pt: Point,
    /// Its SSR.
    ssr: f64,
    /// The start point (nuisance fitted) and its `(SSR, count)`: the honest
    /// "before" (SSR infinite when the start could not be simulated).
    start_pt: Point,
    before: (f64, usize),
}

/// Carry the nuisance of `from` (a fit on another layout) over to `pt` on
/// `pb`: offsets as they are, initial states of blocks that start at the
/// same sample (the first segment of an experiment gives its record's).
fn carry_over(setup: &Setup<'_>, pb: &Problem<'_>, pt: &mut Point, from: &Outcome) {
    let p = setup.free.len();
    if from.pt.g.len() == pt.g.len() {
        pt.g[p..].copy_from_slice(&from.pt.g[p..]);
    }
    let layout = setup.problem(from.segments);
    for (b, blk) in pb.blocks.iter().enumerate() {
        let Some(fb) = layout
            .blocks
            .iter()
            .position(|x| x.exp == blk.exp && x.range.start == blk.range.start)
        else {
            continue;
        };
        for (j, c) in blk.free_state.iter().enumerate() {
            if let Some(k) = layout.blocks[fb].free_state.iter().position(|x| x == c) {
                pt.l[b][j] = from.pt.l[fb][k];
            }
        }
    }
}

/// The longest of [`AUTO_SEGMENTS`] whose segments, with their states
/// fitted at the start values, follow the data.
fn choose_segments(setup: &Setup<'_>, g0: &[f64], run: &mut Run<'_>) -> f64 {
    for &h in &AUTO_SEGMENTS {
        let pb = setup.nuisance_problem(Some(h));
        let mut pt = setup.start_point(&pb, g0);
        let frozen: Vec<bool> = (0..pb.n_globals()).map(|_| true).collect();
        let mut lambda = 1e-3;
        if lm(
            &pb,
            &mut pt,
            f64::INFINITY,
            &frozen,
            5,
            false,
            &mut lambda,
            run,
        )
        .is_ok()
            && pb
                .relative_cost(&pt, f64::INFINITY)
                .is_ok_and(|(s, c)| rms(s, c) <= SEGMENT_COST)
        {
            return h;
        }
    }
    *AUTO_SEGMENTS.last().unwrap_or(&0.25)
}

/// The whole-record cost at `g0` with the nuisance fitted: the "before" of
/// a fit that moved to whole records (SSR infinite when it cannot be
/// simulated).
fn whole_before(setup: &Setup<'_>, g0: &[f64], run: &mut Run<'_>) -> (Point, (f64, usize)) {
    let pb = setup.nuisance_problem(None);
    let mut pt = setup.start_point(&pb, g0);
    start_nuisance(setup, &pb, &mut pt, run);
    let frozen: Vec<bool> = (0..pb.n_globals()).map(|j| j < setup.free.len()).collect();
    let count = pb.count_all();
    let (pt, ssr) = bounded_polish(&pb, pt, &frozen, 10, run);
    (pt, (ssr, count))
}

/// One fit on one layout: scan (optional), nuisance at the start, growing
/// horizons (whole records) or one stage (segments), multi-start when
/// stalled; the best point on the layout's whole objective.
fn solve(
    setup: &Setup<'_>,
    segments: Option<f64>,
    g_start: &[f64],
    seed: Option<&Outcome>,
    do_scan: bool,
    run: &mut Run<'_>,
    notes: &mut Vec<String>,
) -> Result<Outcome, FitError> {
    let opts = setup.opts;
    let pb = setup.problem(segments);
    let ng = pb.n_globals();
    let p = setup.free.len();
    let count_all = pb.count_all();
    let unknowns = pb.n_unknowns();
    if count_all < unknowns {
        return Err(FitError::NotEnoughData {
            residuals: count_all,
            parameters: unknowns,
        });
    }
    let mut pt = setup.start_point(&pb, g_start);
    if let Some(o) = seed {
        carry_over(setup, &pb, &mut pt, o);
    }
    // a warm start that the whole records (or the segments) follow goes
    // straight to them
    let warm = seed.is_none()
        && setup.apply_warm(&pb, &mut pt)
        && {
            run.simulations += 1;
            true
        }
        && follows(&pb, &pt);
    if !warm {
        pt = setup.start_point(&pb, g_start);
        if let Some(o) = seed {
            carry_over(setup, &pb, &mut pt, o);
        }
    }
    let frozen = vec![false; ng];
    let horizons: Vec<f64> = if segments.is_some() || warm {
        vec![f64::INFINITY]
    } else {
        let full_at = opts
            .horizons
            .iter()
            .position(|&h| (0..pb.blocks.len()).all(|b| pb.block_range(b, h) == pb.blocks[b].range))
            .unwrap_or(opts.horizons.len());
        let mut v: Vec<f64> = opts.horizons.iter().take(full_at).copied().collect();
        v.push(f64::INFINITY);
        v
    };
    run.stages = horizons.len() + 1;
    run.stage = 0;
    if do_scan && opts.scan {
        scan(setup, &pb, &mut pt, run, notes);
    }
    // nuisance at the start parameters: the honest "before" (a warm start
    // has it from the fit it starts from)
    let has_nuisance = ng > p || pb.n_locals() > 0;
    if has_nuisance && !warm {
        let pbn = setup.nuisance_problem(segments);
        start_nuisance(setup, &pbn, &mut pt, run);
    }
    run.simulations += 1;
    // the start within its priors' bounds, as the answer will be
    let (pt, ssr0) = if has_nuisance && !warm {
        let nf: Vec<bool> = (0..ng).map(|j| j < p).collect();
        bounded_polish(&pb, pt, &nf, 10, run)
    } else {
        let c = pb.cost(&pt, f64::INFINITY).map_or(f64::INFINITY, |x| x.0);
        (pt, c)
    };
    let before = (ssr0, count_all);
    let start_pt = pt.clone();
    // growing horizons, the best point on the whole objective kept
    let first = (pt.clone(), before.0);
    let (mut best, last_stop) = staged(&pb, pt, first, &frozen, &horizons, opts, run);
    let floor = crate::weights::noise_cost(&setup.weights);
    // multi-start when stalled far above the floor at a bound (a damping
    // at zero included: on the double pendulum missing a 4 ms delay the
    // baseline stalls at 74x the floor with one there, and other starts
    // find the basin where the delay is named)
    let at_bound =
        |g: &[f64]| (0..p).any(|j| crate::identifiability::at_bound(g[j], pb.lo[j], pb.hi[j]));
    if opts.multistart > 0
        && best.1.is_finite()
        && rms(best.1, count_all) > 3.0 * floor
        && (last_stop == Stop::NoDescent || at_bound(&best.0.g))
    {
        // the extra starts are far from anything fitted: they start on the
        // shortest horizon even when this fit went straight to the whole
        // records from a warm start
        let first = if segments.is_some() {
            f64::INFINITY
        } else {
            opts.horizons.first().copied().unwrap_or(f64::INFINITY)
        };
        if let Some(found) = multistart(setup, &pb, &best, &frozen, first, run) {
            notes.push(format!(
                "the local solver stalled at {:.3e} with a parameter at a bound; of {} extra starts the best reached {:.3e}",
                rms(best.1, count_all),
                opts.multistart,
                rms(found.1, count_all)
            ));
            if found.1 < best.1 {
                best = found;
            }
        }
    }
    // the answer within the priors' bounds (never worse than the start,
    // which is within them too)
    let polished = bounded_polish(&pb, best.0, &frozen, opts.max_iterations, run);
    let best = if polished.1 <= before.0 {
        polished
    } else {
        (start_pt.clone(), before.0)
    };
    Ok(Outcome {
        segments,
        pt: best.0,
        ssr: best.1,
        start_pt,
        before,
    })
}

/// `pt` within its priors' bounds: when a local lies outside them (the
/// search may lean on the initial states; the answer may not), clamped and
/// refitted on the whole records with them held inside (the globals where
/// `frozen` is true held); its weighted SSR (infinite when it cannot be
/// simulated). The bounds bind the answer, not the search: far from the
/// optimum a fit leans on the initial states (a spring missing from the
/// start values: held within their priors all along, the per-file offsets
/// took up the slack and the fit stalled at 150x the floor; free, the
/// states came back to 0.002 rad/s by the end). Not even from a warm
/// start, a bounded answer: the story's round-2 fit of a spring added to
/// the arm, warm from round 1's fit, stalled at a weighted RMS of 0.792
/// held within them where the free search and this polish reached 0.763
/// (and the end steps could no longer tell the round-1 Stribeck friction
/// from the Coulomb friction it was), although the polish costs a
/// diagnosis' refits 3 to 6 more iterations each, a fifth of the
/// two_hidden bench case's CPU time.
fn bounded_polish(
    pb: &Problem<'_>,
    pt: Point,
    frozen: &[bool],
    max_iterations: usize,
    run: &mut Run<'_>,
) -> (Point, f64) {
    let q = pb.clamped(&pt);
    if q == pt {
        run.simulations += 1;
        let c = pb.cost(&pt, f64::INFINITY).map_or(f64::INFINITY, |x| x.0);
        return (pt, c);
    }
    let mut q = q;
    let mut lambda = 1e-3;
    run.bounded = true;
    let out = lm(
        pb,
        &mut q,
        f64::INFINITY,
        frozen,
        max_iterations,
        true,
        &mut lambda,
        run,
    );
    run.bounded = false;
    let q = pb.clamped(&q);
    run.simulations += 1;
    let c = match out {
        Ok(_) => pb.cost(&q, f64::INFINITY).map_or(f64::INFINITY, |x| x.0),
        Err(_) => f64::INFINITY,
    };
    (q, c)
}

/// LM over growing `horizons` from `pt` with the globals where `frozen` is
/// true held: each stage from where the previous ended, a stage that
/// cannot be simulated skipped, an intermediate stage skipped when the
/// whole records already follow ([`SKIP_RATIO`]). Returns the best point
/// on the whole objective (at least `best`) and how the last stage ended.
fn staged(
    pb: &Problem<'_>,
    mut pt: Point,
    mut best: (Point, f64),
    frozen: &[bool],
    horizons: &[f64],
    opts: &FitOptions,
    run: &mut Run<'_>,
) -> ((Point, f64), Stop) {
    // per-experiment offsets are held on the short horizons: there an
    // offset trades against the parameters that set a swing's phase (a
    // free swing from nominal values fitted with them free stalled at cost
    // 0.144 with an alpha offset of 0.039 rad; held, 0.037, the clean
    // data's level); they move on the whole records only
    let n_free = pb.n_globals() - pb.offsets.len();
    let short: Vec<bool> = frozen
        .iter()
        .enumerate()
        .map(|(j, f)| *f || j >= n_free)
        .collect();
    let mut lambda: f64 = 1e-3;
    // SSR and count of the last stage
    let mut stage: Option<(f64, usize)> = None;
    let mut last_stop = Stop::Converged;
    for (s, &h) in horizons.iter().enumerate() {
        run.stage = s + 1;
        let last = s + 1 == horizons.len();
        if s > 0 && !last {
            run.simulations += 1;
            if let (Ok((full, nf)), Some((ssr, c))) = (pb.cost(&pt, f64::INFINITY), stage) {
                if rms(full, nf) <= SKIP_RATIO * rms(ssr, c) {
                    continue;
                }
            }
        }
        lambda = lambda.max(1e-3);
        match lm(
            pb,
            &mut pt,
            h,
            if h.is_finite() { &short } else { frozen },
            opts.max_iterations,
            last,
            &mut lambda,
            run,
        ) {
            Ok((ssr, c, stop)) => {
                stage = Some((ssr, c));
                last_stop = stop;
            }
            Err(_) => {
                // the stage left the region where the model can be
                // simulated: go on from the best point so far
                pt = best.0.clone();
                continue;
            }
        }
        let full = if !h.is_finite() {
            // the last stage's cost is the whole record's already
            stage.map_or(f64::INFINITY, |(ssr, _)| ssr)
        } else {
            run.simulations += 1;
            pb.cost(&pt, f64::INFINITY).map_or(f64::INFINITY, |x| x.0)
        };
        if full < best.1 {
            best = (pt.clone(), full);
        } else {
            pt = best.0.clone();
        }
    }
    (best, last_stop)
}

/// Fit only the nuisance unknowns of `pb` (model parameters held) from
/// `pt`; true when the result can be simulated. The one estimator of the
/// nuisance at given parameters: the fit's start (and its "before"),
/// validation and compare all use it.
///
/// Two steps, each unknown from the data that determine it:
/// 1. **the initial state, an observer over the first samples**: the
///    states fitted on the first [`OBSERVER_WINDOW`] with everything else
///    held, within their priors' bounds, over the growing horizons
///    [`OBSERVER_HORIZONS`], each step kept when it lowers the window's
///    cost. A start is a property of the first samples: judged on the whole
///    record instead, a record that starts inside a transient the model
///    does not reproduce (a QUBE episode switched on 5 degrees off upright,
///    clipped at -10 V for 7 samples) was given the start at its prior's
///    edge (4.7 rad/s on a pendulum that had not moved for three samples)
///    that made the rest of the simulation land best, and every window
///    of its prediction diverged.
/// 2. **the sensor zeros, over the whole record** (a zero is the same
///    through the record and only the record determines it), the observed
///    states held.
///
/// Two starts for the observer, the one that follows the window better
/// kept: the data's own smoothed states, and rest (every velocity zero,
/// within its bounds: a clipped release, where the smoother can only
/// extrapolate).
pub(crate) fn lm_nuisance(setup: &Setup<'_>, pb: &Problem<'_>, pt: &mut Point) -> bool {
    observe_nuisance(setup, pb, pt, true)
}

/// [`lm_nuisance`], the sensor zeros fitted (step 2) only when `zeros`:
/// without them, the observer alone on every block of `pb` (the start of
/// each block that lets the model follow it best; the fit's start, and
/// [`crate::release`] on windows).
pub(crate) fn observe_nuisance(
    setup: &Setup<'_>,
    pb: &Problem<'_>,
    pt: &mut Point,
    zeros: bool,
) -> bool {
    let mut sink = |_: &FitProgress| {};
    let mut run = Run {
        bounded: true,
        ..Run::new(FINAL_TOLERANCE, OBSERVER_HORIZONS.len() + 1, &mut sink)
    };
    let cost_over = |q: &Point, h: f64| match pb.cost(q, h) {
        Ok((s, _)) => s,
        Err(_) => f64::INFINITY,
    };
    let n = setup.model.coordinates.len();
    let mut rest = pt.clone();
    for (blk, l) in pb.blocks.iter().zip(rest.l.iter_mut()) {
        for (j, &c) in blk.free_state.iter().enumerate() {
            if c >= n {
                l[j] = 0.0;
            }
        }
        blk.clamp(l);
    }
    let smoothed = pb.clamped(pt);
    let mut best = {
        let (a, b) = (
            cost_over(&smoothed, OBSERVER_WINDOW),
            cost_over(&rest, OBSERVER_WINDOW),
        );
        if b < a {
            (rest, b)
        } else {
            (smoothed, a)
        }
    };
    // 1. the observer: every global held
    let ng = pb.n_globals();
    let held_all = vec![true; ng];
    let mut lambda: f64 = 1e-3;
    for (s, &h) in OBSERVER_HORIZONS.iter().enumerate() {
        run.stage = s + 1;
        let last = s + 1 == OBSERVER_HORIZONS.len();
        let mut q = best.0.clone();
        lambda = lambda.max(1e-3);
        if lm(
            pb,
            &mut q,
            h,
            &held_all,
            setup.opts.max_iterations,
            last,
            &mut lambda,
            &mut run,
        )
        .is_ok()
        {
            let q = pb.clamped(&q);
            let c = cost_over(&q, OBSERVER_WINDOW);
            if c < best.1 {
                best = (q, c);
            }
        }
    }
    let mut out = best.0;
    // 2. the sensor zeros over the whole record, the observed states held
    let p = setup.free.len();
    if zeros && ng > p {
        run.stage = OBSERVER_HORIZONS.len() + 1;
        run.hold_locals = true;
        let frozen: Vec<bool> = (0..ng).map(|j| j < p).collect();
        let before = cost_over(&out, f64::INFINITY);
        let mut q = out.clone();
        lambda = 1e-3;
        if lm(
            pb,
            &mut q,
            f64::INFINITY,
            &frozen,
            setup.opts.max_iterations,
            true,
            &mut lambda,
            &mut run,
        )
        .is_ok()
        {
            let q = pb.clamped(&q);
            if cost_over(&q, f64::INFINITY) < before {
                out = q;
            }
        }
    }
    *pt = out;
    cost_over(pt, f64::INFINITY).is_finite()
}

/// The window (s) over which a record's initial state is observed
/// ([`lm_nuisance`]): a quarter second holds a release transient and
/// little else (a pendulum's swing, the slowest motion these models are
/// fitted on, is near 1 Hz, so the state's effect over the window is still
/// about its first-order one and the window decides the start alone).
pub const OBSERVER_WINDOW: f64 = 0.25;

/// The observer's horizons (s): first 50 ms, five times the velocity
/// smoother's window (where the effect of the state on the samples is
/// nearly linear, so a start at the prior's mean converges), then the
/// whole window.
pub const OBSERVER_HORIZONS: [f64; 2] = [0.05, OBSERVER_WINDOW];

/// The nuisance of `pt` at the edge of what the data allow: initial-state
/// unknowns at their priors' bounds, offsets at theirs (see
/// [`FitResult::nuisance_flags`]). "At" within 1e-6 of the bound's
/// distance from the centre: the projection puts an unknown that wants to
/// go further exactly on its bound.
pub(crate) fn nuisance_flags(setup: &Setup<'_>, pb: &Problem<'_>, pt: &Point) -> Vec<NuisanceFlag> {
    let model = setup.model;
    let n = model.coordinates.len();
    let full = pb.full_at(&pt.g);
    let model_off = setup
        .sim
        .model_offsets(&full)
        .unwrap_or_else(|_| vec![0.0; n]);
    let near = |v: f64, b: f64, centre: f64| (v - b).abs() <= 1e-6 * (b - centre).abs();
    let mut out = Vec::new();
    for (b, blk) in pb.blocks.iter().enumerate() {
        let sig = &setup.sigs[blk.exp];
        let start = pb.block_start(b, pt, &model_off, blk.range.clone());
        for (j, &c) in blk.free_state.iter().enumerate() {
            let p = blk.priors[j];
            if !p.sigma.is_finite() {
                continue;
            }
            let v = pt.l[b][j];
            let (lo, hi) = (blk.lo[j], blk.hi[j]);
            if !(near(v, lo, p.mean) || near(v, hi, p.mean)) {
                continue;
            }
            let coord = &model.coordinates[c % n].name;
            let when = if blk.range.start == 0 {
                "0".to_string()
            } else {
                format!("{:.3} s", sig.t[blk.range.start] - sig.t[0])
            };
            // (a position's local is its deviation from the measurement)
            let shift = if c < n { start.x0[c] - v } else { 0.0 };
            out.push(NuisanceFlag {
                experiment: sig.name.clone(),
                name: if c < n {
                    format!("{coord}({when})")
                } else {
                    format!("{coord}'({when})")
                },
                value: v + shift,
                prior: Some((p.mean + shift, p.sigma)),
                bound: if near(v, lo, p.mean) { lo } else { hi } + shift,
            });
        }
    }
    let p = setup.free.len();
    for (k, &(e, i)) in pb.offsets.iter().enumerate() {
        let v = pt.g[p + k];
        let (lo, hi) = (pb.lo[p + k], pb.hi[p + k]);
        if near(v, lo, 0.0) || near(v, hi, 0.0) {
            out.push(NuisanceFlag {
                experiment: setup.sigs[e].name.clone(),
                name: format!("offset {}", model.coordinates[i].name),
                value: v,
                prior: None,
                bound: if near(v, lo, 0.0) { lo } else { hi },
            });
        }
    }
    out
}

/// Per-experiment nuisance estimates at `pt` (statistics from the normal
/// equations there; NaN standard errors when they cannot be computed).
pub(crate) fn nuisance_estimates(
    setup: &Setup<'_>,
    pb: &Problem<'_>,
    pt: &Point,
) -> Vec<ExperimentEstimate> {
    let ng = pb.n_globals();
    let frozen = vec![false; ng];
    let unknowns = pb.n_unknowns();
    let (cov, sigma2, lv) = match pb.normal(pt, f64::INFINITY) {
        Ok(nrm) => {
            let (cov, s2) = covariance(&nrm, &frozen, unknowns);
            (cov, s2, local_variances(&nrm))
        }
        Err(_) => (
            vec![f64::NAN; ng * ng],
            f64::NAN,
            pb.blocks
                .iter()
                .map(|b| vec![f64::NAN; b.free_state.len()])
                .collect(),
        ),
    };
    let sim = pb.predict(pt).unwrap_or_else(|_| {
        setup
            .sigs
            .iter()
            .map(|s| vec![vec![f64::NAN; s.len()]; s.q.len()])
            .collect()
    });
    experiment_estimates(setup, pb, pt, &cov, &lv, sigma2, &sim, None)
}

/// Unweighted RMSE of simulated against measured over all coordinates and
/// samples.
fn unweighted_rmse(sigs: &[Signals], sim: &[Vec<Vec<f64>>]) -> f64 {
    let mut ss = 0.0;
    let mut n = 0usize;
    for (s, e) in sigs.iter().zip(sim) {
        for (q, qs) in s.q.iter().zip(e) {
            for (a, b) in q.iter().zip(qs) {
                if b.is_finite() {
                    ss += (a - b).powi(2);
                    n += 1;
                }
            }
        }
    }
    (ss / n.max(1) as f64).sqrt()
}

/// Covariance of the globals (`ng x ng`, NaN rows/columns for frozen
/// ones) and `sigma^2`. The information is inverted through its
/// eigen-decomposition after scaling to a unit diagonal: directions the data
/// do not determine (eigenvalue below 1e-14 of the largest) are left out,
/// and the globals that load on them get NaN variances instead of the
/// whole matrix failing.
fn covariance(nrm: &crate::lm::Normal, frozen: &[bool], unknowns: usize) -> (Vec<f64>, f64) {
    let ng = nrm.ng;
    let sigma2 = nrm.ssr / nrm.count.saturating_sub(unknowns).max(1) as f64;
    let info = global_information(nrm);
    let idx: Vec<usize> = (0..ng)
        .filter(|&j| !frozen[j] && info[j * ng + j] > 0.0 && info[j * ng + j].is_finite())
        .collect();
    let nf = idx.len();
    let mut cov = vec![f64::NAN; ng * ng];
    if nf == 0 {
        return (cov, sigma2);
    }
    let d: Vec<f64> = idx.iter().map(|&i| info[i * ng + i].sqrt()).collect();
    let c = nalgebra::DMatrix::from_fn(nf, nf, |a, b| info[idx[a] * ng + idx[b]] / (d[a] * d[b]));
    let eig = nalgebra::SymmetricEigen::new(c);
    let lmax = eig.eigenvalues.iter().copied().fold(0.0f64, f64::max);
    let mut undetermined = vec![false; nf];
    let mut inv = nalgebra::DMatrix::<f64>::zeros(nf, nf);
    for k in 0..nf {
        let l = eig.eigenvalues[k];
        let v = eig.eigenvectors.column(k);
        if l > 1e-14 * lmax {
            inv += (v * v.transpose()) / l;
        } else {
            for a in 0..nf {
                if v[a].abs() > 0.1 {
                    undetermined[a] = true;
                }
            }
        }
    }
    for a in 0..nf {
        for b in 0..nf {
            if undetermined[a] || undetermined[b] {
                continue;
            }
            cov[idx[a] * ng + idx[b]] = sigma2 * inv[(a, b)] / (d[a] * d[b]);
        }
    }
    (cov, sigma2)
}

/// The identifiability analysis of the free model parameters at `pt`.
fn identifiability(
    setup: &Setup<'_>,
    pb: &Problem<'_>,
    pt: &Point,
    nrm: &crate::lm::Normal,
    frozen: &[bool],
    unknowns: usize,
) -> Identifiability {
    let ng = nrm.ng;
    let p = setup.free.len();
    let info = global_information(nrm);
    let (cov, _) = covariance(nrm, frozen, unknowns);
    let live: Vec<usize> = (0..p).filter(|&j| !frozen[j]).collect();
    let params: Vec<ParamInfo<'_>> = live
        .iter()
        .map(|&j| ParamInfo {
            name: &setup.free_names[j],
            value: pt.g[j],
            lo: pb.lo[j],
            hi: pb.hi[j],
            std_error: cov[j * ng + j].sqrt(),
        })
        .collect();
    let sub = |m: &[f64]| -> Vec<f64> {
        live.iter()
            .flat_map(|&i| live.iter().map(move |&j| (i, j)))
            .map(|(i, j)| m[i * ng + j])
            .collect()
    };
    analyse(
        &params,
        &sub(&info),
        &sub(&cov),
        nrm.ssr,
        setup.opts.correlation_threshold,
    )
}

/// Per-experiment nuisance estimates and RMSE.
#[allow(clippy::too_many_arguments)]
fn experiment_estimates(
    setup: &Setup<'_>,
    pb: &Problem<'_>,
    pt: &Point,
    cov: &[f64],
    local_var: &[Vec<f64>],
    sigma2: f64,
    sim: &[Vec<Vec<f64>>],
    before: Option<&Vec<Vec<Vec<f64>>>>,
) -> Vec<ExperimentEstimate> {
    let model = setup.model;
    let n = model.coordinates.len();
    let ng = pb.n_globals();
    let p = setup.free.len();
    let full = pb.full_at(&pt.g);
    let model_off = setup
        .sim
        .model_offsets(&full)
        .unwrap_or_else(|_| vec![0.0; n]);
    setup
        .sigs
        .iter()
        .enumerate()
        .map(|(e, sig)| {
            let b = pb.blocks.iter().position(|b| b.exp == e).unwrap_or(0);
            let start = pb.block_start(b, pt, &model_off, pb.blocks[b].range.clone());
            let blk = &pb.blocks[b];
            let initial_state = (0..2 * n)
                .map(|c| {
                    let name = if c < n {
                        format!("{}(0)", model.coordinates[c].name)
                    } else {
                        format!("{}'(0)", model.coordinates[c - n].name)
                    };
                    let j = blk.free_state.iter().position(|&s| s == c);
                    NuisanceValue {
                        name,
                        value: start.x0[c],
                        std_error: j.map_or(f64::NAN, |j| (sigma2 * local_var[b][j]).sqrt()),
                        estimated: j.is_some(),
                    }
                })
                .collect();
            let offsets = pb
                .offsets
                .iter()
                .enumerate()
                .filter(|(_, o)| o.0 == e)
                .map(|(k, o)| NuisanceValue {
                    name: format!("offset {}", model.coordinates[o.1].name),
                    value: pt.g[p + k],
                    std_error: cov[(p + k) * ng + p + k].sqrt(),
                    estimated: true,
                })
                .collect();
            let rmse = |s: &Vec<Vec<f64>>| -> Vec<f64> {
                (0..n)
                    .map(|i| {
                        let (mut ss, mut c) = (0.0, 0usize);
                        for (a, b) in sig.q[i].iter().zip(&s[i]) {
                            if b.is_finite() {
                                ss += (a - b).powi(2);
                                c += 1;
                            }
                        }
                        (ss / c.max(1) as f64).sqrt()
                    })
                    .collect()
            };
            // (over the samples simulated: a record's release transient,
            // before its start, is not)
            let first = setup.starts.get(e).copied().unwrap_or(0);
            let fits = |s: &Vec<Vec<f64>>| -> Vec<Option<f64>> {
                (0..n)
                    .map(|i| {
                        let (y, yhat) = (&sig.q[i][first..], &s[i][first.min(s[i].len())..]);
                        if yhat.iter().any(|v| !v.is_finite()) {
                            return None;
                        }
                        crate::metrics::fit_percent(y, yhat).ok().flatten()
                    })
                    .collect()
            };
            ExperimentEstimate {
                name: sig.name.clone(),
                initial_state,
                offsets,
                rmse_before: before.map_or(vec![f64::NAN; n], |b| rmse(&b[e])),
                rmse_after: rmse(&sim[e]),
                fit_before: before.map_or(vec![None; n], |b| fits(&b[e])),
                fit_after: fits(&sim[e]),
                release: (first > 0).then(|| sig.t[first] - sig.t[0]),
            }
        })
        .collect()
}

/// Scan each parameter that moves an input delay or a sensor offset over
/// its box (others at the start), on the first 3 s (or the segments), and
/// start from the best value.
fn scan(
    setup: &Setup<'_>,
    pb: &Problem<'_>,
    pt: &mut Point,
    run: &mut Run<'_>,
    notes: &mut Vec<String>,
) {
    let full = pb.full_at(&pt.g);
    let Ok(kinds) = setup.sens.signal_dependencies(&full) else {
        return;
    };
    let dt = setup
        .sigs
        .iter()
        .map(|s| s.sample_time())
        .fold(f64::INFINITY, f64::min);
    let horizon = 3.0;
    for (j, kind) in kinds.iter().enumerate() {
        let Some(kind) = kind else { continue };
        let (lo, hi) = (pb.lo[j], pb.hi[j]);
        let even = |a: f64, b: f64, steps: usize| -> Vec<f64> {
            (0..=steps)
                .map(|k| a + (b - a) * k as f64 / steps as f64)
                .collect()
        };
        // a delay: every sample period up to 40 of them, then a quarter
        // period around the best (the cost is smooth within a period, its
        // minima are periods apart at the most)
        let (grid, fine): (Vec<f64>, Option<f64>) = match kind {
            crate::sensitivity::SignalKind::Delay => {
                let top = hi.min(lo + 40.0 * dt);
                let steps = ((top - lo) / dt).ceil().clamp(1.0, 400.0) as usize;
                (even(lo, top, steps), Some((top - lo) / steps as f64))
            }
            crate::sensitivity::SignalKind::Offset => (even(lo, hi, 40), None),
        };
        let before = pt.g[j];
        let mut best = (before, f64::INFINITY);
        let mut tried = 0usize;
        let mut try_at = |v: f64, best: &mut (f64, f64), run: &mut Run<'_>| {
            let mut q = pt.clone();
            q.g[j] = v;
            run.simulations += 1;
            tried += 1;
            if let Ok((s, _)) = pb.cost(&q, horizon) {
                if s < best.1 {
                    *best = (v, s);
                }
            }
        };
        for &v in grid.iter().chain(std::iter::once(&before)) {
            try_at(v, &mut best, run);
        }
        if let Some(step) = fine {
            let centre = best.0;
            for k in [-3.0, -2.0, -1.0, 1.0, 2.0, 3.0] {
                let v = centre + 0.25 * step * k;
                if v > lo && v < hi {
                    try_at(v, &mut best, run);
                }
            }
        }
        if best.0 != before {
            pt.g[j] = best.0;
            notes.push(format!(
                "`{}` scanned over {} values in [{:.4e}, {:.4e}] before the local solve: start {:.4e} instead of {:.4e}",
                setup.free_names[j],
                tried,
                grid.first().copied().unwrap_or(lo),
                grid.last().copied().unwrap_or(hi),
                best.0,
                before
            ));
        }
    }
}

/// Extra starts spread over the box (log-uniform for positive boxes that
/// span more than a decade), each fitted on the first horizon and compared
/// on the whole record; the best is polished on everything.
fn multistart(
    setup: &Setup<'_>,
    pb: &Problem<'_>,
    best: &(Point, f64),
    frozen: &[bool],
    first_horizon: f64,
    run: &mut Run<'_>,
) -> Option<(Point, f64)> {
    let p = setup.free.len();
    let mut seed: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut rnd = move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut found: Option<(Point, f64)> = None;
    for _ in 0..setup.opts.multistart {
        let mut q = best.0.clone();
        for j in 0..p {
            if frozen[j] {
                continue;
            }
            let (lo, hi) = (pb.lo[j], pb.hi[j]);
            let u = 0.05 + 0.9 * rnd();
            q.g[j] = if lo > 0.0 && hi / lo > 10.0 {
                (lo.ln() + u * (hi.ln() - lo.ln())).exp()
            } else {
                lo + u * (hi - lo)
            };
        }
        let mut lambda = 1e-3;
        if lm(
            pb,
            &mut q,
            first_horizon,
            frozen,
            10,
            false,
            &mut lambda,
            run,
        )
        .is_err()
        {
            continue;
        }
        run.simulations += 1;
        if let Ok((s, _)) = pb.cost(&q, f64::INFINITY) {
            if found.as_ref().is_none_or(|f| s < f.1) {
                found = Some((q, s));
            }
        }
    }
    let (mut q, _) = found?;
    let mut lambda = 1e-3;
    lm(
        pb,
        &mut q,
        f64::INFINITY,
        frozen,
        setup.opts.max_iterations,
        true,
        &mut lambda,
        run,
    )
    .ok()?;
    run.simulations += 1;
    let s = pb.cost(&q, f64::INFINITY).ok()?.0;
    Some((q, s))
}

/// The values of `m`'s base parameters, each taken instead from the
/// parameter of the same name in `from` (a model and its base values) when
/// it has one: the start of a refit of an edited model from a fit of
/// another.
pub(crate) fn values_from(m: &Model, (from, base): (&Model, &[f64])) -> Vec<f64> {
    m.parameters
        .iter()
        .map(|p| {
            from.parameters
                .iter()
                .position(|q| q.name == p.name)
                .map_or(p.value, |i| base[i])
        })
        .collect()
}

/// `start` (values of `m`'s base parameters) with each parameter that
/// `estimates` holds at its estimate.
pub(crate) fn with_estimates(m: &Model, start: Vec<f64>, estimates: &[Estimate]) -> Vec<f64> {
    m.parameters
        .iter()
        .zip(start)
        .map(|(p, v)| {
            estimates
                .iter()
                .find(|e| e.name == p.name)
                .map_or(v, |e| e.value)
        })
        .collect()
}

/// Base parameter values as a full vector (base then derived).
pub fn full_parameters(model: &Model, base: Vec<f64>) -> Vec<f64> {
    ParameterValues::from_base(model, base).full
}

/// The simulated measurements (`[experiment][coordinate][sample]`) of
/// `model` at base values `base`, with the nuisance where fit `at` of the
/// same records left it (its initial states and offsets, its segments):
/// what a fitted model predicts with some of its parameters changed (an
/// effect's contribution, [`crate::decision::Contribution`]).
pub fn simulate_as(
    model: &Model,
    experiments: &[Experiment],
    opts: &FitOptions,
    at: &FitResult,
    base: &[f64],
) -> Result<Vec<Vec<Vec<f64>>>, FitError> {
    let o = FitOptions {
        free: Some(Vec::new()),
        start: Some(base.to_vec()),
        warm: Some(at.warm.clone()),
        ..opts.clone()
    };
    let setup = Setup::new(model, experiments, &o, &[])?;
    let pb = setup.problem(at.segments);
    let mut pt = setup.start_point(&pb, &[]);
    setup.apply_warm(&pb, &mut pt);
    Ok(pb.predict(&pt)?)
}

/// The options of the finer simulation [`simulation_error`] and
/// [`replay_predictable`] compare with: half the shortest substep any
/// record takes under `opts` (automatic or set).
fn finer(experiments: &[Experiment], opts: &FitOptions) -> Result<FitOptions, FitError> {
    let mut h = f64::INFINITY;
    for e in experiments {
        let dt = crate::data::median_dt(&e.t).unwrap_or(1e-3);
        h = h.min(crate::experiment_sim::substep_at(dt, &opts.sim)?);
    }
    Ok(FitOptions {
        sim: SimOptions {
            substep: Some(h / 2.0),
            ..opts.sim
        },
        ..opts.clone()
    })
}

/// How far a simulation at `opts`' substep and one at half of it lie apart
/// on one measured channel, over the records: see [`simulation_error`].
#[derive(Clone, Debug, PartialEq)]
pub struct StepDifference {
    /// The coordinate.
    pub name: String,
    /// The largest RMS difference over the records.
    pub rms: f64,
    /// The largest difference at any sample.
    pub largest: f64,
}

impl StepDifference {
    /// Whether the two simulations part by the channel's own motion: at
    /// some sample they lie a `spread` (the channel's standard deviation,
    /// [`ChannelWeight::spread`]) or more apart. Two signals of standard
    /// deviation `s` that differ by `e` in RMS are correlated at
    /// `1 - e^2 / (2 s^2)`; a difference of `s` leaves them half their
    /// variance in common, as a trajectory shares with an unrelated stretch
    /// of itself. From there on a replay depends on the step (and on a
    /// rounding, the last digit of an initial state) more than on the
    /// parameters: the motion is chaotic on the records' time scale, and
    /// no simulation follows the whole records.
    pub fn parts(&self, weights: &[ChannelWeight]) -> bool {
        self.spread(weights)
            .is_some_and(|s| s > 0.0 && self.largest >= s)
    }

    /// The channel's spread among `weights` ([`ChannelWeight::spread`]).
    pub fn spread(&self, weights: &[ChannelWeight]) -> Option<f64> {
        weights
            .iter()
            .find(|w| w.name == self.name)
            .map(|w| w.spread)
    }
}

/// Per measured channel, the differences between `coarse` and `fine`
/// (`[experiment][coordinate][sample]`), non-finite samples left out.
fn step_differences(
    model: &Model,
    coarse: &[Vec<Vec<f64>>],
    fine: &[Vec<Vec<f64>>],
) -> Vec<StepDifference> {
    let mut out = Vec::new();
    for (c, coord) in model.coordinates.iter().enumerate() {
        let mut worst: Option<(f64, f64)> = None;
        for (a, b) in coarse.iter().zip(fine) {
            let (Some(a), Some(b)) = (a.get(c), b.get(c)) else {
                continue;
            };
            let d: Vec<f64> = a
                .iter()
                .zip(b)
                .map(|(x, y)| x - y)
                .filter(|d| d.is_finite())
                .collect();
            if d.is_empty() {
                continue;
            }
            let rms = (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt();
            let largest = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            worst = Some(worst.map_or((rms, largest), |(r, l)| (r.max(rms), l.max(largest))));
        }
        if let Some((rms, largest)) = worst {
            out.push(StepDifference {
                name: coord.name.clone(),
                rms,
                largest,
            });
        }
    }
    out
}

/// The simulation's own error on each measured channel of fit `at`: per
/// coordinate, the largest RMS over the records of the difference between
/// the simulation at `opts`' substep and one at half the shortest substep
/// any record takes (automatic or set), with the parameters and nuisance
/// as fitted (and the largest difference at any sample,
/// [`StepDifference::parts`]). For RK4, fourth order, that difference is
/// 15/16 of the coarse simulation's error where the error follows the
/// order; at a stability limit (a smooth dry friction's slope near zero
/// speed) the finer simulation is stable and the difference is the error
/// itself. Records that follow plantc's own integrator to the sample
/// cancel it; records from any other simulator or from a rig do not.
/// Channels not measured anywhere are left out.
pub fn simulation_error(
    model: &Model,
    experiments: &[Experiment],
    opts: &FitOptions,
    at: &FitResult,
) -> Result<Vec<StepDifference>, FitError> {
    // (the fit's own prediction is the simulation at `opts`' substep)
    let fine = simulate_as(model, experiments, &finer(experiments, opts)?, at, &at.base)?;
    Ok(step_differences(model, &at.simulated, &fine))
}

/// Does the replay of the whole records from the start values (the
/// nuisance at its data estimates) agree with itself at half the
/// simulation step ([`StepDifference::parts`] on no channel)? A replay
/// that cannot be run is no evidence either way (true).
pub fn replay_predictable(
    model: &Model,
    experiments: &[Experiment],
    opts: &FitOptions,
) -> Result<bool, FitError> {
    // (options whose step cannot be halved are an error here, as the
    // simulation at half the step would report it; `predictable` itself
    // takes a finer simulator it cannot make as no evidence)
    finer(experiments, opts)?;
    at_start_values(model, experiments, opts, |s, pb, pt| {
        predictable(s, pb, pt, experiments, &OnceCell::new())
    })
}

/// Does the replay of `pb` at `pt` agree with itself at half the
/// simulation step ([`StepDifference::parts`] on no channel)? What
/// [`replay_predictable`] asks at the start values and the automatic
/// horizon wherever it would fit whole records. `fine` holds the
/// simulator at half the step once made (None inside when it cannot be).
/// A replay that cannot be run is no evidence either way (true).
fn predictable(
    setup: &Setup<'_>,
    pb: &Problem<'_>,
    pt: &Point,
    experiments: &[Experiment],
    fine: &OnceCell<Option<Simulator>>,
) -> bool {
    let sim = fine.get_or_init(|| {
        let o = finer(experiments, setup.opts).ok()?;
        let s = Simulator::new(setup.model, o.sim).ok()?;
        Some(match setup.sim.law() {
            Some(l) => s.with_loop(l.clone()),
            None => s,
        })
    });
    let Some(sim) = sim.as_ref() else {
        return true;
    };
    let (Ok(coarse), Ok(fine)) = (
        pb.predict(pt),
        Problem {
            sim,
            ..setup.problem(None)
        }
        .predict(pt),
    ) else {
        return true;
    };
    !step_differences(setup.model, &coarse, &fine)
        .iter()
        .any(|d| d.parts(&setup.weights))
}

/// The segment length a fit of `model` at `at`'s values takes when the
/// whole records cannot be fitted: the longest of [`AUTO_SEGMENTS`] whose
/// segments, each from its own state fitted at those values, follow the
/// data (as [`Horizon::Auto`] chooses it at the start values).
pub fn segment_length(
    model: &Model,
    experiments: &[Experiment],
    opts: &FitOptions,
    at: &FitResult,
) -> Result<f64, FitError> {
    let o = FitOptions {
        start: Some(at.base.clone()),
        warm: None,
        ..opts.clone()
    };
    let free_names = o.free_names(model);
    let setup = Setup::new(model, experiments, &o, &free_names)?;
    let mut sink = |_: &FitProgress| {};
    let mut run = Run::new(o.tolerance, 1, &mut sink);
    Ok(choose_segments(
        &setup,
        &setup.free_values(&setup.base),
        &mut run,
    ))
}

/// The model's inputs every record has a column for.
pub fn recorded_inputs(model: &Model, experiments: &[Experiment]) -> Vec<String> {
    model
        .inputs
        .iter()
        .map(|i| i.name.clone())
        .filter(|n| experiments.iter().all(|e| e.values(n).is_some()))
        .collect()
}

/// `experiments` with the model's inputs, where recorded, read as
/// continuous signals ([`Experiment::with_continuous_inputs`]).
pub fn continuous_records(model: &Model, experiments: &[Experiment]) -> Vec<Experiment> {
    let inputs: Vec<String> = model.inputs.iter().map(|i| i.name.clone()).collect();
    experiments
        .iter()
        .map(|e| e.with_continuous_inputs(&inputs))
        .collect()
}

/// [`fit`] with the records' inputs read as they were made: held over each
/// sample interval (a rig's converter, plantc's simulation) or continuous
/// (a simulator integrating a continuous input, a sampled sensor such as a
/// measured torque: [`Experiment::with_continuous_inputs`]). The fit with
/// them held is refitted from where it ended with them continuous (open
/// loop, inputs recorded); that reading has no parameter, so it is kept
/// when its weighted sum of squares is lower by more than the fit resolves
/// (its relative tolerance). Returns the fit kept and, when the inputs are
/// read as continuous, the weighted RMS held and continuous (validate
/// held-out records read the same way). The continuous fit's "before" (the
/// start values, the cost and fit % there) is the held fit's: the same
/// start model, with the inputs held. In a diagnosis the reading also
/// competes with the candidate effects ([`crate::diagnose`]).
pub fn fit_reading_inputs(
    model: &Model,
    experiments: &[Experiment],
    opts: &FitOptions,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<(FitResult, Option<(f64, f64)>), FitError> {
    let held = fit_with_progress(model, experiments, opts, progress)?;
    if let Some((_, continuous)) = refit_continuous(model, experiments, opts, &held, progress) {
        let costs = (held.after_cost, continuous.after_cost);
        let mut kept = continuous;
        kept.before_cost = held.before_cost;
        kept.before_rmse = held.before_rmse;
        for (k, h) in kept.parameters.iter_mut().zip(&held.parameters) {
            k.start = h.start;
        }
        for (k, h) in kept.experiments.iter_mut().zip(&held.experiments) {
            k.rmse_before.clone_from(&h.rmse_before);
            k.fit_before.clone_from(&h.fit_before);
        }
        Ok((kept, Some(costs)))
    } else {
        Ok((held, None))
    }
}

/// `experiments` with their recorded inputs read as continuous signals
/// ([`Experiment::with_continuous_inputs`]) and `held` (their fit under
/// `opts` with the inputs held) refitted on them from where it ended (its
/// values, nuisance and first samples), when that fits better: its
/// weighted sum of squares lower by more than the fit resolves (its
/// relative tolerance; the reading has no parameter, so the likelihood
/// ratio alone decides). None in a closed loop (the inputs are computed),
/// without recorded inputs, when the refit fails or gains no more than that.
pub(crate) fn refit_continuous(
    model: &Model,
    experiments: &[Experiment],
    opts: &FitOptions,
    held: &FitResult,
    progress: &mut dyn FnMut(&FitProgress),
) -> Option<(Vec<Experiment>, FitResult)> {
    if recorded_inputs(model, experiments).is_empty() || held.closed_loop.is_some() {
        return None;
    }
    let records = continuous_records(model, experiments);
    let fo = FitOptions {
        start: Some(held.base.clone()),
        warm: Some(held.warm.clone()),
        starts: Some(held.warm.starts().to_vec()),
        ..opts.clone()
    };
    let refit = fit_with_progress(model, &records, &fo, progress).ok()?;
    // the two costs compare only on the same horizon (a tumbling chain's
    // held fit on the whole records at 1.1e4 noise RMS against the
    // continuous one on 0.25 s segments at 3.4: the segments follow any
    // reading, and the held inputs synth had made were dropped)
    (refit.segments == held.segments && lower_beyond(&refit, held, opts.tolerance))
        .then_some((records, refit))
}

/// Whether fit `a` ends lower than fit `b` by more than a fit resolves: its
/// weighted sum of squares below `b`'s by more than `tolerance`, the fits'
/// relative tolerance on it. Two fits that end closer are at the same
/// minimum, and an alternative without a parameter of its own (another
/// reading of the records, the same model from another start) gains
/// nothing from such a difference.
pub(crate) fn lower_beyond(a: &FitResult, b: &FitResult, tolerance: f64) -> bool {
    a.after_cost < (1.0 - tolerance).sqrt() * b.after_cost
}

/// The measured coordinates of `experiments` in `model`'s order
/// (`[experiment][coordinate][sample]`; NaN for a missing channel).
pub fn measured_of(model: &Model, experiments: &[Experiment]) -> Vec<Vec<Vec<f64>>> {
    experiments
        .iter()
        .map(|e| {
            model
                .coordinates
                .iter()
                .map(|c| {
                    e.values(&c.name)
                        .map_or_else(|| vec![f64::NAN; e.len()], <[f64]>::to_vec)
                })
                .collect()
        })
        .collect()
}

/// The residual count of a fit of `model` to `experiments` (coordinates
/// times samples): the `N` of its cost, `after_cost^2 * N` its weighted sum
/// of squares.
pub fn residual_count(model: &Model, experiments: &[Experiment]) -> usize {
    model.coordinates.len() * experiments.iter().map(Experiment::len).sum::<usize>()
}
