//! Which missing effect explains the data?
//!
//! 1. **Baseline**: the model as written is fitted by simulation error
//!    ([`fit`]).
//! 2. **Equation-error ranking** ([`EquationError`]): every candidate (an
//!    effect of the effect table on one target, see [`candidates`]) is scored
//!    by the BIC gain of its regressor columns on the equations' torque
//!    residuals, with the nominal estimated parameters as nuisance columns.
//!    Fast (no simulation), but it cannot tell Coulomb from Stribeck friction
//!    (identification notes, trap 6) and it over-counts evidence.
//! 3. **Confirmation**: the leading [`DiagnoseOptions::refit`] candidates are
//!    added to the model text losslessly and refitted by simulation error
//!    with the nominal estimated parameters free too (a missing effect
//!    distorts the nominal fit, trap 5), starting from the baseline fit and
//!    the equation-error estimates. They are ranked by their RMSE with a
//!    penalty of [`DiagnoseOptions::per_parameter_gain`] per effect parameter
//!    (an extra parameter must buy a clear gain, trap 6).
//!    When none of the leaders explains the residual and the baseline sits
//!    well above the noise floor, screening goes on down the whole list
//!    (and over every candidate when the ranking is blind: see
//!    [`EquationError::blind`]).
//! 4. **Verdict**: the best refitted candidate is accepted only if it divides
//!    the baseline RMSE by at least [`MIN_GAIN`], or brings it down to the
//!    noise floor ([`FLOOR_REACHED`]) from well above it ([`FLOOR_BASELINE`])
//!    or by [`PARTIAL_GAIN`] to it,
//!    and only if the model without it, restarted from the candidate's
//!    values, does not get there too (the gain is measured against the best
//!    baseline, not a worse restart; not checked for a candidate refitted
//!    from the baseline's own values whose parameters are significant:
//!    no restart is in its gain). Otherwise the model is *adequate* when
//!    the baseline is within [`FLOOR_BASELINE`] of the noise floor, and the
//!    residual *unexplained* ([`Diagnosis::unexplained`]) when it is not.
//!
//! [`MIN_GAIN`] = 3, checked on the three reference recordings of the
//! diagnosis tests (`tests/diagnose.rs`, release build): with the right
//! effect the refit divided the baseline RMSE by 16.0 (`coulomb_pendulum`)
//! and about 410 (`spring_arm`, against a baseline distorted to 0.16 rad);
//! the notes
//! measured 9.9x to 2990x on their cases. On the
//! `clean` case the three refitted candidates gained 1.00x (the baseline
//! already sits at the quantisation floor, 4.35e-4 rad, trap 10). 3x lies
//! between the two on a log scale with a wide margin on both sides.
//!
//! Stribeck against Coulomb (trap 6), measured on `coulomb_pendulum`: both
//! lead the equation-error ranking (BIC gain 1184 and 1169); refitted,
//! Coulomb reaches 5.545e-4 and Stribeck (three parameters, `vs` at its
//! bound) slightly worse, so the penalty of 2 % per parameter is not even
//! needed there; it guards the case where the bigger model wins by a hair.
//!
//! Adding effect kinds: [`regressor_for`] maps a candidate to its
//! equation-error columns. Effects that add parameters to the equations
//! (force effects, an input offset folded into the forces) need nothing more
//! than their edited model; a sensor offset maps to
//! [`Regressor::SensorOffset`], an input delay to [`Regressor::InputDelay`],
//! a deadzone (not in the forces) to [`Regressor::Deadzone`].

use std::fmt;

use plantc_derive::lang::parse_and_check;
use plantc_derive::model::{lower, Model};

use crate::data::Experiment;
use crate::effect_edit::{all_candidates, EffectEditError, EffectInstance, EffectKind};
use crate::equation_error::{
    EquationError, EquationErrorError, EquationErrorOptions, Regressor, Score, Share,
};
use crate::fit::{
    fit, replay_follows, values_from, with_estimates, Estimate, FitError, FitOptions, FitResult,
    Horizon, Offsets,
};

/// Smallest RMSE ratio (baseline / candidate) that counts as a found effect.
pub const MIN_GAIN: f64 = 3.0;

/// A candidate whose refit cost is within this factor of the noise floor
/// (estimated from the data: encoder quantum, high-frequency content)...
pub const FLOOR_REACHED: f64 = 1.25;
/// ...while the baseline's is at least this factor above it, is credited
/// even below [`MIN_GAIN`]: the 3x rule cannot be met when the baseline
/// sits less than 3x above the floor (reproducer: Coulomb friction on the
/// pendulum in one driven run, baseline 3.2x the floor, refit 1.01x).
pub const FLOOR_BASELINE: f64 = 2.0;

/// A baseline at or below this factor of the noise floor leaves nothing an
/// effect could be credited for: [`PARTIAL_GAIN`] from there would take the
/// cost to 0.73x the floor estimate, below what the true model reaches on
/// encoder data. That is 0.82x and 0.86x on the two demos, whose channels
/// rest long (a resting channel's rounding error is a constant the offsets
/// absorb, so the estimate `step / sqrt(12)` is high there), and 1.05-1.07x
/// on records that keep moving (the benchmark's settings with no effect, an
/// input delay, a spring: the right model, its RMSE at the rounding's
/// `step / sqrt(12)`; a 0.2 ms substep moved the clean case only from
/// 1.059x to 1.052x, so it is not the simulation's error). At 1.0 those
/// records spent a second round refitting three candidates to 1.00x, a
/// third of their time. No candidate is refitted there. (Between this and
/// [`FLOOR_REACHED`] a candidate can still reach the floor by
/// [`PARTIAL_GAIN`], and is refitted as anywhere else.)
pub const NOTHING_LEFT: f64 = 1.1;

/// Is a weighted cost at most `factor` times the noise floor `floor`
/// (never without a floor)?
fn within_floor(cost: f64, floor: f64, factor: f64) -> bool {
    floor > 0.0 && cost <= factor * floor
}

/// Is a weighted cost at the noise floor `floor` ([`FLOOR_REACHED`] times it
/// or less; never without a floor)?
fn reaches_floor(cost: f64, floor: f64) -> bool {
    within_floor(cost, floor, FLOOR_REACHED)
}

/// Far above the noise floor (at least [`PARTIAL_BASELINE`] times), a
/// candidate that removes a third of the residual ([`PARTIAL_GAIN`]) is
/// credited below the 3x rule: with two effects in the data neither alone
/// reaches 3x (Coulomb friction on the pendulum with a 4 ms input delay:
/// 1.74x for the Coulomb friction, baseline 9.2x the floor), and the next
/// round finds the other. On clean data and on the real QUBE episodes every
/// candidate stayed below 1.1x.
pub const PARTIAL_GAIN: f64 = 1.5;
/// See [`PARTIAL_GAIN`].
pub const PARTIAL_BASELINE: f64 = 4.0;

/// Options of [`diagnose_with`].
#[derive(Clone, Debug, PartialEq)]
pub struct DiagnoseOptions {
    /// Options of the baseline fit and of the refits (`free` and `start` are
    /// set per refit: the candidate's model is fitted with all its
    /// `estimate` parameters).
    pub fit: FitOptions,
    /// Options of the equation-error ranking.
    pub equation_error: EquationErrorOptions,
    /// How many leaders of the equation-error ranking are refitted.
    pub refit: usize,
    /// Smallest RMSE ratio for a verdict ([`MIN_GAIN`]).
    pub min_gain: f64,
    /// Fractional RMSE reduction each effect parameter has to buy when
    /// refitted candidates are compared (0.02: 2 % per parameter).
    pub per_parameter_gain: f64,
    /// Credit [`PARTIAL_GAIN`] far above the floor ([`PARTIAL_BASELINE`]):
    /// on by default; off where the residual far above the floor is the
    /// response to something no effect stands for (a stabilised replay of
    /// records under an unlogged disturbance, where a spring fitted the
    /// feedback's answer to it for 1.42x).
    pub partial_credit: bool,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            fit: FitOptions::default(),
            equation_error: EquationErrorOptions::default(),
            refit: 3,
            min_gain: MIN_GAIN,
            per_parameter_gain: 0.02,
            partial_credit: true,
        }
    }
}

/// Why the diagnosis failed.
#[derive(Clone, Debug, PartialEq)]
pub enum DiagnoseError {
    /// The model text (original or edited) does not check.
    InvalidModel {
        /// Which model: `baseline` or the candidate's label.
        which: String,
        /// The rendered error messages.
        messages: Vec<String>,
    },
    /// The edit could not be applied.
    Edit {
        /// The candidate's label.
        which: String,
        /// The edit error.
        error: EffectEditError,
    },
    /// The baseline fit failed.
    Fit(FitError),
    /// The equation-error ranking failed.
    EquationError(EquationErrorError),
}

