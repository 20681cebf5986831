//! Which missing effect explains the data?
//!
//! 1. **Baseline**: the model as written is fitted by simulation error
//!    ([`fit`]).
//! 2. **Equation-error ranking** ([`EquationError`]): every candidate (an
//!    effect of the effect table on one target, see [`candidates`]) is scored
//!    by the BIC gain of its regressor columns on the equations' torque
//!    residuals, with the nominal estimated parameters as nuisance columns.
//!    Fast (no simulation), but it cannot tell Coulomb from Stribeck friction
//!    (identification notes, trap 6) and its columns are linearised: it only
//!    orders the search.
//! 3. **Search**: the leading [`DiagnoseOptions::refit`] candidates are
//!    added to the model text losslessly and refitted by simulation error
//!    with the nominal estimated parameters free too (a missing effect
//!    distorts the nominal fit, trap 5), warm from the baseline. A leader
//!    that passes above the floor is started again from the model's
//!    nominal values before the rest are screened. While no
//!    candidate passes, the leaders are started again from the model's
//!    nominal values (a baseline distorted by the missing effect can trap
//!    a refit from it) and the screening goes on down the whole list: an
//!    unexplained residual is never declared without trying every
//!    candidate. A candidate that passes with its residual at the floor
//!    ends the search (nothing is left for another to explain) once the
//!    simpler effect it contains, if any, is refitted too.
//! 4. **Decision**: one rule ([`crate::decision`]): the candidate's fit
//!    against the baseline by the information criterion with the
//!    residual's effective sample count, and its contribution to the
//!    outputs against the noise floor. Among those that pass, the largest
//!    margin wins; a bigger effect over the simpler one it contains must
//!    pass the same rule against it. A winner refitted from other start
//!    values than the baseline's is checked against the model without it
//!    refitted from the winner's values: a gain that was the restart's
//!    replaces the baseline, and every test is judged again.
//!
//! With the baseline at the floor ([`crate::decision::at_floor`]) no
//! candidate can pass the size test, so none is refitted; a sensor offset
//! hidden in per-file offsets that agree is still looked for (that is not
//! in the residual). The verdict is the named effect, or *adequate* (at
//! the floor, no nuisance at the edge of what the data allow), or an
//! *unexplained* residual.
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
use crate::decision::{
    at_floor, effective_samples, noise_residuals, worst_channel, Contribution, EffectTest,
};
use crate::effect_edit::{all_candidates, EffectEditError, EffectInstance, EffectKind, Reach};
use crate::equation_error::{
    EquationError, EquationErrorError, EquationErrorOptions, Regressor, Score, Share,
};
use crate::experiment_sim::{DryFriction, Signals};
use crate::fit::{
    fit, measured_of, replay_follows, residual_count, simulate_as, simulation_error, values_from,
    with_estimates, Estimate, FitError, FitOptions, FitResult, GiveUp, Horizon, NuisanceFlag,
    Offsets,
};
use crate::friction_law::{creeping_law, CreepingLaw};
use crate::savitzky_golay;
use crate::speculate::Step;

/// The records' inputs read as continuous signals by a diagnosis
/// ([`Diagnosis::continuous_inputs`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ContinuousInputs {
    /// The baseline's weighted RMS with the inputs held as recorded.
    pub held: f64,
    /// The baseline's weighted RMS with them continuous.
    pub continuous: f64,
    /// Why, in words: the reading's margin under the decision rule, with
    /// the effect it was taken with, against the effect named held.
    pub why: String,
}

/// Options of [`diagnose_with`].
#[derive(Clone, Debug, PartialEq)]
pub struct DiagnoseOptions {
    /// Options of the baseline fit and of the refits (`free` and `start` are
    /// set per refit: the candidate's model is fitted with all its
    /// `estimate` parameters).
    pub fit: FitOptions,
    /// Options of the equation-error ranking.
    pub equation_error: EquationErrorOptions,
    /// How many leaders of the equation-error ranking are refitted before
    /// the search widens.
    pub refit: usize,
    /// How the records' inputs act between samples is settled (held or
    /// continuous, by the user or an earlier round): the continuous reading
    /// ([`Diagnosis::continuous_inputs`]) is not tried.
    pub inputs_read: bool,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            fit: FitOptions::default(),
            equation_error: EquationErrorOptions::default(),
            refit: 3,
            inputs_read: false,
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
    /// Unweighted RMSE of the baseline fit (SI, all coordinates and
    /// experiments).
    pub rmse_before: f64,
    /// Unweighted RMSE after the refit with the effect added (None: not
    /// refitted or the refit failed).
    pub rmse_after: Option<f64>,
    /// Share of the equation-error residual variance (after re-adjusting the
    /// nominal parameters) the candidate explains, 0..1.
    pub residual_share: f64,
    /// Equation-error BIC gain `N ln(RSS0/RSS1) - k ln N` (orders the
    /// search; the time correlation of the residual inflates it, so it does
    /// not decide).
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
    /// The weighted RMS ratio, baseline over refit (the decision's
    /// `sqrt(S0/S1)`; 0 when not refitted or the fit failed).
    pub gain: f64,
    /// The decision rule's test against the baseline (None when not
    /// refitted).
    pub test: Option<EffectTest>,
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

impl Ranked {
    /// True when the decision rule names it against the baseline.
    pub fn passes(&self) -> bool {
        self.test.as_ref().is_some_and(EffectTest::passes)
    }

    /// A likely refit that did not start from the baseline: its gain may be
    /// the restart's (the model without it, refitted from its values, may
    /// end below the baseline; see `decide`).
    fn likely_restart(&self) -> bool {
        !self.from_baseline && self.test.as_ref().is_some_and(EffectTest::likely)
    }

    /// Its refit stopped where it could no longer change the verdict
    /// (it could not pass, or not beat a standing verdict; [`crate::GiveUp`]):
    /// its cost is not refined.
    pub fn stopped_short(&self) -> bool {
        self.fit.as_ref().is_some_and(|f| f.gave_up)
    }

    /// The decision rule's words on it: passes or not, with the test's
    /// numbers; a refit that stopped where it could no longer change the verdict
    /// ([`crate::GiveUp`]) says so.
    pub fn rule_line(&self) -> String {
        let mut line = match &self.test {
            Some(t) if self.passes() => format!("passes: {}", t.describe()),
            Some(t) => format!("does not pass: {}", t.describe()),
            None => "not judged".to_string(),
        };
        if self.stopped_short() {
            line.push_str("; refit stopped where it could no longer change the verdict (its cost not refined)");
        }
        line
    }
}

/// The outcome of [`diagnose`].
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnosis {
    /// Fit of the unchanged model (to the screening tolerance while far
    /// above the noise floor: [`FitOptions::coarse_far_above_floor`]).
    pub baseline: FitResult,
    /// Candidates, best first: those that pass by their margin, then the
    /// refitted ones by cost, then the others in equation-error order.
    pub ranking: Vec<Ranked>,
    /// The accepted candidate, or None (adequate at the floor, otherwise
    /// [`Diagnosis::unexplained`]).
    pub verdict: Option<Candidate>,
    /// The weighted cost measurement noise alone would leave (1 with the
    /// default weights, [`crate::weights::noise_cost`]).
    pub floor: f64,
    /// The baseline's effective number of independent residuals (the
    /// tests' `N_eff`).
    pub effective_samples: f64,
    /// Whether the baseline's residual is at the floor on every record's
    /// channel ([`crate::decision::at_floor`]): then no candidate effect
    /// was refitted.
    pub at_floor: bool,
    /// The baseline's largest residual RMS over the records' channels, in
    /// noise standard deviations, and where: `(rms, record, channel)`.
    pub worst: Option<(f64, String, String)>,
    /// What the diagnosis noticed on the way (a scale held fixed, a blind
    /// equation-error ranking, screening extended beyond the leaders, a
    /// baseline improved by a restart), in words.
    pub notes: Vec<String>,
    /// The creeping dry-friction law, when the records follow it
    /// ([`crate::friction_law`]): then `baseline` is the fit under it, at
    /// the floor, and there is no verdict.
    pub creeping: Option<CreepingLaw>,
    /// When the records' inputs are read as continuous signals
    /// ([`continuous_inputs`]): the baseline's weighted RMS both ways and
    /// why. The baseline and every refit are then on the records so read
    /// ([`Experiment::with_continuous_inputs`]).
    pub continuous_inputs: Option<ContinuousInputs>,
    /// When no simulation follows the whole records (the replay at half
    /// the step parts from the replay by the channel's own motion at the
    /// fitted values, [`crate::fit::StepDifference::parts`]: chaotic
    /// motion): the segment length the baseline and every refit were then
    /// fitted on, and the words that say why (also among `notes`).
    pub unpredictable: Option<(f64, String)>,
}

impl Diagnosis {
    /// Baseline cost over the noise floor cost (weighted RMS ratio; NaN
    /// without a floor).
    pub fn above_floor(&self) -> f64 {
        if self.floor > 0.0 {
            self.baseline.after_cost / self.floor
        } else {
            f64::NAN
        }
    }

    /// Nuisance estimates of the baseline at the edge of what the data
    /// allow.
    pub fn nuisance_flags(&self) -> &[NuisanceFlag] {
        &self.baseline.nuisance_flags
    }

    /// No verdict while the residual is above the floor: the model is not
    /// adequate, the residual is unexplained by every candidate tried.
    pub fn unexplained(&self) -> bool {
        self.verdict.is_none() && !self.at_floor
    }

    /// No verdict, the residual at the floor and no nuisance at the edge
    /// of what the data allow.
    pub fn adequate(&self) -> bool {
        self.verdict.is_none() && self.at_floor && self.nuisance_flags().is_empty()
    }

    /// What a diagnosis on segments cannot see, when the baseline was
    /// fitted on them (the whole records could not be replayed: an unstable
    /// plant balanced by a controller the model does not hold). Measured on
    /// the pendulum balanced upright with a hidden Coulomb friction of
    /// 6e-4 N m: with the law in the model the loop is simulated over whole
    /// records; replayed open loop on 0.5 s segments its trace hides in the
    /// segments' own estimated states.
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

    /// Where the residual sits against the floor, in words.
    fn residual_words(&self) -> String {
        match &self.worst {
            Some((r, e, c)) => format!(
                "largest residual {r:.2} noise RMS ({c} in {e}; the floor ends at sqrt(2) = 1.41)"
            ),
            None => "no residual".to_string(),
        }
    }

