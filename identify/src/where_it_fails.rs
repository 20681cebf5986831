//! "Where it fails": residual statistics by time segment and by operating
//! regime, turned into findings with human sentences.
//!
//! For each channel, with residual r = y - yhat (measured minus simulated):
//!
//! - **Time segments**: `segments` (10) equal slices of the samples.
//! - **Amplitude bins**: the swing amplitude at each sample is the moving
//!   maximum of |y - local mean| over a centred window of `envelope_window`
//!   seconds (2 s, more than one pendulum period), the local mean taken over the
//!   same window. Its range [min, max] is cut in three equal-width thirds:
//!   small, medium, large.
//! - **Speed bins**: |velocity| from a centred least-squares slope over
//!   `velocity_window` seconds (a first-order Savitzky-Golay derivative, 50 ms),
//!   cut at its tertiles (equal sample counts): low, medium, high.
//! - **Turnarounds**: samples with |velocity| below `turnaround_fraction` (5 %) of
//!   the 95th percentile of |velocity|, against all other samples.
//!
//! Findings (each with its ratio) are emitted when, with R = `ratio_threshold` (2):
//!
//! - RMSE(small amplitude) / RMSE(large) > R, or the inverse;
//! - RMSE(low speed) / RMSE(high speed) > R, or the inverse;
//! - RMSE(turnarounds) / RMSE(elsewhere) > R;
//! - RMSE(last segment) / RMSE(first segment) > R, or the inverse;
//! - |mean| > 0.5 RMSE (bias).
//!
//! Bins with
//! fewer than `min_bin_fraction` (5 %) of the samples or fewer than 20 samples
//! are not compared (the turnaround group needs only 1 %, since turnarounds are
//! brief). When the measured signal is quantised (see
//! [`crate::plausibility::quantum`]) its floor q/sqrt(12) is computed; a
//! comparison whose larger RMSE is below twice the floor is not reported (it is
//! noise), and an overall RMSE below twice the floor gives an "at the
//! quantisation floor" finding instead.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::data::{ChannelSpec, Experiment};
use crate::metrics::{channel_pair, rmse, MetricsError};

/// Settings of the analysis (see the module doc for their meaning).
#[derive(Clone, Debug, PartialEq)]
pub struct FailOptions {
    /// Number of equal time segments.
    pub segments: usize,
    /// Window for the amplitude envelope, s.
    pub envelope_window: f64,
    /// Window for the velocity estimate, s.
    pub velocity_window: f64,
    /// Turnaround threshold as a fraction of the 95th-percentile |velocity|.
    pub turnaround_fraction: f64,
    /// A ratio above this makes a finding.
    pub ratio_threshold: f64,
    /// Smallest bin, as a fraction of the samples, that is compared.
    pub min_bin_fraction: f64,
    /// Unit symbol per channel for sentences (e.g. theta -> rad).
    pub units: BTreeMap<String, String>,
}

impl Default for FailOptions {
    fn default() -> Self {
        FailOptions {
            segments: 10,
            envelope_window: 2.0,
            velocity_window: 0.05,
            turnaround_fraction: 0.05,
            ratio_threshold: 2.0,
            min_bin_fraction: 0.05,
            units: BTreeMap::new(),
        }
    }
}

impl FailOptions {
    /// Defaults, with units taken from the spec's coordinate kinds.
    pub fn for_spec(spec: &ChannelSpec) -> Self {
        let mut o = Self::default();
        for (name, kind) in spec.all() {
            o.units.insert(name.clone(), kind.si_unit().to_string());
        }
        o
    }
}

/// Bias, spread and whiteness of a residual.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ResidualSummary {
    /// Samples.
    pub n: usize,
    /// Mean residual (bias), y - yhat.
    pub mean: f64,
    /// Standard deviation (population) of the residual.
    pub std: f64,
    /// Root mean square.
    pub rmse: f64,
    /// Largest |residual|.
    pub max_abs: f64,
    /// Lag-1 autocorrelation of the mean-removed residual; near 1 means a slow,
    /// systematic error, near 0 white noise. None for a constant residual.
    pub lag1_autocorrelation: Option<f64>,
}