impl fmt::Display for DiagnoseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DiagnoseError::InvalidModel { which, messages } => {
                write!(f, "model `{which}` is invalid: {}", messages.join("; "))
            }
            DiagnoseError::Edit { which, error } => {
                write!(f, "cannot add `{which}` to the model: {error}")
            }
            DiagnoseError::Fit(e) => write!(f, "baseline fit: {e}"),
            DiagnoseError::EquationError(e) => write!(f, "equation-error ranking: {e}"),
        }
    }
}

impl std::error::Error for DiagnoseError {}

impl From<EquationErrorError> for DiagnoseError {
    fn from(e: EquationErrorError) -> Self {
        DiagnoseError::EquationError(e)
    }
}

/// A candidate: an effect on one target, parameters free.
pub type Candidate = EffectInstance;

/// Every candidate effect on every target (see [`all_candidates`]).
pub fn candidates(model: &Model) -> Vec<Candidate> {
    all_candidates(model)
}

/// Check and lower model text.
pub fn model_from_text(which: &str, text: &str) -> Result<Model, DiagnoseError> {
    let checked = parse_and_check(which, text);
    let errors: Vec<String> = checked
        .diagnostics
        .iter()
        .filter(|d| d.is_error())
        .map(|d| d.message.clone())
        .collect();
    match checked.model {
        Some(file) if errors.is_empty() => Ok(lower(&file, checked.symbols.as_ref())),
        _ => Err(DiagnoseError::InvalidModel {
            which: which.to_string(),
            messages: errors,
        }),
    }
}

/// The evidence behind one ranked candidate.
#[derive(Clone, Debug, PartialEq)]
pub struct Evidence {
    /// RMSE of the baseline fit (rad or m, all coordinates and experiments).
    pub rmse_before: f64,
    /// RMSE after the refit with the effect added (None: not refitted or the
    /// refit failed).
    pub rmse_after: Option<f64>,
    /// `rmse_before / rmse_after` (None when not refitted).
    pub gain: Option<f64>,
    /// Share of the equation-error residual variance (after re-adjusting the
    /// nominal parameters) the candidate explains, 0..1.
    pub residual_share: f64,
    /// Equation-error BIC gain `N ln(RSS0/RSS1) - k ln N` (ranks; the time
    /// correlation of the residual inflates it, so it does not decide).
    pub bic_gain: f64,
    /// Position in the equation-error ranking (1 = first).
    pub equation_error_rank: usize,
    /// Where the candidate acts: share of its explained residual variance
    /// per experiment (largest first).
    pub by_experiment: Vec<Share>,
    /// Where the candidate acts: low-speed versus higher-speed samples.
    pub by_speed: Vec<Share>,
    /// One line summarising where it acts, e.g. `free_swing_small 37 %,
    /// free_swing_large 32 %, driven 31 %; 47 % near zero speed`.
    pub acts_where: String,
}

/// One ranked candidate.
#[derive(Clone, Debug, PartialEq)]
pub struct Ranked {
    /// The candidate.
    pub candidate: Candidate,
    /// Its simulation-error refit (None if not refitted, or the fit failed
    /// with the reason in `error`).
    pub fit: Option<FitResult>,
    /// Why the refit failed.
    pub error: Option<String>,
    /// Baseline RMSE / candidate RMSE (0 when not refitted or the fit failed).
    pub gain: f64,
    /// Estimates of the effect's own parameters (model names, e.g.
    /// `Fc_alpha`): from the refit with its standard errors when refitted,
    /// otherwise the linearised equation-error estimates.
    pub parameters: Vec<Estimate>,
    /// The evidence.
    pub evidence: Evidence,
    /// Whether the credited refit started from the baseline's own values of
    /// the model's parameters, or from a fit that started there (a Stribeck
    /// friction from the Coulomb fit on its target): no restart from other
    /// values (the nominal ones) is in its gain.
    pub from_baseline: bool,
}

/// The outcome of [`diagnose`].
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnosis {
    /// Fit of the unchanged model (far above the noise floor, to the
    /// screening tolerance only: [`FitOptions::coarse_far_above_floor`]).
    pub baseline: FitResult,
    /// Candidates, best first: the refitted ones by penalised RMSE, then the
    /// others in equation-error order.
    pub ranking: Vec<Ranked>,
    /// The accepted candidate, or None: no candidate explains the residual
    /// (adequate when the baseline is near the noise floor, otherwise
    /// [`Diagnosis::unexplained`]).
    pub verdict: Option<Candidate>,
    /// The weighted cost measurement noise alone would leave (encoder
    /// quantum, high-frequency content; in the units of
    /// `baseline.after_cost`).
    pub floor: f64,
    /// What the diagnosis noticed on the way (a scale held fixed, a blind
    /// equation-error ranking, screening extended beyond the leaders, a
    /// baseline improved by a restart), in words.
    pub notes: Vec<String>,
    /// Whether [`PARTIAL_GAIN`] far above the floor was credited
    /// ([`DiagnoseOptions::partial_credit`]).
    pub partial_credit: bool,
    /// Whether the baseline was at or below the floor ([`NOTHING_LEFT`]),
    /// so that no candidate effect was refitted.
    pub nothing_left: bool,
}

impl Diagnosis {
    /// Baseline cost over the noise floor (NaN without a floor).
    pub fn above_floor(&self) -> f64 {
        if self.floor > 0.0 {
            self.baseline.after_cost / self.floor
        } else {
            f64::NAN
        }
    }

    /// No verdict while the baseline sits well above the noise floor
    /// ([`FLOOR_BASELINE`] times or more): the model is not adequate, the
    /// residual is unexplained by every candidate tried.
    pub fn unexplained(&self) -> bool {
        self.verdict.is_none() && self.above_floor() >= FLOOR_BASELINE
    }

    /// What a diagnosis on segments cannot see, when the baseline was
    /// fitted on them (the whole records could not be replayed: an unstable
    /// plant balanced by a controller the model does not hold). Measured on
    /// the pendulum balanced upright with a hidden Coulomb friction of
    /// 6e-4 N m: with the law in the model the loop is simulated over whole
    /// records and the friction gains 4.1x; replayed open loop on 0.5 s
    /// segments it gains 1.12x and the baseline sits at 1.1x the floor.
    pub fn segments_caveat(&self) -> Option<String> {
        let h = self.baseline.segments?;
        let mut s = format!(
            "judged on {h} s segments, each from its own estimated state: an effect whose trace within {h} s stays under the noise cannot show"
        );
        if self.baseline.closed_loop.is_none() {
            s.push_str(
                "; if the data were recorded in closed loop, a `recorded controller` block with the law (and its signal columns) lets the loop be simulated over the whole records",
            );
        }
        Some(s)
    }

    /// One line for the verdict: the missing effect, `adequate` (near the
    /// floor) or `unexplained residual` (well above it), with the
    /// [`Diagnosis::segments_caveat`] when there is one.
    pub fn verdict_line(&self) -> String {
        if let Some(v) = &self.verdict {
            let gain = self
                .ranking
                .iter()
                .find(|r| r.candidate.label() == v.label())
                .map_or(0.0, |r| r.gain);
            return format!(
                "missing effect `{}` on `{}` (RMSE {gain:.2}x lower with it)",
                v.effect, v.target
            );
        }
        let caveat = self
            .segments_caveat()
            .map(|c| format!("; {c}"))
            .unwrap_or_default();
        if self.unexplained() {
            let refitted: Vec<&Ranked> = self.ranking.iter().filter(|r| r.fit.is_some()).collect();
            let best = refitted
                .iter()
                .max_by(|a, b| a.gain.total_cmp(&b.gain))
                .map(|r| format!("; the best, {}, gains {:.2}x", r.candidate.label(), r.gain))
                .unwrap_or_default();
            let far = if self.partial_credit {
                format!(", or {PARTIAL_GAIN}x far above it")
            } else {
                String::new()
            };
            format!(
                "unexplained residual: {:.1}x the noise floor, and none of the {} candidates refitted lowers it clearly ({MIN_GAIN}x, or to the floor{far}){best}: an effect outside the vocabulary, or a nominal model too far off{caveat}",
                self.above_floor(),
                refitted.len()
            )
        } else if self.nothing_left {
            format!(
                "adequate: the residual is at the noise floor ({:.2}x), nothing is left for an effect to explain{caveat}",
                self.above_floor()
            )
        } else {
            format!(
                "adequate: the residual is within {FLOOR_BASELINE}x the noise floor ({:.2}x) and no candidate lowers it by {MIN_GAIN}x, or by {PARTIAL_GAIN}x to the floor{caveat}",
                self.above_floor()
            )
        }
    }
}

