//! Bounded simulation-error fit (single shooting, Levenberg-Marquardt).
//!
//! The residuals are simulated minus measured coordinates at every sample of
//! every experiment (all coordinates in their SI units, unweighted). Each free
//! parameter `p` in its `estimate [lo, hi]` box is written as
//! `p = lo + (hi - lo) * s(z)` with the logistic `s`, so every LM step stays
//! inside the box and the unknowns `z` are dimensionless (this also scales
//! them: near a zero lower bound `dp/dz ~ p`, like a log). The Jacobian comes
//! from the exact forward sensitivities ([`SensitivitySimulator`]), not from
//! finite differences.
//!
//! The horizon grows (3 s, 8 s, everything by default): single shooting from
//! table values can stall in a local minimum over the whole record
//! (identification notes, trap 7), while a short horizon is nearly linear in
//! the parameters. An intermediate stage is skipped when the estimates of
//! the previous one already predict the whole record about as well
//! ([`SKIP_RATIO`]); short stages stop at a loose tolerance, the last one
//! when a step gains less than a tenth of the residual variance or
//! [`FINAL_TOLERANCE`] of the SSR.
//!
//! The experiments are simulated in parallel (one scoped thread each).
//!
//! Standard errors come from `sigma^2 (J'J)^-1` with `sigma^2 = SSR/(N - p)`
//! in physical units. Simulation residuals are strongly correlated in time, so
//! these are lower bounds on the true uncertainty; the correlations between
//! estimates are more telling (e.g. `l2` against `J2`, trap 9).

use std::fmt;

use plantc_derive::model::{Model, ParameterValues};
use serde::Serialize;

use crate::data::Experiment;
use crate::experiment_sim::{Signals, SimError, SimOptions, Simulator};
use crate::sensitivity::{estimated_parameters, SensitivitySimulator};

/// Options of [`fit`].
#[derive(Clone, Debug, PartialEq)]
pub struct FitOptions {
    /// Free parameters; `None` means those marked `estimate` in the model.
    pub free: Option<Vec<String>>,
    /// Starting base values (model order); `None` means the nominal values.
    pub start: Option<Vec<f64>>,
    /// Growing fit horizons in s from each experiment's start; the last stage
    /// should be `f64::INFINITY` (everything).
    pub horizons: Vec<f64>,
    /// Most LM iterations per horizon stage.
    pub max_iterations: usize,
    /// Simulation options.
    pub sim: SimOptions,
    /// Pairs of estimates with `|corr|` above this are reported.
    pub correlation_threshold: f64,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            free: None,
            start: None,
            horizons: vec![3.0, 8.0, f64::INFINITY],
            max_iterations: 30,
            sim: SimOptions::default(),
            correlation_threshold: 0.95,
        }
    }
}

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
    /// Fewer residuals than free parameters.
    NotEnoughData {
        /// Number of residuals.
        residuals: usize,
        /// Number of free parameters.
        parameters: usize,
    },
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
                "{residuals} residuals cannot determine {parameters} parameters"
            ),
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
    /// Standard error from `sigma^2 (J'J)^-1` (NaN when `J'J` is singular).
    pub std_error: f64,
    /// Starting value.
    pub start: f64,
    /// True when the estimate sits within 0.1 % of the box width of a bound.
    pub at_bound: bool,
}

/// The result of [`fit`].
#[derive(Clone, Debug, PartialEq)]
pub struct FitResult {
    /// Estimates of the free parameters, in the order they were given.
    pub parameters: Vec<Estimate>,
    /// All base parameter values after the fit (model order).
    pub base: Vec<f64>,
    /// RMSE over all coordinates and experiments at the start values.
    pub before_rmse: f64,
    /// RMSE after the fit.
    pub after_rmse: f64,
    /// Pairs of estimates with `|corr|` above the threshold: `(a, b, corr)`.
    pub correlations: Vec<(String, String, f64)>,
    /// LM iterations over all stages (each one sensitivity simulation).
    pub iterations: usize,
    /// Simulations without sensitivities (trial steps and RMSE evaluations).
    pub simulations: usize,
}