    /// One line for the verdict: the missing effect with its test,
    /// `adequate`, or `unexplained residual`, with the
    /// [`Diagnosis::segments_caveat`] when there is one and the nuisance
    /// that the data do not allow.
    pub fn verdict_line(&self) -> String {
        if let Some(law) = &self.creeping {
            return format!(
                "adequate under another dry-friction law: {}",
                law.describe()
            );
        }
        if let Some(v) = &self.verdict {
            let test = self
                .ranking
                .iter()
                .find(|r| r.candidate.label() == v.label())
                .and_then(|r| r.test.as_ref())
                .map(EffectTest::describe)
                .unwrap_or_default();
            return format!("missing effect `{}` on `{}`: {test}", v.effect, v.target);
        }
        let caveat = self
            .segments_caveat()
            .map(|c| format!("; {c}"))
            .unwrap_or_default();
        let flags = if self.nuisance_flags().is_empty() {
            String::new()
        } else {
            format!(
                "; not adequate: the fit needs nuisance the data do not show: {}",
                self.nuisance_flags()
                    .iter()
                    .map(NuisanceFlag::message)
                    .collect::<Vec<_>>()
                    .join("; ")
            )
        };
        if self.unexplained() {
            let refitted = self.ranking.iter().filter(|r| r.fit.is_some()).count();
            let best = self
                .ranking
                .iter()
                .filter(|r| r.test.is_some())
                .max_by(|a, b| margin(a).total_cmp(&margin(b)))
                .and_then(|r| {
                    r.test
                        .as_ref()
                        .map(|t| format!("; the best, {}: {}", r.candidate.label(), t.describe()))
                })
                .unwrap_or_default();
            format!(
                "unexplained residual: {}, and none of the {refitted} candidates refitted passes the decision rule{best}: an effect outside the vocabulary, or a nominal model too far off{caveat}{flags}",
                self.residual_words()
            )
        } else if flags.is_empty() {
            format!(
                "adequate: the residual is at the noise floor ({}), nothing is left for an effect to explain{caveat}",
                self.residual_words()
            )
        } else {
            format!(
                "the residual is at the noise floor ({}){caveat}{flags}",
                self.residual_words()
            )
        }
    }
}

/// A candidate's margin under the rule (`-inf` without a test).
fn margin(r: &Ranked) -> f64 {
    r.test
        .as_ref()
        .map_or(f64::NEG_INFINITY, EffectTest::margin)
}

/// The passing candidate with the largest margin (the last of equal ones).
fn best_passing(ranking: &[Ranked]) -> Option<usize> {
    (0..ranking.len())
        .filter(|&i| ranking[i].passes())
        .max_by(|&a, &b| margin(&ranking[a]).total_cmp(&margin(&ranking[b])))
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

/// The records with their inputs read as continuous signals
/// ([`Experiment::with_continuous_inputs`]), the baseline refitted on them
/// and the reading's margin under the decision rule, when it fits better.
/// How the inputs act between samples is the records', not an effect (like
/// the dry-friction law, [`crate::friction_law`]): a rig's converter holds
/// each input over its sample interval, as plantc's simulation does, while
/// a simulator that integrates a continuous input (or a sensor that samples
/// one) records points of a signal that moves in between, which a held
/// simulation follows half a sample late (a clean rotary pendulum driven at
/// 0.3-6 Hz, 500 Hz records: a Stribeck friction and two springs named from
/// that alone). The reading has no parameter: its margin is `N_eff
/// ln(S_held / S_continuous)` (`k = 0`), and [`diagnose_from`] weighs it
/// against the round's effect: the reading is taken when its margin beats
/// the effect named with the inputs held (a missing effect that a
/// half-sample shift partly mimics is named first, and the reading is
/// weighed again next round with it in the model), or, when the records
/// read continuous name another effect, when its margin plus that effect's
/// beats the held one
/// (diagnosed so only where that pair can win, see [`diagnose_from`]; the
/// pair is chosen now: on the DFKI double pendulum's measured torques
/// a deadzone on the elbow's torque, held, margin 15.3, stood in for the
/// shoulder's Coulomb friction to the end; read continuous, 10.9 + 8.4, the
/// shoulder's friction is named). Where both readings name the same
/// effect, their difference before it is in the model is mostly its misfit
/// (synthetic held records of a double pendulum whose model lacks its dry
/// friction: the reading 0.06, the same Coulomb friction 267.4 read
/// continuous against 266.8 held; summed, they read the records
/// continuous, and an input delay was named to undo it). A weighted sum of
/// squares lower by less than the fit resolves is no gain
/// ([`crate::fit::refit_continuous`]). Tried only
/// above the floor (at it there is nothing to gain), open loop (a recorded
/// controller's inputs are computed), with inputs recorded.
fn continuous_inputs<'a>(
    model: &'a Model,
    experiments: &'a [Experiment],
    opts: &'a DiagnoseOptions,
    baseline: &FitResult,
) -> Option<Reading<'a>> {
    if opts.inputs_read {
        return None;
    }
    let judge = Judge::new(model, experiments, opts, baseline);
    if judge.fit_at_floor(baseline) {
        return None;
    }
    let fo = FitOptions {
        coarse_far_above_floor: true,
        ..opts.fit.clone()
    };
    let (records, alt) =
        crate::fit::refit_continuous(model, experiments, &fo, baseline, &mut |_| {})?;
    let margin = judge.effective * 2.0 * (baseline.after_cost / alt.after_cost).ln();
    let z = crate::decision::vuong_z(
        &judge.residuals(baseline),
        &judge.residuals(&alt),
        judge.effective,
    );
    let s0 = judge.ssr_of(&baseline.simulated);
    let gain = s0 - judge.ssr_of(&alt.simulated);
    Some(Reading {
        records,
        fit: alt,
        margin,
        z,
        judge,
        s0,
        gain,
    })
}

/// The records' inputs read as continuous signals ([`continuous_inputs`]).
struct Reading<'a> {
    /// The records so read.
    records: Vec<Experiment>,
    /// The baseline refitted on them.
    fit: FitResult,
    /// Its margin over the held baseline, `N_eff ln(S_held / S_continuous)`.
    margin: f64,
    /// Vuong's statistic of the continuous fit against the held one
    /// ([`crate::decision::vuong_z`]).
    z: f64,
    /// The held baseline's judge (its noise and effective sample count).
    judge: Judge<'a>,
    /// The held baseline's weighted sum of squares, in `judge`'s units.
    s0: f64,
    /// The reading's whole gain on it: `s0` less the continuous fit's.
    gain: f64,
}

/// What [`with_raised_floor`] returns: the baseline and the options with
/// the floors raised, and, when no simulation follows the whole records,
/// the segment length both were moved to with the note that says why.
struct RaisedFloor {
    baseline: FitResult,
    opts: DiagnoseOptions,
    unpredictable: Option<(f64, String)>,
}

/// `baseline` (the fit of `model` under `opts`) and `opts`, with the
/// channels' floors raised by the simulation's own error where it is
/// measurable on that fit ([`simulation_error`], [`floor_raises`]; each
/// channel keeps the larger of its error in `opts` and the new one) and
/// the baseline refitted from where it stood under those floors. The
/// error is the model's: a dry friction under the smooth law is stiff at
/// zero speed, so a baseline without one has none and the model with it
/// may. Records from plantc's own integrator cancel it and are judged as
/// before. Where the same step-halving difference shows that no
/// simulation follows the whole records ([`crate::fit::StepDifference::
/// parts`], the horizon automatic), the baseline is first refitted on
/// segments and its floors measured there.
fn with_raised_floor(
    model: &Model,
    experiments: &[Experiment],
    baseline: FitResult,
    opts: &DiagnoseOptions,
) -> Result<RaisedFloor, DiagnoseError> {
    // an error that cannot be measured (the finer simulation fails where
    // the fit's own retried with shorter substeps) is not added
    let differences =
        simulation_error(model, experiments, &opts.fit, &baseline).unwrap_or_default();
    // whole records no simulation follows (chaotic motion): the baseline
    // on segments, and every refit after it
    if baseline.segments.is_none() && matches!(opts.fit.horizon, Horizon::Auto) {
        if let Some(d) = differences.iter().find(|d| d.parts(&baseline.weights)) {
            let h = crate::fit::segment_length(model, experiments, &opts.fit, &baseline)
                .map_err(DiagnoseError::Fit)?;
            let spread = d.spread(&baseline.weights).unwrap_or(f64::NAN);
            let note = format!(
                "no simulation follows the whole records: at the fitted values the replay at half the step parts from the replay by {:.3e} on {} (its spread in the records {:.3e}; chaotic motion, where the step, a rounding or the last digit of a state decide more than the parameters): the baseline and every refit are fitted on {h} s segments, each from its own estimated state",
                d.largest, d.name, spread
            );
            let opts = DiagnoseOptions {
                fit: FitOptions {
                    horizon: Horizon::Segments(h),
                    ..opts.fit.clone()
                },
                ..opts.clone()
            };
            let fo = FitOptions {
                start: Some(baseline.base.clone()),
                coarse_far_above_floor: true,
                ..opts.fit.clone()
            };
            let on_segments = fit(model, experiments, &fo).map_err(DiagnoseError::Fit)?;
            let raised = with_raised_floor(model, experiments, on_segments, &opts)?;
            return Ok(RaisedFloor {
                unpredictable: Some((h, note)),
                ..raised
            });
        }
    }
    let errors: Vec<(String, f64)> = differences
        .iter()
        .map(|d| (d.name.clone(), d.rms))
        .collect();
    let raised = floor_raises(&baseline, &errors, opts.fit.tolerance);
    if raised.is_empty() {
        return Ok(RaisedFloor {
            baseline,
            opts: opts.clone(),
            unpredictable: None,
        });
    }
    let mut errors = opts.fit.simulation_error.clone();
    for (name, e) in raised {
        match errors.iter_mut().find(|(n, _)| *n == name) {
            Some(old) => old.1 = old.1.max(e),
            None => errors.push((name, e)),
        }
    }
    let opts = DiagnoseOptions {
        fit: FitOptions {
            simulation_error: errors,
            ..opts.fit.clone()
        },
        ..opts.clone()
    };
    // (on the baseline's own horizon: the refit moves the floors, not the
    // question; from a baseline at the floor on 2 s segments of a tumbling
    // pendubot, an automatic horizon went to the whole records, where the
    // replay stayed within the angles' spread, and ended 120 times above)
    let fo = FitOptions {
        start: Some(baseline.base.clone()),
        warm: Some(baseline.warm.clone()),
        coarse_far_above_floor: true,
        horizon: baseline
            .segments
            .map_or(opts.fit.horizon, Horizon::Segments),
        ..opts.fit.clone()
    };
    let refitted = fit(model, experiments, &fo).map_err(DiagnoseError::Fit)?;
    Ok(RaisedFloor {
        baseline: refitted,
        opts,
        unpredictable: None,
    })
}

/// The channels of fit `f` whose floor the simulation's own `errors`
/// raise: those where `error^2 > tolerance noise^2`. The weighted sum of
/// squares of a channel scales by `noise^2 / (noise^2 + error^2)`, about
/// `1 - error^2 / noise^2`: a smaller change is below what the fit resolves
/// (it stops on a relative change of `tolerance`), and the floor is the
/// noise's alone (records from plantc's own integrator, or sensors whose
/// noise dwarfs the integrator's error, are judged as before).
fn floor_raises(f: &FitResult, errors: &[(String, f64)], tolerance: f64) -> Vec<(String, f64)> {
    errors
        .iter()
        .filter(|(name, e)| {
            f.weights
                .iter()
                .find(|w| &w.name == name)
                .is_some_and(|w| e * e > tolerance * w.noise * w.noise)
        })
        .cloned()
        .collect()
}

