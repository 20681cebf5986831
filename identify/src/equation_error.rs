//! Equation-error ranking of candidate effects: fast, from the measured
//! angles alone, no simulation.
//!
//! For every sample the equations of motion are evaluated on the measured
//! trajectory: `r = M(q) q'' + bias(q, q') - Q0(q, q') - B(q, q') u` at the
//! fitted nominal parameters. A missing effect shows up as structure in `r`
//! that its regressor column explains. The traps of the identification notes
//! are handled as follows:
//!
//! - **Quantisation noise** (trap 1): `q`, `q'`, `q''` are the value and
//!   derivatives of a local Savitzky-Golay polynomial (order 5 over +-60 ms
//!   by default, 61 samples at 500 Hz; the kernel is derived in
//!   [`crate::savitzky_golay`]). The first and last half windows of each
//!   experiment are dropped.
//! - **Sample rate** (reproducer 15 of the reliability set): every window
//!   and threshold is in physical time, and records faster than
//!   [`EquationErrorOptions::row_rate`] are first reduced to about that rate
//!   by block means (the ZOH-centred input and the coordinates alike, so
//!   both sides stay aligned). The rows of the regression, and with them the
//!   BIC, then count the same seconds of data at 500 Hz and at 10 kHz, and
//!   the noise of `q''` does not grow with the rate (at a fixed window in
//!   samples it grew as `rate^2.5` and fed columns such as an added inertia
//!   `J q''` that match it: errors in variables).
//! - **Zero-order hold** (trap 2): `u[k]` acts over `[t_k, t_k + T)`, so the
//!   input centred on sample `k` is the average `(u[k-1] + u[k]) / 2`; using
//!   `u[k]` shows up as a false half-sample (1 ms) delay.
//! - **Filter both sides alike** (trap 3): the states are smoothed by the
//!   kernel, so the input is smoothed by the same kernel before it enters the
//!   force side.
//! - **Stuck joint** (trap 4): while a joint with dry friction in the nominal
//!   model is stuck, its friction force is undetermined; samples of that
//!   joint's equation where its estimated speed stays below a noise-based
//!   threshold (and a half window around them) are dropped.
//! - **Distorted nominal fit** (trap 5): the derivatives of `r` with respect
//!   to the nominal estimated parameters are nuisance columns regressed
//!   together with every candidate, so a candidate is judged against the best
//!   re-adjusted nominal model, not against the (possibly distorted) fit.
//!
//! Candidate columns are generic ([`Regressor`]): for an effect that adds
//! parameters to the model's equations (force effects, an input offset
//! folded into the forces) they are the symbolic derivatives of the edited
//! model's residual with respect to the new parameters at their start values
//! (a Gauss-Newton step from there); a sensor offset on coordinate `i` uses
//! `dr/dq_i`, an input delay `dr/du * u'` (the input rate of the ZOH-averaged,
//! smoothed input), a deadzone `dr/du * (-sign(u))` where `|u| > w0` (the
//! derivative of the received `dz(u)` with respect to the width). Effects
//! whose residual is far from linear in a parameter get their columns from a
//! scan over it ([`rig_effects`]): cogging (the period count), saturation
//! (the level), speed limit (the speed); `Regressor::Parameters` of a model
//! edited by `effect_edit` with one of them is scored that way too.
//!
//! The equations are stacked, each weighted by the inverse RMS of its own
//! residual, and each candidate is scored by the BIC gain
//! `N ln(RSS0 / RSS1) - k ln N` over the nuisance-only regression. Residuals
//! of smoothed signals are strongly correlated in time, so the BIC over-counts
//! the evidence: it ranks candidates, it does not decide (the simulation-error
//! refit in [`crate::diagnose()`] does; trap 6).

use std::fmt;

use plantc_derive::mechanics::{derive_equations, smooth_signs, Equations};
use plantc_derive::model::{Model, ParameterValues};
use plantc_derive::sym::{diff, Expr, Func, Node, Symbol, Tape};

use crate::data::Experiment;
use crate::experiment_sim::{parameters_slow, Signals, SimError};
use crate::savitzky_golay::{apply, kernel, KernelError};

mod rig_effects;

/// Options of the equation-error ranking.
#[derive(Clone, Debug, PartialEq)]
pub struct EquationErrorOptions {
    /// Savitzky-Golay half window in seconds (window `2h + 1` samples with
    /// `h = round(half_window / dt)`, at least `order + 1`).
    pub half_window: f64,
    /// Records sampled faster than this (Hz) are reduced to about this rate
    /// by block means before smoothing.
    pub row_rate: f64,
    /// Savitzky-Golay polynomial degree.
    pub order: usize,
    /// A joint counts as stuck where its estimated speed is below this many
    /// times the speed-estimate noise.
    pub stuck_speed_factor: f64,
    /// Width `w` of the smooth `tanh(v / w)` standing in for `sign(v)`;
    /// `None` picks the largest speed-estimate noise level (at least 1e-3).
    pub friction_width: Option<f64>,
}

impl EquationErrorOptions {
    /// The Savitzky-Golay half width in samples at sample time `dt`
    /// ([`EquationErrorOptions::half_window`]).
    pub fn half_width(&self, dt: f64) -> usize {
        ((self.half_window / dt).round() as usize).max(self.order + 1)
    }
}

impl Default for EquationErrorOptions {
    fn default() -> Self {
        EquationErrorOptions {
            half_window: 0.06,
            row_rate: 500.0,
            order: 5,
            stuck_speed_factor: 5.0,
            friction_width: None,
        }
    }
}

/// Why the equation-error ranking could not be done.
#[derive(Clone, Debug, PartialEq)]
pub enum EquationErrorError {
    /// The smoothing kernel cannot be built from the options.
    Kernel(KernelError),
    /// The experiment's channels do not match the model.
    Sim(SimError),
    /// The equations of motion could not be formed.
    Mechanics(String),
    /// A tape could not be compiled (a symbol without a value).
    Tape(String),
    /// The base parameter vector has the wrong length.
    ParameterCount {
        /// Expected length.
        expected: usize,
        /// Given length.
        found: usize,
    },
    /// A sensor offset or input delay names a coordinate or input that does
    /// not exist.
    BadIndex(usize),
    /// No experiment is longer than the smoothing window.
    NoSamples,
}