/// Residual summary of measured `y` against simulated `yhat`.
pub fn residual_summary(y: &[f64], yhat: &[f64]) -> Result<ResidualSummary, MetricsError> {
    let total = rmse(y, yhat)?; // checks lengths and finiteness
    let r: Vec<f64> = y.iter().zip(yhat).map(|(a, b)| a - b).collect();
    let n = r.len();
    let mean = r.iter().sum::<f64>() / n as f64;
    let var = r.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64;
    let max_abs = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let lag1 = if var > 0.0 && n > 1 {
        let c1: f64 = r
            .windows(2)
            .map(|w| (w[0] - mean) * (w[1] - mean))
            .sum::<f64>()
            / n as f64;
        Some(c1 / var)
    } else {
        None
    };
    Ok(ResidualSummary {
        n,
        mean,
        std: var.sqrt(),
        rmse: total,
        max_abs,
        lag1_autocorrelation: lag1,
    })
}

/// Residual statistics of one group of samples.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupStats {
    /// `small`, `medium`, `large`, `low`, `high`, `turnaround`, `moving`, or
    /// `segment 3` for time segments.
    pub label: String,
    /// Lower bound of the grouping variable (s, amplitude unit or unit/s).
    pub lower: f64,
    /// Upper bound of the grouping variable.
    pub upper: f64,
    /// Samples in the group.
    pub n: usize,
    /// RMSE of the residual in the group (NaN serialised as null when empty).
    pub rmse: Option<f64>,
    /// Mean residual in the group.
    pub bias: Option<f64>,
}

/// What a finding says.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FindingKind {
    /// Error grows at small swing amplitude.
    SmallAmplitude,
    /// Error grows at large swing amplitude.
    LargeAmplitude,
    /// Error grows at low speed.
    LowSpeed,
    /// Error grows at high speed.
    HighSpeed,
    /// Error concentrates at near-zero-speed turnarounds.
    Turnarounds,
    /// Error grows over time.
    GrowsOverTime,
    /// Error is largest at the start.
    LargestAtStart,
    /// The residual has a clear mean.
    Bias,
    /// The residual is at the quantisation floor: nothing left to explain.
    AtFloor,
    /// The simulation left the data (its error more than twice the
    /// channel's own motion, fit % below -100): the patterns of its error
    /// say nothing about a missing effect.
    Diverged,
}

/// One statement about where the model fails.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Finding {
    /// What it says.
    pub kind: FindingKind,
    /// Experiment name.
    pub experiment: String,
    /// Channel name.
    pub channel: String,
    /// The ratio that triggered it (e.g. RMSE small / RMSE large).
    pub ratio: f64,
    /// The human sentence.
    pub sentence: String,
}

impl std::fmt::Display for Finding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} / {}: {}",
            self.experiment, self.channel, self.sentence
        )
    }
}

/// Everything found for one channel of one experiment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChannelDiagnosis {
    /// Experiment name.
    pub experiment: String,
    /// Channel name.
    pub channel: String,
    /// Overall residual summary.
    pub summary: ResidualSummary,
    /// Quantisation floor q/sqrt(12) of the measured signal, if quantised.
    pub quantisation_floor: Option<f64>,
    /// Time segments, in order.
    pub segments: Vec<GroupStats>,
    /// Amplitude thirds: small, medium, large.
    pub amplitude: Vec<GroupStats>,
    /// Speed tertiles: low, medium, high.
    pub speed: Vec<GroupStats>,
    /// Turnarounds, then moving samples.
    pub turnarounds: Vec<GroupStats>,
    /// Findings, strongest ratio first.
    pub findings: Vec<Finding>,
}

