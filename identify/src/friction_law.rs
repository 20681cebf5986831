//! Which dry-friction law the records follow.
//!
//! plantc simulates dry friction sticking ([`DryFriction::Sticking`]): a
//! joint at rest stays at rest while the force on it is below its static
//! level, as a rig's joints do. Records made by a simulator that integrates
//! `sign(v)` as `tanh(v / w)` (the shared synthetic cases, whose simulator
//! the identification notes name in trap 8), or from a joint whose friction
//! yields before it slides, *creep* instead: a held joint drifts at about
//! `w atanh(load / level)`, and the creep of a held arm drains a swinging
//! pendulum where a stuck arm would not. Such records do not lack an effect:
//! the model's dry friction follows another law. Fitted under the sticking
//! law, the shared clean case's baseline stayed 1.6x the floor and the rule
//! named a Coulomb friction of 1.65e-5 N m on the pendulum to stand in for
//! the creep.
//!
//! [`creeping_law`] tries the creeping law `tanh(v / w)` while a
//! diagnosis' baseline is above the noise floor and the model has dry
//! friction. The width is scanned on a log grid with the baseline's values;
//! the law is pursued only when some width beats sticking there by the
//! likelihood part of the decision rule. The width is then fitted with the
//! model's values, as a parameter of the model, from the scan's best and
//! every half-decade above it (the scan at a sticking fit's values finds it
//! too narrow: a sticking model lets a held joint move only by lowering its
//! friction level, and with the level restored the same motion needs a
//! wider creep; on the shared clean case the scan's best was 4e-4 rad/s,
//! fits started at 4e-4 and 7e-4 stalled at 1.31 and 1.45 times the floor,
//! those from 1.2e-3 and 2.1e-3 reached the truth's 1.0e-3 at the floor).
//! The law is adopted when that fit passes the likelihood part of the rule
//! against the sticking baseline (`k = 1`: the width) and its residual is
//! at the noise floor: a law is a convention of the whole simulation, taken
//! only when it leaves nothing for an effect to explain; a diagnosis takes
//! it over a verdict whose margin is smaller. With an effect missing too,
//! the effect is named first and the law tried again on the next round's
//! model (the shared Coulomb case: round 1 names the pendulum's friction,
//! round 2 finds both joints creeping at 1.2e-3 rad/s, at the floor).
//!
//! The grid spans the widths a record can tell apart: from the speed at
//! which a creep would move a joint by one encoder quantum (its noise floor
//! times `sqrt(12)`) over the longest record, below which creeping and
//! sticking look the same, to a tenth of the joint's RMS speed in the
//! records, above which `tanh(v / w)` is a viscous friction over most of
//! the motion (the model's damping stands for that); four points a decade.
//! A start that cannot reach the floor stops short ([`GiveUp`] below
//! `sqrt(2)` times the floor's weighted RMS, which every channel must be
//! under): the law is adopted only there.

use plantc_derive::model::Model;

use crate::data::Experiment;
use crate::decision::{effective_samples, EffectTest};
use crate::diagnose::{model_from_text, Judge};
use crate::experiment_sim::{dynamics_outputs, DryFriction};
use crate::fit::{fit, simulate_as, values_from, FitOptions, FitResult, GiveUp};

/// Grid points per decade of the width scan. The scan only places the
/// fits' starts, at its best point and every half-decade above: two points
/// a decade would be the least that resolves those; four put the best
/// within a quarter decade of the scan's minimum.
const PER_DECADE: f64 = 4.0;

/// The name of the width parameter while it is fitted.
const WIDTH: &str = "creep_width";

/// The creeping dry-friction law, adopted for the records.
#[derive(Clone, Debug, PartialEq)]
pub struct CreepingLaw {
    /// The width `w` of `tanh(v / w)`, in the coordinates' speed unit.
    pub width: f64,
    /// The baseline refitted under that law.
    pub fit: FitResult,
    /// The decision rule's test of the law (`k = 1`, its width) against
    /// the baseline fitted sticking.
    pub test: EffectTest,
}