impl FitResult {
    /// The JSON form: `{"parameters": {"l2": {"value": .., "std_error": ..}},
    /// "before": {"rmse": ..}, "after": {"rmse": ..}, "correlations": [..],
    /// "iterations": ..}`. Non-finite numbers become `null`.
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
            "before": {"rmse": self.before_rmse},
            "after": {"rmse": self.after_rmse},
            "correlations": corr,
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

/// An intermediate horizon stage is skipped when the RMSE over the whole
/// record is at most this multiple of the RMSE the previous (shorter) stage
/// ended with: the short-horizon estimates already hold over everything.
pub const SKIP_RATIO: f64 = 1.5;

/// On the whole record, LM stops when an accepted step lowers the SSR by
/// less than this fraction (the RMSE by less than 0.0025 %).
pub const FINAL_TOLERANCE: f64 = 5e-5;

fn logistic(z: f64) -> f64 {
    1.0 / (1.0 + (-z).exp())
}

/// The problem: model, simulators, data, box.
struct Problem<'a> {
    model: &'a Model,
    sim: Simulator,
    sens: SensitivitySimulator,
    sigs: Vec<Signals>,
    free: Vec<usize>,
    bounds: Vec<(f64, f64)>,
    base: Vec<f64>,
}

impl Problem<'_> {
    fn theta(&self, z: &[f64]) -> Vec<f64> {
        let mut b = self.base.clone();
        for (j, &i) in self.free.iter().enumerate() {
            let (lo, hi) = self.bounds[j];
            b[i] = lo + (hi - lo) * logistic(z[j]);
        }
        b
    }

    fn dtheta_dz(&self, z: &[f64]) -> Vec<f64> {
        z.iter()
            .zip(&self.bounds)
            .map(|(z, (lo, hi))| {
                let s = logistic(*z);
                (hi - lo) * s * (1.0 - s)
            })
            .collect()
    }

    fn samples(&self, horizon: f64) -> Vec<usize> {
        self.sigs
            .iter()
            .map(|s| s.samples_within(horizon))
            .collect()
    }

    /// Sum of squared residuals and their count; Err on divergence. The
    /// experiments are simulated in parallel.
    fn ssr(&self, base: Vec<f64>, horizon: f64) -> Result<(f64, usize), SimError> {
        let p = ParameterValues::from_base(self.model, base);
        let parts = par_map(&self.sigs, &self.samples(horizon), |sig, n| {
            let tr = self.sim.simulate(sig, &p.full, n)?;
            let mut ssr = 0.0;
            for (q, qs) in sig.q.iter().zip(&tr.q) {
                for k in 0..n {
                    ssr += (qs[k] - q[k]).powi(2);
                }
            }
            Ok((ssr, n * sig.q.len()))
        });
        let mut ssr = 0.0;
        let mut count = 0;
        for part in parts {
            let (s, c) = part?;
            ssr += s;
            count += c;
        }
        Ok((ssr, count))
    }

    /// Normal equations in physical units: `(J'J, J'r, SSR, count)`, the
    /// experiments' sensitivity simulations in parallel.
    fn normal(
        &self,
        base: Vec<f64>,
        horizon: f64,
    ) -> Result<(Vec<f64>, Vec<f64>, f64, usize), SimError> {
        let np = self.free.len();
        let p = ParameterValues::from_base(self.model, base);
        let parts = par_map(&self.sigs, &self.samples(horizon), |sig, n| {
            let tr = self.sens.simulate(sig, &p.full, n)?;
            let mut a = vec![0.0; np * np];
            let mut g = vec![0.0; np];
            let mut ssr = 0.0;
            for (i, q) in sig.q.iter().enumerate() {
                for (k, qk) in q.iter().enumerate().take(n) {
                    let r = tr.q[i][k] - qk;
                    ssr += r * r;
                    for j in 0..np {
                        let sj = tr.dq[i][j][k];
                        g[j] += sj * r;
                        for l in j..np {
                            a[j * np + l] += sj * tr.dq[i][l][k];
                        }
                    }
                }
            }
            Ok((a, g, ssr, n * sig.q.len()))
        });
        let mut a = vec![0.0; np * np];
        let mut g = vec![0.0; np];
        let mut ssr = 0.0;
        let mut count = 0;
        for part in parts {
            let (pa, pg, ps, pc) = part?;
            a.iter_mut().zip(&pa).for_each(|(x, y)| *x += y);
            g.iter_mut().zip(&pg).for_each(|(x, y)| *x += y);
            ssr += ps;
            count += pc;
        }
        for j in 0..np {
            for l in 0..j {
                a[j * np + l] = a[l * np + j];
            }
        }
        Ok((a, g, ssr, count))
    }
}

