//! Is an effect missing? The one rule, and the statistics it reads.
//!
//! **The rule.** A candidate effect (k parameters) is named when the model
//! with it explains the records better than the model without it by both
//! of these:
//!
//! 1. *Likelihood*: `N_eff ln(S0 / S1) > k ln N_eff` (the Bayesian
//!    information criterion on the simulation error), where `S0` and `S1`
//!    are the weighted sums of squares of the two fits (residuals in units
//!    of each channel's noise, [`crate::weights`], so the sum is a Gaussian
//!    negative log-likelihood) and `N_eff` the effective number of
//!    independent residuals: each record's channel counts its samples
//!    divided by its residual's correlation time ([`correlation_time`]),
//!    measured on the model *without* the effect (the null hypothesis:
//!    its residual is then the noise the test is about). A simulation
//!    residual that a slow model error dominates carries few independent
//!    samples, so a small gain there is no evidence; white noise at the
//!    floor carries them all.
//! 2. *Size*: the effect's own contribution to what is measured stands out
//!    of what cannot be told from it: simulated with its parameters at
//!    their null values (no effect; the nested simpler effect for a bigger
//!    one), the other parameters and the nuisance as fitted, the outputs
//!    move, on some channel of some record, by an RMS of at least one noise
//!    standard deviation *and* at least the RMS of what the model with the
//!    effect still misses there ([`Contribution`]). Below the noise an
//!    effect is not a finding, whatever a restart or a rounding pattern
//!    made the cost do (an input offset of 0.6 mV on a +-10 V amplifier);
//!    below the error that remains, it cannot be told from a piece of that
//!    error it happens to fit (a real rig's model error 24 times its noise,
//!    three candidates taking 1 to 3 % of it each): the larger effect is
//!    named first, and a smaller real one in a later round, once the larger
//!    is in.
//!
//! 3. *Form*: its fitted parameters describe the effect its name claims
//!    ([`crate::effect_edit::EffectInstance::in_own_form`]: a Stribeck
//!    friction with a hump, `Fs > Fc`, over a positive sliding level: its own
//!    `Fc` plus the dry friction the model already gives the joint, which
//!    the data cannot tell from it; a cogging with half a period, its
//!    swing from peak to trough, within the range its target covers in a
//!    record). A better fit by a curve of another
//!    shape (a friction that falls at low speed, fitting the stick-slip
//!    transitions of a simulation that resolves them on another step) is
//!    not that effect, and its name would be false.
//!
//! Among the candidates that pass, the verdict is the one with the largest
//! margin `N_eff ln(S0/S1) - k ln N_eff` (the same criterion, so a nested
//! bigger effect wins over its simpler form only by paying for its extra
//! parameters).
//!
//! A channel's `sigma` is its sensor noise ([`crate::weights`]) and, where
//! plantc's own integrator misses the records by more than the fit
//! resolves, that error in quadrature: a model with its true parameters
//! misses by it too, so it is noise to every decision
//! ([`crate::fit::simulation_error`], measured on each diagnosis' baseline:
//! the model's stiffness, a smooth dry friction's, comes with its effects).
//!
//! **The floor**, from the same size test: noise of RMS `sigma` plus a
//! missing effect of RMS at least `sigma` leaves a residual of RMS at
//! least `sqrt(2) sigma` (the two are uncorrelated). A residual below
//! `sqrt(2) sigma` on every channel of every record therefore has no room
//! for a nameable effect: the model is at the floor ([`at_floor`]), and
//! nothing is refitted.
//!
//! **Adequate** means: no candidate passes, the residual is at the floor,
//! and no nuisance estimate sits at the edge of what the data allow
//! ([`crate::fit::NuisanceFlag`]). No candidate passing with the residual
//! above the floor is an *unexplained* residual.

use serde::Serialize;