impl fmt::Display for EquationErrorError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EquationErrorError::Kernel(e) => write!(f, "{e}"),
            EquationErrorError::Sim(e) => write!(f, "{e}"),
            EquationErrorError::Mechanics(m) => write!(f, "equations of motion: {m}"),
            EquationErrorError::Tape(m) => write!(f, "compiling the equation residuals: {m}"),
            EquationErrorError::ParameterCount { expected, found } => {
                write!(f, "expected {expected} base parameter values, got {found}")
            }
            EquationErrorError::BadIndex(i) => {
                write!(f, "no coordinate or input number {i} in the model")
            }
            EquationErrorError::NoSamples => write!(
                f,
                "no experiment is longer than the smoothing window of the equation-error ranking"
            ),
        }
    }
}

impl std::error::Error for EquationErrorError {}

impl From<SimError> for EquationErrorError {
    fn from(e: SimError) -> Self {
        EquationErrorError::Sim(e)
    }
}

impl From<KernelError> for EquationErrorError {
    fn from(e: KernelError) -> Self {
        EquationErrorError::Kernel(e)
    }
}

/// Where a candidate's columns come from (see the module docs).
#[derive(Clone, Debug)]
pub enum Regressor {
    /// The edited model (the effect added) with new parameters `names`: the
    /// columns are `d r / d p` at the new parameters' values in `model` (their
    /// start values), the other parameters at the baseline's values (by name).
    /// Estimates are `p = p0 - beta`.
    Parameters {
        /// The edited model.
        model: Box<Model>,
        /// The new parameters (names in `model`).
        names: Vec<String>,
    },
    /// An offset `d` on the measured coordinate `coordinate` (measured = true
    /// + d): column `d r / d q_i`, estimate `d = beta`.
    SensorOffset {
        /// Coordinate index.
        coordinate: usize,
        /// Name given to the estimate.
        name: String,
    },
    /// A delay `Td` of input `input` (applied = `u(t - Td)`): since
    /// `r(u) = Td * (d r / d u) * u'` to first order, the column is
    /// `(d r / d u) u'` with `u'` the rate of the smoothed ZOH-averaged input;
    /// estimate `Td = beta`.
    InputDelay {
        /// Input index.
        input: usize,
        /// Name given to the estimate.
        name: String,
    },
    /// A deadzone of half-width `w` on input `input` (applied =
    /// `sign(u) max(|u| - w, 0)`): the baseline residual is, to first order,
    /// `-w * (d r / d u) * d dz/dw`, and `d dz/dw = -sign(u)` where
    /// `|u| > w`, zero elsewhere; the column is `(d r / d u) (-sign(u))` on
    /// the samples of the smoothed ZOH-averaged input with `|u| > start`
    /// (zero on the others); estimate `w = -beta`.
    Deadzone {
        /// Input index.
        input: usize,
        /// Name given to the estimate.
        name: String,
        /// The width (>= 0, the input's SI unit) that selects the samples
        /// outside the deadzone (the candidate's start value).
        start: f64,
    },
    /// A cogging torque `-A sin(N q + phase)` on coordinate `coordinate`:
    /// for each integer `N` of a scan, columns `sin(N q)` and `cos(N q)`
    /// (smoothed like the states) in the coordinate's equation; the best `N`
    /// wins, `A` and `phase` follow from the two coefficients. Counts one
    /// parameter more than its columns (the scanned `N`).
    Cogging {
        /// Coordinate index.
        coordinate: usize,
        /// Names given to the estimates of `A`, `N` and `phase`.
        names: [String; 3],
    },
    /// A saturation of input `input` at level `L`: the plant received
    /// `sat(u)` where the model assumes `u`, so the residual holds
    /// `(d r/d u) (u - sat(u))` (each held sample clipped, then averaged and
    /// smoothed like the input). For each level of a scan over the
    /// commanded `|u|` that term is removed from the residual (coefficient
    /// 1: no free scale) and the nuisance regression redone; the best level
    /// wins. One parameter, no column.
    Saturation {
        /// Input index.
        input: usize,
        /// Name given to the estimate of `L`.
        name: String,
    },
    /// A speed limit `-c dz(q', vmax)` (rounded as in the language) on
    /// coordinate `coordinate`: for each `vmax` of a scan over the measured
    /// speeds, the column `dz(q', vmax)` in the coordinate's equation, whose
    /// coefficient is `c` (only `c > 0` counts); the best `vmax` wins.
    SpeedLimit {
        /// Coordinate index.
        coordinate: usize,
        /// Names given to the estimates of `vmax` and `c`.
        names: [String; 2],
    },
    /// Stribeck friction `-(Fc + (Fs - Fc) exp(-(q'/vs)^2)) sign(q')` on
    /// coordinate `coordinate`: for each `vs` of a logarithmic scan, the
    /// columns `sign(q')` and `exp(-(q'/vs)^2) sign(q')` in the
    /// coordinate's equation, with coefficients `-Fc` and `-(Fs - Fc)`
    /// (only `Fs > Fc` counts); the best `vs` wins.
    Stribeck {
        /// Coordinate index.
        coordinate: usize,
        /// Names given to the estimates of `Fc`, `Fs` and `vs`.
        names: [String; 3],
    },
}

/// A parameter estimate of the equation-error regression (a linearised
/// step; its standard error ignores the time correlation of the residual and
/// is therefore optimistic).
#[derive(Clone, Debug, PartialEq)]
pub struct LinearEstimate {
    /// Parameter name.
    pub name: String,
    /// Estimate.
    pub value: f64,
    /// Standard error from the regression.
    pub std_error: f64,
}

/// A share of the explained residual variance.
#[derive(Clone, Debug, PartialEq)]
pub struct Share {
    /// What the share is of: an experiment name, or a speed regime
    /// (`near zero speed`, `moving`).
    pub label: String,
    /// Fraction of the candidate's reduction of the residual sum of squares
    /// (0..1; regimes of one kind sum to 1).
    pub share: f64,
}