/// `f` over the experiments (with their sample counts), one scoped thread
/// per experiment after the first (which runs on the calling thread); the
/// results come back in experiment order.
fn par_map<T: Send>(
    sigs: &[Signals],
    counts: &[usize],
    f: impl Fn(&Signals, usize) -> T + Sync,
) -> Vec<T> {
    if sigs.len() < 2 {
        return sigs.iter().zip(counts).map(|(s, &n)| f(s, n)).collect();
    }
    std::thread::scope(|scope| {
        let f = &f;
        let handles: Vec<_> = sigs[1..]
            .iter()
            .zip(&counts[1..])
            .map(|(s, &n)| scope.spawn(move || f(s, n)))
            .collect();
        let mut out = vec![f(&sigs[0], counts[0])];
        for h in handles {
            match h.join() {
                Ok(v) => out.push(v),
                Err(e) => std::panic::resume_unwind(e),
            }
        }
        out
    })
}

/// Cholesky solve of the SPD `a x = b` (`n x n`); None if not positive definite.
fn cholesky_solve(a: &[f64], n: usize, b: &[f64]) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if s.is_nan() || s <= 0.0 || s.is_infinite() {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    let mut y = b.to_vec();
    for i in 0..n {
        for k in 0..i {
            y[i] -= l[i * n + k] * y[k];
        }
        y[i] /= l[i * n + i];
    }
    for i in (0..n).rev() {
        for k in i + 1..n {
            y[i] -= l[k * n + i] * y[k];
        }
        y[i] /= l[i * n + i];
    }
    Some(y)
}

