//! The data of identify's HTML report ([`crate::report_html`]): the story
//! as printed, the before/after table, per experiment the measured outputs
//! overlaid with every stage's simulation (fit % per stage), the inputs,
//! the last stage's residual (an envelope) and residual tests, and the
//! added effects' model-file snippets.
//!
//! The report is built from a [`Story`] and the measured experiments; it
//! carries the `--json` summary of `plantc identify` as it is (`summary`),
//! so the file a person reads and the JSON a script reads say the same.
//! Every signal is reduced to at most [`COLUMNS`] columns (the minimum and
//! maximum of each, which keeps peaks), so a report stays small whatever
//! the records' length.

use serde::Serialize;

use crate::data::Experiment;
use crate::metrics::FitReport;
use crate::plot::{envelope, FigureChannels};
use crate::residual_tests::{residual_test, ResidualTest, DEFAULT_LAGS};
use crate::story::Story;

/// Columns a signal is reduced to (about the report figures' width in
/// pixels: one column per pixel keeps what the eye can see).
pub const COLUMNS: usize = 800;

/// Everything the HTML report shows.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// The model file, as given.
    pub model: String,
    /// The story as `plantc identify` prints it (rounds, the decision
    /// rule's lines, the table).
    pub story: String,
    /// `plantc identify --json`'s summary (verdict, rounds, fit, stages).
    pub summary: serde_json::Value,
    /// The stages in order, with their whole-record fits.
    pub stages: Vec<StageRow>,
    /// The rounds of diagnosis: candidates and the rule's verdict on each.
    pub rounds: Vec<RoundRow>,
    /// Per experiment: the figures' data.
    pub experiments: Vec<ExperimentFigure>,
    /// The last stage's residual tests, per experiment and output.
    pub residual_tests: Vec<ResidualTest>,
    /// The label of the stage the residuals and their tests are of.
    pub residual_stage: String,
    /// Model-file snippets of the effects added (and of simpler forms put
    /// in their place).
    pub snippets: Vec<Snippet>,
}

/// One stage of the before/after table.
#[derive(Clone, Debug, Serialize)]
pub struct StageRow {
    /// `nominal`, `+ coulomb_friction@alpha, fitted`...
    pub label: String,
    /// Fit % and RMSE of the whole records simulated.
    pub report: FitReport,
    /// Fit % and RMSE of the segments the stage was fitted on (an extra
    /// view, when it was fitted on segments).
    pub segments: Option<FitReport>,
    /// The fit's cost (weighted RMS), where a fit made the stage.
    pub cost: Option<f64>,
}

/// One round of diagnosis.
#[derive(Clone, Debug, Serialize)]
pub struct RoundRow {
    /// From 1.
    pub round: usize,
    /// The candidates refitted, in rank order.
    pub candidates: Vec<CandidateRow>,
    /// The effect added (`coulomb_friction@alpha`), None when none was.
    pub effect: Option<String>,
}

/// A candidate effect of a round and the decision rule's line on it.
#[derive(Clone, Debug, Serialize)]
pub struct CandidateRow {
    /// `coulomb_friction@alpha`.
    pub label: String,
    /// RMSE of its refit.
    pub refit_rmse: f64,
    /// Its equation-error rank.
    pub rank: usize,
    /// Whether it passed the decision rule.
    pub passes: bool,
    /// The rule's line, as identify prints it.
    pub rule: String,
}

/// An effect's model-file snippet.
#[derive(Clone, Debug, Serialize)]
pub struct Snippet {
    /// What it is: `round 1: coulomb_friction@alpha`.
    pub title: String,
    /// The lines added to the model file.
    pub text: String,
}

/// The figures of one experiment.
#[derive(Clone, Debug, Serialize)]
pub struct ExperimentFigure {
    /// The experiment's name.
    pub name: String,
    /// First and last sample time (s).
    pub span: (f64, f64),
    /// The outputs, measured and simulated.
    pub outputs: Vec<OutputFigure>,
    /// The inputs the file holds.
    pub inputs: Vec<Trace>,
}

/// One output of one experiment: measured, every stage, the residual.
#[derive(Clone, Debug, Serialize)]
pub struct OutputFigure {
    /// The channel.
    pub channel: String,
    /// Its unit.
    pub unit: String,
    /// The measured signal.
    pub measured: Trace,
    /// Each stage's simulation, in stage order.
    pub stages: Vec<StageTrace>,
    /// The last stage's residual (measured - simulated): `(t, min, max)`
    /// per column.
    pub residual: Vec<(f64, f64, f64)>,
}

/// One stage's simulation of one output.
#[derive(Clone, Debug, Serialize)]
pub struct StageTrace {
    /// The stage's label.
    pub label: String,
    /// Its fit % on this output (None: a constant channel).
    pub fit_percent: Option<f64>,
    /// The simulation diverged (no fit % to speak of).
    pub diverged: bool,
    /// The reduced signal (non-finite samples left out).
    pub trace: Trace,
}

/// A named signal reduced to at most [`COLUMNS`] columns: `(t, value)`
/// points in time order.
#[derive(Clone, Debug, Serialize)]
pub struct Trace {
    /// The channel's name.
    pub name: String,
    /// Its unit.
    pub unit: String,
    /// The points.
    pub points: Vec<(f64, f64)>,
}