/// The equation-error score of one candidate.
#[derive(Clone, Debug, PartialEq)]
pub struct Score {
    /// `N ln(RSS0 / RSS1) - k ln N` (stacked, weighted equations).
    pub bic_gain: f64,
    /// `(RSS0 - RSS1) / RSS0`: share of the nuisance-adjusted residual
    /// variance the candidate explains.
    pub residual_share: f64,
    /// Number of independent columns the candidate added (0 when they are
    /// already spanned by the nuisance columns).
    pub columns: usize,
    /// Linearised estimates of the candidate's parameters.
    pub estimates: Vec<LinearEstimate>,
    /// Where the explained variance lies: by experiment (largest first).
    pub by_experiment: Vec<Share>,
    /// Where the explained variance lies: `near zero speed` (samples where
    /// the speed of the equation's own coordinate is below a quarter of its
    /// RMS over all experiments) versus `moving`.
    pub by_speed: Vec<Share>,
}

/// Smoothed signals of one experiment over its valid (inner) samples.
#[derive(Clone, Debug)]
struct Smoothed {
    name: String,
    /// `q[i][k]`, `qd`, `qdd`: coordinate, speed, acceleration.
    q: Vec<Vec<f64>>,
    qd: Vec<Vec<f64>>,
    qdd: Vec<Vec<f64>>,
    /// Smoothed ZOH-average input and its rate, per input.
    u: Vec<Vec<f64>>,
    ud: Vec<Vec<f64>>,
    /// `keep[i][k]`: sample `k` is used in equation `i`.
    keep: Vec<Vec<bool>>,
    /// The measured coordinates and commanded inputs over the whole record
    /// at the recorded (uniform) rate, the block length of the reduction and
    /// the smoothing kernel, for columns that are nonlinear functions of them
    /// (the function is applied at the recorded rate, then the signal is
    /// reduced and smoothed like the states: [`Smoothed::coordinate_like`],
    /// [`Smoothed::input_like`]).
    raw_q: Vec<Vec<f64>>,
    raw_u: Vec<Vec<f64>>,
    block: usize,
    k0: Vec<f64>,
}

impl Smoothed {
    fn len(&self) -> usize {
        self.q.first().map_or(0, Vec::len)
    }

    /// A function of the coordinates at the recorded rate, reduced and
    /// smoothed like the coordinates (index `k` = smoothed sample `k`).
    fn coordinate_like(&self, y: &[f64]) -> Vec<f64> {
        apply(&self.k0, &block_means(y, self.block))
    }

    /// A function of the inputs at the recorded rate, ZOH-centred, reduced
    /// and smoothed like the inputs.
    fn input_like(&self, x: &[f64]) -> Vec<f64> {
        apply(&self.k0, &block_means(&zoh_centred(x), self.block))
    }
}

/// `u[k]` acts over `[t_k, t_k + T)`: the input centred on sample `k` is
/// `(u[k-1] + u[k]) / 2` (trap 2).
fn zoh_centred(u: &[f64]) -> Vec<f64> {
    (0..u.len())
        .map(|k| 0.5 * (u[k.saturating_sub(1)] + u[k]))
        .collect()
}

/// Means of consecutive blocks of `b` samples (a trailing partial block is
/// dropped); `b <= 1` returns the signal unchanged.
fn block_means(y: &[f64], b: usize) -> Vec<f64> {
    if b <= 1 {
        return y.to_vec();
    }
    y.chunks_exact(b)
        .map(|c| c.iter().sum::<f64>() / b as f64)
        .collect()
}

/// The prepared equation-error problem of a baseline model on a set of
/// experiments: smoothed signals, row selection, weighted residuals and
/// nuisance columns.
#[derive(Clone, Debug)]
pub struct EquationError {
    n: usize,
    m: usize,
    width: f64,
    exps: Vec<Smoothed>,
    /// Baseline parameter values by name (base parameters).
    base: Vec<(String, f64)>,
    /// Row weight per equation (1 / RMS of its raw residual).
    weight: Vec<f64>,
    /// Per row: experiment, sample, equation.
    rows: Vec<(usize, usize, usize)>,
    /// Weighted baseline residual per row.
    r: Vec<f64>,
    /// Weighted nuisance columns.
    nuisance: Vec<Vec<f64>>,
    /// Weighted `dr/dq_j` and `(dr/du_j) u_j'` columns.
    dq: Vec<Vec<f64>>,
    du: Vec<Vec<f64>>,
    /// Weighted `dr/du_j` columns.
    dr_du: Vec<Vec<f64>>,
    /// Residual after the nuisance-only regression and its RSS.
    r0: Vec<f64>,
    rss0: f64,
    /// Low-speed threshold per coordinate (for the `by_speed` shares).
    slow: Vec<f64>,
    /// The scale held fixed, if the residual was homogeneous.
    scale: Option<ScaleFixed>,
    /// The nuisance columns before the scale was fixed (only then).
    nuisance_full: Option<Vec<Vec<f64>>>,
}

/// Relative residual below which columns count as spanning a vector
/// exactly: the nuisance columns the residual, or a candidate column (a
/// duplicate of a model parameter's). An algebraic identity leaves 1e-20 or
/// so; a real fit, even a perfect one on noise-free data, leaves smoothing
/// error.
const SCALE_TOLERANCE: f64 = 1e-9;

/// The scale degeneracy of the equation error, when it has one.
///
/// The torque residual `M(q) q'' + bias - Q` is often homogeneous in the
/// estimated parameters: with the inertias, a length, the dampings and an
/// input gain all marked `estimate`, scaling them together scales the
/// residual (Euler: `sum_j p_j dr/dp_j = r`), so the residual is an exact
/// combination of its own nuisance columns and the regression drives every
/// parameter to 0 (RSS 0: every candidate scores 0, a silent blind spot).
/// The ranking then keeps the common scale: the nuisance may move the
/// parameters only in directions `x` (relative changes `dp_j / p_j`) with
/// `sum_j a_j x_j = 0`, where `a` (relative) is the homogeneity direction:
/// for a residual of degree 1 in all of them, the geometric mean of the
/// parameters is held.
#[derive(Clone, Debug, PartialEq)]
pub struct ScaleFixed {
    /// The nuisance parameters that carry the scale, with their weight in
    /// the homogeneity direction (relative; the largest is 1).
    pub parameters: Vec<(String, f64)>,
}