/// The columns of a candidate for the equation-error ranking. Effects that
/// add parameters to the model's equations are handled generically through
/// the edited model (`edited` = the candidate applied to the model text).
pub fn regressor_for(candidate: &Candidate, edited: Model) -> Regressor {
    let first_name = || {
        candidate
            .parameters
            .first()
            .map_or_else(|| candidate.label(), |p| p.name.clone())
    };
    match candidate.kind {
        EffectKind::Sensor => {
            if let Some(i) = edited
                .coordinates
                .iter()
                .position(|c| c.name == candidate.target)
            {
                return Regressor::SensorOffset {
                    coordinate: i,
                    name: first_name(),
                };
            }
        }
        EffectKind::Actuator if candidate.effect == "input_delay" => {
            if let Some(j) = edited
                .inputs
                .iter()
                .position(|u| u.name == candidate.target)
            {
                return Regressor::InputDelay {
                    input: j,
                    name: first_name(),
                };
            }
        }
        EffectKind::Actuator if candidate.effect == "deadzone" => {
            if let Some(j) = edited
                .inputs
                .iter()
                .position(|u| u.name == candidate.target)
            {
                return Regressor::Deadzone {
                    input: j,
                    name: first_name(),
                    start: candidate.parameters.first().map_or(0.0, |p| p.value),
                };
            }
        }
        // force effects and input offsets (folded into the forces) add
        // parameters to the equations: generic columns
        EffectKind::Force | EffectKind::Actuator => {}
    }
    Regressor::Parameters {
        model: Box::new(edited),
        names: candidate
            .parameters
            .iter()
            .map(|p| p.name.clone())
            .collect(),
    }
}

fn where_summary(score: &Score) -> String {
    let exps: Vec<String> = score
        .by_experiment
        .iter()
        .filter(|s| s.share >= 0.005)
        .map(|s| format!("{} {:.0} %", s.label, 100.0 * s.share))
        .collect();
    let mut s = if exps.is_empty() {
        "nowhere in particular".to_string()
    } else {
        exps.join(", ")
    };
    if let Some(slow) = score.by_speed.first() {
        s.push_str(&format!("; {:.0} % {}", 100.0 * slow.share, slow.label));
    }
    s
}

/// [`diagnose_with`] with default options around the given fit options.
pub fn diagnose(
    text: &str,
    experiments: &[Experiment],
    opts: &FitOptions,
) -> Result<Diagnosis, DiagnoseError> {
    diagnose_with(
        text,
        experiments,
        &DiagnoseOptions {
            fit: opts.clone(),
            ..DiagnoseOptions::default()
        },
    )
}

/// Rank the candidates and give a verdict (see the module docs).
pub fn diagnose_with(
    text: &str,
    experiments: &[Experiment],
    opts: &DiagnoseOptions,
) -> Result<Diagnosis, DiagnoseError> {
    let model = model_from_text("baseline", text)?;
    let fo = FitOptions {
        coarse_far_above_floor: true,
        ..opts.fit.clone()
    };
    let baseline = fit(&model, experiments, &fo).map_err(DiagnoseError::Fit)?;
    diagnose_from(text, experiments, baseline, opts)
}