/// What the decision rule reads about the records and the model without
/// the effects under test: the measurements, the channels' noise, the
/// residual count and that fit's effective sample count.
pub(crate) struct Judge<'a> {
    experiments: &'a [Experiment],
    opts: &'a DiagnoseOptions,
    measured: Vec<Vec<Vec<f64>>>,
    noise: Vec<f64>,
    records: Vec<String>,
    channels: Vec<String>,
    samples: usize,
    effective: f64,
    /// The model without the candidates, for [`Judge::dry_level`].
    model: &'a Model,
    /// Its dry-friction level per coordinate (derived once, when a form
    /// test first asks).
    dry_levels: std::sync::OnceLock<Vec<plantc_derive::sym::Expr>>,
}

impl<'a> Judge<'a> {
    /// The largest range (largest less smallest sample) coordinate
    /// `target` covers in one record (0 where no record measures it).
    fn covered(&self, target: &str) -> f64 {
        self.experiments
            .iter()
            .filter_map(|e| e.range(target))
            .fold(0.0, f64::max)
    }

    /// The dry-friction level (`D` in `Q = ... - D sign(q')`) the model
    /// without the candidates gives coordinate `target` at rest, at the
    /// parameter values `value` gives by name (0 without one, or when the
    /// equations cannot be derived): the sliding level a Stribeck hump on
    /// that joint stands on besides its own `Fc`.
    fn dry_level(&self, target: &str, value: impl Fn(&str) -> f64) -> f64 {
        let Some(i) = self.model.coordinates.iter().position(|c| c.name == target) else {
            return 0.0;
        };
        let levels = self.dry_levels.get_or_init(|| {
            plantc_derive::mechanics::derive_equations(self.model)
                .map(|eqs| {
                    plantc_derive::mechanics::decompose_dry_friction(
                        &eqs,
                        plantc_derive::mechanics::FALLBACK_SIGN_WIDTH,
                    )
                    .levels
                    .into_iter()
                    .map(|l| self.model.expand_derived(l))
                    .collect()
                })
                .unwrap_or_default()
        });
        let Some(level) = levels.get(i) else {
            return 0.0;
        };
        // (a parameter by its fitted value; a state at rest)
        let v = level.eval_with(&mut |s| {
            let name = s.name();
            if self.model.parameters.iter().any(|p| p.name == name) {
                value(name)
            } else {
                0.0
            }
        });
        if v.is_finite() {
            v
        } else {
            0.0
        }
    }

    /// The judge of effects added to `model` fitted by `null` (the fit
    /// without them) on `experiments`.
    pub(crate) fn new(
        model: &'a Model,
        experiments: &'a [Experiment],
        opts: &'a DiagnoseOptions,
        null: &FitResult,
    ) -> Judge<'a> {
        let measured = measured_of(model, experiments);
        let noise: Vec<f64> = null.weights.iter().map(|w| w.noise).collect();
        let res = noise_residuals(&measured, &null.simulated, &noise);
        Judge {
            experiments,
            opts,
            records: experiments.iter().map(|e| e.name.clone()).collect(),
            channels: model.coordinates.iter().map(|c| c.name.clone()).collect(),
            samples: residual_count(model, experiments),
            effective: effective_samples(&res),
            measured,
            noise,
            model,
            dry_levels: std::sync::OnceLock::new(),
        }
    }

    /// The null fit's effective number of independent residuals.
    pub(crate) fn effective_samples(&self) -> f64 {
        self.effective
    }

    /// The weighted sum of squares of a fit.
    pub(crate) fn ssr(&self, f: &FitResult) -> f64 {
        f.after_cost * f.after_cost * self.samples as f64
    }

    /// A fit's residual in noise units.
    pub(crate) fn residuals(&self, f: &FitResult) -> Vec<Vec<Vec<f64>>> {
        noise_residuals(&self.measured, &f.simulated, &self.noise)
    }

    /// The weighted sum of squares of simulated outputs (`simulate_as`'s
    /// shape; samples a simulation left out do not count).
    pub(crate) fn ssr_of(&self, simulated: &[Vec<Vec<f64>>]) -> f64 {
        noise_residuals(&self.measured, simulated, &self.noise)
            .iter()
            .flatten()
            .flatten()
            .map(|r| r * r)
            .sum()
    }

    /// The decision rule's likelihood test of sums of squares `s0`
    /// (without) against `s1` (with `k` more parameters) over
    /// `effective` independent residuals.
    pub(crate) fn likelihood_test(&self, s0: f64, s1: f64, effective: f64, k: usize) -> EffectTest {
        EffectTest::new(s0, s1, self.samples, effective, k)
    }

    /// The experiments judged on.
    pub(crate) fn experiments(&self) -> &'a [Experiment] {
        self.experiments
    }

    /// The diagnosis' options.
    pub(crate) fn options(&self) -> &'a DiagnoseOptions {
        self.opts
    }

    /// The test of `r` (refitted, model `m`) against a fit without its
    /// effect of sum of squares `s0`; `nested` compares with the simpler
    /// effect it contains instead of with no effect (`k` its extra
    /// parameters). The contribution is simulated only when the
    /// likelihood part passes.
    fn test(&self, r: &Ranked, m: &Model, s0: f64, nested: bool) -> Option<EffectTest> {
        Some(self.effect_test(&r.candidate, m, r.fit.as_ref()?, s0, nested))
    }

    /// [`Judge::effect_test`] asking only whether the effect is needed at
    /// all, whatever its form (the removal of an effect; its form is the
    /// question of its simpler nested effect).
    pub(crate) fn need_test(
        &self,
        effect: &Candidate,
        m: &Model,
        f: &FitResult,
        s0: f64,
    ) -> EffectTest {
        self.effect_test_inner(effect, m, f, s0, false, false)
    }

    /// The test of `effect` in model `m` fitted by `f` against a fit
    /// without it of sum of squares `s0` (see [`Judge::test`]).
    pub(crate) fn effect_test(
        &self,
        effect: &Candidate,
        m: &Model,
        f: &FitResult,
        s0: f64,
        nested: bool,
    ) -> EffectTest {
        self.effect_test_inner(effect, m, f, s0, nested, true)
    }

    /// [`Judge::effect_test`]; without `form`, the form is not asked.
    fn effect_test_inner(
        &self,
        effect: &Candidate,
        m: &Model,
        f: &FitResult,
        s0: f64,
        nested: bool,
        form: bool,
    ) -> EffectTest {
        let k = if nested {
            effect.parameters.len().saturating_sub(1).max(1)
        } else {
            effect.parameters.len()
        };
        let mut t = EffectTest::new(s0, self.ssr(f), self.samples, self.effective, k);
        let value = |name: &str| {
            m.parameters
                .iter()
                .position(|p| p.name == name)
                .map_or(f64::NAN, |i| f.base[i])
        };
        t.in_own_form = !form
            || effect.in_own_form(
                value,
                || self.dry_level(&effect.target, value),
                || self.covered(&effect.target),
            );
        if t.likely() && t.in_own_form {
            let base = effect.nulled(m, &f.base, nested);
            t.contribution = Some(
                match simulate_as(m, self.experiments, &self.opts.fit, f, &base) {
                    Ok(without) => Contribution::between(
                        &f.simulated,
                        &without,
                        &self.measured,
                        &self.noise,
                        &self.records,
                        &self.channels,
                    ),
                    // nulled, the model cannot be simulated (it diverges
                    // without the effect): the effect holds it together
                    Err(_) => Contribution {
                        size: f64::INFINITY,
                        remaining: 0.0,
                        experiment: String::new(),
                        channel: "(the model diverges without it)".to_string(),
                    },
                },
            );
        }
        t
    }

    /// The options of a screening refit of candidate `r` against
    /// `baseline`: it gives up once it is at least as good as the baseline
    /// but cannot reach a margin above `bar` under the rule, `N_eff
    /// ln(S0/S1) - k ln N_eff > bar`, i.e. cannot bring its weighted RMS
    /// below the baseline's times `exp(-(bar + k ln N_eff) / (2 N_eff))`
    /// ([`GiveUp`]). With `bar` 0 that is the likelihood part of the rule:
    /// such a candidate can change no decision (it neither passes nor is
    /// likely; against the simpler effect it contains, a bigger one that
    /// passes passes by the same algebra). With `bar` a standing verdict's
    /// margin ([`Search::standing_margin`]) it cannot take the verdict
    /// from it, the one question its refit is there to answer. Either way
    /// its cost is not refined to the screening tolerance: work in
    /// proportion to the question.
    ///
    /// "Cannot" is the Gauss-Newton model's word, a first-order one: it is
    /// taken only for an effect linear in its parameters, whose reach
    /// varies smoothly with them. An effect with a shape parameter is
    /// refitted to the tolerance: its sensitivity can vanish at a start
    /// and its cost has several basins (a Stribeck hump on the QUBE arm
    /// that a long descent takes to a weighted RMS ratio of 1.050 was
    /// stopped at 1.001 on that word); nor is a dry friction that holds
    /// its joint ([`holds_its_joint`]).
    fn screening_options(&self, r: &Ranked, baseline: &FitResult, bar: f64) -> DiagnoseOptions {
        if !first_order_at_null(&r.candidate, self.opts) {
            return self.opts.clone();
        }
        let n = self.effective.max(1.0);
        let k = r.candidate.parameters.len() as f64;
        DiagnoseOptions {
            fit: FitOptions {
                give_up: Some(GiveUp {
                    once_at: tie_level(baseline),
                    unless_below: baseline.after_cost * (-(bar + k * n.ln()) / (2.0 * n)).exp(),
                }),
                ..self.opts.fit.clone()
            },
            ..self.opts.clone()
        }
    }

    /// Judge `r` against the baseline (sum of squares `s0`).
    fn judge(&self, r: &mut Ranked, m: &Model, s0: f64) {
        r.test = self.test(r, m, s0, false);
        r.gain = r.test.as_ref().map_or(0.0, EffectTest::rms_ratio);
    }

    /// The largest residual RMS over the records' channels (`residuals`
    /// in noise units), with its record and channel names.
    fn worst(&self, residuals: &[Vec<Vec<f64>>]) -> Option<(f64, String, String)> {
        worst_channel(residuals).map(|(r, e, c)| {
            (
                r,
                self.records.get(e).cloned().unwrap_or_default(),
                self.channels.get(c).cloned().unwrap_or_default(),
            )
        })
    }

    /// Is a fit's residual at the floor?
    pub(crate) fn fit_at_floor(&self, f: &FitResult) -> bool {
        at_floor(&self.residuals(f))
    }
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
    let reading = continuous_inputs(&model, experiments, opts, &baseline);
    let held_cost = baseline.after_cost;
    let d = diagnose_on((text, &model), experiments, baseline, opts)?;
    let Some(Reading {
        records,
        fit: alt,
        margin: hold_margin,
        z,
        judge,
        s0,
        gain,
    }) = reading
    else {
        return Ok(d);
    };
    // the reading against the round's effect: taken when its own margin
    // beats the effect named with the inputs held. Where it does not, the
    // held effect may stand in for it, and the records read continuous
    // name another: the pair (reading and that effect) is taken when its
    // margin beats the held effect's (decided now: deferred, the reading
    // would be weighed next round against a model that holds the
    // stand-in). Where both readings name the same effect it is named
    // held, and the reading is weighed again next round with that effect
    // in the model. The continuous records are diagnosed for the pair only
    // when it can win: the reading is significant (Vuong's test) and some
    // other effect refitted held could beat the held one with the whole of
    // the reading's gain added (`stand_in_possible`).
    let held_best = verdict_margin(&d).unwrap_or(0.0);
    let alone = d.verdict.is_none() || hold_margin > held_best;
    let pair_may_win =
        z > crate::decision::VUONG_99 && stand_in_possible(&d, &judge, (s0, gain), held_best);
    if !(alone || pair_may_win) {
        return Ok(d);
    }
    let continuous_cost = alt.after_cost;
    let opts = DiagnoseOptions {
        inputs_read: true,
        ..opts.clone()
    };
    let mut c = diagnose_on((text, &model), &records, alt, &opts)?;
    let continuous_best = hold_margin + verdict_margin(&c).unwrap_or(0.0).max(0.0);
    let other_effect = match (&d.verdict, &c.verdict) {
        (Some(h), Some(v)) => h.label() != v.label(),
        _ => false,
    };
    if !(alone || other_effect && continuous_best > held_best) {
        return Ok(d);
    }
    let against = match &d.verdict {
        Some(v) => format!("{}'s {held_best:.1} held", v.label()),
        None => "any effect named held".to_string(),
    };
    let margins = match (&c.verdict, verdict_margin(&c)) {
        (Some(v), Some(m)) if !alone => format!(
            "margin {hold_margin:.1} plus {m:.1} for {} named on the records so read: {continuous_best:.1}",
            v.label()
        ),
        _ => format!("margin {hold_margin:.1}"),
    };
    let why = format!(
        "{margins}, beyond {against}: records made by integrating a continuous input, or sampling one"
    );
    c.notes.push(format!(
        "inputs read as continuous signals, not held over each sample interval: weighted RMS {:.4e} held, {:.4e} continuous ({why})",
        held_cost, continuous_cost
    ));
    c.continuous_inputs = Some(ContinuousInputs {
        held: held_cost,
        continuous: continuous_cost,
        why,
    });
    Ok(c)
}