impl fmt::Display for ScaleFixed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names: Vec<&str> = self.parameters.iter().map(|(n, _)| n.as_str()).collect();
        write!(
            f,
            "the equations are homogeneous in {}: scaled together they leave the motion unchanged, so the data fix only their ratios; the ranking held their common scale",
            names.join(", ")
        )
    }
}

/// Columns whose least-squares fit of `r` leaves `rss` span `r` exactly
/// (to [`SCALE_TOLERANCE`]).
fn spans(rss: f64, r: &[f64]) -> bool {
    let rr = dot(r, r);
    rr > 0.0 && rss <= SCALE_TOLERANCE * rr
}

/// The nuisance columns without the homogeneity direction (see
/// [`ScaleFixed`]), given the coefficients `coef` with which they span the
/// residual exactly. None when no parameter carries the scale.
fn fix_scale(
    cols: &[Vec<f64>],
    coef: &[f64],
    names: &[String],
    values: &[f64],
) -> Option<(Vec<Vec<f64>>, ScaleFixed)> {
    // relative columns N_j s_j (s_j = |p_j|, or the column's inverse norm
    // for a parameter at 0) and the direction a_rel with r = sum a_rel_j N_j s_j
    let s: Vec<f64> = cols
        .iter()
        .zip(values)
        .map(|(c, v)| {
            if *v != 0.0 && v.is_finite() {
                v.abs()
            } else {
                let nc = dot(c, c).sqrt();
                if nc > 0.0 {
                    1.0 / nc
                } else {
                    1.0
                }
            }
        })
        .collect();
    let a: Vec<f64> = coef.iter().zip(&s).map(|(b, s)| b / s).collect();
    let star = (0..a.len()).max_by(|&i, &j| a[i].abs().total_cmp(&a[j].abs()))?;
    if a[star] == 0.0 {
        return None;
    }
    // basis of {x : a . x = 0}: e_j - (a_j / a_star) e_star, j != star
    let rel = |j: usize| -> Vec<f64> { cols[j].iter().map(|x| x * s[j]).collect() };
    let c_star = rel(star);
    let out: Vec<Vec<f64>> = (0..cols.len())
        .filter(|&j| j != star)
        .map(|j| {
            let f = a[j] / a[star];
            rel(j).iter().zip(&c_star).map(|(x, y)| x - f * y).collect()
        })
        .collect();
    let a_star = a[star];
    let parameters = names
        .iter()
        .zip(&a)
        .filter(|(_, aj)| aj.abs() > 1e-6 * a_star.abs())
        .map(|(n, aj)| (n.clone(), aj / a_star))
        .collect();
    Some((out, ScaleFixed { parameters }))
}

fn has_sign(e: Expr) -> bool {
    let mut stack = vec![e];
    let mut seen = std::collections::HashSet::new();
    while let Some(x) = stack.pop() {
        if !seen.insert(x) {
            continue;
        }
        if let Node::Func(Func::Sign, _) = x.node() {
            return true;
        }
        stack.extend(x.children());
    }
    false
}

/// Tape input symbols: `q`, `q'`, `q''`, inputs, full parameters.
fn inputs_of(model: &Model) -> Vec<Symbol> {
    let cs = model.coordinate_symbols();
    let mut v: Vec<Symbol> = cs.iter().map(|c| c.q).collect();
    v.extend(cs.iter().map(|c| c.qd));
    v.extend(cs.iter().map(|c| c.qdd));
    v.extend(model.input_symbols());
    v.extend(model.parameter_symbols());
    v
}

fn equations(model: &Model, width: f64) -> Result<Equations, EquationErrorError> {
    let eqs = derive_equations(model).map_err(|e| EquationErrorError::Mechanics(e.to_string()))?;
    Ok(smooth_signs(&eqs, width))
}

fn compile(outs: &[Expr], model: &Model) -> Result<Tape, EquationErrorError> {
    Tape::compile(outs, &inputs_of(model)).map_err(|e| EquationErrorError::Tape(e.to_string()))
}

/// Result of a least-squares solve.
struct Lsq {
    coef: Vec<f64>,
    rss: f64,
    /// Diagonal of `(X'X)^-1` (NaN for dependent columns).
    inv_diag: Vec<f64>,
    /// Columns found independent of the earlier ones.
    independent: Vec<bool>,
}

/// Least squares `y ~ X` by normal equations with unit-diagonal scaling and
/// a Cholesky that skips columns dependent on earlier ones (coefficient 0).
fn least_squares(cols: &[&[f64]], y: &[f64]) -> Lsq {
    let k = cols.len();
    let mut a = vec![0.0; k * k];
    let mut b = vec![0.0; k];
    for i in 0..k {
        b[i] = dot(cols[i], y);
        for j in i..k {
            let v = dot(cols[i], cols[j]);
            a[i * k + j] = v;
            a[j * k + i] = v;
        }
    }
    let yy = dot(y, y);
    let sc: Vec<f64> = (0..k)
        .map(|i| {
            let d = a[i * k + i].sqrt();
            if d > 0.0 && d.is_finite() {
                d
            } else {
                0.0
            }
        })
        .collect();
    let mut s = vec![0.0; k * k];
    for i in 0..k {
        for j in 0..k {
            if sc[i] > 0.0 && sc[j] > 0.0 {
                s[i * k + j] = a[i * k + j] / (sc[i] * sc[j]);
            }
        }
    }
    // Cholesky with skipping
    let mut l = vec![0.0; k * k];
    let mut ok = vec![false; k];
    for i in 0..k {
        if sc[i] == 0.0 {
            continue;
        }
        for j in 0..=i {
            if j < i && !ok[j] {
                continue;
            }
            let mut v = s[i * k + j];
            for p in 0..j {
                v -= l[i * k + p] * l[j * k + p];
            }
            if i == j {
                if v > 1e-9 {
                    l[i * k + i] = v.sqrt();
                    ok[i] = true;
                }
            } else {
                l[i * k + j] = v / l[j * k + j];
            }
        }
        if !ok[i] {
            for p in 0..k {
                l[i * k + p] = 0.0;
            }
        }
    }
    let solve = |rhs: &[f64]| -> Vec<f64> {
        let mut z = vec![0.0; k];
        for i in 0..k {
            if !ok[i] {
                continue;
            }
            let mut v = rhs[i];
            for p in 0..i {
                v -= l[i * k + p] * z[p];
            }
            z[i] = v / l[i * k + i];
        }
        for i in (0..k).rev() {
            if !ok[i] {
                continue;
            }
            let mut v = z[i];
            for p in i + 1..k {
                v -= l[p * k + i] * z[p];
            }
            z[i] = v / l[i * k + i];
        }
        z
    };
    let bs: Vec<f64> = (0..k)
        .map(|i| if ok[i] { b[i] / sc[i] } else { 0.0 })
        .collect();
    let xs = solve(&bs);
    let coef: Vec<f64> = (0..k)
        .map(|i| if ok[i] { xs[i] / sc[i] } else { 0.0 })
        .collect();
    let rss = (yy - dot(&bs, &xs)).max(0.0);
    let inv_diag = (0..k)
        .map(|i| {
            if !ok[i] {
                return f64::NAN;
            }
            let mut e = vec![0.0; k];
            e[i] = 1.0;
            solve(&e)[i] / (sc[i] * sc[i])
        })
        .collect();
    Lsq {
        coef,
        rss,
        inv_diag,
        independent: ok,
    }
}