/// [`diagnose_with`] against a baseline fitted already: `baseline` must be
/// the fit of the model in `text` to `experiments` under `opts.fit` (as
/// the last round of the identify story leaves it).
pub fn diagnose_from(
    text: &str,
    experiments: &[Experiment],
    baseline: FitResult,
    opts: &DiagnoseOptions,
) -> Result<Diagnosis, DiagnoseError> {
    let model = model_from_text("baseline", text)?;
    let nuisance = opts.fit.free_names(&model);
    let ee = EquationError::new(
        &model,
        &baseline.base,
        &nuisance,
        experiments,
        &opts.equation_error,
    )?;
    let mut notes = Vec::new();
    if let Some(sf) = ee.scale_fixed() {
        notes.push(format!("equation-error ranking: {sf}"));
    }
    // equation-error scores
    let mut scored = Vec::new();
    for c in candidates(&model) {
        let edited = c.apply(text).map_err(|error| DiagnoseError::Edit {
            which: c.label(),
            error,
        })?;
        let m = model_from_text(&c.label(), &edited)?;
        let score = ee.score(&regressor_for(&c, m.clone()))?;
        scored.push((c, m, score));
    }
    scored.sort_by(|a, b| b.2.bic_gain.total_cmp(&a.2.bic_gain));
    let informative = |s: &Score| s.columns > 0 && s.bic_gain > 0.0;
    let blind = ee.blind() || !scored.iter().any(|(_, _, s)| informative(s));
    let mut ranking = Vec::new();
    // per ranked candidate: its edited model and its equation-error score's
    // standing (informative; adds a column at all)
    let mut edited = Vec::new();
    for (rank, (c, m, score)) in scored.into_iter().enumerate() {
        let standing = (informative(&score), score.columns > 0);
        ranking.push(Ranked {
            parameters: score
                .estimates
                .iter()
                .map(|e| Estimate {
                    name: e.name.clone(),
                    value: e.value,
                    std_error: e.std_error,
                    start: m.parameter(&e.name).map_or(f64::NAN, |p| p.value),
                    at_bound: false,
                    fixed: false,
                })
                .collect(),
            evidence: Evidence {
                rmse_before: baseline.after_cost,
                rmse_after: None,
                gain: None,
                residual_share: score.residual_share,
                bic_gain: score.bic_gain,
                equation_error_rank: rank + 1,
                acts_where: where_summary(&score),
                by_experiment: score.by_experiment,
                by_speed: score.by_speed,
            },
            candidate: c,
            fit: None,
            error: None,
            gain: 0.0,
            from_baseline: false,
        });
        edited.push((m, standing));
    }
    let floor = crate::weights::noise_cost(&baseline.weights);
    let above_floor = floor > 0.0 && baseline.after_cost >= FLOOR_BASELINE * floor;
    // At or below the noise floor what is left is noise: no effect could
    // be credited ([`NOTHING_LEFT`]), so no candidate effect is refitted
    // (a sensor offset hidden in the per-experiment offsets is still
    // looked for below: that is not residual). In the round after an
    // effect that reached the floor this was a third of a whole case's
    // time (demo_coulomb: three refits, 1.2 s of 5.9 s).
    let nothing_left = within_floor(baseline.after_cost, floor, NOTHING_LEFT);
    if nothing_left {
        notes.push(format!(
            "the baseline is at the noise floor ({:.2}x): no effect candidate refitted, an effect could only fit the noise (sensor offsets still checked)",
            baseline.after_cost / floor
        ));
    }
    if blind && above_floor {
        notes.push(
            "the equation-error ranking cannot discriminate (no candidate explains any of the torque residual): every candidate is screened by simulation error instead".to_string(),
        );
    }
    // Refit the leaders that explain anything at all (a candidate whose
    // columns the model's own parameters already span, e.g. viscous
    // friction where a damping is estimated, adds nothing); all candidates
    // are eligible when the ranking is blind.
    // each refit starts warm from the baseline; a second start from the
    // nominal values follows while nothing has settled the diagnosis
    let refit_at = |ranking: &mut [Ranked], idx: usize| {
        refit(
            &mut ranking[idx],
            &edited[idx].0,
            &model,
            &baseline,
            experiments,
            opts,
        );
    };
    // (each candidate's second start once)
    let second_started = std::cell::RefCell::new(Vec::new());
    // A second start is from the model's nominal values: when the whole
    // records replayed from there leave the data (the QUBE balanced in
    // closed loop: a weighted RMS of 600 against the baseline's 0.09), a
    // fit from there on the whole records wanders to the bounds of the box
    // (13 second starts of 1-8.5 s each, 38 s of the diagnosis' 50, every
    // one 30-6000x above the baseline). Not on segments, which do not
    // replay the whole records. Checked once, when the first is due.
    let nominal_follows = std::cell::OnceCell::new();
    let may_restart = || {
        baseline.segments.is_some()
            || *nominal_follows.get_or_init(|| {
                let nominal = FitOptions {
                    start: None,
                    ..opts.fit.clone()
                };
                replay_follows(&model, experiments, &nominal).unwrap_or(true)
            })
    };
    // a candidate that passes by more than a partial gain: the verdict
    // gain, or to the floor
    let passes_clearly = |r: &Ranked| {
        passes(r, baseline.after_cost, floor, opts)
            && (r.gain >= opts.min_gain || refit_within(r, floor, FLOOR_REACHED))
    };
    // (`partial_counts`: whether a candidate that passes by a partial gain
    // only, [`PARTIAL_GAIN`] far above the floor, ends the struggle)
    let second_start_at = |ranking: &mut [Ranked], idx: usize, partial_counts: bool| {
        if !settled(ranking, floor) && !second_started.borrow().contains(&idx) && may_restart() {
            second_started.borrow_mut().push(idx);
            // far above the floor with nothing explaining it yet, the
            // baseline itself is suspect: every refitted candidate gets its
            // start from the nominal values
            let explains = |r: &Ranked| {
                if partial_counts {
                    passes(r, baseline.after_cost, floor, opts)
                } else {
                    passes_clearly(r)
                }
            };
            let struggling = floor > 0.0
                && baseline.after_cost >= PARTIAL_BASELINE * floor
                && !ranking.iter().any(explains);
            second_start(
                &mut ranking[idx],
                &edited[idx].0,
                &baseline,
                struggling,
                experiments,
                opts,
            );
        }
    };
    let second_at = |ranking: &mut [Ranked], idx: usize| second_start_at(ranking, idx, true);
    // Near the floor ([`FLOOR_REACHED`]) a candidate can pass only by
    // [`PARTIAL_GAIN`] down to 0.83x the floor estimate or below, which
    // the true model seldom reaches on moving records: only the
    // equation-error leader is refitted there (cogging on the arm, the
    // right model at 1.17x: a second round of three refits, 1.2 s, none
    // passing)
    let near_floor = within_floor(baseline.after_cost, floor, FLOOR_REACHED);
    let mut leaders: Vec<usize> = (0..ranking.len())
        .filter(|&i| !nothing_left && (blind || edited[i].1 .0))
        .take(if near_floor { 1 } else { opts.refit })
        .collect();
    // An inertia's equation-error column is the measured acceleration,
    // whose noise is also in the torque residual (errors in variables): its
    // score is inflated by that noise (demo_coulomb: added inertia first
    // by BIC, 1277 against the Coulomb friction's 909, 1.07x refitted). It
    // is refitted after the leaders whose columns do not share the
    // residual's noise.
    leaders.sort_by_key(|&i| ranking[i].candidate.line() == "inertia");
    // The leaders are refitted in that order until one explains the
    // residual: down to the noise floor estimate itself ([`EXPLAINED`]),
    // or, when no leader still to refit contains it ([`NESTED`]), to
    // [`NOTHING_LEFT`] or by a decisive gain ([`DECISIVE_GAIN`]) at the floor
    // ([`FLOOR_REACHED`]). Past it
    // another could only win by fitting noise, or by explaining the same
    // residual better than a decisive effect does (a second effect is the
    // next round's). A nested effect over it would have to beat it by
    // [`NESTED_GAIN`]: from the estimate itself, below what the true model
    // reaches on encoder data (0.82x and 0.86x on the demos); from 1.1x
    // only to 0.88x, which it can, so it is refitted first.
    // demo_coulomb: the Stribeck friction and the added inertia not
    // refitted after the Coulomb friction reached 0.86x, 30 % of the
    // case's time; a spring on the arm (1.03x) or an input delay (1.06x):
    // two leaders, a third of the case; cogging on the arm (30.5x, 1.17x
    // the floor): a drag and a spring.
    // (Far above the floor a decisive gain can be a stand-in's: viscous
    // friction for a drag.)
    // (the refitted one that explains it and its cost over the floor)
    let mut explained_by: Option<(String, f64)> = None;
    let mut from_coulomb_done: Vec<(usize, f64)> = Vec::new();
    for &idx in &leaders {
        explained_by = ranking
            .iter()
            .find(|r| {
                let decisive = r.gain >= DECISIVE_GAIN && refit_within(r, floor, FLOOR_REACHED);
                passes(r, baseline.after_cost, floor, opts)
                    && (refit_within(r, floor, EXPLAINED)
                        || ((refit_within(r, floor, NOTHING_LEFT) || decisive)
                            && !nested_pending(r, &ranking, &leaders, true)))
            })
            .map(|r| {
                let cost = r.fit.as_ref().map_or(f64::NAN, |f| f.after_cost);
                (r.candidate.label(), cost / floor)
            });
        if explained_by.is_some() {
            break;
        }
        refit_at(&mut ranking, idx);
        // a leader that shows some of the effect, but less than a clear
        // gain, may be trapped where the baseline put it: its second start
        // now, so that the loop can stop on it (a 0.4 V deadzone: 2.9x from
        // the baseline, the floor from the nominal values; the drag and the
        // inertia after it not refitted). Not a Stribeck friction while the
        // Coulomb friction on its target is a leader still to refit: its
        // refit from the Coulomb fit below is its cheaper second chance (6
        // iterations against 24).
        let partial = (SECOND_START_GAIN..opts.min_gain).contains(&ranking[idx].gain);
        if partial && !nested_pending(&ranking[idx], &ranking, &leaders, false) {
            second_at(&mut ranking, idx);
        }
        // a Coulomb friction that passes above the floor: the Stribeck
        // friction on its target from its fit now, once that one's own
        // refit (when a leader) is done, so that the loop can stop on it
        // (the Stribeck case of the benchmark's settings: the second start
        // from the nominal values, 29 iterations, and the added inertia's
        // refit not needed)
        let pending: Vec<usize> = leaders
            .iter()
            .copied()
            .filter(|&j| ranking[j].fit.is_none() && ranking[j].error.is_none())
            .collect();
        stribecks_from_coulombs(
            &mut ranking,
            &edited,
            &mut from_coulomb_done,
            |i| !pending.contains(&i),
            (baseline.after_cost, floor),
            experiments,
            opts,
        );
    }
    // A refit that rejected its effect from the baseline (no gain worth a
    // second start, its parameters not significant: a drag or an inertia
    // refitted to zero, a saturation at its bound) gets its second start
    // after the other candidates' refits from the baseline, and only if
    // none of those explains the residual or it is the equation-error
    // leader (a 0.3 V input offset, fourth by equation error behind a
    // saturation, an inertia and a deadzone each refitted to nothing: three
    // second starts of 0.8 s each, before the input offset's refit reached
    // the floor)
    let second_or_defer = |ranking: &mut [Ranked], idx: usize, deferred: &mut Vec<usize>| {
        let r = &ranking[idx];
        if r.fit.is_some() && r.gain < SECOND_START_GAIN && !significant(r) {
            deferred.push(idx);
        } else {
            second_at(ranking, idx);
        }
    };
    let mut deferred = Vec::new();
    for &idx in &leaders {
        second_or_defer(&mut ranking, idx, &mut deferred);
    }
    // When none of them explains the residual and the residual sits well
    // above the noise floor, the equation-error ranking has missed (its
    // columns are linearised, its noise is that of q''), so screening goes
    // on down the list, every candidate that adds a column (a low or
    // negative BIC is no proof: at 100 Hz the q'' noise buries a Coulomb
    // friction the refit then finds), until one explains it: "adequate" is
    // never said far above the floor without trying every candidate.
    // (However few leaders were informative: at 100 Hz only two were, and
    // the Coulomb friction came after them.)
    if above_floor {
        let rest: Vec<usize> = (0..ranking.len())
            .filter(|&i| !leaders.contains(&i) && (blind || edited[i].1 .1))
            .collect();
        for (k, idx) in rest.into_iter().enumerate() {
            if ranking
                .iter()
                .any(|r| passes(r, baseline.after_cost, floor, opts))
            {
                break;
            }
            if k == 0 && !blind {
                notes.push(format!(
                    "none of the {} equation-error leaders explains the residual ({:.1}x the noise floor): the other candidates were refitted too",
                    leaders.len(),
                    baseline.after_cost / floor
                ));
            }
            refit_at(&mut ranking, idx);
            second_or_defer(&mut ranking, idx, &mut deferred);
        }
    }
    // (a candidate the later refits credited with a partial gain only does
    // not end the struggle that these were deferred in: the leaders' second
    // starts came before those refits)
    for idx in deferred {
        second_start_at(&mut ranking, idx, false);
    }
    // A speed force that passes by a partial gain only, while nothing
    // passes clearly, bends like the missing force over part of the
    // speeds only: the other speed forces on its target are refitted too,
    // whatever their equation-error rank, and started again from the
    // nominal values as struggling candidates (a Stribeck friction on the
    // arm over its gearbox friction: no admissible hump by equation error,
    // a quadratic drag credited with 1.69x and the next round 3.9x the
    // floor unexplained; the hump stalled at 1.17x from the baseline, from
    // the template ([`second_start`]) it reached the floor).
    if !ranking.iter().any(passes_clearly) {
        let partial_targets: Vec<String> = ranking
            .iter()
            .filter(|r| {
                SPEED_FORCES.contains(&r.candidate.effect.as_str())
                    && passes(r, baseline.after_cost, floor, opts)
            })
            .map(|r| r.candidate.target.clone())
            .collect();
        let others: Vec<usize> = (0..ranking.len())
            .filter(|&j| {
                let c = &ranking[j].candidate;
                ranking[j].fit.is_none()
                    && ranking[j].error.is_none()
                    && SPEED_FORCES.contains(&c.effect.as_str())
                    && partial_targets.contains(&c.target)
                    && edited[j].1 .1
            })
            .collect();
        for j in others {
            refit_at(&mut ranking, j);
            second_start_at(&mut ranking, j, false);
        }
    }
    // a candidate that explains the residual competes with the simpler
    // effect it contains (Stribeck friction with `Fs = Fc` is Coulomb
    // friction): that one is refitted too, so the per-parameter penalty can
    // prefer it
    for idx in 0..ranking.len() {
        if !passes(&ranking[idx], baseline.after_cost, floor, opts) {
            continue;
        }
        let c = ranking[idx].candidate.clone();
        for (outer, inner) in NESTED {
            if c.effect != *outer {
                continue;
            }
            // (not one the model's own parameters span: a Coulomb friction
            // on a joint whose dry friction the model already estimates)
            if let Some(j) = ranking
                .iter()
                .position(|r| {
                    r.candidate.effect == *inner
                        && r.candidate.target == c.target
                        && r.fit.is_none()
                })
                .filter(|&j| edited[j].1 .1)
            {
                refit_at(&mut ranking, j);
                second_at(&mut ranking, j);
            }
        }
    }
    // ...and the other way round (see [`stribecks_from_coulombs`]), for
    // the pairs the leaders' loop left
    stribecks_from_coulombs(
        &mut ranking,
        &edited,
        &mut from_coulomb_done,
        |_| true,
        (baseline.after_cost, floor),
        experiments,
        opts,
    );
    // ...and with the simpler forces on its target: a speed limit (two
    // parameters) or a Stribeck friction (three) bends like a quadratic
    // drag (one) over the speeds a record reaches, and the equation-error
    // order among them is noise (vocabulary drag on the arm: speed limit
    // 3.12x and Stribeck 2.91x refitted, the drag itself fourth and never
    // refitted); refitted, the per-parameter penalty decides
    // (not when a one-parameter force on that target passes already)
    // (forces of the target's speed only: a cogging torque or a spring,
    // functions of its position, bend like none of them; cogging at 30x
    // on the arm: a drag and a spring refitted for nothing, 1.5 s)
    let passing_force = |r: &Ranked| {
        SPEED_FORCES.contains(&r.candidate.effect.as_str())
            && passes(r, baseline.after_cost, floor, opts)
    };
    let winners: Vec<(String, usize)> = ranking
        .iter()
        .filter(|r| {
            passing_force(r)
                && r.candidate.parameters.len() > 1
                && !ranking.iter().any(|o| {
                    o.candidate.target == r.candidate.target
                        && o.candidate.parameters.len() == 1
                        && passing_force(o)
                })
        })
        .map(|r| (r.candidate.target.clone(), r.candidate.parameters.len()))
        .collect();
    for (target, size) in winners {
        let simpler: Vec<usize> = (0..ranking.len())
            .filter(|&j| {
                let c = &ranking[j].candidate;
                ranking[j].fit.is_none()
                    && SPEED_FORCES.contains(&c.effect.as_str())
                    && c.target == target
                    && c.parameters.len() < size
                    && edited[j].1 .1
            })
            .collect();
        for j in simpler {
            refit_at(&mut ranking, j);
        }
    }
    // a sensor offset is absorbed by the per-experiment offsets of the
    // baseline: judged against the baseline without them instead. Not
    // once a candidate explains the residual with those offsets free: a
    // sensor offset alone would have left the baseline at the floor (a
    // spring on the pendulum, its offsets agreeing without it: the
    // baseline without them and the sensor offset refitted, 0.8 s, after
    // the spring reached 0.85x)
    let explained = ranking.iter().any(|r| {
        passes(r, baseline.after_cost, floor, opts) && refit_within(r, floor, NOTHING_LEFT)
    });
    if !explained {
        sensor_offsets_from_nuisance(&mut ranking, text, &model, &baseline, experiments, opts);
    }
    // the leaders the loop skipped that no later step refitted either
    // (before decide(), which reorders the ranking)
    let not_refitted: Vec<String> = leaders
        .iter()
        .filter(|&&i| ranking[i].fit.is_none() && ranking[i].error.is_none())
        .map(|&i| ranking[i].candidate.label())
        .collect();
    let mut baseline = baseline;
    let verdict = decide(
        &mut ranking,
        &model,
        &mut baseline,
        floor,
        experiments,
        opts,
        &mut notes,
    );
    if nominal_follows.get() == Some(&false) {
        notes.push(
            "the whole records replayed from the nominal values leave the data: no candidate refitted again from there (second starts), only from the baseline".to_string(),
        );
    }
    if let Some((done, ratio)) = explained_by.filter(|_| !not_refitted.is_empty()) {
        notes.push(format!(
            "{done} explains the residual ({ratio:.2}x the noise floor estimate): the equation-error leader(s) {} not refitted",
            not_refitted.join(", ")
        ));
    }
    Ok(Diagnosis {
        baseline,
        ranking,
        verdict,
        floor,
        notes,
        partial_credit: opts.partial_credit,
        nothing_left,
    })
}