/// Correlation time of a residual series: `1 + 2 sum_k rho_k`, summed by
/// Geyer's initial positive sequence (pairs `rho_{2m} + rho_{2m+1}` until
/// one is not positive). The autocorrelation is taken about zero, not the
/// mean: a residual offset is one piece of evidence, not `n`. 1 for white
/// noise, about `n` for a constant. Long series are first averaged in
/// groups of `g` samples so that at most [`MAX_LAGGED`] remain, and the
/// correlation time of the averages is multiplied by `g` (an upper bound:
/// at least as conservative).
pub fn correlation_time(r: &[f64]) -> f64 {
    let n = r.len();
    if n < 2 {
        return 1.0;
    }
    let g = n.div_ceil(MAX_LAGGED);
    let x: Vec<f64> = if g > 1 {
        r.chunks(g)
            .map(|c| c.iter().sum::<f64>() / c.len() as f64)
            .collect()
    } else {
        r.to_vec()
    };
    let m = x.len();
    let c0: f64 = x.iter().map(|v| v * v).sum();
    if c0.is_nan() || c0 <= 0.0 || !c0.is_finite() {
        return 1.0;
    }
    let rho = |k: usize| -> f64 {
        x[..m - k]
            .iter()
            .zip(&x[k..])
            .map(|(a, b)| a * b)
            .sum::<f64>()
            / c0
    };
    let mut tau = -1.0;
    let mut k = 0;
    while k + 1 < m {
        let pair = rho(k) + rho(k + 1);
        if pair <= 0.0 {
            break;
        }
        tau += 2.0 * pair;
        k += 2;
    }
    (tau.max(1.0) * g as f64).min(n as f64)
}

/// Series longer than this are averaged in groups before their correlation
/// is summed (the sum costs series length times lags).
pub const MAX_LAGGED: usize = 20_000;

/// Per record and channel, the residual in units of the channel's noise:
/// `(measured - simulated) / noise`, over the samples where the simulation
/// is finite. `measured` and `simulated` are `[record][channel][sample]`.
pub fn noise_residuals(
    measured: &[Vec<Vec<f64>>],
    simulated: &[Vec<Vec<f64>>],
    noise: &[f64],
) -> Vec<Vec<Vec<f64>>> {
    measured
        .iter()
        .zip(simulated)
        .map(|(m, s)| {
            m.iter()
                .zip(s)
                .zip(noise)
                .map(|((y, yh), sig)| {
                    y.iter()
                        .zip(yh)
                        .filter(|(_, h)| h.is_finite())
                        .map(|(a, b)| (a - b) / sig.max(f64::MIN_POSITIVE))
                        .collect()
                })
                .collect()
        })
        .collect()
}

/// The effective number of independent residuals: each record's channel
/// counts its samples over its [`correlation_time`], at least 1 in all.
pub fn effective_samples(residuals: &[Vec<Vec<f64>>]) -> f64 {
    residuals
        .iter()
        .flatten()
        .filter(|r| !r.is_empty())
        .map(|r| r.len() as f64 / correlation_time(r))
        .sum::<f64>()
        .max(1.0)
}

/// The one-sided 99 % point of the standard normal: the level at which a
/// [`vuong_z`] statistic says one of two fits with as many parameters
/// explains the records better (the 1 % of the residual tests' bands).
pub const VUONG_99: f64 = 2.326;

/// Vuong's statistic for two non-nested fits with as many parameters over
/// the same samples (residuals `a` and `b` in noise units, shaped as
/// [`noise_residuals`]; a record's channel counts only where both kept the
/// same samples): the mean of the per-sample differences of squares
/// `a_i^2 - b_i^2` (twice the log-likelihood difference) over its standard
/// error with `effective` independent samples. Above [`VUONG_99`], `b`
/// explains the records better than `a` beyond what the sample's own
/// scatter makes of a difference of sums; a positive sum alone (`N_eff
/// ln(S_a/S_b) > 0`) is that half the time when neither is right.
pub fn vuong_z(a: &[Vec<Vec<f64>>], b: &[Vec<Vec<f64>>], effective: f64) -> f64 {
    let d: Vec<f64> = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        // (a channel whose simulations ended on other samples, one of them
        // diverged, has no pairs)
        .filter(|(x, y)| x.len() == y.len())
        .flat_map(|(x, y)| x.iter().zip(y).map(|(x, y)| x * x - y * y))
        .filter(|v| v.is_finite())
        .collect();
    if d.len() < 2 {
        return 0.0;
    }
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0);
    if var <= 0.0 {
        return 0.0;
    }
    effective.max(1.0).sqrt() * mean / var.sqrt()
}