/// Whether an effect other than `d`'s verdict, refitted with the inputs
/// held, could beat the verdict's margin `held_best` on the records read
/// continuous, with the reading's margin counted in: its sum of squares
/// less the reading's whole gain `delta` (from the held baseline's `s0`,
/// both in `judge`'s units) beats it. An effect cannot gain more from the
/// reading than the baseline does: what the reading removes is a part of
/// the residual, which an effect leaves (it does not touch it: the gain is
/// the same) or takes part of (it stood in for the reading: less is left
/// for it). So its sum of squares on the records read continuous is at
/// least its held one less `delta`, and no less than the noise's own (one
/// per residual in noise units: a fit is not expected below it), and its
/// margin there at most the bound tested. (At a baseline far from the
/// records `delta` can exceed what an effect leaves: 8.9e4 on the noisy
/// Coulomb case, whose Coulomb friction leaves 6.0e4 of the noise's 6.0e4.)
fn stand_in_possible(
    d: &Diagnosis,
    judge: &Judge<'_>,
    (s0, delta): (f64, f64),
    held_best: f64,
) -> bool {
    let verdict = d.verdict.as_ref().map(Candidate::label);
    let n = judge.effective_samples();
    let noise = judge.samples as f64;
    d.ranking
        .iter()
        .filter(|r| Some(r.candidate.label()) != verdict)
        .filter_map(|r| {
            Some((
                judge.ssr_of(&r.fit.as_ref()?.simulated),
                r.candidate.parameters.len(),
            ))
        })
        .any(|(s, k)| {
            let reach = (s - delta).max(noise);
            n * (s0 / reach).ln() - k as f64 * n.ln() > held_best
        })
}

/// The margin of a diagnosis' verdict under the decision rule, when it
/// names an effect.
fn verdict_margin(d: &Diagnosis) -> Option<f64> {
    d.verdict.as_ref()?;
    d.ranking.first().map(margin)
}

/// [`diagnose_from`] with the records' inputs as they are read (`model`:
/// `text` checked and lowered).
fn diagnose_on(
    (text, model): (&str, &Model),
    experiments: &[Experiment],
    baseline: FitResult,
    opts: &DiagnoseOptions,
) -> Result<Diagnosis, DiagnoseError> {
    let RaisedFloor {
        baseline,
        opts,
        unpredictable,
    } = with_raised_floor(model, experiments, baseline, opts)?;
    // every refit is judged on the samples the baseline was (a record's
    // release transient left out, [`crate::release`])
    let opts = &DiagnoseOptions {
        fit: FitOptions {
            starts: Some(baseline.warm.starts().to_vec()),
            ..opts.fit.clone()
        },
        ..opts.clone()
    };
    let nuisance = opts.fit.free_names(model);
    let ee = EquationError::new(
        model,
        &baseline.base,
        &nuisance,
        experiments,
        &opts.equation_error,
    )?;
    let mut notes = Vec::new();
    if let Some((_, note)) = &unpredictable {
        notes.push(note.clone());
    }
    if let Some(sf) = ee.scale_fixed() {
        notes.push(format!("equation-error ranking: {sf}"));
    }
    // equation-error scores
    let mut scored = Vec::new();
    for c in candidates(model) {
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
                rmse_before: baseline.after_rmse,
                rmse_after: None,
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
            test: None,
            from_baseline: false,
        });
        edited.push((m, standing));
    }
    let floor = crate::weights::noise_cost(&baseline.weights);
    let judge = Judge::new(model, experiments, opts, &baseline);
    let base_res = judge.residuals(&baseline);
    let baseline_at_floor = at_floor(&base_res);
    let worst = judge.worst(&base_res);
    if baseline_at_floor {
        notes.push(
            "the baseline's residual is below sqrt(2) noise RMS on every channel of every record: a missing effect of the noise's size would raise it above, so no candidate effect was refitted (sensor offsets still checked)".to_string(),
        );
    } else if blind {
        notes.push(
            "the equation-error ranking cannot discriminate (no candidate explains any of the torque residual): every candidate is screened by simulation error instead".to_string(),
        );
    }
    let s0 = judge.ssr(&baseline);
    let mut search = Search {
        judge: &judge,
        model,
        baseline: &baseline,
        edited: &edited,
        s0,
        restart_ok: std::cell::OnceCell::new(),
        second_started: Vec::new(),
        ahead: Default::default(),
        restart_fit: None,
    };
    if !baseline_at_floor {
        search.run(&mut ranking, blind, &mut notes);
    }
    // a sensor offset is absorbed by the per-experiment offsets of the
    // baseline: judged against the baseline without them instead, unless a
    // candidate already explains the residual down to the floor
    let explained = ranking
        .iter()
        .any(|r| r.passes() && r.fit.as_ref().is_some_and(|f| judge.fit_at_floor(f)));
    if !explained {
        sensor_offsets_from_nuisance(&mut ranking, text, model, &baseline, &judge);
    }
    if search.restart_ok.get() == Some(&false) {
        notes.push(
            "the whole records replayed from the nominal values leave the data: no candidate refitted again from there (second starts), only from the baseline".to_string(),
        );
    }
    let restart_fit = search.restart_fit.take();
    let mut baseline = baseline;
    let by_label = edited_by_label(&ranking, &edited);
    let verdict = decide(
        &mut ranking,
        &by_label,
        model,
        &mut baseline,
        &judge,
        restart_fit,
        &mut notes,
    );
    // the records may follow another dry-friction law than the sticking
    // one ([`crate::friction_law`]): tried while the baseline is above the
    // floor, adopted when it reaches the floor with a larger margin than
    // the verdict's
    let creeping = (!baseline_at_floor)
        .then(|| creeping_law(text, model, &judge, &baseline))
        .flatten()
        .filter(|law| {
            let verdict_margin = verdict
                .as_ref()
                .and_then(|v| ranking.iter().find(|r| r.candidate.label() == v.label()))
                .map_or(f64::NEG_INFINITY, margin);
            law.test.margin() > verdict_margin
        });
    let (verdict, at_floor, worst) = match &creeping {
        Some(law) => {
            notes.push(format!(
                "{}; the candidates above were judged against the baseline fitted sticking",
                law.describe()
            ));
            baseline = law.fit.clone();
            (None, true, judge.worst(&judge.residuals(&baseline)))
        }
        None => (verdict, baseline_at_floor, worst),
    };
    Ok(Diagnosis {
        baseline,
        ranking,
        verdict,
        floor,
        effective_samples: judge.effective,
        at_floor,
        worst,
        notes,
        creeping,
        continuous_inputs: None,
        unpredictable,
    })
}

/// The edited models by candidate label (the ranking gets reordered).
fn edited_by_label(ranking: &[Ranked], edited: &[(Model, (bool, bool))]) -> Vec<(String, Model)> {
    ranking
        .iter()
        .zip(edited)
        .map(|(r, (m, _))| (r.candidate.label(), m.clone()))
        .collect()
}

/// The search of a diagnosis: which candidates are refitted, from where.
struct Search<'a> {
    judge: &'a Judge<'a>,
    model: &'a Model,
    baseline: &'a FitResult,
    /// Per ranked candidate (in the ranking's first order): its edited
    /// model and its equation-error standing (informative, adds a column).
    edited: &'a [(Model, (bool, bool))],
    /// The baseline's weighted sum of squares.
    s0: f64,
    /// Whether second starts from the nominal values may run: the whole
    /// records replayed from there follow the data (checked once, lazily;
    /// always on segments). From values whose replay leaves the data (the
    /// QUBE balanced in closed loop) a fit wanders to the bounds of the
    /// box, every second start far above the baseline.
    restart_ok: std::cell::OnceCell<bool>,
    second_started: Vec<usize>,
    /// Refits computed ahead on other cores ([`crate::parallel`]).
    ahead: crate::speculate::Ahead,
    /// The model without a candidate's effect refitted from its values
    /// ([`Search::restart_is_the_baselines`]), for `decide`, which would
    /// make the same fit.
    restart_fit: Option<RestartFit>,
}