/// Does refitted candidate `r` explain the residual against a baseline
/// cost: [`MIN_GAIN`], or down to the noise floor from well above it, or
/// [`PARTIAL_GAIN`] far above it ([`PARTIAL_BASELINE`]) or down to it?
///
/// The last: a baseline less than [`FLOOR_BASELINE`] above the floor is
/// not "well above" it, yet an effect that takes it down to the floor by
/// [`PARTIAL_GAIN`] is no noise (rate survey, quadratic drag of 7e-4 on the
/// arm: baseline 1.80x the floor, the drag 1.92x down to 0.94x; on clean
/// data no candidate gained more than 1.1x).
fn passes(r: &Ranked, base_cost: f64, floor: f64, opts: &DiagnoseOptions) -> bool {
    r.fit.as_ref().is_some_and(|f| {
        let to_floor = reaches_floor(f.after_cost, floor);
        r.gain >= opts.min_gain
            || (to_floor && base_cost >= FLOOR_BASELINE * floor)
            || (opts.partial_credit
                && floor > 0.0
                && base_cost >= PARTIAL_BASELINE * floor
                && r.gain >= PARTIAL_GAIN)
            || (to_floor && r.gain >= PARTIAL_GAIN)
    })
}

/// Rank the refitted candidates and pick the verdict.
///
/// Refitted candidates that pass come first, then the others, each by cost
/// with a per-parameter penalty (the refit's cost; for a sensor offset,
/// judged against another baseline, the larger of its refit's cost and the
/// baseline's divided by its gain). The best
/// one that [`passes`] is then checked against the *best* baseline: the
/// model without the effect is refitted from the candidate's values of the
/// model's own parameters. A refit restarted from other nominal values can
/// land in a better minimum that the effect has no part in (a spring of
/// 1e-95 N m/rad credited with 3.9x); if the model without the effect gets
/// there too, the gain was the restart's, not the effect's, and the
/// baseline is replaced by the better fit. Not for a candidate refitted
/// from the baseline's own values whose effect is [`significant`]: no
/// restart is in its gain.
fn decide(
    ranking: &mut [Ranked],
    model: &Model,
    baseline: &mut FitResult,
    floor: f64,
    experiments: &[Experiment],
    opts: &DiagnoseOptions,
    notes: &mut Vec<String>,
) -> Option<Candidate> {
    let mut checked: Vec<String> = Vec::new();
    loop {
        let base_cost = baseline.after_cost;
        // a sensor offset's gain is measured against the baseline without
        // per-experiment offsets; its own refit cost still counts when
        // worse (rate survey, a spring of 3.5e-3 N m/rad on the pendulum:
        // the offset "gained" 9.57x against that baseline but its refit sat
        // 10x above the spring's, which reached the floor)
        let penalised = |r: &Ranked| match &r.fit {
            Some(f) => {
                let cost = if r.gain > 0.0 {
                    f.after_cost.max(base_cost / r.gain)
                } else {
                    f.after_cost
                };
                cost / (1.0 - opts.per_parameter_gain).powi(r.candidate.parameters.len() as i32)
            }
            None => f64::INFINITY,
        };
        // the candidates that pass first: a sensor offset ranked by its own
        // cost can sort below one that explains nothing
        let fails = |r: &Ranked| !passes(r, base_cost, floor, opts);
        ranking.sort_by(|a, b| {
            fails(a)
                .cmp(&fails(b))
                .then(penalised(a).total_cmp(&penalised(b)))
                .then(
                    a.evidence
                        .equation_error_rank
                        .cmp(&b.evidence.equation_error_rank),
                )
        });
        prefer_nested(ranking, base_cost, floor, opts);
        let top = ranking.first()?;
        if !passes(top, base_cost, floor, opts) {
            return None;
        }
        let label = top.candidate.label();
        if checked.contains(&label) {
            return Some(top.candidate.clone());
        }
        checked.push(label.clone());
        let f = top.fit.as_ref().expect("passes implies refitted");
        // A refit from the baseline's own values whose effect is
        // significant owes its gain to the effect, not to a restart: the
        // model without it cannot do better than the baseline from there
        // but by the baseline's own unfinished descent (a spring on the
        // arm: 1.02x in 11 iterations, a sixth of the case's time)
        // (against the first baseline only: a replaced one is not where
        // the candidate started)
        if checked.len() == 1 && top.from_baseline && significant(top) {
            return Some(top.candidate.clone());
        }
        // the model without the effect, from the candidate's values
        let start = with_estimates(model, baseline.base.clone(), &f.parameters);
        let horizon = baseline.segments.map_or(Horizon::Whole, Horizon::Segments);
        let mut again_opts = screening(opts, start, horizon);
        again_opts.warm = Some(f.warm.clone());
        let Ok(again) = fit(model, experiments, &again_opts) else {
            return Some(top.candidate.clone());
        };
        if again.after_cost >= 0.999 * base_cost {
            return Some(top.candidate.clone());
        }
        notes.push(format!(
            "the model without {label}, refitted from that candidate's values, reaches a cost {:.3}x lower than the first baseline: the better baseline is kept and every gain is measured against it",
            base_cost / again.after_cost
        ));
        let ratio = again.after_cost / base_cost;
        for r in ranking.iter_mut().filter(|r| r.fit.is_some()) {
            r.gain *= ratio;
            r.evidence.gain = Some(r.gain);
            r.evidence.rmse_before *= ratio;
        }
        *baseline = again;
    }
}

