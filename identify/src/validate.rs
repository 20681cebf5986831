//! Validation of a model on experiments, like MATLAB's `compare` and
//! `resid`: simulation fit, k-step-ahead prediction fit and residual tests.
//!
//! The model's parameters are fixed; only each experiment's nuisance
//! unknowns (initial velocities, sensor zero offsets, as the options say)
//! are estimated, as MATLAB's `compare` estimates initial conditions. So a
//! held-out recording is judged by the model, not by its starting state.
//!
//! - **Simulation**: every experiment simulated whole (in closed loop when a
//!   recorded controller is in the loop) against its measurements: fit %
//!   and RMSE per channel. A simulation that cannot be run, or leaves the
//!   data (its residuals on some channel more than twice that channel's
//!   own motion: fit % below -100), is reported as diverged with the
//!   reason, not as a number.
//! - **Initial states** of the held-out records: fitted with their priors
//!   from the data ([`crate::initial_state`]) by an observer over the
//!   first [`crate::fit::OBSERVER_WINDOW`] seconds (a record that starts
//!   inside a fast transient, a controller switched on with its voltage
//!   clipped, is started from what its first samples show), then the
//!   sensor zeros over the whole record, the start held.
//! - **k-step-ahead prediction** (`horizon` in s): from each window start
//!   `t0` the model is simulated from the smoothed state there (a local
//!   quadratic through the samples within 10 ms on either side: its value
//!   minus the offsets, its slope; at a record's start, where a smoother
//!   could only extrapolate, the state fitted over the first samples; a
//!   recorded controller starts from its filter state on the data),
//!   and the prediction at `t` is taken from the latest window that starts
//!   at least `horizon` before `t`. Windows start every tenth of the
//!   horizon, so predictions are between `horizon` and `1.1 horizon` ahead:
//!   never easier than asked. Samples within the first `horizon` of a record
//!   have no prediction.
//! - **Residual tests** ([`crate::residual_tests`]) on the prediction
//!   residuals when a horizon is given, else on the simulation residuals.

use serde::Serialize;

use plantc_derive::model::Model;

use crate::data::Experiment;
use crate::experiment_sim::BlockStart;
use crate::fit::{lm_nuisance, nuisance_estimates, FitError, FitOptions, Offsets, Setup};
use crate::fit::{ExperimentEstimate, Horizon};
use crate::initial_state::smoothed_state;
use crate::problem::par_each;
use crate::residual_tests::{residual_test, ResidualTest, DEFAULT_LAGS};

/// Options of [`validate`].
#[derive(Clone, Debug, PartialEq)]
pub struct ValidateOptions {
    /// Nuisance settings (initial state, offsets), weights, closed loop and
    /// simulation options; `free`, `start` and the fit stages are ignored.
    pub fit: FitOptions,
    /// k-step-ahead prediction horizon in s.
    pub horizon: Option<f64>,
    /// Lags of the residual tests.
    pub lags: usize,
}

impl Default for ValidateOptions {
    fn default() -> Self {
        ValidateOptions {
            fit: FitOptions::default(),
            horizon: None,
            lags: DEFAULT_LAGS,
        }
    }
}

/// Fit % and RMSE of one channel.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ChannelScore {
    /// Channel name.
    pub channel: String,
    /// Fit % as MATLAB's `compare` (None when the channel is constant or
    /// there is no prediction).
    pub fit_percent: Option<f64>,
    /// RMSE (SI) over the samples that have a prediction.
    pub rmse: f64,
    /// Samples scored.
    pub samples: usize,
}

/// The validation of one experiment.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ExperimentValidation {
    /// Experiment name.
    pub name: String,
    /// Whole-record simulation per coordinate (None when it diverged).
    #[serde(skip)]
    pub simulated: Option<Vec<Vec<f64>>>,
    /// Why the simulation is missing.
    pub simulation_error: Option<String>,
    /// Simulation scores per channel (empty when it diverged).
    pub simulation: Vec<ChannelScore>,
    /// k-step-ahead predictions per coordinate (NaN where none).
    #[serde(skip)]
    pub predicted: Option<Vec<Vec<f64>>>,
    /// Prediction scores per channel.
    pub prediction: Vec<ChannelScore>,
    /// The nuisance estimated on this experiment.
    pub nuisance: ExperimentEstimate,
    /// Residual tests per channel.
    pub residual_tests: Vec<ResidualTest>,
}