/// RMS of each record's channel in noise units, with the record and
/// channel indices.
fn channel_rms(residuals: &[Vec<Vec<f64>>]) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
    residuals.iter().enumerate().flat_map(|(e, chans)| {
        chans
            .iter()
            .enumerate()
            .filter(|(_, r)| !r.is_empty())
            .map(move |(c, r)| {
                (
                    e,
                    c,
                    (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt(),
                )
            })
    })
}

/// Is a residual (in noise units, see [`noise_residuals`]) at the floor:
/// every record's channel below `sqrt(2)` noise RMS (see the module docs)?
pub fn at_floor(residuals: &[Vec<Vec<f64>>]) -> bool {
    channel_rms(residuals).all(|(_, _, rms)| rms < std::f64::consts::SQRT_2)
}

/// The largest residual RMS over the records' channels, in noise units,
/// with where it is: `(rms, record, channel)`.
pub fn worst_channel(residuals: &[Vec<Vec<f64>>]) -> Option<(f64, usize, usize)> {
    channel_rms(residuals)
        .map(|(e, c, r)| (r, e, c))
        .max_by(|a, b| a.0.total_cmp(&b.0))
}

/// How much an effect moves what is measured, on the record's channel
/// where it stands out most: the RMS of the simulated outputs with the
/// effect minus those with its parameters at their null values, and the
/// RMS of what the model with the effect still misses there, both in units
/// of the channel's noise.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Contribution {
    /// That RMS in noise standard deviations.
    pub size: f64,
    /// The residual RMS of the model with the effect on that record's
    /// channel, in noise standard deviations.
    pub remaining: f64,
    /// The record where it is largest.
    pub experiment: String,
    /// The channel where it is largest.
    pub channel: String,
}

impl Contribution {
    /// The contribution of simulated outputs `with` against `without`
    /// (`[record][channel][sample]`), for `measured` outputs, channels named
    /// `channels`, records `records`, with the channels' `noise`: on the
    /// record's channel where the contribution is largest against
    /// `max(1, remaining)`.
    pub fn between(
        with: &[Vec<Vec<f64>>],
        without: &[Vec<Vec<f64>>],
        measured: &[Vec<Vec<f64>>],
        noise: &[f64],
        records: &[String],
        channels: &[String],
    ) -> Contribution {
        let d = noise_residuals(with, without, noise);
        let rest = noise_residuals(measured, with, noise);
        let rms = |r: &[f64]| {
            if r.is_empty() {
                0.0
            } else {
                (r.iter().map(|v| v * v).sum::<f64>() / r.len() as f64).sqrt()
            }
        };
        let mut best: Option<Contribution> = None;
        for (e, chans) in d.iter().enumerate() {
            for (c, r) in chans.iter().enumerate() {
                if r.is_empty() {
                    continue;
                }
                let size = rms(r);
                let remaining = rest.get(e).and_then(|x| x.get(c)).map_or(0.0, |x| rms(x));
                let score = size / remaining.max(1.0);
                let better = best
                    .as_ref()
                    .is_none_or(|b| score > b.size / b.remaining.max(1.0));
                if better && size.is_finite() {
                    best = Some(Contribution {
                        size,
                        remaining,
                        experiment: records.get(e).cloned().unwrap_or_default(),
                        channel: channels.get(c).cloned().unwrap_or_default(),
                    });
                }
            }
        }
        best.unwrap_or(Contribution {
            size: 0.0,
            remaining: 0.0,
            experiment: String::new(),
            channel: String::new(),
        })
    }

    /// True when it stands out of the noise and of what the model with it
    /// still misses (see the module docs).
    pub fn reaches_floor(&self) -> bool {
        self.size >= self.remaining.max(1.0)
    }
}