/// Is every parameter of refitted candidate `r`'s effect estimated at least
/// [`SIGNIFICANT`] standard errors from zero (an effect the data tell from
/// its absence; a parameter at a bound or without a standard error is not)?
pub(crate) fn significant(r: &Ranked) -> bool {
    !r.parameters.is_empty()
        && r.parameters.iter().all(|e| {
            !e.at_bound
                && !e.fixed
                && e.std_error.is_finite()
                && e.value.abs() >= SIGNIFICANT * e.std_error
        })
}

/// Standard errors from zero for an effect's parameter to count as
/// [`significant`].
const SIGNIFICANT: f64 = 3.0;

/// The coordinates whose per-experiment offsets in `baseline` agree: every
/// experiment (at least two) estimated one, each significant (3 standard
/// errors), all of one sign, and their spread within a fifth of their mean
/// (plus 3 standard errors). Returns (coordinate, mean).
///
/// Files of a real rig each have their own encoder zero (the shared QUBE
/// episodes: -0.025 to +0.073 rad): those are nuisance, not physics. One
/// offset the files share is a property of the sensor: a `sensor_offset`.
pub fn consistent_offsets(model: &Model, baseline: &FitResult) -> Vec<(usize, f64)> {
    let mut out = Vec::new();
    if baseline.experiments.len() < 2 {
        return out;
    }
    for (i, c) in model.coordinates.iter().enumerate() {
        let name = format!("offset {}", c.name);
        let vals: Vec<(f64, f64)> = baseline
            .experiments
            .iter()
            .filter_map(|e| e.offsets.iter().find(|o| o.name == name && o.estimated))
            .map(|o| (o.value, o.std_error))
            .collect();
        if vals.len() != baseline.experiments.len()
            || vals
                .iter()
                .any(|&(v, s)| !v.is_finite() || !s.is_finite() || v.abs() < 3.0 * s)
        {
            continue;
        }
        let mean = vals.iter().map(|v| v.0).sum::<f64>() / vals.len() as f64;
        let same_sign = vals.iter().all(|v| v.0.signum() == mean.signum());
        let lo = vals.iter().map(|v| v.0).fold(f64::INFINITY, f64::min);
        let hi = vals.iter().map(|v| v.0).fold(f64::NEG_INFINITY, f64::max);
        let smax = vals.iter().map(|v| v.1).fold(0.0, f64::max);
        if same_sign && hi - lo <= 0.2 * mean.abs() + 3.0 * smax {
            out.push((i, mean));
        }
    }
    out
}

/// For each coordinate whose per-experiment offsets agree
/// ([`consistent_offsets`]), its `sensor_offset` candidate is judged against
/// the baseline refitted without per-experiment offsets on that coordinate
/// (the candidate's own refit has none there either: the model's offset
/// replaces them), so its gain says what one shared offset explains.
fn sensor_offsets_from_nuisance(
    ranking: &mut [Ranked],
    text: &str,
    model: &Model,
    baseline: &FitResult,
    experiments: &[Experiment],
    opts: &DiagnoseOptions,
) {
    if matches!(opts.fit.offsets, Offsets::None) {
        return;
    }
    let estimated_on: Vec<String> = baseline
        .experiments
        .first()
        .map(|e| {
            e.offsets
                .iter()
                .filter(|o| o.estimated)
                .filter_map(|o| o.name.strip_prefix("offset ").map(str::to_string))
                .collect()
        })
        .unwrap_or_default();
    let horizon = baseline.segments.map_or(Horizon::Whole, Horizon::Segments);
    for (i, mean) in consistent_offsets(model, baseline) {
        let coord = &model.coordinates[i].name;
        let Some(r) = ranking
            .iter_mut()
            .find(|r| r.candidate.kind == EffectKind::Sensor && &r.candidate.target == coord)
        else {
            continue;
        };
        // the baseline without per-experiment offsets on this coordinate
        let others: Vec<String> = estimated_on
            .iter()
            .filter(|c| *c != coord)
            .cloned()
            .collect();
        let without = FitOptions {
            offsets: Offsets::On(others),
            ..screening(opts, baseline.base.clone(), horizon)
        };
        let Ok(a) = fit(model, experiments, &without) else {
            continue;
        };
        // the candidate (its refit has no per-experiment offset there),
        // started at the offsets' mean
        let b = match r.fit.clone() {
            Some(f) => f,
            None => {
                let Ok(edited) = r.candidate.apply(text) else {
                    continue;
                };
                let Ok(m) = model_from_text(&r.candidate.label(), &edited) else {
                    continue;
                };
                for e in r.parameters.iter_mut().take(1) {
                    e.value = mean;
                }
                match refit_from(
                    &r.parameters,
                    &m,
                    horizon,
                    Some((model, baseline)),
                    true,
                    experiments,
                    opts,
                ) {
                    Ok(f) => f,
                    Err(_) => continue,
                }
            }
        };
        r.evidence.rmse_before = a.after_cost;
        r.evidence.acts_where = format!(
            "the per-experiment offsets of {coord} agree (mean {mean:.4e}): one sensor offset; {}",
            r.evidence.acts_where
        );
        credit(r, b, a.after_cost, false);
    }
}

/// Record candidate `r`'s refit `f`, judged against a baseline cost.
fn credit(r: &mut Ranked, f: FitResult, baseline_cost: f64, from_baseline: bool) {
    let gain = baseline_cost / f.after_cost.max(f64::MIN_POSITIVE);
    r.gain = gain;
    r.from_baseline = from_baseline;
    r.evidence.rmse_after = Some(f.after_cost);
    r.evidence.gain = Some(gain);
    r.parameters = f
        .parameters
        .iter()
        .filter(|e| r.candidate.parameters.iter().any(|p| p.name == e.name))
        .cloned()
        .collect();
    r.fit = Some(f);
    r.error = None;
}

/// Where [`stribeck_from_coulomb`] starts the Stribeck velocity: fractions
/// of the fastest the target moves in the Coulomb fit, tried in this order.
/// On the rate survey's Stribeck pendulum (vs = 0.1 rad/s, top speed about
/// 5.5 rad/s) starts at 0.03 and 0.1 reach the truth from the Coulomb fit,
/// 0.3 and 1 stall where the refit from the baseline did (Fs < Fc, the
/// hump 0.02 rad/s wide: the Coulomb friction again). The second start only
/// when the first found a hump (`Fs > Fc`) that does not beat the Coulomb
/// friction enough: each is a whole refit (7 s on the DFKI records).
const STRIBECK_VS_STARTS: [f64; 2] = [1.0 / 50.0, 1.0 / 200.0];