/// Analyses the named channels of one measured/simulated pair.
pub fn where_it_fails(
    measured: &Experiment,
    simulated: &Experiment,
    channels: &[&str],
    options: &FailOptions,
) -> Result<Vec<ChannelDiagnosis>, MetricsError> {
    let mut out = Vec::new();
    for &ch in channels {
        let (y, yhat) = channel_pair(measured, simulated, ch)?;
        // (from where the simulation starts: not over a release transient)
        let first = crate::metrics::simulated_from(y, yhat);
        let (y, yhat) = (&y[first..], &yhat[first..]);
        let t = measured.t.get(first..).unwrap_or(&measured.t);
        // a simulation that could not be finished: diverged, and nothing more
        if y.len() == yhat.len()
            && y.iter().all(|v| v.is_finite())
            && yhat.iter().any(|v| !v.is_finite())
        {
            let at = yhat.iter().position(|v| !v.is_finite()).unwrap_or(0);
            out.push(ChannelDiagnosis {
                experiment: measured.name.clone(),
                channel: ch.to_string(),
                summary: ResidualSummary {
                    n: y.len(),
                    mean: f64::NAN,
                    std: f64::NAN,
                    rmse: f64::INFINITY,
                    max_abs: f64::INFINITY,
                    lag1_autocorrelation: None,
                },
                quantisation_floor: crate::weights::quantum(y).map(|q| q / 12f64.sqrt()),
                segments: Vec::new(),
                amplitude: Vec::new(),
                speed: Vec::new(),
                turnarounds: Vec::new(),
                findings: vec![Finding {
                    kind: FindingKind::Diverged,
                    experiment: measured.name.clone(),
                    channel: ch.to_string(),
                    ratio: f64::INFINITY,
                    sentence: format!(
                        "the simulation diverged: it could not be continued past t = {:.3} s",
                        t.get(at).copied().unwrap_or(f64::NAN)
                            - measured.t.first().copied().unwrap_or(0.0)
                    ),
                }],
            });
            continue;
        }
        let summary = residual_summary(y, yhat).map_err(|e| match e {
            MetricsError::LengthMismatch {
                measured: m,
                simulated: s,
                ..
            } => MetricsError::LengthMismatch {
                experiment: measured.name.clone(),
                channel: ch.to_string(),
                measured: m,
                simulated: s,
            },
            MetricsError::NotFinite { index, .. } => MetricsError::NotFinite {
                experiment: measured.name.clone(),
                channel: ch.to_string(),
                index,
            },
            other => other,
        })?;
        if t.len() != y.len() {
            return Err(MetricsError::LengthMismatch {
                experiment: measured.name.clone(),
                channel: "t".into(),
                measured: t.len(),
                simulated: y.len(),
            });
        }
        out.push(diagnose(&measured.name, ch, t, y, yhat, summary, options));
    }
    Ok(out)
}

