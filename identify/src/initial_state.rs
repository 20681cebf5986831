//! What the data say about a block's initial state: the prior of the
//! nuisance unknowns.
//!
//! Per-file initial states are unknowns of every fit, but they are not free:
//! the data show them. A record that starts at rest starts at rest; one
//! that starts in a fast transient (a controller switched on with its
//! voltage clipped at the rails) shows a fast, uncertain velocity. Each
//! estimated component gets a Gaussian prior from a local smoother, in the
//! units the fit's residuals are in (the channels' noise, see
//! [`crate::weights`]), so a fit is a maximum a posteriori estimate:
//!
//! - **velocity** at sample `k`: the slope at `t_k` of a least-squares
//!   quadratic through the samples within a window around it (one-sided
//!   at the ends of a record), with its standard error
//!   `s * sqrt((X'X)^-1_bb)`, `s` the larger of the fit's own residual RMS
//!   (which grows where the motion is not a quadratic over the window: a
//!   release transient) and the channel's noise floor (a reading that does
//!   not change over the window still allows any speed below about a
//!   quantum per window), and, added in quadrature, the larger difference
//!   between that slope and those of the neighbouring orders on the same
//!   samples, the local line's and the local cubic's (the smoother's own
//!   bias: the line's shows where a one-sided window meets a transient, the
//!   cubic's where a third derivative projects onto the slope, which on a
//!   symmetric window neither residual sees);
//! - **position** (estimated by default; `--estimate-initial velocities`
//!   takes the first sample as it is): the measured value, within the
//!   channel's noise: the unknown is the deviation `delta` from the
//!   measurement (minus the offsets), prior `N(0, noise)`.
//!
//! Each prior also bounds its unknown at [`prior_bound`] standard
//! deviations: a fit can never move an initial state beyond what the data
//! allow, and one that ends at such a bound is reported by name
//! ([`crate::fit::NuisanceFlag`]): the model needed a start the data do not
//! show.

/// A Gaussian prior `N(mean, sigma^2)` on one nuisance unknown, bounded at
/// `mean +- bound * sigma`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Prior {
    /// Prior mean (SI).
    pub mean: f64,
    /// Prior standard deviation (SI, > 0).
    pub sigma: f64,
}

impl Prior {
    /// The prior's interval at `z` standard deviations.
    pub fn interval(&self, z: f64) -> (f64, f64) {
        (self.mean - z * self.sigma, self.mean + z * self.sigma)
    }

    /// `(value - mean) / sigma`.
    pub fn z(&self, value: f64) -> f64 {
        (value - self.mean) / self.sigma
    }
}

/// Smallest window the velocity smoother spans, s: 10 ms, the window
/// Quanser's and our own filtered derivatives settle in (50 rad/s), and at
/// least [`MIN_WINDOW_SAMPLES`] samples so that a quadratic keeps degrees
/// of freedom for its residual.
pub const MIN_WINDOW: f64 = 0.01;

/// Fewest samples a velocity window holds: a quadratic (3 coefficients)
/// plus 3 degrees of freedom for the residual that measures its own error.
pub const MIN_WINDOW_SAMPLES: usize = 6;

/// The velocity prior at sample `k` of a record `(t, y)` whose noise floor
/// is `noise` (see the module docs). The window spans [`MIN_WINDOW`] s on
/// each available side (one-sided at the ends), widened to hold at least
/// [`MIN_WINDOW_SAMPLES`] samples.
pub fn velocity_prior(t: &[f64], y: &[f64], k: usize, noise: f64) -> Prior {
    smoothed_state(t, y, k, noise).1
}