/// A refit of the baseline model from candidate `label`'s fit (the one of
/// weighted RMS `from_cost`).
struct RestartFit {
    label: String,
    from_cost: f64,
    fit: FitResult,
}

impl RestartFit {
    /// Whether this is the refit from `r`'s present fit.
    fn is_of(&self, r: &Ranked) -> bool {
        self.label == r.candidate.label()
            && r.fit
                .as_ref()
                .is_some_and(|f| f.after_cost == self.from_cost)
    }
}

impl Search<'_> {
    /// Refit candidate `idx` warm from the baseline and judge it; its
    /// refit may stop where it cannot reach a margin above `bar`
    /// ([`Judge::screening_options`]).
    fn refit(&self, ranking: &mut [Ranked], idx: usize, bar: f64) {
        if let Some(done) = self.ahead.take(Step::refit(bar), idx, &ranking[idx]) {
            ranking[idx] = done;
            return;
        }
        let label = ranking[idx].candidate.label();
        crate::progress::candidates(&[idx + 1], ranking.len(), &label);
        let opts = self
            .judge
            .screening_options(&ranking[idx], self.baseline, bar);
        refit(
            &mut ranking[idx],
            &self.edited[idx].0,
            self.model,
            self.baseline,
            self.judge.experiments,
            &opts,
        );
        self.judge
            .judge(&mut ranking[idx], &self.edited[idx].0, self.s0);
    }

    /// Refit candidate `idx` again from the model's nominal values (once),
    /// keep the better, judge it.
    fn second_start(&mut self, ranking: &mut [Ranked], idx: usize) {
        if self.second_started.contains(&idx) || !self.may_restart() {
            return;
        }
        self.second_started.push(idx);
        if let Some(done) = self.ahead.take(Step::SecondStart, idx, &ranking[idx]) {
            ranking[idx] = done;
            return;
        }
        let opts = self
            .judge
            .screening_options(&ranking[idx], self.baseline, 0.0);
        second_start(
            &mut ranking[idx],
            &self.edited[idx].0,
            self.model,
            self.baseline,
            self.judge.experiments,
            &opts,
        );
        self.judge
            .judge(&mut ranking[idx], &self.edited[idx].0, self.s0);
    }

    /// Compute the [`Step`]s of `upcoming` (in that order) ahead on the
    /// other cores, from their candidates' present states, up to the first
    /// result that `stop`s the caller's walk of that list (a refit that
    /// settles the diagnosis; see [`crate::speculate`] for the rule). Each
    /// is the same function of that state as when run in turn (a refit or a
    /// second start, then the judgement), and is used only if the state is
    /// still the same when its turn comes: the outcome is that of the
    /// sequential search on any number of threads.
    fn look_ahead(
        &self,
        ranking: &[Ranked],
        step: Step,
        upcoming: &[usize],
        stop: impl Fn(&Ranked) -> bool + Sync,
    ) {
        let (judge, model, baseline, edited, s0) =
            (self.judge, self.model, self.baseline, self.edited, self.s0);
        let n = ranking.len();
        self.ahead.compute(
            step,
            ranking,
            upcoming,
            |r, idx| {
                crate::progress::candidates(&[idx + 1], n, &r.candidate.label());
                let m = &edited[idx].0;
                match step {
                    Step::Refit { bar } => {
                        let opts = judge.screening_options(r, baseline, f64::from_bits(bar));
                        refit(r, m, model, baseline, judge.experiments, &opts);
                    }
                    Step::SecondStart => {
                        let opts = judge.screening_options(r, baseline, 0.0);
                        second_start(r, m, model, baseline, judge.experiments, &opts);
                    }
                }
                judge.judge(r, m, s0);
            },
            stop,
        );
    }

    /// The margin of a verdict that stands whatever the candidates not
    /// yet refitted turn out to be, short of one with a larger margin; 0
    /// when there is none. `decide` names the passing candidate with the
    /// largest margin unless it is a bigger effect that loses to the
    /// simpler one it contains, or a gain a restart made (the model without
    /// it, refitted from its values, ends below the baseline: checked here
    /// as `decide` would, and kept for it). A candidate that cannot reach
    /// a larger margin cannot change such a verdict.
    fn standing_margin(&mut self, ranking: &[Ranked]) -> f64 {
        let Some(best) = best_passing(ranking) else {
            return 0.0;
        };
        let r = &ranking[best];
        if r.candidate.nested().is_some() {
            return 0.0;
        }
        if self.restart_is_the_baselines(r) {
            return 0.0;
        }
        margin(r).max(0.0)
    }

    fn may_restart(&self) -> bool {
        self.baseline.segments.is_some()
            || *self.restart_ok.get_or_init(|| {
                let nominal = FitOptions {
                    start: None,
                    ..self.judge.opts.fit.clone()
                };
                replay_follows(self.model, self.judge.experiments, &nominal).unwrap_or(true)
            })
    }

    /// Whether `r`, a likely refit that did not start from the baseline,
    /// owes its gain to the restart: the model without its effect, refitted
    /// from its values, ends below the baseline (the check `decide` makes).
    fn restart_is_the_baselines(&mut self, r: &Ranked) -> bool {
        if !r.likely_restart() {
            return false;
        }
        let Some(f) = r.fit.as_ref() else {
            return false;
        };
        // (once per fit of it)
        if let Some(known) = self.restart_fit.as_ref().filter(|k| k.is_of(r)) {
            return lower_minimum(&known.fit, self.baseline);
        }
        let Ok(again) = refit_from_fit(
            self.model,
            &self.baseline.base,
            f,
            self.baseline,
            self.judge,
        ) else {
            return false;
        };
        let lower = lower_minimum(&again, self.baseline);
        self.restart_fit = Some(RestartFit {
            label: r.candidate.label(),
            from_cost: f.after_cost,
            fit: again,
        });
        lower
    }

    /// Refine the refit of the passing candidate with the largest margin
    /// (when it passes above the floor) at the final tolerance, and keep
    /// it when it then settles the diagnosis: true when it does. The
    /// screening tolerance is set for comparing margins, not for telling
    /// whether a fit can still reach the floor: a slow descent stopped
    /// there (a cart's force saturation at 16 times the floor, which its
    /// fit in the next round took to the floor, while 25 more candidates
    /// were refitted to see whether one beat it: 61 s CPU). The refinement
    /// gives up once the Gauss-Newton model cannot reach the floor
    /// ([`GiveUp`], [`crate::fit::FAR_ABOVE_FLOOR`] times the noise's
    /// weighted RMS, the level of [`at_floor`] over all channels): it is
    /// a question with a yes or no, and a no (a leader that another effect
    /// still missing holds above the floor) leaves everything as it was,
    /// for one sensitivity simulation or a few.
    fn refine_to_floor(&self, ranking: &mut [Ranked]) -> bool {
        let Some(best) = best_passing(ranking) else {
            return false;
        };
        let Some(f) = ranking[best].fit.as_ref() else {
            return false;
        };
        let floor = crate::weights::noise_cost(&self.baseline.weights);
        if floor.is_nan() || floor <= 0.0 || f.gave_up {
            return false;
        }
        let m = &self.edited[best].0;
        let fo = FitOptions {
            start: Some(f.base.clone()),
            warm: Some(f.warm.clone()),
            tolerance: crate::fit::FINAL_TOLERANCE,
            give_up: Some(GiveUp {
                once_at: f64::INFINITY,
                unless_below: crate::fit::FAR_ABOVE_FLOOR * floor,
            }),
            ..screening(
                self.judge.opts,
                f.base.clone(),
                self.baseline
                    .segments
                    .map_or(Horizon::Whole, Horizon::Segments),
            )
        };
        let from_baseline = ranking[best].from_baseline;
        let Ok(refined) = fit(m, self.judge.experiments, &fo) else {
            return false;
        };
        if refined.gave_up || refined.after_cost >= f.after_cost {
            return false;
        }
        let mut r = ranking[best].clone();
        credit(&mut r, refined, from_baseline);
        self.judge.judge(&mut r, m, self.s0);
        if !self.settles(&r) {
            return false;
        }
        ranking[best] = r;
        self.refit_nested(ranking, best);
        true
    }

    /// The second start of candidate `idx` ([`Search::second_start`]);
    /// true when it then settles the diagnosis (the simpler effect it
    /// contains is refitted beside it).
    fn restart_settles(&mut self, ranking: &mut [Ranked], idx: usize) -> bool {
        self.second_start(ranking, idx);
        self.settle(ranking, idx)
    }

    /// Whether candidate `idx` as it stands settles the diagnosis; when it
    /// does, the simpler effect it contains is refitted beside it.
    fn settle(&self, ranking: &mut [Ranked], idx: usize) -> bool {
        let settles = self.settles(&ranking[idx]);
        if settles {
            self.refit_nested(ranking, idx);
        }
        settles
    }

    /// A candidate that passes with its residual at the floor: nothing is
    /// left for another to explain.
    fn settles(&self, r: &Ranked) -> bool {
        settles(self.judge, r)
    }

    /// Refit the simpler effect `r` contains (Coulomb under Stribeck), for
    /// the decision between them.
    fn refit_nested(&self, ranking: &mut [Ranked], idx: usize) {
        let Some(inner) = ranking[idx].candidate.nested() else {
            return;
        };
        let target = ranking[idx].candidate.target.clone();
        if let Some(j) = ranking.iter().position(|r| {
            r.candidate.effect == inner && r.candidate.target == target && r.fit.is_none()
        }) {
            // (not one the model's own parameters span: a Coulomb friction
            // on a joint whose dry friction the model already estimates)
            if self.edited[j].1 .1 {
                self.refit(ranking, j, 0.0);
            }
        }
    }

    /// A Coulomb friction that passes above the floor: the Stribeck
    /// friction on its target refitted from its fit (the hump can hide in
    /// the Coulomb-like minimum a refit from the baseline finds).
    fn stribeck_from_coulomb(&self, ranking: &mut [Ranked], done: &mut Vec<usize>) {
        for j in 0..ranking.len() {
            let inner = &ranking[j];
            if inner.candidate.effect != "coulomb_friction"
                || !inner.passes()
                || done.contains(&j)
                || self.settles(inner)
            {
                continue;
            }
            let Some(i) = ranking.iter().position(|r| {
                r.candidate.effect == "stribeck_friction"
                    && r.candidate.target == inner.candidate.target
            }) else {
                continue;
            };
            done.push(j);
            let (coulomb_fit, from_baseline) = match &inner.fit {
                Some(f) => (f.clone(), inner.from_baseline),
                None => continue,
            };
            stribeck_from_coulomb(
                &mut ranking[i],
                &self.edited[i].0,
                (&self.edited[j].0, &coulomb_fit, from_baseline),
                self.judge.experiments,
                self.judge.opts,
            );
            self.judge
                .judge(&mut ranking[i], &self.edited[i].0, self.s0);
        }
    }

    /// The whole search (see the module docs).
    fn run(&mut self, ranking: &mut [Ranked], blind: bool, notes: &mut Vec<String>) {
        let n = ranking.len();
        let mut leaders: Vec<usize> = (0..n)
            .filter(|&i| blind || self.edited[i].1 .0)
            .take(self.judge.opts.refit)
            .collect();
        // An inertia's equation-error column is the measured acceleration,
        // whose noise is also in the torque residual (errors in variables):
        // its score is inflated by that noise. It is refitted after the
        // leaders whose columns do not share the residual's noise.
        leaders.sort_by_key(|&i| ranking[i].candidate.line() == "inertia");
        let mut stribecks = Vec::new();
        // refit one candidate (warm from the baseline); true when it settles
        // the diagnosis (passes at the floor; the simpler effect it contains
        // is refitted beside it)
        let try_one = |this: &mut Self, ranking: &mut [Ranked], idx: usize, bar: f64| -> bool {
            this.refit(ranking, idx, bar);
            this.settle(ranking, idx)
        };
        let mut settled = false;
        // A verdict that stands sets the bar the others must clear. It is
        // taken at fixed points of the walks, where no refit is being
        // computed ahead: when the leaders' walk starts and once its first
        // leader, the likeliest to set one, is in (refitted alone while no
        // verdict stands, its fit spreading its experiments over the
        // cores), and when the walk over the rest starts. A candidate that
        // changes the verdict in between does not move the bar for the
        // rest of that walk, so the refits computed ahead with it stay
        // valid (a lower bar only refines more: the same verdict; moved at
        // the first candidate of the rest that passed, the QUBE episodes'
        // twelve refits computed ahead were all computed again, 29 -> 37 s
        // wall on 2 threads).
        let mut bar = self.standing_margin(ranking);
        for (k, &idx) in leaders.iter().enumerate() {
            if k == 1 && bar == 0.0 {
                bar = self.standing_margin(ranking);
            }
            if k > 0 || bar > 0.0 {
                self.look_ahead(ranking, Step::refit(bar), &leaders[k..], |r| {
                    settles(self.judge, r)
                });
            }
            if try_one(self, ranking, idx, bar) {
                settled = true;
                break;
            }
        }
        self.stribeck_from_coulomb(ranking, &mut stribecks);
        if !settled {
            settled = self.refine_to_floor(ranking);
        }
        // The leader that passes above the floor may be trapped where the
        // distorted baseline put it (see the second starts below): it is
        // started again from the nominal values before the other
        // candidates are screened, and where it then settles none of them
        // can change the verdict (the walk ends at the first candidate
        // that settles, as the leaders' does). A Coulomb friction's warm
        // refit held in a phase-error minimum at 1.28 times the floor,
        // its Stribeck refit ended out of its own form, and 15 more
        // candidates were refitted before the restart reached the floor.
        if !settled {
            if let Some(best) = best_passing(ranking) {
                settled = self.restart_settles(ranking, best);
            }
        }
        if !settled {
            // No leader passes at the floor: the verdict is the candidate
            // with the largest margin, so every other candidate that adds a
            // column is screened too (the equation-error ranking orders the
            // search, its linearised columns do not decide: a 1.5 V
            // saturation ranked low there, and a cogging torque that
            // mimicked part of it passed first)
            let rest: Vec<usize> = (0..n)
                .filter(|&i| !leaders.contains(&i) && (blind || self.edited[i].1 .1))
                .collect();
            if !rest.is_empty() && !blind {
                notes.push(format!(
                    "no equation-error leader passes the decision rule with the residual at the floor: the other {} candidates were refitted too",
                    rest.len()
                ));
            }
            let bar = self.standing_margin(ranking);
            for (k, &idx) in rest.iter().enumerate() {
                self.look_ahead(ranking, Step::refit(bar), &rest[k..], |r| {
                    settles(self.judge, r)
                });
                if try_one(self, ranking, idx, bar) {
                    settled = true;
                    break;
                }
            }
        }
        // The would-be verdict above the floor may be trapped where the
        // distorted baseline put it (a spring on the arm: 4.5x from the
        // baseline, 400x from the nominal values): it is started again from
        // the nominal values, and so is whichever candidate then leads,
        // until the leader has had its second start or settles.
        while !settled {
            let Some(best) = best_passing(ranking) else {
                break;
            };
            if self.second_started.contains(&best) || !self.may_restart() {
                break;
            }
            settled = self.restart_settles(ranking, best);
        }
        let any = |ranking: &[Ranked]| ranking.iter().any(Ranked::passes);
        if !settled && !any(ranking) {
            // nothing passes: a baseline distorted by the missing effect can
            // trap every refit from it; the refitted candidates are started
            // again from the nominal values, in equation-error order
            let refitted: Vec<usize> = (0..n).filter(|&i| ranking[i].fit.is_some()).collect();
            let mut checked_restart = false;
            for (k, &idx) in refitted.iter().enumerate() {
                if !self.second_started.contains(&idx) && self.may_restart() {
                    let next: Vec<usize> = refitted[k..]
                        .iter()
                        .copied()
                        .filter(|i| !self.second_started.contains(i))
                        .collect();
                    // (the walk ends at one that settles, and may end at
                    // the first likely one that did not start from the
                    // baseline: the restart check below)
                    self.look_ahead(ranking, Step::SecondStart, &next, |r| {
                        settles(self.judge, r) || r.likely_restart()
                    });
                }
                if self.restart_settles(ranking, idx) {
                    break;
                }
                // a restart's gain is the baseline's: once one is likely,
                // the model without the effect is refitted from its values
                // (as `decide` will); when that is a better minimum the
                // other second starts are of no use (every candidate is
                // judged again against it, and the story diagnoses again
                // from it)
                if !checked_restart && self.restart_is_the_baselines(&ranking[idx]) {
                    break;
                }
                checked_restart |= ranking[idx].likely_restart();
            }
        }
        // a speed force that passes may stand in for another speed force on
        // its target (a drag for a Stribeck hump over a gearbox friction;
        // at the floor, a Stribeck friction with the gearbox friction
        // lowered for a drag): those are refitted too, from the baseline
        // and from the nominal values. Where one settles the diagnosis
        // only those with fewer parameters can still win: at the floor both
        // sums of squares are the noise's, and the margin then differs by
        // the parameters' price `k ln N_eff`.
        let targets: Vec<String> = ranking
            .iter()
            .filter(|r| SPEED_FORCES.contains(&r.candidate.effect.as_str()) && r.passes())
            .map(|r| r.candidate.target.clone())
            .collect();
        let settled_k = ranking
            .iter()
            .filter(|r| self.settles(r))
            .map(|r| r.candidate.parameters.len())
            .min();
        let stand_ins: Vec<usize> = (0..n)
            .filter(|&j| {
                let c = &ranking[j].candidate;
                ranking[j].fit.is_none()
                    && ranking[j].error.is_none()
                    && SPEED_FORCES.contains(&c.effect.as_str())
                    && targets.contains(&c.target)
                    && self.edited[j].1 .1
                    && settled_k.is_none_or(|k| c.parameters.len() < k)
            })
            .collect();
        // (each touches only its own candidate: all refits, then all
        // second starts, is the same as one after the other per
        // candidate)
        for (k, &j) in stand_ins.iter().enumerate() {
            self.look_ahead(ranking, Step::refit(0.0), &stand_ins[k..], |_| false);
            self.refit(ranking, j, 0.0);
        }
        // (second starts are for a baseline the missing effect distorted:
        // where a candidate settles, the baseline is one effect away from
        // the records and the refits from it stand)
        let restarts: &[usize] = if settled_k.is_some() { &[] } else { &stand_ins };
        for (k, &j) in restarts.iter().enumerate() {
            if self.may_restart() {
                let next: Vec<usize> = restarts[k..]
                    .iter()
                    .copied()
                    .filter(|i| !self.second_started.contains(i))
                    .collect();
                self.look_ahead(ranking, Step::SecondStart, &next, |_| false);
            }
            self.second_start(ranking, j);
        }
        // every passing effect competes with the simpler one it contains
        for idx in 0..n {
            if ranking[idx].passes() {
                self.refit_nested(ranking, idx);
            }
        }
        self.stribeck_from_coulomb(ranking, &mut stribecks);
        crate::progress::clear();
    }
}