/// The analysis of one channel (inputs already checked).
fn diagnose(
    experiment: &str,
    channel: &str,
    t: &[f64],
    y: &[f64],
    yhat: &[f64],
    summary: ResidualSummary,
    o: &FailOptions,
) -> ChannelDiagnosis {
    let n = y.len();
    let r: Vec<f64> = y.iter().zip(yhat).map(|(a, b)| a - b).collect();
    let dt = crate::data::median_dt(t)
        .unwrap_or(1.0)
        .max(f64::MIN_POSITIVE);
    let unit = o.units.get(channel).cloned().unwrap_or_default();
    let floor = crate::weights::quantum(y).map(|q| q / 12f64.sqrt());

    // Time segments.
    let nseg = o.segments.clamp(1, n.max(1));
    let segments: Vec<GroupStats> = (0..nseg)
        .map(|s| {
            let (a, b) = (s * n / nseg, (s + 1) * n / nseg);
            let (lo, hi) = (t[a.min(n - 1)], t[b.saturating_sub(1).max(a).min(n - 1)]);
            stats(format!("segment {}", s + 1), lo, hi, a..b, &r)
        })
        .collect();

    // Amplitude thirds of the envelope.
    let half_env = ((o.envelope_window / 2.0) / dt).round().max(1.0) as usize;
    let env = envelope(y, half_env);
    let (elo, ehi) = min_max(&env);
    let amplitude = thirds(&env, elo, ehi, ["small", "medium", "large"], &r);
    // (each full-length buffer freed once used: a long record cannot hold
    // them all at once)
    drop(env);

    // Speed tertiles.
    let half_vel = ((o.velocity_window / 2.0) / dt).round().max(1.0) as usize;
    let mut speed_abs = velocity(t, y, half_vel);
    for v in &mut speed_abs {
        *v = v.abs();
    }
    let mut sorted = speed_abs.clone();
    sorted.sort_by(f64::total_cmp);
    let q = |p: f64| sorted[((p * (n - 1) as f64).round() as usize).min(n - 1)];
    let (c1, c2) = (q(1.0 / 3.0), q(2.0 / 3.0));
    let (smin, smax) = (sorted[0], sorted[n - 1]);
    let q95 = q(0.95);
    drop(sorted);
    let speed = vec![
        group("low", smin, c1, &speed_abs, &r, |v| v <= c1),
        group("medium", c1, c2, &speed_abs, &r, |v| v > c1 && v <= c2),
        group("high", c2, smax, &speed_abs, &r, |v| v > c2),
    ];

    // Turnarounds.
    let thr = o.turnaround_fraction * q95;
    let turnarounds = vec![
        group("turnaround", 0.0, thr, &speed_abs, &r, |v| v < thr),
        group("moving", thr, smax, &speed_abs, &r, |v| v >= thr),
    ];

    // Findings.
    let min_n = ((o.min_bin_fraction * n as f64).ceil() as usize).max(20);
    // Turnarounds are brief by nature: their group needs 1 % of the samples.
    let min_turn = ((0.01 * n as f64).ceil() as usize).max(20);
    let usable = |g: &GroupStats, min: usize| g.n >= min && g.rmse.is_some();
    let above_floor = |x: f64| !floor.is_some_and(|f| x <= 2.0 * f);
    let mut findings = Vec::new();
    let mut push = |kind, ratio: f64, sentence: String| {
        findings.push(Finding {
            kind,
            experiment: experiment.to_string(),
            channel: channel.to_string(),
            ratio,
            sentence,
        })
    };
    let rm = |g: &GroupStats| g.rmse.unwrap_or(0.0);
    let rt = o.ratio_threshold;
    let u = if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    };
    // (the decision rule's floor: noise plus a missing effect of one noise
    // RMS is at least sqrt(2) noise RMS, `crate::decision::at_floor`)
    let at_floor = floor.is_some_and(|f| summary.rmse < std::f64::consts::SQRT_2 * f);
    if let (Some(f), true) = (floor, at_floor) {
        push(
            FindingKind::AtFloor,
            summary.rmse / f,
            format!(
                "residual is at the quantisation floor: RMSE {}{u} vs floor {} ({:.1}x)",
                sci(summary.rmse),
                sci(f),
                summary.rmse / f
            ),
        );
    }
    let mut compare = |a: &GroupStats,
                       b: &GroupStats,
                       kind: FindingKind,
                       text: &dyn Fn(f64, f64, f64) -> String| {
        let min_a = if kind == FindingKind::Turnarounds {
            min_turn
        } else {
            min_n
        };
        if usable(a, min_a)
            && usable(b, min_n)
            && rm(a) > 0.0
            && rm(b) > 0.0
            && above_floor(rm(a).max(rm(b)))
        {
            let ratio = rm(a) / rm(b);
            if ratio > rt {
                push(kind, ratio, text(rm(a), rm(b), ratio));
            }
        }
    };
    let (small, large) = (&amplitude[0], &amplitude[2]);
    compare(small, large, FindingKind::SmallAmplitude, &|a, b, k| {
        format!(
            "error grows at small swing amplitude: RMSE {}{u} at small amplitude vs {} at large ({k:.1}x)",
            sci(a),
            sci(b)
        )
    });
    compare(large, small, FindingKind::LargeAmplitude, &|a, b, k| {
        format!(
            "error grows at large swing amplitude: RMSE {}{u} at large amplitude vs {} at small ({k:.1}x)",
            sci(a),
            sci(b)
        )
    });
    let (low, high) = (&speed[0], &speed[2]);
    // A channel at rest for a third of the samples or more has a speed
    // tertile bound of (numerically) zero: say "at rest" instead of printing it.
    let at_rest = |c: f64| c <= 1e-9 * smax;
    compare(low, high, FindingKind::LowSpeed, &|a, b, k| {
        if at_rest(c1) {
            format!(
                "error grows at rest: RMSE {}{u} while at rest vs {} at high speed ({k:.1}x)",
                sci(a),
                sci(b)
            )
        } else {
            format!(
                "error grows at low speed: RMSE {}{u} at low speed (|velocity| < {}{u}/s) vs {} at high speed ({k:.1}x)",
                sci(a),
                sci(c1),
                sci(b)
            )
        }
    });
    compare(high, low, FindingKind::HighSpeed, &|a, b, k| {
        if at_rest(c2) {
            format!(
                "error grows while it moves: RMSE {}{u} while moving vs {} at rest ({k:.1}x)",
                sci(a),
                sci(b)
            )
        } else if at_rest(c1) {
            format!(
                "error grows at high speed: RMSE {}{u} at high speed (|velocity| > {}{u}/s) vs {} at rest ({k:.1}x)",
                sci(a),
                sci(c2),
                sci(b)
            )
        } else {
            format!(
                "error grows at high speed: RMSE {}{u} at high speed (|velocity| > {}{u}/s) vs {} at low speed ({k:.1}x)",
                sci(a),
                sci(c2),
                sci(b)
            )
        }
    });
    let share = 100.0 * turnarounds[0].n as f64 / n as f64;
    compare(
        &turnarounds[0],
        &turnarounds[1],
        FindingKind::Turnarounds,
        &|a, b, k| {
            format!(
                "error concentrates at turnarounds (|velocity| < {}{u}/s, {share:.0} % of samples): RMSE {}{u} vs {} elsewhere ({k:.1}x)",
                sci(thr),
                sci(a),
                sci(b)
            )
        },
    );
    if nseg >= 2 {
        let (first, last) = (&segments[0], &segments[nseg - 1]);
        compare(last, first, FindingKind::GrowsOverTime, &|a, b, k| {
            format!(
                "error grows over time: RMSE {}{u} in the last segment (t = {:.1}-{:.1} s) vs {} in the first ({k:.1}x)",
                sci(a),
                last.lower,
                last.upper,
                sci(b)
            )
        });
        compare(first, last, FindingKind::LargestAtStart, &|a, b, k| {
            format!(
                "error is largest at the start: RMSE {}{u} in the first segment (t = {:.1}-{:.1} s) vs {} in the last ({k:.1}x)",
                sci(a),
                first.lower,
                first.upper,
                sci(b)
            )
        });
    }
    if !at_floor && summary.rmse > 0.0 && summary.mean.abs() > 0.5 * summary.rmse {
        let k = summary.mean.abs() / summary.rmse;
        push(
            FindingKind::Bias,
            k,
            format!(
                "residual is biased: mean {}{u}, {:.0} % of the RMSE {} (an offset or a missing static effect?)",
                sci(summary.mean),
                100.0 * k,
                sci(summary.rmse)
            ),
        );
    }
    findings.sort_by(|a, b| b.ratio.total_cmp(&a.ratio));
    // a simulation that left the data: only that is said
    let mean_y = y.iter().sum::<f64>() / n.max(1) as f64;
    let motion = (y.iter().map(|v| (v - mean_y).powi(2)).sum::<f64>() / n.max(1) as f64).sqrt();
    if summary.rmse > crate::fit::DIVERGED_COST * motion {
        findings = vec![Finding {
            kind: FindingKind::Diverged,
            experiment: experiment.to_string(),
            channel: channel.to_string(),
            ratio: summary.rmse / motion.max(f64::MIN_POSITIVE),
            // a channel that never moved has no motion to compare with
            // (its ratio, printed in full, ran to 300 digits)
            sentence: if motion > 0.0 {
                format!(
                    "the simulation diverged: its error RMS {}{u} is {}x the channel's own motion ({}{u}); the pattern of its error says nothing about a missing effect",
                    sci(summary.rmse),
                    sci(summary.rmse / motion),
                    sci(motion)
                )
            } else {
                format!(
                    "the simulation diverged: its error RMS is {}{u} where the measured channel never moves; the pattern of its error says nothing about a missing effect",
                    sci(summary.rmse)
                )
            },
        }];
    }

    ChannelDiagnosis {
        experiment: experiment.to_string(),
        channel: channel.to_string(),
        summary,
        quantisation_floor: floor,
        segments,
        amplitude,
        speed,
        turnarounds,
        findings,
    }
}