/// Refit Stribeck candidate `r` (model `m`) from the fit of the Coulomb
/// friction on its target (`coulomb`: that model, its fit and gain): the
/// model's parameters and the nuisance where the Coulomb fit left them,
/// `Fc` at 0.8 and `Fs` at 2 times its level, `vs` at
/// [`STRIBECK_VS_STARTS`] of the target's top speed, until one beats the
/// Coulomb friction by [`NESTED_GAIN`]; the best refit is credited when it
/// beats the one `r` has.
fn stribeck_from_coulomb(
    r: &mut Ranked,
    m: &Model,
    (coulomb_model, coulomb, coulomb_gain, coulomb_from_baseline): (&Model, &FitResult, f64, bool),
    baseline_cost: f64,
    experiments: &[Experiment],
    opts: &DiagnoseOptions,
) {
    let target = r.candidate.target.clone();
    if r.gain >= NESTED_GAIN * coulomb_gain {
        return;
    }
    let Some(ci) = coulomb_model
        .coordinates
        .iter()
        .position(|c| c.name == target)
    else {
        return;
    };
    let index = |m: &Model, base: &str| {
        let name = r.candidate.parameter_name(base)?;
        m.parameters.iter().position(|p| p.name == name)
    };
    // the Coulomb friction's level (its `Fc` is named as the Stribeck's)
    let Some(fc) = index(coulomb_model, "Fc")
        .map(|k| coulomb.base[k])
        .filter(|v| *v > 0.0)
    else {
        return;
    };
    // the fastest the target moves in the Coulomb fit's (noise-free) simulation
    let top = coulomb
        .simulated
        .iter()
        .zip(experiments)
        .filter_map(|(sim, e)| Some((sim.get(ci)?, &e.t)))
        .flat_map(|(q, t)| {
            (1..q.len().min(t.len())).map(move |k| ((q[k] - q[k - 1]) / (t[k] - t[k - 1])).abs())
        })
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    if top <= 0.0 {
        return;
    }
    let start = values_from(m, (coulomb_model, &coulomb.base));
    let (Some(i_fc), Some(i_fs), Some(i_vs)) = (index(m, "Fc"), index(m, "Fs"), index(m, "vs"))
    else {
        return;
    };
    let horizon = coulomb.segments.map_or(Horizon::Whole, Horizon::Segments);
    let mut best: Option<FitResult> = None;
    for fraction in STRIBECK_VS_STARTS {
        let mut s = start.clone();
        s[i_fc] = 0.8 * fc;
        s[i_fs] = 2.0 * fc;
        s[i_vs] = (fraction * top).clamp(
            m.parameters[i_vs].estimate.map_or(0.0, |b| b.0),
            m.parameters[i_vs].estimate.map_or(f64::INFINITY, |b| b.1),
        );
        let mut fo = screening(opts, s, horizon);
        fo.warm = Some(coulomb.warm.clone());
        let Ok(f) = fit(m, experiments, &fo) else {
            continue;
        };
        // done when it beats the Coulomb friction, or when the data want no
        // hump at all from there (Fs down to Fc)
        let hump = f.base[i_fs] > f.base[i_fc];
        let done = !hump
            || baseline_cost / f.after_cost.max(f64::MIN_POSITIVE) >= NESTED_GAIN * coulomb_gain;
        if best.as_ref().is_none_or(|b| f.after_cost < b.after_cost) {
            best = Some(f);
        }
        if done {
            break;
        }
    }
    if let Some(f) = best {
        if r.fit.as_ref().is_none_or(|g| f.after_cost < g.after_cost) {
            // a restart only if the Coulomb fit was one
            credit(r, f, baseline_cost, coulomb_from_baseline);
        }
    }
}

/// A Stribeck friction refitted from the baseline can stall in the
/// Coulomb-like minimum: for each Coulomb friction that passes but stays
/// above the floor, the Stribeck friction on its target is refitted again
/// from the Coulomb fit ([`stribeck_from_coulomb`]), when `ready` says the
/// Stribeck friction (its index) may be: once per pair, and again when a
/// later refit of the Coulomb friction (its second start) did better
/// (`done`: the Coulomb frictions' indices and the costs refitted from).
fn stribecks_from_coulombs(
    ranking: &mut [Ranked],
    edited: &[(Model, (bool, bool))],
    done: &mut Vec<(usize, f64)>,
    ready: impl Fn(usize) -> bool,
    (base_cost, floor): (f64, f64),
    experiments: &[Experiment],
    opts: &DiagnoseOptions,
) {
    for j in 0..ranking.len() {
        let inner = &ranking[j];
        let Some(inner_fit) = &inner.fit else {
            continue;
        };
        let from = inner_fit.after_cost;
        if done
            .iter()
            .any(|&(k, cost)| k == j && from * SAME_MINIMUM >= cost)
            || inner.candidate.effect != "coulomb_friction"
            || !passes(inner, base_cost, floor, opts)
            || reaches_floor(from, floor)
        {
            continue;
        }
        let Some(i) = ranking.iter().position(|r| {
            r.candidate.effect == "stribeck_friction"
                && r.candidate.target == inner.candidate.target
        }) else {
            continue;
        };
        if !ready(i) {
            continue;
        }
        done.retain(|&(k, _)| k != j);
        done.push((j, from));
        let inner_fit = inner_fit.clone();
        let inner_gain = inner.gain;
        let inner_from_baseline = inner.from_baseline;
        stribeck_from_coulomb(
            &mut ranking[i],
            &edited[i].0,
            (&edited[j].0, &inner_fit, inner_gain, inner_from_baseline),
            base_cost,
            experiments,
            opts,
        );
    }
}

/// The force effects that are functions of their target's speed (the
/// family whose simpler members are refitted against a winner with more
/// parameters).
const SPEED_FORCES: &[&str] = &[
    "viscous_friction",
    "coulomb_friction",
    "quadratic_drag",
    "stribeck_friction",
    "speed_limit",
];

/// (effect, the simpler effect it contains on the same target).
pub(crate) const NESTED: &[(&str, &str)] = &[("stribeck_friction", "coulomb_friction")];

/// How much lower the cost of an effect has to be than that of the simpler
/// effect it contains ([`NESTED`]) for the bigger one to be preferred.
/// Measured on Coulomb-only data (tests/diagnose_robust.rs, Furuta case):
/// Stribeck 9.59x against Coulomb 8.65x (1.11), the extra `Fs`, `vs` fitting
/// the smoothed stick-slip transition; on the vocabulary's Stribeck case the
/// two differ by far more.
pub const NESTED_GAIN: f64 = 1.25;

/// Move the simpler effect to the top when the top one contains it and
/// does not beat it by [`NESTED_GAIN`].
fn prefer_nested(ranking: &mut [Ranked], base_cost: f64, floor: f64, opts: &DiagnoseOptions) {
    let Some(top) = ranking.first() else {
        return;
    };
    for (outer, inner) in NESTED {
        if top.candidate.effect != *outer {
            continue;
        }
        let Some(j) = ranking.iter().position(|r| {
            r.candidate.effect == *inner
                && r.candidate.target == top.candidate.target
                && passes(r, base_cost, floor, opts)
        }) else {
            continue;
        };
        if ranking[0].gain < NESTED_GAIN * ranking[j].gain {
            ranking[..=j].rotate_right(1);
            return;
        }
    }
}

/// A warm refit whose cost ends above the baseline's by more than this
/// factor is trapped (the candidate contains the baseline, so it can do at
/// least as well); one that ends level with it just found nothing.
pub const TRAPPED: f64 = 1.01;

/// A screening refit stops when a step lowers the SSR by less than this
/// fraction: it is compared with others by ratios of costs (1.25x at the
/// least), to which a change of 0.02 % is noise. Not looser: a slow descent
/// can still be going somewhere (the vocabulary's Stribeck friction on the
/// arm, refitted from nominal values, stopped at 2.05x with 1e-3 and went
/// on to 53x with 2e-4).
pub const SCREENING_TOLERANCE: f64 = 2e-4;

/// A refit gain from which a candidate shows some of the effect: worth a
/// second start from the nominal values ([`second_start`]), for a leader
/// at once.
const SECOND_START_GAIN: f64 = 1.2;

/// A second start is credited when its cost is lower than the first
/// refit's by more than this factor; within it, both found the same minimum.
const SAME_MINIMUM: f64 = 1.001;

/// A refit gain above which a second start is not tried.
const DECISIVE_GAIN: f64 = 30.0;