/// The smoothed position at sample `k` (the local quadratic's value at
/// `t_k`, the measurement when there is too little data) and the velocity
/// prior ([`velocity_prior`]): the state a k-step-ahead prediction starts
/// from.
pub fn smoothed_state(t: &[f64], y: &[f64], k: usize, noise: f64) -> (f64, Prior) {
    let n = t.len().min(y.len());
    let fallback = (
        y.get(k).copied().unwrap_or(f64::NAN),
        Prior {
            mean: 0.0,
            sigma: f64::INFINITY,
        },
    );
    if n < 3 || k >= n {
        return fallback;
    }
    let tk = t[k];
    let (mut a, mut b) = within(&t[..n], (k, k), tk, MIN_WINDOW);
    // widen, alternating sides, to the fewest samples
    while b + 1 - a < MIN_WINDOW_SAMPLES.min(n) {
        if b + 1 < n {
            b += 1;
        }
        if b + 1 - a < MIN_WINDOW_SAMPLES.min(n) && a > 0 {
            a -= 1;
        }
    }
    // least squares y = c0 + c1 s + c2 s^2, s = (t - t_k)/scale
    let scale = (t[b] - t[a]).max(f64::MIN_POSITIVE);
    let window = (a, b);
    let Some((c, inv)) = local_polynomial::<3>((t, y), window, tk, scale) else {
        return fallback;
    };
    let count = b + 1 - a;
    let rss: f64 = (a..=b)
        .map(|i| {
            let s = (t[i] - tk) / scale;
            (y[i] - (c[0] + c[1] * s + c[2] * s * s)).powi(2)
        })
        .sum();
    let s2 = (rss / (count - 3).max(1) as f64).max(noise * noise);
    // the local line's slope on the same samples: what changes with the
    // smoother's order is its own bias, and it counts in the prior (at a
    // record's start inside a fast transient the quadratic extrapolates:
    // flat for three samples, then 250 rad/s^2, its slope at t0 -1.3 rad/s
    // where the line's is +0.9 and the truth about 0); and the local
    // cubic's: on a symmetric window the line's slope is the quadratic's,
    // and a third derivative projects onto the slope unseen by either's
    // residual (a tumbling elbow at 40 rad/s: slope priors of +-0.025 rad/s
    // that the segments' states ended against)
    let line = local_polynomial::<2>((t, y), window, tk, scale).map_or(c[1], |(l, _)| l[1]);
    let cubic = local_polynomial::<4>((t, y), window, tk, scale)
        .map(|(q, _)| q[1])
        .filter(|v| v.is_finite())
        .unwrap_or(c[1]);
    // and the third derivative as a cubic over twice the window reads it,
    // projected onto the quadratic's slope: on the window itself a cubic's
    // slope is too noisy to tell a bias of a few hundredths of a rad/s
    // from the rounding (a tumbling elbow at -18.5 rad/s: the quadratic
    // 0.09 off, the window's cubic agreeing with it by chance)
    let third = third_derivative_bias((t, y), window, tk, scale, &inv);
    let bias = ((c[1] - line).abs().max((c[1] - cubic).abs()) / scale).max(third);
    (
        c[0],
        Prior {
            mean: c[1] / scale,
            sigma: ((s2 * inv[(1, 1)]) / (scale * scale) + bias * bias).sqrt(),
        },
    )
}

/// The bias of the local quadratic's slope at `tk` (per second) that the
/// third derivative makes, `y'''/6 * [(X'X)^-1 X' s^3]_1` (`inv` the
/// quadratic's `(X'X)^-1` on `window`, `s = (t - tk) / scale`), with `y'''`
/// from a least-squares cubic over the samples within twice the window's
/// reach of `tk` (0 when that cubic cannot be fitted). Exact for a cubic
/// motion; over twice the span (and twice the samples) the noise of the
/// cubic's `y'''` is about `2^3 sqrt(2) = 11` times smaller than over the
/// window.
fn third_derivative_bias(
    (t, y): (&[f64], &[f64]),
    (a, b): (usize, usize),
    tk: f64,
    scale: f64,
    inv: &nalgebra::SMatrix<f64, 3, 3>,
) -> f64 {
    let n = t.len().min(y.len());
    let reach = 2.0 * (tk - t[a]).max(t[b] - tk);
    let (wa, wb) = within(&t[..n], (a, b), tk, reach);
    let wide = (t[wb] - t[wa]).max(f64::MIN_POSITIVE);
    let Some((c, _)) = local_polynomial::<4>((t, y), (wa, wb), tk, wide) else {
        return 0.0;
    };
    if !c[3].is_finite() {
        return 0.0;
    }
    // y'''/6 in the window's own s, projected onto its slope
    let c3 = c[3] * (scale / wide).powi(3);
    let proj: f64 = (a..=b)
        .map(|i| {
            let s = (t[i] - tk) / scale;
            (inv[(1, 0)] + inv[(1, 1)] * s + inv[(1, 2)] * s * s) * s * s * s
        })
        .sum();
    (c3 * proj).abs() / scale
}

/// Samples `a..=b` of `t` widened on each side to every sample within
/// `reach` of `tk`.
fn within(t: &[f64], (mut a, mut b): (usize, usize), tk: f64, reach: f64) -> (usize, usize) {
    while a > 0 && tk - t[a - 1] <= reach {
        a -= 1;
    }
    while b + 1 < t.len() && t[b + 1] - tk <= reach {
        b += 1;
    }
    (a, b)
}