impl Trace {
    /// `x` over `t` reduced to the minimum and maximum of each of
    /// [`COLUMNS`] equal sample ranges (time columns for a uniform rate),
    /// in time order ([`crate::plot::min_max`]).
    pub fn reduced(name: &str, unit: &str, t: &[f64], x: &[f64]) -> Trace {
        let points = crate::plot::min_max(t, x, COLUMNS);
        Trace {
            name: name.to_string(),
            unit: unit.to_string(),
            points,
        }
    }
}

impl Report {
    /// The report of `story` told on `measured` with `channels` (the
    /// model's outputs and inputs with their units; see
    /// [`FigureChannels::of_model`]); `text` is the story as printed,
    /// `summary` the `--json` summary.
    pub fn new(
        model: &str,
        story: &Story,
        measured: &[Experiment],
        channels: &FigureChannels,
        text: &str,
        summary: serde_json::Value,
    ) -> Report {
        let stages = story
            .stages
            .iter()
            .map(|s| StageRow {
                label: s.label.clone(),
                report: s.report.clone(),
                segments: s.segment_report.clone(),
                cost: s.cost,
            })
            .collect();
        let rounds = story
            .rounds
            .iter()
            .enumerate()
            .map(|(k, r)| RoundRow {
                round: k + 1,
                candidates: r
                    .ranking
                    .iter()
                    .filter(|c| c.fit.is_some())
                    .map(|c| CandidateRow {
                        label: c.candidate.label(),
                        refit_rmse: c.fit.as_ref().map_or(f64::NAN, |f| f.after_rmse),
                        rank: c.evidence.equation_error_rank,
                        passes: c.passes(),
                        // the words identify prints
                        rule: c.rule_line(),
                    })
                    .collect(),
                effect: r.effect.as_ref().map(|e| e.label()),
            })
            .collect();
        let mut snippets: Vec<Snippet> = story
            .rounds
            .iter()
            .enumerate()
            .filter_map(|(k, r)| {
                let e = r.effect.as_ref()?;
                Some(Snippet {
                    title: format!("round {}: {}", k + 1, e.label()),
                    text: e.snippet(),
                })
            })
            .collect();
        for s in &story.simplifications {
            snippets.push(Snippet {
                title: format!(
                    "simplified: {} in place of {} (round {})",
                    s.to.label(),
                    s.from.label(),
                    s.round
                ),
                text: s.to.snippet(),
            });
            if let Some(then) = &s.then {
                snippets.push(Snippet {
                    title: format!("added with the simplification: {}", then.label()),
                    text: then.snippet(),
                });
            }
        }
        for r in &story.removals {
            snippets.push(Snippet {
                title: format!(
                    "removed: {} (round {}), no longer needed",
                    r.effect.label(),
                    r.round
                ),
                text: r.effect.snippet(),
            });
        }
        let last = story.stages.last();
        let mut residual_tests = Vec::new();
        let experiments = measured
            .iter()
            .enumerate()
            .map(|(i, m)| {
                let t = &m.t;
                let span = (
                    t.first().copied().unwrap_or(0.0),
                    t.last().copied().unwrap_or(0.0),
                );
                let inputs: Vec<(&str, &str, &[f64])> = channels
                    .inputs
                    .iter()
                    .filter_map(|(n, u)| {
                        let v = m.values(n)?;
                        (v.len() == t.len()).then_some((n.as_str(), u.as_str(), v))
                    })
                    .collect();
                let mut outputs = Vec::new();
                for (ch, unit) in &channels.outputs {
                    let Some(y) = m.values(ch) else {
                        continue;
                    };
                    let stage_traces = story
                        .stages
                        .iter()
                        .filter_map(|s| {
                            let sim = s.simulated.get(i)?.values(ch)?;
                            let fit = s.report.experiments.get(i)?.channels.get(ch)?;
                            Some(StageTrace {
                                label: s.label.clone(),
                                fit_percent: fit.fit_percent,
                                diverged: fit.diverged,
                                trace: Trace::reduced(ch, unit, t, sim),
                            })
                        })
                        .collect();
                    let residual = last
                        .and_then(|s| s.simulated.get(i)?.values(ch))
                        .filter(|sim| sim.len() == y.len())
                        .map(|sim| {
                            let r: Vec<f64> = y.iter().zip(sim).map(|(a, b)| a - b).collect();
                            let dt = m.sample_time().unwrap_or(0.0);
                            let ins: Vec<(&str, &[f64])> =
                                inputs.iter().map(|(n, _, v)| (*n, *v)).collect();
                            residual_tests.push(residual_test(
                                &m.name,
                                ch,
                                &r,
                                &ins,
                                DEFAULT_LAGS,
                                dt,
                            ));
                            envelope(t, &r, span, COLUMNS)
                        })
                        .unwrap_or_default();
                    outputs.push(OutputFigure {
                        channel: ch.clone(),
                        unit: unit.clone(),
                        measured: Trace::reduced(ch, unit, t, y),
                        stages: stage_traces,
                        residual,
                    });
                }
                ExperimentFigure {
                    name: m.name.clone(),
                    span,
                    outputs,
                    inputs: inputs
                        .iter()
                        .map(|(n, u, v)| Trace::reduced(n, u, t, v))
                        .collect(),
                }
            })
            .collect();
        Report {
            model: model.to_string(),
            story: text.to_string(),
            summary,
            stages,
            rounds,
            experiments,
            residual_tests,
            residual_stage: last.map(|s| s.label.clone()).unwrap_or_default(),
            snippets,
        }
    }
}