/// Where a running fit is, reported once per LM iteration by
/// [`fit_with_progress`].
#[derive(Clone, Debug, PartialEq)]
pub struct FitProgress {
    /// Horizon stage (0-based) and the number of stages.
    pub stage: usize,
    /// Number of horizon stages.
    pub stages: usize,
    /// The stage's horizon in s (`INFINITY` = the whole record).
    pub horizon: f64,
    /// LM iterations so far, over all stages.
    pub iteration: usize,
    /// RMSE over the stage's horizon at the current estimates.
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

/// [`fit`], calling `progress` after each LM iteration's linearisation (for
/// progress bars on long fits).
pub fn fit_with_progress(
    model: &Model,
    experiments: &[Experiment],
    opts: &FitOptions,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<FitResult, FitError> {
    if experiments.is_empty() {
        return Err(FitError::NoExperiments);
    }
    let free_names = opts
        .free
        .clone()
        .unwrap_or_else(|| estimated_parameters(model));
    if free_names.is_empty() {
        return Err(FitError::NoFreeParameters);
    }
    let n_base = model.parameters.len();
    let base = match &opts.start {
        Some(s) if s.len() == n_base && s.iter().all(|v| v.is_finite()) => s.clone(),
        Some(_) => return Err(FitError::BadStart { expected: n_base }),
        None => model.parameters.iter().map(|p| p.value).collect(),
    };
    let sens = SensitivitySimulator::new(model, &free_names, opts.sim)?;
    let free = sens.free_indices().to_vec();
    let mut bounds = Vec::with_capacity(free.len());
    for (&i, name) in free.iter().zip(&free_names) {
        match model.parameters[i].estimate {
            Some((lo, hi)) if lo < hi && lo.is_finite() && hi.is_finite() => bounds.push((lo, hi)),
            _ => return Err(FitError::NoBounds { name: name.clone() }),
        }
    }
    let sigs = experiments
        .iter()
        .map(|e| Signals::from_experiment(model, e))
        .collect::<Result<Vec<_>, _>>()?;
    let pb = Problem {
        model,
        sim: Simulator::new(model, opts.sim)?,
        sens,
        sigs,
        free,
        bounds,
        base: base.clone(),
    };
    let np = pb.free.len();
    // z from the start values, kept a little inside the box
    let mut z: Vec<f64> = pb
        .free
        .iter()
        .zip(&pb.bounds)
        .map(|(&i, &(lo, hi))| {
            let s = ((base[i] - lo) / (hi - lo)).clamp(1e-6, 1.0 - 1e-6);
            (s / (1.0 - s)).ln()
        })
        .collect();
    let (ssr0, count) = pb.ssr(pb.theta(&z), f64::INFINITY)?;
    if count < np {
        return Err(FitError::NotEnoughData {
            residuals: count,
            parameters: np,
        });
    }
    let before_rmse = (ssr0 / count as f64).sqrt();
    let mut iterations = 0;
    let mut simulations = 1;
    // the last stage covering every sample is the final one; later stages
    // would repeat it
    let full_at = opts
        .horizons
        .iter()
        .position(|&h| pb.samples(h) == pb.samples(f64::INFINITY))
        .unwrap_or(opts.horizons.len());
    let mut stages: Vec<f64> = opts.horizons.iter().take(full_at).copied().collect();
    stages.push(f64::INFINITY);
    // (J'J at the last full-horizon linearisation, SSR at the final z) when
    // the last step taken was negligible: no extra simulation for the
    // statistics
    let mut converged: Option<(Vec<f64>, f64)> = None;
    let mut lambda: f64 = 1e-3;
    // RMSE at the end of the previous stage, over its horizon
    let mut stage_rmse: Option<f64> = None;
    for (stage, &horizon) in stages.iter().enumerate() {
        let last_stage = stage + 1 == stages.len();
        if stage > 0 && !last_stage {
            // when the parameters fitted on the short horizon already
            // predict the whole record about as well, skip to it
            simulations += 1;
            if let (Ok((full, nf)), Some(short)) = (pb.ssr(pb.theta(&z), f64::INFINITY), stage_rmse)
            {
                if (full / nf.max(1) as f64).sqrt() <= SKIP_RATIO * short {
                    continue;
                }
            }
        }
        // the damping carries over from the previous stage (a hard problem
        // stays hard when the horizon grows), never below the initial 1e-3
        lambda = lambda.max(1e-3);
        converged = None;
        for _ in 0..opts.max_iterations {
            let Ok((a, g, ssr, count)) = pb.normal(pb.theta(&z), horizon) else {
                break;
            };
            iterations += 1;
            progress(&FitProgress {
                stage,
                stages: stages.len(),
                horizon,
                iteration: iterations,
                rmse: (ssr / count.max(1) as f64).sqrt(),
            });
            // short horizons only bring the parameters into the basin: a
            // loose relative tolerance there. On the whole record, stop when
            // a step gains less than a tenth of the residual variance (it
            // moves the estimates by well under one standard error) or less
            // than FINAL_TOLERANCE of the SSR (a wrong model with stiff dry
            // friction otherwise crawls for dozens of iterations)
            let tol = if last_stage {
                (0.1 / count.saturating_sub(np).max(1) as f64).max(FINAL_TOLERANCE)
            } else {
                1e-3
            };
            // chain rule to z: J_z = J_theta * diag(dtheta/dz)
            let d = pb.dtheta_dz(&z);
            let mut az = vec![0.0; np * np];
            let mut gz = vec![0.0; np];
            for j in 0..np {
                gz[j] = g[j] * d[j];
                for l in 0..np {
                    az[j * np + l] = a[j * np + l] * d[j] * d[l];
                }
            }
            let mut accepted = false;
            let mut small_step = false;
            let mut new_ssr = ssr;
            while lambda < 1e12 {
                let mut m = az.clone();
                for j in 0..np {
                    m[j * np + j] += lambda * az[j * np + j].max(1e-12);
                }
                let neg: Vec<f64> = gz.iter().map(|v| -v).collect();
                let Some(step) = cholesky_solve(&m, np, &neg) else {
                    lambda *= 10.0;
                    continue;
                };
                let zt: Vec<f64> = z.iter().zip(&step).map(|(a, b)| a + b).collect();
                simulations += 1;
                match pb.ssr(pb.theta(&zt), horizon) {
                    Ok((s, _)) if s < ssr => {
                        small_step = step.iter().all(|v| v.abs() < 1e-6) || (ssr - s) < tol * ssr;
                        lambda = (lambda / 3.0).max(1e-9);
                        z = zt;
                        new_ssr = s;
                        accepted = true;
                        break;
                    }
                    _ => lambda *= 4.0,
                }
            }
            if !accepted || small_step {
                if last_stage {
                    converged = Some((a, new_ssr));
                }
                stage_rmse = Some((new_ssr / count.max(1) as f64).sqrt());
                break;
            }
        }
    }
    // Final statistics over everything, in physical units.
    let theta = pb.theta(&z);
    let (a, ssr, count) = match converged {
        Some((a, ssr)) => (
            a,
            ssr,
            pb.samples(f64::INFINITY)
                .iter()
                .zip(&pb.sigs)
                .map(|(n, s)| n * s.q.len())
                .sum(),
        ),
        None => {
            let (a, _, ssr, count) = pb.normal(theta.clone(), f64::INFINITY)?;
            iterations += 1;
            (a, ssr, count)
        }
    };
    let after_rmse = (ssr / count as f64).sqrt();
    let dof = count.saturating_sub(np).max(1) as f64;
    let sigma2 = ssr / dof;
    // covariance via the column-scaled inverse (conditioning)
    let sc: Vec<f64> = (0..np)
        .map(|j| a[j * np + j].sqrt().max(f64::MIN_POSITIVE))
        .collect();
    let scaled: Vec<f64> = (0..np * np)
        .map(|k| a[k] / (sc[k / np] * sc[k % np]))
        .collect();
    let mut cov = vec![f64::NAN; np * np];
    for j in 0..np {
        let mut e = vec![0.0; np];
        e[j] = 1.0;
        if let Some(col) = cholesky_solve(&scaled, np, &e) {
            for l in 0..np {
                cov[l * np + j] = sigma2 * col[l] / (sc[l] * sc[j]);
            }
        }
    }
    let parameters: Vec<Estimate> = pb
        .free
        .iter()
        .enumerate()
        .map(|(j, &i)| {
            let (lo, hi) = pb.bounds[j];
            let v = theta[i];
            Estimate {
                name: free_names[j].clone(),
                value: v,
                std_error: cov[j * np + j].sqrt(),
                start: base[i],
                at_bound: (v - lo).min(hi - v) < 1e-3 * (hi - lo),
            }
        })
        .collect();
    let mut correlations = Vec::new();
    for j in 0..np {
        for l in j + 1..np {
            let c = cov[j * np + l] / (cov[j * np + j] * cov[l * np + l]).sqrt();
            if c.abs() > opts.correlation_threshold {
                correlations.push((free_names[j].clone(), free_names[l].clone(), c));
            }
        }
    }
    Ok(FitResult {
        parameters,
        base: theta,
        before_rmse,
        after_rmse,
        correlations,
        iterations,
        simulations,
    })
}