/// The least-squares polynomial with `D` coefficients in `s = (t - tk) /
/// scale` through samples `a..=b` of `(t, y)`: its coefficients (lowest
/// power first) and the inverse of its normal matrix (their covariance per
/// unit residual variance); None when those samples cannot determine it
/// (fewer than `D`, or a singular normal matrix).
fn local_polynomial<const D: usize>(
    (t, y): (&[f64], &[f64]),
    (a, b): (usize, usize),
    tk: f64,
    scale: f64,
) -> Option<(nalgebra::SVector<f64, D>, nalgebra::SMatrix<f64, D, D>)> {
    if b + 1 - a < D {
        return None;
    }
    let mut m = nalgebra::SMatrix::<f64, D, D>::zeros();
    let mut r = nalgebra::SVector::<f64, D>::zeros();
    for i in a..=b {
        let s = (t[i] - tk) / scale;
        let mut pw = nalgebra::SVector::<f64, D>::zeros();
        let mut p = 1.0;
        for k in 0..D {
            pw[k] = p;
            p *= s;
        }
        m += pw * pw.transpose();
        r += pw * y[i];
    }
    let inv = m.try_inverse()?;
    Some((inv * r, inv))
}

/// Where a prior bounds its unknown, in standard deviations, for `count`
/// priors in one problem: the two-sided 99 % point with a Bonferroni
/// correction over them, `z = Phi^-1(1 - 0.01 / (2 count))` (2.58 for one,
/// 3.29 for ten, 3.89 for a hundred). Under the priors, the chance that
/// any of the true values lies outside its bound is then at most 1 %; an
/// estimate that needs to go there is reported, not accepted silently.
pub fn prior_bound(count: usize) -> f64 {
    normal_quantile(1.0 - 0.01 / (2.0 * count.max(1) as f64))
}