/// A candidate that passes with its residual at the floor (see
/// [`Search::settles`]).
fn settles(judge: &Judge<'_>, r: &Ranked) -> bool {
    r.passes() && r.fit.as_ref().is_some_and(|f| judge.fit_at_floor(f))
}

/// The force effects that are functions of their target's speed (the
/// family whose members can stand in for one another over the speeds a
/// record reaches).
const SPEED_FORCES: &[&str] = &[
    "viscous_friction",
    "coulomb_friction",
    "quadratic_drag",
    "stribeck_friction",
    "speed_limit",
];

/// (effect, the simpler effect it contains on the same target).
pub(crate) const NESTED: &[(&str, &str)] = &[("stribeck_friction", "coulomb_friction")];

/// Order the ranking (passing candidates by margin, then refitted ones by
/// cost, then the rest in equation-error order) and pick the verdict: the
/// passing candidate with the largest margin, a bigger effect over its
/// simpler form only when it passes the rule against it, and not a gain a
/// restart made (see the module docs).
///
/// `known`: a refit of the model without a candidate's effect from that
/// candidate's values that the search made already (the same fit this
/// check makes).
fn decide(
    ranking: &mut [Ranked],
    edited: &[(String, Model)],
    model: &Model,
    baseline: &mut FitResult,
    judge: &Judge<'_>,
    mut known: Option<RestartFit>,
    notes: &mut Vec<String>,
) -> Option<Candidate> {
    let model_of = |label: &str| edited.iter().find(|(l, _)| l == label).map(|(_, m)| m);
    let mut checked: Vec<String> = Vec::new();
    // the targets whose simpler effect was refitted from the bigger one's
    let mut from_bigger: Vec<String> = Vec::new();
    loop {
        ranking.sort_by(|a, b| {
            b.passes()
                .cmp(&a.passes())
                .then(margin(b).total_cmp(&margin(a)))
                .then(a.fit.is_none().cmp(&b.fit.is_none()))
                .then(
                    a.evidence
                        .equation_error_rank
                        .cmp(&b.evidence.equation_error_rank),
                )
        });
        // a bigger effect over its simpler form: the simpler one is refitted
        // from the bigger one's values first (once), then the rule between
        // the two when the simpler one passes, or the simpler one first
        if let Some(top) = ranking.first().filter(|t| t.passes()) {
            if let Some(inner) = top.candidate.nested() {
                let target = top.candidate.target.clone();
                if let Some(j) = ranking
                    .iter()
                    .position(|r| r.candidate.effect == inner && r.candidate.target == target)
                {
                    if !from_bigger.contains(&target) {
                        from_bigger.push(target.clone());
                        simpler_from_bigger(ranking, j, &model_of, model, baseline, judge, notes);
                    }
                }
                if let Some(j) = ranking.iter().position(|r| {
                    r.candidate.effect == inner && r.candidate.target == target && r.passes()
                }) {
                    let top = &ranking[0];
                    let s_inner = ranking[j].fit.as_ref().map(|f| judge.ssr(f));
                    let m = model_of(&top.candidate.label());
                    let against = match (s_inner, m) {
                        (Some(s), Some(m)) => judge.test(top, m, s, true),
                        _ => None,
                    };
                    if !against.as_ref().is_some_and(EffectTest::passes) {
                        ranking[..=j].rotate_right(1);
                        notes.push(format!(
                            "{} does not pass the decision rule against the simpler {} it contains: the simpler one is preferred",
                            ranking[1].candidate.label(),
                            ranking[0].candidate.label()
                        ));
                    }
                }
            }
        }
        // a gain a restart made belongs to the model without the effect: the
        // passing leader, or with none passing the refit that passes the
        // likelihood part with the largest margin (its effect below the
        // noise, the rest of its gain the restart's), when it did not start
        // from the baseline, is checked against the model without it
        // refitted from its values
        let passing = ranking.first().is_some_and(Ranked::passes);
        let restart = if passing {
            ranking.first()
        } else {
            ranking
                .iter()
                .filter(|r| {
                    r.fit.is_some() && r.likely_restart() && !checked.contains(&r.candidate.label())
                })
                .max_by(|a, b| margin(a).total_cmp(&margin(b)))
        };
        let top = restart?;
        let label = top.candidate.label();
        let verdict = passing.then(|| top.candidate.clone());
        if top.from_baseline || checked.contains(&label) {
            return verdict;
        }
        checked.push(label.clone());
        let f = top.fit.as_ref().expect("passes implies refitted");
        // the model without the effect, from the candidate's values
        let again = match known.take() {
            Some(k) if k.is_of(top) => k.fit,
            _ => match refit_from_fit(model, &baseline.base, f, baseline, judge) {
                Ok(a) => a,
                Err(_) => return verdict,
            },
        };
        if !lower_minimum(&again, baseline) {
            if passing {
                return verdict;
            }
            // (no verdict: the next such refit is checked)
            continue;
        }
        notes.push(format!(
            "the model without {label}, refitted from that candidate's values, reaches a weighted RMS {:.3}x lower than the first baseline: the better baseline is kept and every candidate is judged against it",
            baseline.after_cost / again.after_cost
        ));
        let s0 = judge.ssr(&again);
        for r in ranking.iter_mut().filter(|r| r.fit.is_some()) {
            r.evidence.rmse_before = again.after_rmse;
            if let Some(m) = model_of(&r.candidate.label()) {
                judge.judge(r, m, s0);
            }
        }
        *baseline = again;
    }
}

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
/// replaces them), so its test says what one shared offset explains.
fn sensor_offsets_from_nuisance(
    ranking: &mut [Ranked],
    text: &str,
    model: &Model,
    baseline: &FitResult,
    judge: &Judge<'_>,
) {
    let opts = judge.opts;
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
        let Ok(a) = fit(model, judge.experiments, &without) else {
            continue;
        };
        let Ok(edited) = r.candidate.apply(text) else {
            continue;
        };
        let Ok(m) = model_from_text(&r.candidate.label(), &edited) else {
            continue;
        };
        // the candidate (its refit has no per-experiment offset there),
        // started at the offsets' mean. Both it and its null `a` start from
        // the baseline's values (unless the search's refit was a second
        // start): no restart is in the gain, and the restart check of
        // `decide`, which refits the model *with* the per-experiment
        // offsets, would compare it with another null (one that holds the
        // offset in the files' zeros)
        let (b, from_baseline) = match r.fit.clone() {
            Some(f) => (f, r.from_baseline),
            None => {
                for e in r.parameters.iter_mut().take(1) {
                    e.value = mean;
                }
                match refit_from(
                    (&r.candidate, &r.parameters),
                    &m,
                    horizon,
                    Some((model, baseline)),
                    true,
                    judge.experiments,
                    opts,
                ) {
                    Ok(f) => (f, true),
                    Err(_) => continue,
                }
            }
        };
        r.evidence.rmse_before = a.after_rmse;
        r.evidence.acts_where = format!(
            "the per-experiment offsets of {coord} agree (mean {mean:.4e}): one sensor offset; {}",
            r.evidence.acts_where
        );
        credit(r, b, from_baseline);
        let s0 = judge.ssr(&a);
        judge.judge(r, &m, s0);
    }
}