impl CreepingLaw {
    /// The law in words, with the rule's numbers.
    pub fn describe(&self) -> String {
        format!(
            "the records' dry friction creeps: simulated as tanh(v / {:.3e}) instead of sticking, the baseline reaches the noise floor ({}); pass `--friction smooth:{:.3e}` to simulate the model so",
            self.width,
            self.test.describe(),
            self.width
        )
    }
}

/// The coordinates of `model` with a dry-friction level.
fn dry_coordinates(model: &Model) -> Vec<usize> {
    dynamics_outputs(model, DryFriction::Sticking)
        .map(|c| {
            c.dry
                .iter()
                .enumerate()
                .filter(|(_, d)| **d)
                .map(|(i, _)| i)
                .collect()
        })
        .unwrap_or_default()
}

/// The unit of the width: the speed unit of the dry-friction coordinates
/// (None when they mix angles and lengths).
fn width_unit(model: &Model, dry: &[usize]) -> Option<&'static str> {
    let units: Vec<&'static str> = dry
        .iter()
        .map(|&i| match model.coordinates[i].kind {
            plantc_derive::model::CoordinateKind::Angle => "rad/s",
            _ => "m/s",
        })
        .collect();
    let first = *units.first()?;
    units.iter().all(|u| *u == first).then_some(first)
}

/// The widths the records can tell apart (see the module docs), or None.
fn width_bracket(
    model: &Model,
    experiments: &[Experiment],
    baseline: &FitResult,
    dry: &[usize],
) -> Option<(f64, f64)> {
    let longest = experiments
        .iter()
        .filter_map(|e| Some(e.t.last()? - e.t.first()?))
        .fold(0.0f64, f64::max);
    let mut lo = f64::INFINITY;
    let mut hi = 0.0f64;
    for &i in dry {
        let name = &model.coordinates[i].name;
        let quantum = baseline
            .weights
            .iter()
            .find(|w| &w.name == name)
            .map(|w| w.noise * 12f64.sqrt())?;
        lo = lo.min(quantum / longest);
        let (mut ss, mut count) = (0.0, 0usize);
        for e in experiments {
            let Some(q) = e.values(name) else { continue };
            for k in 1..q.len().min(e.t.len()) {
                let dt = e.t[k] - e.t[k - 1];
                let v = (q[k] - q[k - 1]) / dt;
                if v.is_finite() && dt > 0.0 {
                    ss += v * v;
                    count += 1;
                }
            }
        }
        if count > 0 {
            hi = hi.max(0.1 * (ss / count as f64).sqrt());
        }
    }
    (lo.is_finite() && lo > 0.0 && hi > lo).then_some((lo, hi))
}

