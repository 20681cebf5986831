//! How much each measured channel counts in a fit: its noise floor,
//! estimated from the data.
//!
//! Each channel's residual is divided by its *noise floor* `sigma` (the RMS
//! the sensor's own noise leaves): the weighted residual is then in units
//! of that noise, a weighted cost of 1 is the noise floor itself, and a
//! sum of squared weighted residuals is, up to the residual's correlation
//! in time, a Gaussian negative log-likelihood. That is what lets the
//! diagnosis decide by a likelihood ratio ([`crate::decision`]) and the
//! nuisance carry Gaussian priors in the same units ([`crate::problem`]).
//! A channel's *spread* (how much it moves) never sets its weight: a
//! channel that barely moves (an arm held by friction, 0.011 rad) would
//! otherwise be blown up to outweigh one that swings (1/spread = 285 per
//! rad against 1.1); the spread is kept only to tell whether a replay
//! follows the data at all ([`crate::fit::follows_data`]).
//!
//! The *noise floor* of a channel is the larger of two estimates:
//! - quantisation: when the samples lie on a grid `q` (an encoder), the
//!   rounding noise `q / sqrt(12)`; a channel with too few distinct steps
//!   to show its grid (it barely moves) takes its smallest step as `q`,
//!   and a constant channel the resolution its numbers are written with;
//! - high-frequency content: the RMS residual of a 5-point local quadratic
//!   fit, scaled to white noise (the residual of white noise of variance
//!   `s^2` through that smoother has variance `18/35 s^2`). On smooth
//!   motion sampled fast the fit is exact up to `dt^3` terms, so what is
//!   left is the noise.
//!
//! A user may override the weight of any channel (`--weight alpha=20`: the
//! residual is multiplied by 20 per SI unit).

use serde::Serialize;

/// Noise floor and weight of one measured channel.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ChannelWeight {
    /// Channel (coordinate) name.
    pub name: String,
    /// Estimated noise floor (RMS, SI).
    pub noise: f64,
    /// Quantisation step when the samples lie on a grid.
    pub quantum: Option<f64>,
    /// Pooled standard deviation about each experiment's mean (SI): how
    /// much the channel moves (not its weight).
    pub spread: f64,
    /// Weight applied to the residual (1 / SI unit): `1 / noise` unless
    /// the user set it.
    pub weight: f64,
    /// Where the noise floor comes from, in words (`encoder quantum
    /// 1.53e-3 rad / sqrt(12)`, `high-frequency noise`).
    pub basis: String,
    /// True when the user set the weight.
    pub overridden: bool,
    /// The simulation's own error on this channel (RMS, SI) when it is
    /// part of the floor ([`with_simulation_error`]).
    pub simulation_error: Option<f64>,
}

/// The quantisation step of a signal, when it is quantised: the smallest
/// nonzero step `q0` between consecutive samples (above print rounding,
/// 1e-7 of the signal's magnitude plus 1e-12), accepted when at least 90 %
/// of the nonzero steps are whole multiples of it within 2 %, then refined
/// by least squares over those steps. Judged on the steps, not on the
/// values: values printed with 9 decimals put a sample 2,000 steps from the
/// first 1e-3 of a step off a grid read from them, and one glitch does not
/// hide an encoder. None for unquantised data (fewer than 10 steps, or
/// steps that are not multiples of the smallest).
pub fn quantum(values: &[f64]) -> Option<f64> {
    let mag = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let tiny = 1e-7 * mag + 1e-12;
    let steps: Vec<f64> = values
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| *d > tiny)
        .collect();
    if steps.len() < 10 {
        return None;
    }
    let q0 = steps.iter().copied().fold(f64::INFINITY, f64::min);
    let (mut on_grid, mut sdm, mut smm) = (0usize, 0.0, 0.0);
    for d in &steps {
        let m = d / q0;
        if (m - m.round()).abs() < 0.02 {
            on_grid += 1;
            sdm += d * m.round();
            smm += m.round() * m.round();
        }
    }
    (on_grid as f64 >= 0.9 * steps.len() as f64).then(|| sdm / smm)
}

/// RMS noise estimated from high-frequency content: the residual of a
/// centred 5-point quadratic fit (Savitzky-Golay smoothing weights
/// `(-3, 12, 17, 12, -3)/35`), scaled to white noise. NaN for fewer than 5
/// samples.
pub fn high_frequency_noise(values: &[f64]) -> f64 {
    if values.len() < 5 {
        return f64::NAN;
    }
    let mut ss = 0.0;
    let mut n = 0usize;
    for w in values.windows(5) {
        let smooth = (-3.0 * w[0] + 12.0 * w[1] + 17.0 * w[2] + 12.0 * w[3] - 3.0 * w[4]) / 35.0;
        let r = w[2] - smooth;
        ss += r * r;
        n += 1;
    }
    (ss / n as f64 / (18.0 / 35.0)).sqrt()
}