/// Compact scientific notation: 3.1e-3.
fn sci(x: f64) -> String {
    format!("{x:.1e}")
}

fn min_max(x: &[f64]) -> (f64, f64) {
    x.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        })
}

/// Residual statistics over the given sample indices.
/// (The indices are walked, not collected: a long record's would be as
/// large as the record.)
fn stats(
    label: String,
    lower: f64,
    upper: f64,
    idx: impl Iterator<Item = usize> + Clone,
    r: &[f64],
) -> GroupStats {
    let n = idx.clone().count();
    let (rmse, bias) = if n == 0 {
        (None, None)
    } else {
        let s2: f64 = idx.clone().map(|i| r[i] * r[i]).sum();
        let s1: f64 = idx.map(|i| r[i]).sum();
        (Some((s2 / n as f64).sqrt()), Some(s1 / n as f64))
    };
    GroupStats {
        label,
        lower,
        upper,
        n,
        rmse,
        bias,
    }
}

/// Statistics over the samples whose grouping value passes `keep`.
fn group(
    label: &str,
    lower: f64,
    upper: f64,
    var: &[f64],
    r: &[f64],
    keep: impl Fn(f64) -> bool + Copy,
) -> GroupStats {
    let idx = (0..var.len()).filter(move |&i| keep(var[i]));
    stats(label.to_string(), lower, upper, idx, r)
}