/// Try the creeping law on a diagnosis' baseline (see the module docs):
/// Some when it is adopted.
pub(crate) fn creeping_law(
    text: &str,
    model: &Model,
    judge: &Judge<'_>,
    baseline: &FitResult,
) -> Option<CreepingLaw> {
    let (experiments, opts) = (judge.experiments(), judge.options());
    if opts.fit.sim.dry_friction != DryFriction::Sticking || baseline.segments.is_some() {
        return None;
    }
    let dry = dry_coordinates(model);
    let unit = width_unit(model, &dry)?;
    if model.parameters.iter().any(|p| p.name == WIDTH) {
        return None;
    }
    let (lo, hi) = width_bracket(model, experiments, baseline, &dry)?;
    // (the baseline's: `decide` may have replaced the judge's)
    let effective = effective_samples(&judge.residuals(baseline));
    let law = |dry_friction: DryFriction| FitOptions {
        sim: crate::experiment_sim::SimOptions {
            dry_friction,
            ..opts.fit.sim
        },
        ..opts.fit.clone()
    };
    let under = |w: f64| law(DryFriction::Smooth { width: w });
    let steps = (PER_DECADE * (hi / lo).log10()).ceil().max(1.0) as usize;
    let grid: Vec<f64> = (0..=steps)
        .map(|k| lo * (hi / lo).powf(k as f64 / steps as f64))
        .collect();
    // 1. the scan at the baseline's values: pursued only when some width
    //    beats sticking there by the rule's likelihood part
    let scan = |w: Option<f64>| -> f64 {
        let fo = w.map_or_else(|| law(DryFriction::Sticking), &under);
        simulate_as(model, experiments, &fo, baseline, &baseline.base)
            .map_or(f64::INFINITY, |sim| judge.ssr_of(&sim))
    };
    let costs: Vec<f64> =
        crate::parallel::par_map(grid.len() + 1, |k| scan((k < grid.len()).then(|| grid[k])));
    let sticking = costs[grid.len()];
    let best = (0..grid.len())
        .filter(|&k| costs[k].is_finite())
        .min_by(|&a, &b| costs[a].total_cmp(&costs[b]))?;
    if !judge
        .likelihood_test(sticking, costs[best], effective, 1)
        .likely()
    {
        return None;
    }
    // 2. the width fitted with the model's values, as a parameter of the
    //    model (they move together: a creeping arm friction and the
    //    pendulum's damping share the swing's decay). The scan at the
    //    sticking fit's values finds the width too narrow: a sticking
    //    model lets a held joint move only by lowering its friction level,
    //    and with the level restored the same motion needs a wider creep;
    //    so the fit starts at the scan's best and every half-decade above
    //    it, the best end kept. A start that cannot reach the
    //    floor (its weighted RMS below sqrt(2) times the floor's, as every
    //    channel must be) stops there ([`GiveUp`]): the law is adopted
    //    only at the floor.
    let with_width = format!(
        "{text}\nparameter {WIDTH} = {:e} [{unit}] \"width of the dry friction's creep, tanh(v / {WIDTH})\" estimate [{lo:e}, {hi:e}]\n",
        grid[best]
    );
    let m2 = model_from_text("creeping", &with_width).ok()?;
    let parameter = m2.parameters.iter().position(|p| p.name == WIDTH)?;
    let floor = crate::weights::noise_cost(&baseline.weights);
    let starts: Vec<f64> = (0..)
        .map(|k| grid[best] * 10f64.powf(0.5 * k as f64))
        .take_while(|&w| w <= hi)
        .collect();
    let fits: Vec<Option<FitResult>> = crate::parallel::par_map(starts.len(), |k| {
        let mut start = values_from(&m2, (model, &baseline.base));
        start[parameter] = starts[k];
        let fo = FitOptions {
            start: Some(start),
            warm: Some(baseline.warm.clone()),
            multistart: 0,
            give_up: Some(GiveUp {
                once_at: f64::INFINITY,
                unless_below: std::f64::consts::SQRT_2 * floor,
            }),
            ..law(DryFriction::SmoothFitted { parameter })
        };
        fit(&m2, experiments, &fo).ok()
    });
    let g = fits
        .into_iter()
        .flatten()
        .min_by(|a, b| a.after_cost.total_cmp(&b.after_cost))?;
    if g.gave_up || g.after_cost.is_nan() || g.after_cost >= std::f64::consts::SQRT_2 * floor {
        return None;
    }
    let width = g.base[parameter];
    // 3. the model as it stands under that law, from those values (the
    //    story goes on with it)
    let fo = FitOptions {
        start: Some(values_from(model, (&m2, &g.base))),
        warm: Some(g.warm.clone()),
        multistart: 0,
        ..under(width)
    };
    let f = fit(model, experiments, &fo).ok()?;
    let test = judge.likelihood_test(judge.ssr(baseline), judge.ssr(&f), effective, 1);
    (test.likely() && judge.fit_at_floor(&f)).then_some(CreepingLaw {
        width,
        fit: f,
        test,
    })
}
