//! plantc-identify: measured data, fit metrics and residual diagnostics for
//! identifying a plant model from experiments.
//!
//! - [`read_experiment`] / [`read_experiments`] load CSV or MAT v5 files into
//!   [`Experiment`]s, checked against a [`ChannelSpec`].
//! - [`compare`] computes fit % and RMSE per channel ([`FitReport`]).
//! - [`where_it_fails()`] and [`residual_summary`] locate where a model misses.
//! - [`plot_comparison`] draws measured vs simulated and residuals to SVG.
//! - [`Simulator`] simulates a model over a measured experiment (ZOH input,
//!   fixed-step RK4, one compiled tape); [`SensitivitySimulator`] adds exact
//!   forward sensitivities to the free parameters.
//! - [`fit()`] estimates bounded parameters by simulation error on a block
//!   problem: per-experiment initial states and sensor zeros as nuisance,
//!   weighted channels, segments when the replay diverges, a recorded
//!   controller simulated in the loop for closed-loop data ([`LoopLaw`]),
//!   growing horizons, scans and extra starts; the result is the best point
//!   on the whole records, with standard errors and [`Identifiability`]
//!   findings (a degenerate fit says so).
//! - [`validate()`] checks a fitted model on held-out files: simulation,
//!   k-step-ahead prediction and residual tests ([`residual_test`]).
//! - [`EquationError`] ranks candidate effects by equation error (smoothed
//!   derivatives, BIC gain); [`diagnose()`] confirms the leaders by
//!   simulation-error refits and names the missing effect or says "adequate".
//! - [`identify()`] is the whole story (rounds of diagnose -> add the effect
//!   -> refit, then validation), for the CLI, tests and editors alike.
//! - [`Report`] gathers a story's report (stages, rounds, figures' data,
//!   residual tests, snippets) and [`render_html`] writes it as one
//!   self-contained HTML file.
//! - [`synthesize`] makes measurement-like data from a model with hidden
//!   effects ([`synth`]).

// numeric kernels index several arrays in step; index loops read better there
#![allow(clippy::needless_range_loop)]

mod affine_input;
mod csv_reader;
pub mod data;
pub mod error;
pub mod identifiability;
mod lagged_products;
mod lm;
mod mat_reader;
pub mod parallel;
pub mod plausibility;
mod problem;
pub mod progress;
mod release;
mod speculate;
pub mod units;
pub mod weights;

pub use data::{
    parse_channel_map, parse_rename, read_experiment, read_experiment_with, read_experiments,
    unwrap_angle, Channel, ChannelSpec, Experiment, ReadOptions,
};
pub use error::{CellProblem, DataError, DataWarning};
pub use units::Kind;

pub mod closed_loop;
pub mod decision;
pub mod diagnose;
pub mod effect_edit;
pub mod equation_error;
pub mod experiment_sim;
pub mod fit;
pub mod friction_law;
pub mod initial_state;
pub mod metrics;
pub mod plot;
pub mod report;
pub mod report_html;
pub mod residual_tests;
pub mod savitzky_golay;
pub mod sensitivity;
pub mod stabilised_replay;
pub mod story;
pub mod synth;
pub mod validate;
pub mod where_it_fails;

pub use closed_loop::LoopLaw;
pub use diagnose::{
    candidates, diagnose, diagnose_from, diagnose_with, Candidate, ContinuousInputs, DiagnoseError,
    DiagnoseOptions, Diagnosis, Evidence, Ranked,
};
pub use effect_edit::{EffectEditError, EffectInstance, EffectKind};
pub use equation_error::{
    EquationError, EquationErrorOptions, Regressor, ScaleFixed, Score, Share,
};
pub use experiment_sim::{
    velocity_at, BlockStart, DryFriction, InitialVelocity, Signals, SimError, SimOptions,
    Simulator, Trajectory,
};
pub use fit::{
    continuous_records, fit, fit_reading_inputs, fit_with_progress, recorded_inputs,
    resolve_closed_loop, signals_for, simulation_error, ClosedLoop, Estimate, ExperimentEstimate,
    FitError, FitOptions, FitProgress, FitResult, GiveUp, Horizon, NuisanceFlag, NuisanceValue,
    Offsets, WarmStart,
};
pub use identifiability::Identifiability;
pub use metrics::{compare, fit_percent, rmse, ChannelFit, ExperimentFit, FitReport, MetricsError};
pub use plot::{
    plot_comparison, plot_residual_tests, render_comparison, render_residual_tests, FigureChannels,
    PlotError,
};
pub use report::Report;
pub use report_html::render_html;
pub use residual_tests::{residual_test, CrossCorrelation, ResidualTest};
pub use sensitivity::{
    estimated_parameters, ExtraColumn, SensitivitySimulator, SensitivityTrajectory, SignalKind,
};
pub use story::{
    fitted_instance, identify, Removal, Round, Simplification, Stage, Story, StoryError,
    StoryOptions, StoryProgress,
};
pub use synth::{
    friction_name, parse_friction, synthesize, EffectSpec, ExperimentSpec, SynthError,
    SynthOptions, SynthSpec, Synthesized,
};
pub use validate::{
    as_experiments, into_experiments, validate, ChannelScore, ExperimentValidation,
    ValidateOptions, Validation,
};
pub use weights::ChannelWeight;
pub use where_it_fails::{
    residual_summary, where_it_fails, ChannelDiagnosis, FailOptions, Finding, FindingKind,
    GroupStats, ResidualSummary,
};
