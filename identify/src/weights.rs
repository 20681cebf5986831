//! How much each measured channel counts in a fit: its noise floor and its
//! scale, estimated from the data.
//!
//! Simulation residuals in SI units let the channel with the largest motion
//! decide a fit alone (an arm that spins 77 rad in a step against a
//! pendulum that swings 0.2 rad). Each channel's residual is therefore
//! divided by its *scale*: the pooled standard deviation of the channel
//! about each experiment's mean (how much it moves), never less than ten
//! times its noise floor (a channel that barely moves is not blown up to
//! fit its quantisation). The weighted cost is then a sum of `(1 - fit)^2`
//! like terms, comparable across channels, and dimensionless.
//!
//! The *noise floor* of a channel is the larger of two estimates:
//! - quantisation: when every sample lies on a grid `q` (an encoder), the
//!   rounding noise `q / sqrt(12)`;
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
    /// Pooled standard deviation about each experiment's mean (SI).
    pub spread: f64,
    /// Weight applied to the residual (1 / SI unit).
    pub weight: f64,
    /// True when the user set the weight.
    pub overridden: bool,
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
/// records, so one bad file does not decide).
pub fn noise_floor(records: &[&[f64]]) -> (f64, Option<f64>) {
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
    let qn = q.map_or(0.0, |q| q / 12f64.sqrt());
    (qn.max(hf), q)
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
/// per experiment), with user overrides `(name, weight)`.
pub fn channel_weights(
    names: &[String],
    records: &[Vec<&[f64]>],
    overrides: &[(String, f64)],
) -> Vec<ChannelWeight> {
    names
        .iter()
        .zip(records)
        .map(|(name, recs)| {
            let (noise, quantum) = noise_floor(recs);
            let spread = pooled_spread(recs);
            let auto = 1.0 / spread.max(10.0 * noise).max(f64::MIN_POSITIVE.sqrt());
            let over = overrides.iter().find(|(n, _)| n == name).map(|o| o.1);
            ChannelWeight {
                name: name.clone(),
                noise,
                quantum,
                spread,
                weight: over.unwrap_or(auto),
                overridden: over.is_some(),
            }
        })
        .collect()
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

    /// A channel that barely moves gets 1/(10 noise), not 1/spread.
    #[test]
    fn weights_floor_and_override() {
        let q = 0.01;
        let still: Vec<f64> = (0..100).map(|k| if k % 7 == 0 { q } else { 0.0 }).collect();
        let moving: Vec<f64> = (0..100).map(|k| (k as f64 * 0.1).sin()).collect();
        let names = vec!["a".to_string(), "b".to_string()];
        let w = channel_weights(&names, &[vec![&still[..]], vec![&moving[..]]], &[]);
        assert!(w[0].weight <= 1.0 / (10.0 * w[0].noise) * 1.000001);
        assert!((w[1].weight - 1.0 / w[1].spread).abs() < 1e-12);
        let w = channel_weights(
            &names,
            &[vec![&still[..]], vec![&moving[..]]],
            &[("b".into(), 3.0)],
        );
        assert_eq!(w[1].weight, 3.0);
        assert!(w[1].overridden);
    }
}