/// The result of [`validate`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Validation {
    /// Per experiment.
    pub experiments: Vec<ExperimentValidation>,
    /// The prediction horizon (s), if asked.
    pub horizon: Option<f64>,
    /// The recorded controller in the loop, if any.
    pub closed_loop: Option<String>,
}

impl Validation {
    /// Mean fit % of a channel over the experiments (simulation, or
    /// prediction with `predicted`); None when no experiment has one.
    pub fn mean_fit(&self, channel: &str, predicted: bool) -> Option<f64> {
        let v: Vec<f64> = self
            .experiments
            .iter()
            .filter_map(|e| {
                let s = if predicted {
                    &e.prediction
                } else {
                    &e.simulation
                };
                s.iter()
                    .find(|c| c.channel == channel)
                    .and_then(|c| c.fit_percent)
            })
            .collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    }
}

/// Fit % and RMSE over the samples where the prediction is finite (walked
/// in passes, not copied: a long record's copies cost as much as its
/// simulation).
fn score(channel: &str, y: &[f64], yhat: &[f64]) -> ChannelScore {
    let pairs = || y.iter().zip(yhat).filter(|(_, h)| h.is_finite());
    let n = pairs().count();
    let sse: f64 = pairs().map(|(a, b)| (a - b).powi(2)).sum();
    let rmse = if n == 0 {
        f64::NAN
    } else {
        (sse / n as f64).sqrt()
    };
    // as `fit_percent`: None for a non-finite measurement
    let fit = if pairs().any(|(a, _)| !a.is_finite()) {
        None
    } else {
        crate::metrics::fit_percent_of(pairs)
    };
    ChannelScore {
        channel: channel.to_string(),
        fit_percent: fit,
        rmse,
        samples: n,
    }
}