/// The test of one effect against the model without it (see the module
/// docs).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EffectTest {
    /// Weighted sum of squares of the fit without the effect (`S0`).
    pub ssr_without: f64,
    /// ...and with it (`S1`).
    pub ssr_with: f64,
    /// Residual count of either fit.
    pub samples: usize,
    /// Effective independent residuals (`N_eff`) of the fit without it.
    pub effective_samples: f64,
    /// The effect's parameter count (`k`).
    pub parameters: usize,
    /// `N_eff ln(S0 / S1)`.
    pub statistic: f64,
    /// `k ln N_eff`.
    pub threshold: f64,
    /// The effect's contribution, when simulated (only for an effect that
    /// passes the likelihood part: the size test needs one simulation).
    pub contribution: Option<Contribution>,
    /// Whether its fitted parameters describe it in its own form.
    pub in_own_form: bool,
}

impl EffectTest {
    /// The likelihood part of a test of `k` parameters between sums of
    /// squares `s0` (without) and `s1` (with), over `samples` residuals of
    /// which `effective` independent.
    pub fn new(s0: f64, s1: f64, samples: usize, effective: f64, k: usize) -> EffectTest {
        let effective = effective.max(1.0);
        let statistic = if s0 > 0.0 && s1 > 0.0 && s0.is_finite() && s1.is_finite() {
            effective * (s0 / s1).ln()
        } else {
            f64::NEG_INFINITY
        };
        EffectTest {
            ssr_without: s0,
            ssr_with: s1,
            samples,
            effective_samples: effective,
            parameters: k,
            statistic,
            threshold: k as f64 * effective.ln(),
            contribution: None,
            in_own_form: true,
        }
    }

    /// The likelihood part passes.
    pub fn likely(&self) -> bool {
        self.statistic > self.threshold
    }

    /// Every part passes: the effect is named (see the module docs).
    pub fn passes(&self) -> bool {
        self.likely()
            && self.in_own_form
            && self
                .contribution
                .as_ref()
                .is_some_and(Contribution::reaches_floor)
    }

    /// The margin `N_eff ln(S0/S1) - k ln N_eff` that ranks passing effects.
    pub fn margin(&self) -> f64 {
        self.statistic - self.threshold
    }

    /// RMS ratio without / with (the square root of the sums' ratio: the
    /// weighted RMS, in noise units, falls by this factor).
    pub fn rms_ratio(&self) -> f64 {
        (self.ssr_without / self.ssr_with).sqrt()
    }