/// Noise floor of one channel over several records: the larger of the
/// quantisation noise and the high-frequency estimate (the median over the
/// records, so one bad file does not decide), with the quantum when the
/// samples lie on a grid.
pub fn noise_floor(records: &[&[f64]]) -> (f64, Option<f64>) {
    let (noise, quantum, _) = noise_floor_with_basis(records);
    (noise, quantum)
}

/// The smallest step a record's numbers can resolve when it shows no
/// grid: its smallest nonzero step between samples (an upper bound on its
/// resolution), or, for a record that never changes, the resolution of
/// the numbers themselves (1e-7 of their magnitude, about single
/// precision, plus 1e-12).
fn resolution(values: &[f64]) -> f64 {
    let mag = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let written = 1e-7 * mag + 1e-12;
    values
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| *d > written)
        .fold(None, |acc: Option<f64>, d| {
            Some(acc.map_or(d, |a| a.min(d)))
        })
        .unwrap_or(written)
}

/// [`noise_floor`] and, in words, where the floor comes from.
pub fn noise_floor_with_basis(records: &[&[f64]]) -> (f64, Option<f64>, String) {
    let q = records
        .iter()
        .filter_map(|r| quantum(r))
        .fold(None, |acc: Option<f64>, q| {
            Some(acc.map_or(q, |a| a.min(q)))
        });
    let mut hf: Vec<f64> = records
        .iter()
        .map(|r| high_frequency_noise(r))
        .filter(|v| v.is_finite())
        .collect();
    hf.sort_by(f64::total_cmp);
    let hf = hf.get(hf.len() / 2).copied().unwrap_or(0.0);
    // no grid to read (a channel that barely moves): its smallest step
    let step = q.unwrap_or_else(|| {
        records
            .iter()
            .filter(|r| !r.is_empty())
            .map(|r| resolution(r))
            .fold(f64::INFINITY, f64::min)
    });
    let step = if step.is_finite() { step } else { 1e-12 };
    let qn = step / 12f64.sqrt();
    if hf > qn {
        (hf, q, "high-frequency noise".to_string())
    } else {
        let what = if q.is_some() {
            "quantum"
        } else {
            "smallest step"
        };
        (qn, q, format!("{what} {step:.3e} / sqrt(12)"))
    }
}

/// Pooled standard deviation of a channel about each record's mean.
pub fn pooled_spread(records: &[&[f64]]) -> f64 {
    let mut ss = 0.0;
    let mut n = 0usize;
    for r in records {
        if r.is_empty() {
            continue;
        }
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        ss += r.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
        n += r.len();
    }
    if n == 0 {
        0.0
    } else {
        (ss / n as f64).sqrt()
    }
}

/// Weights of the channels `names`, each given as its records (one slice
/// per experiment), with user overrides `(name, weight)`: `1 / noise`.
pub fn channel_weights(
    names: &[String],
    records: &[Vec<&[f64]>],
    overrides: &[(String, f64)],
) -> Vec<ChannelWeight> {
    names
        .iter()
        .zip(records)
        .map(|(name, recs)| {
            let (noise, quantum, basis) = noise_floor_with_basis(recs);
            let spread = pooled_spread(recs);
            let auto = weight_of(noise);
            let over = overrides.iter().find(|(n, _)| n == name).map(|o| o.1);
            ChannelWeight {
                name: name.clone(),
                noise,
                quantum,
                spread,
                weight: over.unwrap_or(auto),
                overridden: over.is_some(),
                basis,
                simulation_error: None,
            }
        })
        .collect()
}

/// The weight of a channel of noise floor `noise`: `1 / noise` (finite for
/// a noiseless channel).
fn weight_of(noise: f64) -> f64 {
    1.0 / noise.max(f64::MIN_POSITIVE.sqrt())
}

/// Raise the floors of `weights` by the simulation's own error on each
/// channel `(name, RMS)` ([`crate::fit::simulation_error`]): the noise
/// becomes `sqrt(noise^2 + error^2)` and a weight not set by the user
/// `1 / that`. A model with its true parameters still misses the data by
/// the integrator's error, so that error is part of what no effect can be
/// told from, like the sensor's noise (the two are independent).
pub fn with_simulation_error(weights: &mut [ChannelWeight], errors: &[(String, f64)]) {
    for w in weights.iter_mut() {
        let Some(&(_, e)) = errors.iter().find(|(n, _)| *n == w.name) else {
            continue;
        };
        if !(e > 0.0 && e.is_finite()) {
            continue;
        }
        w.noise = w.noise.hypot(e);
        if !w.overridden {
            w.weight = weight_of(w.noise);
        }
        w.basis = format!(
            "{} and the simulation's own error {e:.3e} (step halving)",
            w.basis
        );
        w.simulation_error = Some(e);
    }
}