/// Validate `model` at base parameter values `base` on `experiments`.
pub fn validate(
    model: &Model,
    base: &[f64],
    experiments: &[Experiment],
    opts: &ValidateOptions,
) -> Result<Validation, FitError> {
    if experiments.is_empty() {
        return Err(FitError::NoExperiments);
    }
    if let Some(h) = opts.horizon {
        if !(h > 0.0 && h.is_finite()) {
            return Err(FitError::BadOption(format!(
                "the prediction horizon must be a positive number of seconds, got {h}"
            )));
        }
    }
    let fo = FitOptions {
        free: Some(Vec::new()),
        start: Some(base.to_vec()),
        horizon: Horizon::Whole,
        offsets: match &opts.fit.offsets {
            // on held-out data every eligible offset is estimated (nothing
            // is dropped afterwards)
            Offsets::Auto => Offsets::Auto,
            o => o.clone(),
        },
        ..opts.fit.clone()
    };
    let mut setup = Setup::new(model, experiments, &fo, &[])?;
    let n = model.coordinates.len();
    let names: Vec<&str> = model.coordinates.iter().map(|c| c.name.as_str()).collect();
    let pb = setup.nuisance_problem(None);
    let mut pt = setup.start_point(&pb, &[]);
    // nuisance: per experiment (independent), whole records
    let fitted = lm_nuisance(&setup, &pb, &mut pt);
    // the estimates (their normal equations run a sensitivity simulation of
    // every record) before the records' simulations are held
    let estimates = nuisance_estimates(&setup, &pb, &pt);
    let mut simulated = if fitted { pb.predict(&pt).ok() } else { None };
    let full = pb.full_at(&pt.g);
    let model_off = setup.sim.model_offsets(&full).map_err(FitError::Sim)?;
    let noise: Vec<f64> = setup.weights().iter().map(|w| w.noise).collect();
    // the state at each record's start: the fitted one (the model over the
    // first samples, with the priors), when the fit could be simulated
    let starts: Vec<Option<Vec<f64>>> = (0..experiments.len())
        .map(|e| {
            let b = pb.blocks.iter().position(|b| b.exp == e)?;
            fitted.then(|| {
                pb.block_start(b, &pt, &model_off, pb.blocks[b].range.clone())
                    .x0
            })
        })
        .collect();
    let mut predictions: Vec<Option<Vec<Vec<f64>>>> = match opts.horizon {
        None => vec![None; experiments.len()],
        Some(h) => par_each(experiments.len(), |e| {
            predict_ahead(
                &setup,
                (&pb.exp_offsets(&pt.g, e), &model_off, starts[e].as_deref()),
                &full,
                &noise,
                e,
                h,
            )
        }),
    };
    let spreads: Vec<f64> = setup.weights().iter().map(|w| w.spread).collect();
    let closed_loop = setup.sim.law().map(|l| l.name.clone());
    drop(pb);
    // The scoring needs of the signals only the inputs (in closed loop the
    // law's replayed ones) and the sample times: the measured coordinates
    // are the experiments' own (the signals hold copies of them, which a
    // long record cannot afford twice beside its simulation and residuals).
    let mut sigs = std::mem::take(&mut setup.sigs);
    let starts = std::mem::take(&mut setup.starts);
    drop(setup);
    let dts: Vec<f64> = sigs.iter().map(|s| s.sample_time()).collect();
    for (sig, exp) in sigs.iter_mut().zip(experiments) {
        sig.t = Vec::new();
        let same = names.iter().zip(&sig.q).all(|(name, q)| {
            exp.values(name)
                .is_some_and(|v| v.len() == q.len() && v.iter().zip(q).all(|(a, b)| a == b))
        });
        if same {
            sig.q = Vec::new();
        }
    }
    let mut out = Vec::new();
    for (e, exp) in experiments.iter().enumerate() {
        let sig = &sigs[e];
        let measured: Vec<&[f64]> = if sig.q.is_empty() {
            names
                .iter()
                .map(|name| exp.values(name).unwrap_or_default())
                .collect()
        } else {
            sig.q.iter().map(Vec::as_slice).collect()
        };
        // a simulation that left the data is called diverged
        let left = simulated.as_ref().and_then(|s| {
            (0..n).find(|&i| {
                // (over the samples simulated: none before a release)
                let sim = &s[e][i];
                let r = if sim[starts[e].min(sim.len())..]
                    .iter()
                    .all(|v| v.is_finite())
                {
                    score(names[i], measured[i], sim).rmse
                } else {
                    f64::NAN
                };
                r.is_nan() || r > crate::fit::DIVERGED_COST * spreads[i]
            })
        });
        // (moved out, not copied: a long record's simulation is large)
        let sim_e = simulated
            .as_mut()
            .map(|s| std::mem::take(&mut s[e]))
            .filter(|_| left.is_none());
        let simulation: Vec<ChannelScore> = match &sim_e {
            Some(s) => (0..n)
                .map(|i| score(names[i], measured[i], &s[i]))
                .collect(),
            None => Vec::new(),
        };
        let pred = predictions[e].take();
        let prediction: Vec<ChannelScore> = match &pred {
            Some(p) => (0..n)
                .map(|i| score(names[i], measured[i], &p[i]))
                .collect(),
            None => Vec::new(),
        };
        let resid_source = pred.as_ref().or(sim_e.as_ref());
        let inputs: Vec<(&str, &[f64])> = model
            .inputs
            .iter()
            .zip(&sig.u)
            .map(|(i, u)| (i.name.as_str(), u.as_slice()))
            .collect();
        let residual_tests = match resid_source {
            Some(p) => (0..n)
                .map(|i| {
                    let r: Vec<f64> = measured[i].iter().zip(&p[i]).map(|(a, b)| a - b).collect();
                    residual_test(&exp.name, names[i], &r, &inputs, opts.lags, dts[e])
                })
                .collect(),
            None => Vec::new(),
        };
        out.push(ExperimentValidation {
            name: exp.name.clone(),
            simulation_error: match (left, simulated.is_some()) {
                (Some(i), _) => Some(format!(
                    "the simulation of the whole record diverged: it left the data on {} (residual RMS above twice the channel's own motion, fit % below -100)",
                    names[i]
                )),
                (None, false) => Some(
                    "the simulation of the whole record diverged (an unstable plant replayed open loop: use a prediction horizon, or a recorded controller in the loop)".to_string(),
                ),
                _ => None,
            },
            simulated: sim_e,
            simulation,
            predicted: pred,
            prediction,
            nuisance: estimates[e].clone(),
            residual_tests,
        });
    }
    Ok(Validation {
        experiments: out,
        horizon: opts.horizon,
        closed_loop,
    })
}