/// Three equal-width bins of `var` over [lo, hi].
fn thirds(var: &[f64], lo: f64, hi: f64, labels: [&str; 3], r: &[f64]) -> Vec<GroupStats> {
    let w = (hi - lo) / 3.0;
    let (b1, b2) = (lo + w, lo + 2.0 * w);
    vec![
        group(labels[0], lo, b1, var, r, |v| v < b1),
        group(labels[1], b1, b2, var, r, |v| v >= b1 && v < b2),
        group(labels[2], b2, hi, var, r, |v| v >= b2),
    ]
}

/// Swing amplitude: moving max of |x - moving mean|, centred windows of
/// half-width `h` samples (clamped at the ends).
pub fn envelope(x: &[f64], h: usize) -> Vec<f64> {
    let n = x.len();
    let mut prefix = vec![0.0; n + 1];
    for i in 0..n {
        prefix[i + 1] = prefix[i] + x[i];
    }
    let dev: Vec<f64> = (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(h), (i + h + 1).min(n));
            let mean = (prefix[b] - prefix[a]) / (b - a) as f64;
            (x[i] - mean).abs()
        })
        .collect();
    drop(prefix);
    // the moving maximum in O(n) (a monotonic queue of candidate indices),
    // not O(n h): a 2 s window at 2 kHz is 4,000 samples wide
    let mut out = Vec::with_capacity(n);
    let mut queue = std::collections::VecDeque::new();
    let mut next = 0; // next index to enter the window
    for i in 0..n {
        let (a, b) = (i.saturating_sub(h), (i + h + 1).min(n));
        while next < b {
            while queue.back().is_some_and(|&j: &usize| dev[j] <= dev[next]) {
                queue.pop_back();
            }
            queue.push_back(next);
            next += 1;
        }
        while queue.front().is_some_and(|&j| j < a) {
            queue.pop_front();
        }
        out.push(queue.front().map_or(0.0f64, |&j| dev[j].max(0.0)));
    }
    out
}

/// Velocity: least-squares slope over a centred window of half-width `h`
/// samples (first-order Savitzky-Golay derivative; clamped at the ends).
pub fn velocity(t: &[f64], x: &[f64], h: usize) -> Vec<f64> {
    let n = x.len().min(t.len());
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(h), (i + h + 1).min(n));
            let m = (b - a) as f64;
            let tm = t[a..b].iter().sum::<f64>() / m;
            let xm = x[a..b].iter().sum::<f64>() / m;
            let (mut sxy, mut sxx) = (0.0, 0.0);
            for k in a..b {
                sxy += (t[k] - tm) * (x[k] - xm);
                sxx += (t[k] - tm) * (t[k] - tm);
            }
            if sxx > 0.0 {
                sxy / sxx
            } else {
                0.0
            }
        })
        .collect()
}

#[cfg(test)]
mod envelope_tests {
    use super::envelope;

    /// The O(n h) definition.
    fn naive(x: &[f64], h: usize) -> Vec<f64> {
        let n = x.len();
        let dev: Vec<f64> = (0..n)
            .map(|i| {
                let (a, b) = (i.saturating_sub(h), (i + h + 1).min(n));
                let mean = x[a..b].iter().sum::<f64>() / (b - a) as f64;
                (x[i] - mean).abs()
            })
            .collect();
        (0..n)
            .map(|i| {
                let (a, b) = (i.saturating_sub(h), (i + h + 1).min(n));
                dev[a..b].iter().fold(0.0f64, |m, &v| m.max(v))
            })
            .collect()
    }

    #[test]
    fn linear_time_envelope_equals_the_definition() {
        let mut s = 1u64;
        let x: Vec<f64> = (0..3000)
            .map(|i| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (i as f64 * 0.01).sin() * 2.0 + (s >> 40) as f64 * 1e-7
            })
            .collect();
        for h in [1, 2, 7, 50, 499, 5000] {
            let (a, b) = (envelope(&x, h), naive(&x, h));
            for (p, q) in a.iter().zip(&b) {
                // the means come from prefix sums in `envelope`: rounding only
                assert!((p - q).abs() <= 1e-12, "h = {h}: {p} vs {q}");
            }
        }
    }
}