    /// One line: the numbers of both parts.
    pub fn describe(&self) -> String {
        let size = match &self.contribution {
            Some(c) => format!(
                "; contribution {:.2} noise RMS against {:.2} still missed ({} in {}){}",
                c.size,
                c.remaining,
                c.channel,
                c.experiment,
                if c.reaches_floor() {
                    ""
                } else if c.size < 1.0 {
                    ": below the noise"
                } else {
                    ": below what the model with it still misses"
                }
            ),
            None => String::new(),
        };
        let form = if self.in_own_form {
            ""
        } else {
            "; its fitted parameters are not in the effect's own form"
        };
        format!(
            "weighted RMS ratio {:.3} (without / with); N_eff ln(S0/S1) = {:.1} against k ln N_eff = {:.1} (k = {}, N_eff = {:.0} of {}){size}{form}",
            self.rms_ratio(),
            // (a refit that gained nothing, to the rounding of its cost,
            // reads 0.0, not -0.0)
            if self.statistic.abs() < 0.05 {
                0.0
            } else {
                self.statistic
            },
            self.threshold,
            self.parameters,
            self.effective_samples,
            self.samples
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect()
    }

    /// Vuong's statistic: two fits that differ only by noise drawn alike
    /// are not told apart (|z| below the 99 % point), a fit whose residual
    /// lacks a systematic error the other has is (z far above it, and the
    /// same with the sign turned for the fits swapped). Uniform noise of
    /// variance 1/12, scaled to unit variance (fourth moment 9/5); the
    /// systematic error a sine of amplitude 0.5 (adds 0.125 to the mean
    /// square; the difference of squares scatters by sqrt(0.8 + 0.8 +
    /// 4 x 0.125) = 1.45 per sample: z about sqrt(4000) 0.125 / 1.45 = 5.4,
    /// give or take the statistic's own standard deviation of 1).
    #[test]
    fn vuong_tells_a_systematic_error_from_noise() {
        let unit = 12f64.sqrt();
        let a: Vec<f64> = lcg(4000, 3).iter().map(|v| v * unit).collect();
        let b: Vec<f64> = lcg(4000, 4).iter().map(|v| v * unit).collect();
        let n = a.len() as f64;
        let z = vuong_z(&[vec![a.clone()]], &[vec![b.clone()]], n);
        assert!(z.abs() < VUONG_99, "{z}");
        let worse: Vec<f64> = a
            .iter()
            .enumerate()
            .map(|(i, v)| v + 0.5 * (i as f64 * 0.01).sin())
            .collect();
        let z = vuong_z(&[vec![worse.clone()]], &[vec![b.clone()]], n);
        assert!(z > VUONG_99 && (z - 5.4).abs() < 2.5, "{z}");
        let back = vuong_z(&[vec![b]], &[vec![worse]], n);
        assert!((back + z).abs() < 1e-12, "{back} {z}");
    }

    /// White noise has a correlation time near 1; an AR(1) series with
    /// coefficient a has (1 + a)/(1 - a) (19 for a = 0.9); a constant
    /// about its length.
    #[test]
    fn correlation_times() {
        let w = lcg(20_000, 1);
        let t = correlation_time(&w);
        assert!((0.8..1.3).contains(&t), "{t}");
        let mut x = 0.0;
        let ar: Vec<f64> = lcg(50_000, 2)
            .into_iter()
            .map(|e| {
                x = 0.9 * x + e;
                x
            })
            .collect();
        let t = correlation_time(&ar);
        assert!((15.0..23.0).contains(&t), "{t}");
        let c = vec![1.0; 1000];
        assert!(correlation_time(&c) > 900.0);
        // long series are grouped, and stay an upper bound of the truth
        let long: Vec<f64> = lcg(100_000, 3)
            .into_iter()
            .map(|e| {
                x = 0.9 * x + e;
                x
            })
            .collect();
        let t = correlation_time(&long);
        assert!((15.0..40.0).contains(&t), "{t}");
    }

    /// The rule's parts, on numbers worked by hand.
    #[test]
    fn the_rule() {
        // S0/S1 = 2 over 100 independent residuals: 100 ln 2 = 69.3 > 4.6
        let mut t = EffectTest::new(200.0, 100.0, 1000, 100.0, 1);
        assert!(t.likely());
        assert!(!t.passes(), "no size yet");
        t.contribution = Some(Contribution {
            size: 0.5,
            remaining: 1.0,
            experiment: "a".into(),
            channel: "x".into(),
        });
        assert!(!t.passes(), "below the noise");
        t.contribution.as_mut().unwrap().size = 3.0;
        assert!(t.passes());
        t.contribution.as_mut().unwrap().remaining = 5.0;
        assert!(!t.passes(), "below what the model with it still misses");
        // a 1 % gain over 100 independent residuals: 1.0 < 4.6
        let t = EffectTest::new(101.0, 100.0, 1000, 100.0, 1);
        assert!(!t.likely());
        // the same gain over 10^5 independent residuals: 995 > 11.5
        let t = EffectTest::new(1.01e5, 1e5, 100_000, 1e5, 1);
        assert!(t.likely());
    }

    /// The floor: noise alone is at it, noise plus a sine of one noise RMS
    /// is not.
    #[test]
    fn floor() {
        let noise: Vec<f64> = lcg(5000, 4).iter().map(|v| v * 12f64.sqrt()).collect();
        assert!(at_floor(&[vec![noise.clone()]]));
        let with: Vec<f64> = noise
            .iter()
            .enumerate()
            .map(|(k, v)| v + 2.0 * (k as f64 * 0.01).sin())
            .collect();
        assert!(!at_floor(&[vec![noise], vec![with]]));
    }
}