/// k-step-ahead predictions of experiment `e` (see the module docs).
fn predict_ahead(
    setup: &Setup<'_>,
    (exp_off, model_off, start): (&[f64], &[f64], Option<&[f64]>),
    full: &[f64],
    noise: &[f64],
    e: usize,
    horizon: f64,
) -> Option<Vec<Vec<f64>>> {
    let sig = &setup.sigs[e];
    let n = sig.q.len();
    let len = sig.len();
    let mut out = vec![vec![f64::NAN; len]; n];
    // samples per horizon from the median period
    let dt = sig.sample_time();
    let hk = ((horizon / dt).round() as usize).max(1);
    let stride = (hk / 10).max(1);
    // (a release transient before the record's start is not predicted)
    let first = setup.starts.get(e).copied().unwrap_or(0);
    let mut k0 = first;
    while k0 + hk < len {
        let end = (k0 + hk + stride).min(len);
        let mut x0 = vec![0.0; 2 * n];
        match start.filter(|_| k0 == first) {
            // at the record's start a smoother only extrapolates: the
            // state fitted over the first samples
            Some(s) => x0.copy_from_slice(s),
            None => {
                for i in 0..n {
                    let (q, v) = smoothed_state(&sig.t, &sig.q[i], k0, noise[i]);
                    x0[i] = q - model_off[i] - exp_off[i];
                    x0[n + i] = if v.mean.is_finite() { v.mean } else { 0.0 };
                }
            }
        }
        let start = BlockStart {
            range: k0..end,
            x0,
            offsets: exp_off.to_vec(),
        };
        if let Ok(tr) = setup.sim.simulate_block(sig, full, &start) {
            for i in 0..n {
                for k in (k0 + hk)..end {
                    out[i][k] = tr.q[i][k - k0];
                }
            }
        }
        k0 += stride;
    }
    Some(out)
}

/// Simulated (or predicted) coordinates as experiments with the measured
/// ones' names, files and instants, for figures and where-it-fails.
pub fn as_experiments(
    model: &Model,
    measured: &[Experiment],
    sim: &[Option<&Vec<Vec<f64>>>],
) -> Vec<Experiment> {
    measured
        .iter()
        .zip(sim)
        .map(|(m, s)| experiment_like(model, m, s.cloned()))
        .collect()
}

/// [`as_experiments`] taking the simulations over instead of copying them
/// (a long record's simulation is as large as its data).
pub fn into_experiments(
    model: &Model,
    measured: &[Experiment],
    sim: Vec<Option<Vec<Vec<f64>>>>,
) -> Vec<Experiment> {
    measured
        .iter()
        .zip(sim)
        .map(|(m, s)| experiment_like(model, m, s))
        .collect()
}

/// `sim` (one vector per coordinate; None: NaN) as an experiment like `m`.
fn experiment_like(model: &Model, m: &Experiment, sim: Option<Vec<Vec<f64>>>) -> Experiment {
    let mut sim = sim.map(Vec::into_iter);
    Experiment {
        name: m.name.clone(),
        file: m.file.clone(),
        t: m.t.clone(),
        channels: model
            .coordinates
            .iter()
            .map(|c| crate::data::Channel {
                name: c.name.clone(),
                unit_note: None,
                values: sim
                    .as_mut()
                    .and_then(Iterator::next)
                    .unwrap_or_else(|| vec![f64::NAN; m.len()]),
            })
            .collect(),
    }
}