/// The signals on a uniform grid: unchanged when the stamps are uniform
/// within 1 %; otherwise resampled at the median period over the same span
/// (jitter, dropped samples): coordinates by the cubic through the four
/// nearest stamps, inputs as held (the value logged at the last stamp at or
/// before the new instant, as the DAC held it).
pub fn uniform(sig: Signals) -> Signals {
    let n = sig.len();
    if n < 4 {
        return sig;
    }
    let dt = sig.sample_time();
    if sig
        .t
        .windows(2)
        .all(|w| ((w[1] - w[0]) - dt).abs() <= 0.01 * dt)
    {
        return sig;
    }
    let (t0, t1) = (sig.t[0], sig.t[n - 1]);
    let len = ((t1 - t0) / dt).floor() as usize + 1;
    let t: Vec<f64> = (0..len).map(|k| t0 + k as f64 * dt).collect();
    let idx: Vec<usize> = t
        .iter()
        .map(|&x| {
            sig.t
                .partition_point(|&s| s <= x)
                .saturating_sub(1)
                .min(n - 1)
        })
        .collect();
    let cubic = |y: &[f64], x: f64, i: usize| -> f64 {
        let a = i.saturating_sub(1).min(n - 4);
        let pts = &sig.t[a..a + 4];
        let mut v = 0.0;
        for j in 0..4 {
            let mut l = 1.0;
            for k in 0..4 {
                if k != j {
                    l *= (x - pts[k]) / (pts[j] - pts[k]);
                }
            }
            v += l * y[a + j];
        }
        v
    };
    let q = sig
        .q
        .iter()
        .map(|y| t.iter().zip(&idx).map(|(&x, &i)| cubic(y, x, i)).collect())
        .collect();
    let u = sig
        .u
        .iter()
        .map(|y| idx.iter().map(|&i| y[i]).collect())
        .collect();
    Signals {
        name: sig.name,
        t,
        q,
        u,
        replay: None,
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (mut s, mut c) = (0.0, 0usize);
    for x in v {
        s += x * x;
        c += 1;
    }
    if c == 0 {
        0.0
    } else {
        (s / c as f64).sqrt()
    }
}

impl EquationError {
    /// Prepare the ranking of `model` at base values `base` (model order,
    /// e.g. a fit's `base`), with the parameters `nuisance` re-adjusted in
    /// every regression.
    pub fn new(
        model: &Model,
        base: &[f64],
        nuisance: &[String],
        experiments: &[Experiment],
        opts: &EquationErrorOptions,
    ) -> Result<EquationError, EquationErrorError> {
        if base.len() != model.parameters.len() {
            return Err(EquationErrorError::ParameterCount {
                expected: model.parameters.len(),
                found: base.len(),
            });
        }
        let (n, m) = (model.coordinates.len(), model.inputs.len());
        let mut exps = Vec::new();
        let mut noise = vec![0.0f64; n];
        let mut noise_count = 0usize;
        let mut k1_norm = 0.0;
        for e in experiments {
            let sig = uniform(Signals::from_experiment(model, e)?);
            if sig.len() < 4 {
                continue;
            }
            let dt0 = (sig.t[sig.len() - 1] - sig.t[0]) / (sig.len() - 1) as f64;
            // reduce fast records to about `row_rate` by block means
            let block = if opts.row_rate > 0.0 && dt0 > 0.0 {
                ((1.0 / opts.row_rate) / dt0).round().max(1.0) as usize
            } else {
                1
            };
            let dt = dt0 * block as f64;
            let h = opts.half_width(dt);
            let q_red: Vec<Vec<f64>> = sig.q.iter().map(|y| block_means(y, block)).collect();
            if q_red.first().map_or(0, Vec::len) <= 2 * h + 1 {
                continue;
            }
            let k0 = kernel(h, opts.order, 0, dt)?;
            let k1 = kernel(h, opts.order, 1, dt)?;
            let k2 = kernel(h, opts.order, 2, dt)?;
            k1_norm = dot(&k1, &k1).sqrt().max(k1_norm);
            let q: Vec<Vec<f64>> = q_red.iter().map(|y| apply(&k0, y)).collect();
            for i in 0..n {
                let d = rms(q[i].iter().zip(&q_red[i][h..]).map(|(a, b)| a - b));
                noise[i] += d * d;
            }
            noise_count += 1;
            let zoh: Vec<Vec<f64>> = sig
                .u
                .iter()
                .map(|u| block_means(&zoh_centred(u), block))
                .collect();
            let keep_len = q[0].len();
            exps.push(Smoothed {
                name: sig.name.clone(),
                qd: q_red.iter().map(|y| apply(&k1, y)).collect(),
                qdd: q_red.iter().map(|y| apply(&k2, y)).collect(),
                u: zoh.iter().map(|y| apply(&k0, y)).collect(),
                ud: zoh.iter().map(|y| apply(&k1, y)).collect(),
                keep: vec![vec![true; keep_len]; n],
                q,
                raw_q: sig.q,
                raw_u: sig.u,
                block,
                k0,
            });
        }
        if exps.is_empty() {
            return Err(EquationErrorError::NoSamples);
        }
        // speed-estimate noise per coordinate: quantisation-like noise of the
        // angle (its deviation from the local polynomial) through the
        // first-derivative kernel
        let speed_noise: Vec<f64> = noise
            .iter()
            .map(|s| (s / noise_count as f64).sqrt() * k1_norm)
            .collect();
        let width = opts
            .friction_width
            .unwrap_or_else(|| speed_noise.iter().fold(1e-3f64, |a, b| a.max(*b)));
        let raw =
            derive_equations(model).map_err(|e| EquationErrorError::Mechanics(e.to_string()))?;
        for (i, noise_i) in speed_noise.iter().enumerate() {
            if !has_sign(raw.forces[i]) {
                continue;
            }
            let limit = (opts.stuck_speed_factor * noise_i).max(width);
            for ex in &mut exps {
                let len = ex.len();
                let h = ex.k0.len() / 2;
                let stuck: Vec<bool> = ex.qd[i].iter().map(|v| v.abs() < limit).collect();
                for (k, &s) in stuck.iter().enumerate() {
                    if s {
                        let lo = k.saturating_sub(h);
                        let hi = (k + h + 1).min(len);
                        for keep in &mut ex.keep[i][lo..hi] {
                            *keep = false;
                        }
                    }
                }
            }
        }
        let eqs = smooth_signs(&raw, width);
        let res = eqs.residuals();
        let free_syms: Vec<Symbol> = nuisance
            .iter()
            .map(|name| {
                model
                    .parameter(name)
                    .map(|p| p.symbol)
                    .ok_or_else(|| SimError::UnknownParameter { name: name.clone() })
            })
            .collect::<Result<_, _>>()?;
        let expanded: Vec<Expr> = res.iter().map(|e| model.expand_derived(*e)).collect();
        let mut outs = res.clone();
        for &p in &free_syms {
            outs.extend(expanded.iter().map(|e| diff(*e, p)));
        }
        for c in &eqs.coords {
            outs.extend(res.iter().map(|e| diff(*e, c.q)));
        }
        for &u in &eqs.inputs {
            outs.extend(res.iter().map(|e| diff(*e, u)));
        }
        let tape = compile(&outs, model)?;
        let full = ParameterValues::from_base(model, base.to_vec()).full;
        let np = free_syms.len();
        let mut rows = Vec::new();
        let mut raw_r = Vec::new();
        let mut raw_n: Vec<Vec<f64>> = vec![Vec::new(); np];
        let mut raw_dq: Vec<Vec<f64>> = vec![Vec::new(); n];
        let mut raw_du: Vec<Vec<f64>> = vec![Vec::new(); m];
        let mut raw_dr_du: Vec<Vec<f64>> = vec![Vec::new(); m];
        eval_rows(&tape, &exps, n, m, &full, |e, k, out| {
            for i in 0..n {
                if !exps[e].keep[i][k] {
                    continue;
                }
                rows.push((e, k, i));
                raw_r.push(out[i]);
                for j in 0..np {
                    raw_n[j].push(out[n + j * n + i]);
                }
                for j in 0..n {
                    raw_dq[j].push(out[n + np * n + j * n + i]);
                }
                for j in 0..m {
                    let d = out[n + np * n + n * n + j * n + i];
                    raw_du[j].push(d * exps[e].ud[j][k]);
                    raw_dr_du[j].push(d);
                }
            }
        });
        let weight: Vec<f64> = (0..n)
            .map(|i| {
                let s = rms(rows
                    .iter()
                    .zip(&raw_r)
                    .filter(|((_, _, eq), _)| *eq == i)
                    .map(|(_, r)| *r));
                if s > 0.0 && s.is_finite() {
                    1.0 / s
                } else {
                    0.0
                }
            })
            .collect();
        let wt = |v: Vec<f64>| -> Vec<f64> {
            v.iter()
                .zip(&rows)
                .map(|(x, (_, _, i))| x * weight[*i])
                .collect()
        };
        let r = wt(raw_r);
        let nuisance_cols: Vec<Vec<f64>> = raw_n.into_iter().map(wt).collect();
        let dq: Vec<Vec<f64>> = raw_dq.into_iter().map(wt).collect();
        let du: Vec<Vec<f64>> = raw_du.into_iter().map(wt).collect();
        let dr_du: Vec<Vec<f64>> = raw_dr_du.into_iter().map(wt).collect();
        let values: Vec<f64> = nuisance
            .iter()
            .map(|name| {
                model
                    .parameters
                    .iter()
                    .position(|p| &p.name == name)
                    .map_or(0.0, |i| base[i])
            })
            .collect();
        let cols: Vec<&[f64]> = nuisance_cols.iter().map(Vec::as_slice).collect();
        let mut fit0 = least_squares(&cols, &r);
        // the nuisance columns span the residual: hold the scale fixed
        let fixed = spans(fit0.rss, &r)
            .then(|| fix_scale(&nuisance_cols, &fit0.coef, nuisance, &values))
            .flatten();
        let (nuisance_cols, scale, nuisance_full) = match fixed {
            Some((cols, scale)) => (cols, Some(scale), Some(nuisance_cols)),
            None => (nuisance_cols, None, None),
        };
        let cols: Vec<&[f64]> = nuisance_cols.iter().map(Vec::as_slice).collect();
        if scale.is_some() {
            fit0 = least_squares(&cols, &r);
        }
        let r0 = residual(&r, &cols, &fit0.coef);
        let slow = (0..n)
            .map(|i| 0.25 * rms(exps.iter().flat_map(|e| e.qd[i].iter().copied())))
            .collect();
        Ok(EquationError {
            n,
            m,
            width,
            base: model
                .parameters
                .iter()
                .zip(base)
                .map(|(p, v)| (p.name.clone(), *v))
                .collect(),
            exps,
            weight,
            rows,
            r,
            nuisance: nuisance_cols,
            dq,
            du,
            dr_du,
            rss0: fit0.rss,
            r0,
            slow,
            scale,
            nuisance_full,
        })
    }

    /// The common scale held fixed during the ranking, when the residual is
    /// homogeneous in the nuisance parameters (see [`ScaleFixed`]).
    pub fn scale_fixed(&self) -> Option<&ScaleFixed> {
        self.scale.as_ref()
    }

    /// True when the nuisance columns still span the residual after the
    /// scale is fixed: no candidate can explain anything, the ranking cannot
    /// discriminate (another exact dependency among the estimated
    /// parameters).
    pub fn blind(&self) -> bool {
        spans(self.rss0, &self.r)
    }

    /// Number of (sample, equation) rows in the regression.
    pub fn rows(&self) -> usize {
        self.rows.len()
    }

    /// The `tanh` width used in place of `sign`.
    pub fn friction_width(&self) -> f64 {
        self.width
    }

    /// Residual sum of squares (weighted) after the nuisance-only regression.
    pub fn baseline_rss(&self) -> f64 {
        self.rss0
    }

    /// Score one candidate.
    pub fn score(&self, reg: &Regressor) -> Result<Score, EquationErrorError> {
        // regression target, candidate columns, estimate names, start values
        // and the sign of the estimate (p = p0 + sign * beta)
        type Columns = (Vec<f64>, Vec<Vec<f64>>, Vec<String>, Vec<f64>, f64);
        let (target, cand, names, p0, sign): Columns = match reg {
            Regressor::Parameters { model, names } => {
                if let Some(r) = rig_effects::recognise(model, names, self.n, self.m) {
                    return self.score(&r);
                }
                let (t, c, p0) = self.parameter_columns(model, names)?;
                (t, c, names.clone(), p0, -1.0)
            }
            Regressor::SensorOffset { coordinate, name } => {
                let c = self
                    .dq
                    .get(*coordinate)
                    .ok_or(EquationErrorError::BadIndex(*coordinate))?;
                (
                    self.r.clone(),
                    vec![c.clone()],
                    vec![name.clone()],
                    vec![0.0],
                    1.0,
                )
            }
            Regressor::InputDelay { input, name } => {
                let c = self
                    .du
                    .get(*input)
                    .ok_or(EquationErrorError::BadIndex(*input))?;
                (
                    self.r.clone(),
                    vec![c.clone()],
                    vec![name.clone()],
                    vec![0.0],
                    1.0,
                )
            }
            Regressor::Deadzone { input, name, start } => {
                let d = self
                    .dr_du
                    .get(*input)
                    .ok_or(EquationErrorError::BadIndex(*input))?;
                let c = self
                    .rows
                    .iter()
                    .zip(d)
                    .map(|((e, k, _), d)| {
                        let u = self.exps[*e].u[*input][*k];
                        if u.abs() > *start {
                            -u.signum() * d
                        } else {
                            0.0
                        }
                    })
                    .collect();
                (self.r.clone(), vec![c], vec![name.clone()], vec![0.0], -1.0)
            }
            Regressor::Cogging { coordinate, names } => {
                return self.score_cogging(*coordinate, names);
            }
            Regressor::Saturation { input, name } => {
                return self.score_saturation(*input, name);
            }
            Regressor::SpeedLimit { coordinate, names } => {
                return self.score_speed_limit(*coordinate, names);
            }
            Regressor::Stribeck { coordinate, names } => {
                return self.score_stribeck(*coordinate, names);
            }
        };
        // with the scale held fixed, a candidate column the model's own
        // parameters already span (viscous friction on a joint whose damping
        // is estimated, an added inertia where the inertia is) would only
        // give the scale back: it adds nothing
        let cand: Vec<Vec<f64>> = match &self.nuisance_full {
            Some(full) => {
                let refs: Vec<&[f64]> = full.iter().map(Vec::as_slice).collect();
                cand.into_iter()
                    .map(|c| {
                        if spans(least_squares(&refs, &c).rss, &c) {
                            vec![0.0; c.len()]
                        } else {
                            c
                        }
                    })
                    .collect()
            }
            None => cand,
        };
        let (mut score, coef, var) = self.finish(&target, &cand, 0);
        score.estimates = names
            .iter()
            .enumerate()
            .map(|(j, name)| LinearEstimate {
                name: name.clone(),
                value: p0[j] + sign * coef[j],
                std_error: var[j].sqrt(),
            })
            .collect();
        Ok(score)
    }

    /// Score with candidate columns `cand` on top of the nuisance, `extra`
    /// scanned parameters counted in the penalty; returns the score (with
    /// empty estimates), the coefficients of `cand` and their variances.
    fn finish(
        &self,
        target: &[f64],
        cand: &[Vec<f64>],
        extra: usize,
    ) -> (Score, Vec<f64>, Vec<f64>) {
        let mut cols: Vec<&[f64]> = self.nuisance.iter().map(Vec::as_slice).collect();
        let nn = cols.len();
        cols.extend(cand.iter().map(Vec::as_slice));
        let fit = least_squares(&cols, target);
        let independent = fit.independent[nn..].iter().filter(|b| **b).count();
        // a column-free candidate (saturation) counts when its target moved
        let moved = cand.is_empty() && target != self.r.as_slice();
        let k = independent + if independent > 0 || moved { extra } else { 0 };
        let nrows = self.rows.len() as f64;
        let rss1 = fit.rss.min(self.rss0);
        let bic_gain = if k == 0 || rss1 <= 0.0 {
            0.0
        } else {
            nrows * (self.rss0 / rss1).ln() - k as f64 * nrows.ln()
        };
        let dof = (nrows - (nn + k) as f64).max(1.0);
        let sigma2 = fit.rss / dof;
        let var: Vec<f64> = (0..cand.len())
            .map(|j| sigma2 * fit.inv_diag[nn + j])
            .collect();
        let r1 = residual(target, &cols, &fit.coef);
        let (by_experiment, by_speed) = self.shares(&r1);
        (
            Score {
                bic_gain,
                residual_share: ((self.rss0 - rss1) / self.rss0).max(0.0),
                columns: k,
                estimates: Vec::new(),
                by_experiment,
                by_speed,
            },
            fit.coef[nn..].to_vec(),
            var,
        )
    }

    /// Where the reduction of the squared residual from the nuisance-only
    /// residual to `r1` lies: by experiment (largest first) and by speed.
    fn shares(&self, r1: &[f64]) -> (Vec<Share>, Vec<Share>) {
        let mut by_exp = vec![0.0; self.exps.len()];
        let mut by_speed = vec![0.0; 2];
        for (row, (e, kk, i)) in self.rows.iter().enumerate() {
            let d = self.r0[row].powi(2) - r1[row].powi(2);
            by_exp[*e] += d;
            let slow = self.exps[*e].qd[*i][*kk].abs() < self.slow[*i];
            by_speed[usize::from(!slow)] += d;
        }
        let shares = |v: &[f64]| -> Vec<f64> {
            let pos: Vec<f64> = v.iter().map(|x| x.max(0.0)).collect();
            let s: f64 = pos.iter().sum();
            pos.iter()
                .map(|x| if s > 0.0 { x / s } else { 0.0 })
                .collect()
        };
        let mut by_experiment: Vec<Share> = self
            .exps
            .iter()
            .zip(shares(&by_exp))
            .map(|(e, share)| Share {
                label: e.name.clone(),
                share,
            })
            .collect();
        by_experiment.sort_by(|a, b| b.share.total_cmp(&a.share));
        let sp = shares(&by_speed);
        let by_speed = vec![
            Share {
                label: "near zero speed".into(),
                share: sp[0],
            },
            Share {
                label: "moving".into(),
                share: sp[1],
            },
        ];
        (by_experiment, by_speed)
    }

    /// Target (edited residual at the start values) and columns
    /// (`d r / d p_new`), weighted, plus the start values.
    #[allow(clippy::type_complexity)] // (target, columns, start values)
    fn parameter_columns(
        &self,
        model: &Model,
        names: &[String],
    ) -> Result<(Vec<f64>, Vec<Vec<f64>>, Vec<f64>), EquationErrorError> {
        if model.coordinates.len() != self.n || model.inputs.len() != self.m {
            return Err(EquationErrorError::Mechanics(
                "the edited model has other coordinates or inputs".into(),
            ));
        }
        let eqs = equations(model, self.width)?;
        let res = eqs.residuals();
        let expanded: Vec<Expr> = res.iter().map(|e| model.expand_derived(*e)).collect();
        let mut outs = res.clone();
        let mut p0 = Vec::new();
        for name in names {
            let p = model
                .parameter(name)
                .ok_or_else(|| SimError::UnknownParameter { name: name.clone() })?;
            p0.push(p.value);
            outs.extend(expanded.iter().map(|e| diff(*e, p.symbol)));
        }
        let tape = compile(&outs, model)?;
        let base: Vec<f64> = model
            .parameters
            .iter()
            .map(|p| {
                self.base
                    .iter()
                    .find(|(n, _)| *n == p.name)
                    .map_or(p.value, |(_, v)| *v)
            })
            .collect();
        let full = ParameterValues::from_base(model, base).full;
        let n = self.n;
        let k = names.len();
        let mut target = Vec::with_capacity(self.rows.len());
        let mut cols = vec![Vec::with_capacity(self.rows.len()); k];
        eval_rows(&tape, &self.exps, n, self.m, &full, |e, kk, out| {
            for i in 0..n {
                if !self.exps[e].keep[i][kk] {
                    continue;
                }
                let w = self.weight[i];
                target.push(out[i] * w);
                for (j, c) in cols.iter_mut().enumerate() {
                    c.push(out[n + j * n + i] * w);
                }
            }
        });
        Ok((target, cols, p0))
    }
}

fn residual(y: &[f64], cols: &[&[f64]], coef: &[f64]) -> Vec<f64> {
    let mut r = y.to_vec();
    for (c, b) in cols.iter().zip(coef) {
        if *b != 0.0 {
            for (ri, ci) in r.iter_mut().zip(c.iter()) {
                *ri -= b * ci;
            }
        }
    }
    r
}

/// Evaluate `tape` at every valid sample of every experiment, in row order.
/// The parameters are fixed here, so the tape is split and its
/// parameter-only part runs once (bit-identical to evaluating it whole).
fn eval_rows(
    tape: &Tape,
    exps: &[Smoothed],
    n: usize,
    m: usize,
    full: &[f64],
    mut f: impl FnMut(usize, usize, &[f64]),
) {
    let mut tin = vec![0.0; 3 * n + m + full.len()];
    tin[3 * n + m..].copy_from_slice(full);
    let split = tape.split_by_inputs(&parameters_slow(3 * n + m, full.len()));
    let mut out = vec![0.0; split.n_outputs()];
    let mut scratch = vec![0.0; split.scratch_len()];
    split.eval_slow(&tin, &mut scratch);
    for (e, ex) in exps.iter().enumerate() {
        for k in 0..ex.len() {
            if (0..n).all(|i| !ex.keep[i][k]) {
                continue;
            }
            for i in 0..n {
                tin[i] = ex.q[i][k];
                tin[n + i] = ex.qd[i][k];
                tin[2 * n + i] = ex.qdd[i][k];
            }
            for j in 0..m {
                tin[3 * n + j] = ex.u[j][k];
            }
            split.eval_fast(&tin, &mut out, &mut scratch);
            f(e, k, &out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_squares_skips_dependent_columns() {
        let x1: Vec<f64> = (0..50).map(|k| k as f64).collect();
        let x2: Vec<f64> = x1.iter().map(|v| 2.0 * v).collect();
        let x3: Vec<f64> = (0..50).map(|k| ((k * 7) % 11) as f64).collect();
        let y: Vec<f64> = x1.iter().zip(&x3).map(|(a, b)| 3.0 * a - b).collect();
        let f = least_squares(&[&x1, &x2, &x3], &y);
        assert_eq!(f.independent, vec![true, false, true]);
        assert!((f.coef[0] - 3.0).abs() < 1e-9 && f.coef[1] == 0.0);
        assert!((f.coef[2] + 1.0).abs() < 1e-9);
        assert!(f.rss < 1e-12 * dot(&y, &y));
    }
}