/// The standard normal quantile `Phi^-1(p)` for `0 < p < 1` (Acklam's
/// rational approximation, relative error below 1.2e-9, refined by one
/// Halley step on `erfc`).
pub fn normal_quantile(p: f64) -> f64 {
    if !(p > 0.0 && p < 1.0) {
        return if p <= 0.0 {
            f64::NEG_INFINITY
        } else {
            f64::INFINITY
        };
    }
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383_577_518_672_69e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let p_low = 0.02425;
    let x = if p < p_low {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - p_low {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        let q = (-2.0 * (1.0 - p).ln()).sqrt();
        -(((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    // one Halley step: e = Phi(x) - p
    let e = 0.5 * erfc(-x / std::f64::consts::SQRT_2) - p;
    let u = e * (2.0 * std::f64::consts::PI).sqrt() * (x * x / 2.0).exp();
    x - u / (1.0 + x * u / 2.0)
}

/// The complementary error function (Numerical Recipes' Chebyshev fit,
/// relative error below 1.2e-7; the Halley step above needs no more).
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let r = t
        * (-z * z - 1.26551223
            + t * (1.00002368
                + t * (0.37409196
                    + t * (0.09678418
                        + t * (-0.18628806
                            + t * (0.27886807
                                + t * (-1.13520398
                                    + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277)))))))))
            .exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quantiles against tabulated values (Abramowitz & Stegun, Table 26.1).
    #[test]
    fn normal_quantiles() {
        for (p, z) in [
            (0.5, 0.0),
            (0.975, 1.959963985),
            (0.995, 2.575829304),
            (0.9995, 3.290526731),
            (0.025, -1.959963985),
            (1e-6, -4.753424309),
        ] {
            let q = normal_quantile(p);
            assert!((q - z).abs() < 2e-6, "{p}: {q} vs {z}");
        }
        assert!((prior_bound(1) - 2.575829304).abs() < 2e-6);
        assert!((prior_bound(10) - 3.290526731).abs() < 2e-6);
    }

    /// At rest on an encoder, the prior is zero within about a quantum per
    /// window; on a known ramp plus rounding it holds the true slope.
    #[test]
    fn velocity_priors() {
        let q = 2.0 * std::f64::consts::PI / 4096.0;
        let noise = q / 12f64.sqrt();
        let t: Vec<f64> = (0..200).map(|k| k as f64 * 0.002).collect();
        let rest = vec![0.5 * q; 200];
        let p = velocity_prior(&t, &rest, 0, noise);
        assert!(p.mean.abs() < 1e-12, "{p:?}");
        assert!(p.sigma > 0.0 && p.sigma < 3.0 * q / MIN_WINDOW, "{p:?}");
        let v = 3.0;
        let ramp: Vec<f64> = t.iter().map(|t| ((0.1 + v * t) / q).round() * q).collect();
        for k in [0, 50, 199] {
            let p = velocity_prior(&t, &ramp, k, noise);
            assert!((p.mean - v).abs() < 3.0 * p.sigma, "{k}: {p:?}");
            assert!(p.sigma < 0.2, "{k}: {p:?}");
        }
    }

    /// A third derivative (a tumbling elbow: 40 rad/s and a jerk of 6e4
    /// rad/s^3, 500 Hz, 4096-count encoder) biases a symmetric window's
    /// slope without showing in the quadratic's residual: the prior holds
    /// the true velocity within 3 of its standard deviations and stays
    /// informative. Without the cubic's word its bias is 0.57 rad/s against
    /// a standard deviation of 0.10 (the pendubot's segment states ended
    /// against such priors, identify/tests/chaotic_records.rs).
    #[test]
    fn a_third_derivative_widens_the_prior() {
        let q = 2.0 * std::f64::consts::PI / 4096.0;
        let noise = q / 12f64.sqrt();
        let t: Vec<f64> = (0..101).map(|k| -0.1 + k as f64 * 0.002).collect();
        let y: Vec<f64> = t
            .iter()
            .map(|t| ((40.0 * t + 1e4 * t * t * t) / q).round() * q)
            .collect();
        let p = velocity_prior(&t, &y, 50, noise);
        assert!((p.mean - 40.0).abs() < 3.0 * p.sigma, "{p:?}");
        assert!(p.sigma < 2.0, "{p:?}");
    }

    /// A third derivative too small for the window's own cubic to tell
    /// from the encoder's rounding still counts. The samples: a tumbling
    /// pendubot's elbow (`plantc synth` of models/pendubot.plant with an
    /// elbow spring of 1e-3 N m/rad, 0.2 N m RMS multisine, seed 2; 4096
    /// counts, 500 Hz) around t = 5.75 s, where it turns at -18.5 rad/s
    /// with a jerk of about -6500 rad/s^3. The velocity there, -18.48 rad/s:
    /// the slopes at the centre of least-squares cubics and quintics over
    /// +-24 to +-40 ms agree on -18.46 to -18.49 (and the identified model,
    /// at the true values within 1e-4, started its segment at -18.474); the
    /// window's quadratic says -18.568, 0.09 off, and its cubic -18.560.
    /// Without the wider cubic's word the prior's standard deviation was
    /// 0.023 and the segment's state ended 4.2 of them from its mean.
    #[test]
    fn a_small_third_derivative_counts() {
        let q = 2.0 * std::f64::consts::PI / 4096.0;
        let noise = q / 12f64.sqrt();
        let counts: [i32; 51] = [
            -8087, -8134, -8182, -8229, -8276, -8322, -8368, -8413, -8456, -8498, -8539, -8578,
            -8616, -8653, -8688, -8723, -8755, -8787, -8818, -8848, -8877, -8904, -8931, -8957,
            -8983, -9007, -9031, -9054, -9076, -9098, -9119, -9139, -9159, -9178, -9197, -9215,
            -9233, -9250, -9267, -9283, -9299, -9314, -9329, -9344, -9358, -9372, -9385, -9398,
            -9411, -9424, -9436,
        ];
        // the times as the record writes them (4 decimals)
        let t: Vec<f64> = (0..51)
            .map(|k| format!("{:.4}", 5.7 + k as f64 * 0.002).parse().unwrap())
            .collect();
        let y: Vec<f64> = counts.iter().map(|&c| c as f64 * q).collect();
        let p = velocity_prior(&t, &y, 25, noise);
        assert!((p.mean + 18.48).abs() < 2.0 * p.sigma, "{p:?}");
        assert!(p.sigma < 0.2, "{p:?}");
    }

    /// A fast transient the quadratic cannot follow widens the prior.
    #[test]
    fn transients_widen_the_prior() {
        let t: Vec<f64> = (0..200).map(|k| k as f64 * 0.002).collect();
        let noise = 1e-4;
        let smooth: Vec<f64> = t.iter().map(|t| 0.2 * t).collect();
        // a 40 Hz oscillation: half a period in the window, no quadratic
        let jerky: Vec<f64> = t
            .iter()
            .map(|t| 0.2 * t + 0.01 * (2.0 * std::f64::consts::PI * 40.0 * t).sin())
            .collect();
        let a = velocity_prior(&t, &smooth, 0, noise);
        let b = velocity_prior(&t, &jerky, 0, noise);
        assert!(b.sigma > 2.0 * a.sigma, "{a:?} {b:?}");
    }
}