/// The simpler effect `ranking[j]` nested in the bigger one that leads,
/// `ranking[0]`: refitted from the bigger one's values too, the better of
/// its fits kept and judged. The rule between the two compares their
/// minima, and the simpler one's refit from the baseline can stall where
/// the bigger one's extra freedom escaped: on demo_coulomb the Stribeck
/// refit reached the truth where the Coulomb refit from the baseline
/// stalled at 2.3x its weighted RMS; on a Furuta pendulum with lumped
/// parameters the Coulomb refit stopped at 2.7x the Stribeck's, which was
/// at the floor with the truth a Coulomb friction.
fn simpler_from_bigger<'m>(
    ranking: &mut [Ranked],
    j: usize,
    model_of: &impl Fn(&str) -> Option<&'m Model>,
    model: &Model,
    baseline: &FitResult,
    judge: &Judge<'_>,
    notes: &mut Vec<String>,
) {
    let (Some(m), Some(big)) = (
        model_of(&ranking[j].candidate.label()),
        ranking[0].fit.as_ref(),
    ) else {
        return;
    };
    let own = ranking[j].fit.as_ref();
    let base = own.map_or_else(
        || values_from(m, (model, &baseline.base)),
        |f| f.base.clone(),
    );
    let Ok(again) = refit_from_fit(m, &base, big, baseline, judge) else {
        return;
    };
    if own.is_some_and(|f| again.after_cost >= f.after_cost) {
        return;
    }
    if let Some(f) = own {
        notes.push(format!(
            "{} refitted from {}'s values reaches a weighted RMS {:.3}x lower than its first refit: that fit is kept",
            ranking[j].candidate.label(),
            ranking[0].candidate.label(),
            f.after_cost / again.after_cost
        ));
    }
    credit(&mut ranking[j], again, false);
    let s0 = judge.ssr(baseline);
    judge.judge(&mut ranking[j], m, s0);
}

/// Model `m` refitted from fit `f`'s values (its estimates over `base`, its
/// nuisance warm), on the baseline's horizon, as a screening refit.
fn refit_from_fit(
    m: &Model,
    base: &[f64],
    f: &FitResult,
    baseline: &FitResult,
    judge: &Judge<'_>,
) -> Result<FitResult, FitError> {
    let start = with_estimates(m, base.to_vec(), &f.parameters);
    let horizon = baseline.segments.map_or(Horizon::Whole, Horizon::Segments);
    let mut o = screening(judge.opts, start, horizon);
    o.warm = Some(f.warm.clone());
    fit(m, judge.experiments, &o)
}

/// Record candidate `r`'s refit `f` (its test is the caller's).
fn credit(r: &mut Ranked, f: FitResult, from_baseline: bool) {
    r.from_baseline = from_baseline;
    r.evidence.rmse_after = Some(f.after_rmse);
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
/// of the fastest the target moves in the Coulomb fit. On the rate
/// survey's Stribeck pendulum (vs = 0.1 rad/s, top speed about 5.5 rad/s)
/// starts at 0.03 and 0.1 reach the truth from the Coulomb fit, 0.3 and 1
/// stall where the refit from the baseline did (the hump 0.02 rad/s wide:
/// the Coulomb friction again).
const STRIBECK_VS_STARTS: [f64; 2] = [1.0 / 50.0, 1.0 / 200.0];

/// Refit Stribeck candidate `r` (model `m`) from the fit of the Coulomb
/// friction on its target (`coulomb`: that model, its fit, whether it
/// started from the baseline): the model's parameters where the Coulomb
/// fit left them, `Fc` at 0.8 and `Fs` at 2 times its level, `vs` at
/// [`STRIBECK_VS_STARTS`] of the target's top speed; the best refit is
/// kept when it beats the one `r` has. The nuisance (initial states,
/// sensor zeros) is estimated again from the records, not taken from the
/// Coulomb fit: there it stands in for part of the hump the Coulomb law
/// lacks (bench `stribeck_alpha`: pendulum zeros of -1e-3 rad against
/// -2e-4 at the truth held the refit at 2.27 noise RMS; estimated again,
/// 0.82).
fn stribeck_from_coulomb(
    r: &mut Ranked,
    m: &Model,
    (coulomb_model, coulomb, coulomb_from_baseline): (&Model, &FitResult, bool),
    experiments: &[Experiment],
    opts: &DiagnoseOptions,
) {
    let target = r.candidate.target.clone();
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
    let Some(fc) = index(coulomb_model, "Fc")
        .map(|k| coulomb.base[k])
        .filter(|v| *v > 0.0)
    else {
        return;
    };
    // the fastest the target moves in the Coulomb fit's simulation
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
        let Ok(f) = fit(m, experiments, &screening(opts, s, horizon)) else {
            continue;
        };
        // no hump wanted from there (Fs down to Fc): the next start cannot
        // do better than the Coulomb friction either
        let hump = f.base[i_fs] > f.base[i_fc];
        if best.as_ref().is_none_or(|b| f.after_cost < b.after_cost) {
            best = Some(f);
        }
        if !hump {
            break;
        }
    }
    if let Some(f) = best {
        if r.fit.as_ref().is_none_or(|g| f.after_cost < g.after_cost) {
            credit(r, f, coulomb_from_baseline);
        }
    }
}

/// A screening refit stops when a step lowers the SSR by less than this
/// fraction. The decision compares sums of squares through
/// `N_eff ln(S0/S1)` against `k ln N_eff`: an error `e` in `ln S` moves
/// the statistic by `N_eff e`, a hundredth of the threshold for `N_eff e <
/// 0.01 ln N_eff`, i.e. `e < 2e-4` up to `N_eff` of about 350 residual
/// correlation times. Not looser: a slow descent can still be going
/// somewhere (the vocabulary's Stribeck friction on the arm, refitted from
/// nominal values, stopped at 2.05x with 1e-3 and went on to 53x with
/// 2e-4).
pub const SCREENING_TOLERANCE: f64 = 2e-4;

/// The weighted RMS up to which a screening refit ties with `baseline`:
/// its sum of squares above the baseline's by less than the screening
/// tolerance, the relative change a screening refit no longer resolves
/// (the mirror of [`lower_minimum`]). A candidate's refit that starts at the
/// baseline's own values (its effect nulled) reproduces the baseline's cost
/// only to rounding; within this level it is as good as the baseline: its
/// give-up may stop it there ([`GiveUp::once_at`]) and it was not trapped.
fn tie_level(baseline: &FitResult) -> f64 {
    baseline.after_cost / (1.0 - SCREENING_TOLERANCE).sqrt()
}