/// Refit one candidate's model from the baseline (its estimates, its
/// nuisance as a warm start) and the equation-error estimates of the
/// candidate's own parameters; if that fails (a baseline distorted by the
/// missing effect can make the edited model diverge), from the model's
/// nominal values instead.
fn refit(
    r: &mut Ranked,
    m: &Model,
    model: &Model,
    baseline: &FitResult,
    experiments: &[Experiment],
    opts: &DiagnoseOptions,
) {
    // the candidate is judged on the baseline's terms: the same horizon
    let horizon = baseline.segments.map_or(Horizon::Whole, Horizon::Segments);
    let base = Some((model, baseline));
    let mut outcome = refit_from(&r.parameters, m, horizon, base, true, experiments, opts);
    // The candidate's model contains the baseline's (the effect at zero),
    // so a refit that ends above the baseline's cost ([`TRAPPED`]) is trapped where the
    // warm start put it (the vocabulary's deadzone: 0.80x): again from the
    // same values with the growing horizons, and the better kept.
    // (Not on segments: there is no growing horizon to take, only the
    // nuisance's start would differ, at the price of a whole segment fit;
    // on the balanced pendulum under an unlogged disturbance, when segment
    // fits took no warm start, these repeats were half of the 143 s.)
    let trapped = baseline.segments.is_none()
        && outcome
            .as_ref()
            .map_or(true, |f| f.after_cost > TRAPPED * baseline.after_cost);
    if trapped {
        let cold = refit_from(&r.parameters, m, horizon, base, false, experiments, opts);
        outcome = match (outcome, cold) {
            (Ok(a), Ok(b)) => Ok(if b.after_cost < a.after_cost { b } else { a }),
            (Ok(a), Err(_)) => Ok(a),
            (Err(_), cold) => cold,
        };
    }
    let outcome = outcome.map(|f| (f, true)).or_else(|_| {
        refit_from(&r.parameters, m, horizon, None, false, experiments, opts).map(|f| (f, false))
    });
    match outcome {
        Ok((f, from_baseline)) => credit(r, f, baseline.after_cost, from_baseline),
        Err(e) => r.error = Some(e.to_string()),
    }
}

/// A baseline distorted by the missing effect can trap the refit from it in
/// a local minimum (shared spring_arm case: 5.2x from the baseline, 438x
/// from the nominal values): refit candidate `r` again from the model's
/// nominal values, with the growing horizons, and keep the better. Worth it
/// for the equation-error leader and for a candidate that already shows
/// some gain; one that does nothing from the baseline is not worth a second
/// fit (this keeps clean data cheap), nor one that already gained
/// decisively. Except when `struggling` (the baseline far above the noise
/// floor and no candidate explaining it yet): then the baseline is as
/// suspect as the candidates' starts from it (rate survey, a 0.56 V
/// deadzone on a 1.2 V rms drive: 1.14x from the baseline, the truth
/// and the floor from the nominal values).
fn second_start(
    r: &mut Ranked,
    m: &Model,
    baseline: &FitResult,
    struggling: bool,
    experiments: &[Experiment],
    opts: &DiagnoseOptions,
) {
    let Some(first) = &r.fit else {
        return;
    };
    let gain = baseline.after_cost / first.after_cost.max(f64::MIN_POSITIVE);
    let worth_it = r.evidence.equation_error_rank == 1 || gain >= SECOND_START_GAIN || struggling;
    if !worth_it || gain >= DECISIVE_GAIN {
        return;
    }
    let horizon = baseline.segments.map_or(Horizon::Whole, Horizon::Segments);
    // A candidate the equation error could not estimate (a scan with no
    // admissible value) starts its own parameters from the template, not
    // where its first refit stalled (a Stribeck hump on the arm over its
    // gearbox friction: 1.28x from the stalled hump, the floor from the
    // template's)
    // (an empty equation-error score explains nothing at all)
    let unscored = r.evidence.bic_gain == 0.0 && r.evidence.residual_share == 0.0;
    let estimates: &[Estimate] = if unscored { &[] } else { &r.parameters };
    if let Ok(f) = refit_from(estimates, m, horizon, None, false, experiments, opts) {
        // (the same minimum found again is the first refit's, from the
        // baseline)
        if f.after_cost * SAME_MINIMUM < first.after_cost {
            credit(r, f, baseline.after_cost, false);
        }
    }
}

/// A refitted candidate at or below this factor of the noise floor
/// estimate explains the residual: the diagnosis refits no further leader.
/// The estimate itself, stricter than [`NOTHING_LEFT`]: a nested effect
/// over it must then beat it by [`NESTED_GAIN`] to 0.8x the estimate to
/// win, which the true model does not reach even on the demos' resting
/// channels (0.82x, 0.86x). (At [`NOTHING_LEFT`] the loop stops too when
/// no leader still to refit contains the candidate.)
pub const EXPLAINED: f64 = 1.0;

/// Did candidate `r`'s refit end at most `factor` times the noise floor
/// `floor` ([`within_floor`]; never when not refitted)?
fn refit_within(r: &Ranked, floor: f64, factor: f64) -> bool {
    r.fit
        .as_ref()
        .is_some_and(|f| within_floor(f.after_cost, floor, factor))
}

/// Is a leader nested with candidate `r` ([`NESTED`], on its target)
/// still to be refitted: one that contains `r` (`containing`: a Stribeck
/// friction over the Coulomb friction `r`), or one that `r` contains (the
/// Coulomb friction under the Stribeck friction `r`)?
fn nested_pending(r: &Ranked, ranking: &[Ranked], leaders: &[usize], containing: bool) -> bool {
    leaders.iter().any(|&j| {
        let o = &ranking[j];
        let (outer, inner) = if containing { (o, r) } else { (r, o) };
        o.fit.is_none()
            && o.error.is_none()
            && o.candidate.target == r.candidate.target
            && NESTED
                .iter()
                .any(|(a, b)| outer.candidate.effect == *a && inner.candidate.effect == *b)
    })
}

/// Is the diagnosis settled by the refits so far: a candidate that gained
/// decisively ([`DECISIVE_GAIN`]) or explains the residual down to the
/// noise floor? Then second starts cannot change the verdict.
fn settled(ranking: &[Ranked], floor: f64) -> bool {
    ranking.iter().any(|r| {
        r.fit.is_some() && (r.gain >= DECISIVE_GAIN || refit_within(r, floor, FLOOR_REACHED))
    })
}

/// Refit candidate `r`'s model `m` from the baseline's values (`from`) or
/// the nominal ones, with the candidate's equation-error estimates; `warm`
/// starts the nuisance where the baseline's ended and goes straight to its
/// horizon (see [`FitOptions::warm`]).
fn refit_from(
    estimates: &[Estimate],
    m: &Model,
    horizon: Horizon,
    from: Option<(&Model, &FitResult)>,
    warm: bool,
    experiments: &[Experiment],
    opts: &DiagnoseOptions,
) -> Result<FitResult, FitError> {
    let mut start = match from {
        Some((model, baseline)) => values_from(m, (model, &baseline.base)),
        None => m.parameters.iter().map(|p| p.value).collect(),
    };
    // a baseline at the noise floor leaves an effect nothing to explain:
    // its linearised estimates fit noise and can start far above the
    // baseline (a spring on the arm in the round after the Coulomb
    // friction: 9x, 18 iterations back down), so the refit may start from
    // the effect at its template start, next to the baseline itself, when
    // that fits better. Not above the floor: there a start worse than the
    // baseline still leads to the effect where the baseline's own minimum
    // traps it (rate survey: saturation 2/5, cogging 3/5 when allowed).
    let at_floor = from
        .is_some_and(|(_, b)| reaches_floor(b.after_cost, crate::weights::noise_cost(&b.weights)));
    let alternative = at_floor.then(|| start.clone());
    for e in estimates {
        if let Some(j) = m.parameters.iter().position(|q| q.name == e.name) {
            if let Some((lo, hi)) = m.parameters[j].estimate {
                // a linearised estimate well inside the box is a better start
                if e.value.is_finite() && e.value > lo && e.value < hi {
                    start[j] = e.value;
                }
            }
        }
    }
    let mut fo = screening(opts, start, horizon);
    fo.warm = from.filter(|_| warm).map(|(_, b)| b.warm.clone());
    fo.alternative_start = alternative;
    fit(m, experiments, &fo)
}

/// The fit options of a screening refit: every `estimate` parameter free
/// from `start`, no extra starts, no refit without undetermined parameters
/// (the story's final fit does both).
fn screening(opts: &DiagnoseOptions, start: Vec<f64>, horizon: Horizon) -> FitOptions {
    FitOptions {
        free: None,
        start: Some(start),
        horizon,
        multistart: 0,
        act_on_identifiability: false,
        tolerance: SCREENING_TOLERANCE,
        warm: None,
        alternative_start: None,
        simulate_start: false,
        ..opts.fit.clone()
    }
}