/// One line per channel saying what weighs it (for reports).
pub fn describe(weights: &[ChannelWeight]) -> String {
    weights
        .iter()
        .map(|w| {
            if w.overridden {
                format!("{}: {:.4e} per SI unit (set by the user)", w.name, w.weight)
            } else {
                format!("{}: 1/noise, noise {:.3e} ({})", w.name, w.noise, w.basis)
            }
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// The weighted RMS that measurement noise alone would leave: the noise
/// floor of a fit's cost (`FitResult::after_cost`) with these weights.
pub fn noise_cost(weights: &[ChannelWeight]) -> f64 {
    let n = weights.len().max(1) as f64;
    (weights
        .iter()
        .map(|w| (w.weight * w.noise).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Encoder data: the grid is found, the floor is q/sqrt(12) (the
    /// rounding noise of a smooth signal), the spread is the signal's.
    #[test]
    fn quantised_sine() {
        let q = 2.0 * std::f64::consts::PI / 4096.0;
        let v: Vec<f64> = (0..5000)
            .map(|k| ((0.5 * (k as f64 * 0.002 * 3.0).sin()) / q).round() * q)
            .collect();
        let found = quantum(&v).expect("on a grid");
        assert!((found - q).abs() < 1e-12 * q, "{found} vs {q}");
        let (noise, qq) = noise_floor(&[&v]);
        assert_eq!(qq, Some(found));
        // the high-frequency estimate of rounding noise is of the same
        // order as q/sqrt(12); the floor takes the larger
        assert!(
            noise >= 0.999 * q / 12f64.sqrt() && noise < 2.0 * q,
            "{noise}"
        );
        let spread = pooled_spread(&[&v]);
        assert!((spread - 0.5 / 2f64.sqrt()).abs() < 0.01, "{spread}");
    }

    /// White noise of known RMS on a slow signal is measured within 5 %.
    #[test]
    fn white_noise_level() {
        // a deterministic pseudo-random sequence (LCG), uniform on
        // [-0.5, 0.5): RMS 1/sqrt(12)
        let mut s: u64 = 12345;
        let v: Vec<f64> = (0..20000)
            .map(|k| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let r = (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
                (k as f64 * 1e-3).sin() + 1e-3 * r
            })
            .collect();
        let hf = high_frequency_noise(&v);
        let truth = 1e-3 / 12f64.sqrt();
        assert!((hf / truth - 1.0).abs() < 0.05, "{hf} vs {truth}");
        assert_eq!(quantum(&v), None);
    }

    /// Weights come from the noise, never from the spread: a channel that
    /// barely moves (an arm held still, a few encoder counts) weighs per
    /// SI unit what a swinging one on the same encoder does.
    #[test]
    fn weights_from_noise_and_override() {
        let q = 2.0 * std::f64::consts::PI / 4096.0;
        // held: wanders over four counts; swinging: 0.5 rad
        let held: Vec<f64> = (0..5000)
            .map(|k| ((2.0 * (k as f64 * 0.001).sin()).round()) * q)
            .collect();
        let swing: Vec<f64> = (0..5000)
            .map(|k| ((0.5 * (k as f64 * 0.01).sin()) / q).round() * q)
            .collect();
        let names = vec!["arm".to_string(), "pendulum".to_string()];
        let w = channel_weights(&names, &[vec![&held[..]], vec![&swing[..]]], &[]);
        // held has only a handful of steps: its smallest step is the quantum
        for x in &w {
            assert!(
                (x.noise - q / 12f64.sqrt()).abs() < 0.3 * q,
                "{}: {} vs {}",
                x.name,
                x.noise,
                q / 12f64.sqrt()
            );
            assert!((x.weight - 1.0 / x.noise).abs() < 1e-9 * x.weight);
        }
        assert!(w[0].spread < 0.01 * w[1].spread);
        let ratio = w[0].weight / w[1].weight;
        assert!((0.5..2.0).contains(&ratio), "{ratio}");
        let w = channel_weights(
            &names,
            &[vec![&held[..]], vec![&swing[..]]],
            &[("pendulum".into(), 3.0)],
        );
        assert_eq!(w[1].weight, 3.0);
        assert!(w[1].overridden);
        assert!((noise_cost(&w[..1]) - 1.0).abs() < 1e-9);
    }

    /// A constant channel still gets a finite weight.
    #[test]
    fn constant_channel_has_a_finite_floor() {
        let c = vec![0.25; 100];
        let (noise, q) = noise_floor(&[&c]);
        assert_eq!(q, None);
        assert!(noise > 0.0 && noise < 1e-6, "{noise}");
    }
}