/// Whether `again`, the baseline model refitted from a candidate's values,
/// found a lower minimum than `baseline` (lower by more than a screening
/// refit resolves, [`crate::fit::lower_beyond`]): a tie is no reason to
/// replace the baseline every candidate was judged against (one at 1.000x
/// did, and the effect the records had was then judged against a null no
/// better than the first).
fn lower_minimum(again: &FitResult, baseline: &FitResult) -> bool {
    crate::fit::lower_beyond(again, baseline, SCREENING_TOLERANCE)
}

/// Refit one candidate's model from the baseline (its estimates, its
/// nuisance as a warm start) and the equation-error estimates of the
/// candidate's own parameters; if that ends above the baseline (the
/// candidate contains the baseline, so it can do at least as well: the
/// warm start trapped it; beyond a tie for a refit that may give up, and
/// anywhere not below it for a dry friction that holds its joint, see
/// [`holds_its_joint`]), again from the same values with the growing
/// horizons, the better kept; if both fail, from the model's nominal
/// values.
fn refit(
    r: &mut Ranked,
    m: &Model,
    model: &Model,
    baseline: &FitResult,
    experiments: &[Experiment],
    opts: &DiagnoseOptions,
) {
    let horizon = baseline.segments.map_or(Horizon::Whole, Horizon::Segments);
    let base = Some((model, baseline));
    let mut outcome = refit_from(
        (&r.candidate, &r.parameters),
        m,
        horizon,
        base,
        true,
        experiments,
        opts,
    );
    // (not on segments: there is no growing horizon to take)
    // (a refit that may give up stops within a tie of the baseline
    // ([`tie_level`]): not trapped there; a dry friction that holds its
    // joint, refitted from the baseline's nuisance (fitted for a joint that
    // moves), found nothing when it ends at the baseline's cost, not below
    // it ([`holds_its_joint`]); an effect with a shape parameter is
    // trapped above the baseline)
    let trapped = baseline.segments.is_none()
        && outcome.as_ref().map_or(true, |f| {
            if holds_its_joint(&r.candidate, opts) {
                !lower_minimum(f, baseline)
            } else if r.candidate.linear_in_parameters() {
                f.after_cost > tie_level(baseline)
            } else {
                f.after_cost > baseline.after_cost
            }
        });
    if trapped {
        let cold = refit_from(
            (&r.candidate, &r.parameters),
            m,
            horizon,
            base,
            false,
            experiments,
            opts,
        );
        outcome = match (outcome, cold) {
            (Ok(a), Ok(b)) => Ok(if b.after_cost < a.after_cost { b } else { a }),
            (Ok(a), Err(_)) => Ok(a),
            (Err(_), cold) => cold,
        };
    }
    let outcome = outcome.map(|f| (f, true)).or_else(|_| {
        refit_from(
            (&r.candidate, &r.parameters),
            m,
            horizon,
            None,
            false,
            experiments,
            opts,
        )
        .map(|f| (f, false))
    });
    match outcome {
        Ok((f, from_baseline)) => credit(r, f, from_baseline),
        Err(e) => r.error = Some(e.to_string()),
    }
}

/// Refit candidate `r` again with the growing horizons, from the
/// baseline's values and from the model's nominal values, and keep the
/// best. The first refit started warm (the baseline's nuisance, straight to
/// the whole records); there a phase error of an oscillation holds the fit
/// in a local minimum that the short horizons first fitted avoid (the
/// bundled demo_coulomb: the Coulomb friction refitted warm stopped at
/// RMSE 7.7e-4 with Fc 7.5 % high, refitted from the same values with the
/// growing horizons it reached the truth's 3.3e-4). A baseline distorted by
/// the missing effect can trap even that (shared spring_arm case: 5.2x
/// from the baseline, 438x from the nominal values), hence the nominal
/// start. A candidate the equation error could not estimate (a scan with
/// no admissible value) starts its own parameters from the template.
fn second_start(
    r: &mut Ranked,
    m: &Model,
    model: &Model,
    baseline: &FitResult,
    experiments: &[Experiment],
    opts: &DiagnoseOptions,
) {
    let horizon = baseline.segments.map_or(Horizon::Whole, Horizon::Segments);
    let unscored = r.evidence.bic_gain == 0.0 && r.evidence.residual_share == 0.0;
    let estimates: Vec<Estimate> = if unscored {
        Vec::new()
    } else {
        r.parameters.clone()
    };
    // the baseline's values with the growing horizons (not on segments:
    // there is no growing horizon to take), then the nominal values
    let mut starts = Vec::new();
    if baseline.segments.is_none() {
        starts.push(Some((model, baseline)));
    }
    starts.push(None);
    for from in starts {
        if let Ok(f) = refit_from(
            (&r.candidate, &estimates),
            m,
            horizon,
            from,
            false,
            experiments,
            opts,
        ) {
            // credited as a restart (not the warm refit from the baseline),
            // so a winner among them is checked against the model without
            // it refitted from its values (`decide`): a gain that belongs
            // to the restart is not the effect's
            if r.fit.as_ref().is_none_or(|g| f.after_cost < g.after_cost) {
                credit(r, f, false);
            }
        }
    }
}

/// Refit candidate `r`'s model `m` from the baseline's values (`from`) or
/// the nominal ones, with the candidate's equation-error estimates; `warm`
/// starts the nuisance where the baseline's ended and goes straight to its
/// horizon (see [`FitOptions::warm`]).
fn refit_from(
    (candidate, estimates): (&Candidate, &[Estimate]),
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
    // the effect at its template start, next to the baseline itself, is
    // offered too: a linearised estimate that fits noise can start far
    // above the baseline. For an effect linear in its parameters so is the
    // baseline itself, the effect at its null value, where its
    // sensitivities do not vanish (they do for a shape parameter: a
    // saturation beyond every input): such a refit never starts above the
    // baseline's cost, and there the Gauss-Newton model's reach is the
    // score test of the effect ([`GiveUp`]). The QUBE's added inertia on
    // the pendulum, from its estimate and from its template, descended 50
    // and 102 iterations to 2,700 and 160 times the baseline's weighted RMS,
    // and was then started again cold. The price: where the baseline's own
    // parameters absorbed the effect (a Coulomb friction on a QUBE pendulum
    // taken up by its damping) the truth starts above the baseline, the
    // null is taken, and its refit may stop in another basin (4 times the
    // floor where the estimate's reached it); the search then refits the
    // rest and starts the leader again from the nominal values, and names
    // the same effect (0.9 -> 3.5 s CPU on that record).
    // A threshold effect's template can lie beyond everything the records
    // reach (a 5 V saturation on a 1.2 V RMS multisine): there it acts on
    // no sample, so that start is the baseline itself with the effect's
    // sensitivities zero, and a refit from it ends on the baseline's cost
    // (the rotary pendulum's saturation and speed limit, first by
    // equation error, refitted to a weighted RMS ratio of exactly 1 while
    // a fit from the scan's level reached the noise floor). Not offered.
    let alternatives: Vec<Vec<f64>> = match from {
        Some(_) if !candidate.linear_in_parameters() => {
            if acts_on_records(candidate, m, &start, experiments, &opts.equation_error) {
                vec![start.clone()]
            } else {
                Vec::new()
            }
        }
        // (every such effect's null, a level at zero, is inside its box)
        Some(_) => vec![start.clone(), candidate.nulled(m, &start, false)],
        None => Vec::new(),
    };
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
    fo.alternative_starts = alternatives;
    fit(m, experiments, &fo)
}

/// Whether what `candidate` does near its null is its first-order term, so
/// that the Gauss-Newton model at the baseline (the effect at zero) is the
/// score test of the effect: an effect linear in its parameters
/// ([`EffectInstance::linear_in_parameters`]) that does not hold its joint
/// ([`holds_its_joint`]).
fn first_order_at_null(candidate: &Candidate, opts: &DiagnoseOptions) -> bool {
    candidate.linear_in_parameters() && !holds_its_joint(candidate, opts)
}

/// A Coulomb friction under the sticking law: its level also decides where
/// its joint holds (a mode, not a term), so at zero, where the joint never
/// sticks, its sensitivity is the sliding term alone (a Furuta arm held by
/// 0.015 N m through its free swings: the warm refits from zero and from the
/// equation-error estimate stayed at a weighted RMS ratio of 1.000, the
/// refit with the growing horizons reached 52.8). Such an effect is
/// refitted to the tolerance (no give-up), and a warm refit of it that ends
/// at the baseline's cost is started again with the growing horizons (see
/// `refit`). Its nulled start is still offered, the lowest starting cost
/// choosing as for any linear effect, although no cost tells which basin
/// the later steps need: a cart's 0.5 N friction on a double pendulum,
/// refitted from its estimate alone, ended lower (weighted RMS ratio 21.0
/// against 17.2 with the nulled start offered) but where the Stribeck
/// refit from its values no longer reached the floor, and three false
/// effects followed.
fn holds_its_joint(candidate: &Candidate, opts: &DiagnoseOptions) -> bool {
    candidate.effect == "coulomb_friction"
        && matches!(opts.fit.sim.dry_friction, DryFriction::Sticking)
}

/// Whether `candidate` acts on the records at `values` (`m`'s parameter
/// order): a threshold effect ([`EffectInstance::threshold`]) only when
/// its level lies below what its target reaches on some record, the
/// largest magnitude of the recorded input, or the largest speed of the
/// coordinate as the equation-error ranking smooths it (the same
/// Savitzky-Golay derivative its level scan reads); any other effect
/// always. A record that cannot be read so counts as reached.
fn acts_on_records(
    candidate: &Candidate,
    m: &Model,
    values: &[f64],
    experiments: &[Experiment],
    smoothing: &EquationErrorOptions,
) -> bool {
    let Some((name, reach)) = candidate.threshold() else {
        return true;
    };
    let Some(level) = m
        .parameters
        .iter()
        .position(|p| p.name == name)
        .and_then(|j| values.get(j).copied())
    else {
        return true;
    };
    let target = &candidate.target;
    experiments.iter().any(|e| {
        let Ok(sig) = Signals::from_experiment(m, e) else {
            return true;
        };
        match reach {
            Reach::InputMagnitude => match m.inputs.iter().position(|u| u.name == *target) {
                Some(j) => sig.u[j].iter().any(|u| u.abs() > level),
                None => true,
            },
            Reach::Speed => {
                let Some(i) = m.coordinates.iter().position(|c| c.name == *target) else {
                    return true;
                };
                let dt = sig.sample_time();
                let h = smoothing.half_width(dt);
                match savitzky_golay::kernel(h, smoothing.order, 1, dt) {
                    Ok(k1) if sig.q[i].len() > 2 * h + 1 => savitzky_golay::apply(&k1, &sig.q[i])
                        .iter()
                        .any(|v| v.abs() > level),
                    _ => true,
                }
            }
        }
    })
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
        alternative_starts: Vec::new(),
        simulate_start: false,
        ..opts.fit.clone()
    }
}
