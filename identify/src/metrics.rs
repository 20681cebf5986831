//! Fit metrics between measured and simulated experiments: fit % (as MATLAB's
//! `compare`, normalised root-mean-square error) and RMSE, per channel and pooled.

use std::collections::BTreeMap;
use std::fmt;

use serde::{Deserialize, Serialize};

use crate::data::Experiment;

/// Why metrics cannot be computed.
#[derive(Clone, Debug, PartialEq)]
pub enum MetricsError {
    /// Measured and simulated signals differ in length.
    LengthMismatch {
        /// Experiment name.
        experiment: String,
        /// Channel name.
        channel: String,
        /// Measured samples.
        measured: usize,
        /// Simulated samples.
        simulated: usize,
    },
    /// A channel is absent from the measured or simulated experiment.
    MissingChannel {
        /// Experiment name.
        experiment: String,
        /// Channel name.
        channel: String,
        /// `"measured"` or `"simulated"`.
        side: &'static str,
    },
    /// A signal holds NaN or infinity (a diverged simulation, typically).
    NotFinite {
        /// Experiment name.
        experiment: String,
        /// Channel name.
        channel: String,
        /// 0-based sample index.
        index: usize,
    },
    /// No samples to compare.
    Empty,
    /// Different numbers of measured and simulated experiments.
    ExperimentCount {
        /// Measured experiments.
        measured: usize,
        /// Simulated experiments.
        simulated: usize,
    },
}

impl fmt::Display for MetricsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MetricsError::LengthMismatch {
                experiment,
                channel,
                measured,
                simulated,
            } => write!(
                f,
                "{experiment}: channel `{channel}` has {measured} measured but {simulated} simulated samples"
            ),
            MetricsError::MissingChannel {
                experiment,
                channel,
                side,
            } => write!(f, "{experiment}: no {side} channel `{channel}`"),
            MetricsError::NotFinite {
                experiment,
                channel,
                index,
            } => write!(
                f,
                "{experiment}: channel `{channel}` is not finite at sample {index} (did the simulation diverge?)"
            ),
            MetricsError::Empty => write!(f, "no samples to compare"),
            MetricsError::ExperimentCount {
                measured,
                simulated,
            } => write!(
                f,
                "{measured} measured experiments but {simulated} simulated ones"
            ),
        }
    }
}

impl std::error::Error for MetricsError {}

/// Fit of one channel.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChannelFit {
    /// 100 (1 - ||y - yhat|| / ||y - mean(y)||); `None` (JSON null) when the
    /// measured channel is constant, where the ratio is undefined.
    pub fit_percent: Option<f64>,
    /// sqrt(mean((y - yhat)^2)), in the channel's SI unit (infinite when
    /// the simulation could not be finished).
    pub rmse: f64,
    /// The simulation diverged: it could not be finished (non-finite
    /// values), or it left the data (fit % below -100: its error more than
    /// twice the channel's own motion about its mean). A number then means
    /// nothing about the model's accuracy, only that it failed.
    #[serde(default)]
    pub diverged: bool,
}

/// Fits of one experiment's channels.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExperimentFit {
    /// The measured file.
    pub file: String,
    /// Channel name to fit, sorted by name.
    pub channels: BTreeMap<String, ChannelFit>,
}

/// Fits of all experiments, with the RMSE pooled over all experiments, channels
/// and samples. Serialises as
/// `{"experiments": [{"file": ..., "channels": {"theta": {"fit_percent": .., "rmse": ..}}}], "rmse": ..}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitReport {
    /// Per experiment, in input order.
    pub experiments: Vec<ExperimentFit>,
    /// sqrt(sum of all squared residuals / number of residuals). Mixes units if
    /// the channels have different ones (rad and m).
    pub rmse: f64,
}

/// Checks lengths and finiteness of a pair of signals.
fn check(y: &[f64], yhat: &[f64], experiment: &str, channel: &str) -> Result<(), MetricsError> {
    if y.len() != yhat.len() {
        return Err(MetricsError::LengthMismatch {
            experiment: experiment.into(),
            channel: channel.into(),
            measured: y.len(),
            simulated: yhat.len(),
        });
    }
    if y.is_empty() {
        return Err(MetricsError::Empty);
    }
    if let Some(index) = y
        .iter()
        .zip(yhat)
        .position(|(a, b)| !a.is_finite() || !b.is_finite())
    {
        return Err(MetricsError::NotFinite {
            experiment: experiment.into(),
            channel: channel.into(),
            index,
        });
    }
    Ok(())
}

/// Sum of squared residuals.
fn sse(y: &[f64], yhat: &[f64]) -> f64 {
    y.iter().zip(yhat).map(|(a, b)| (a - b) * (a - b)).sum()
}

/// Root-mean-square error between measured `y` and simulated `yhat`.
pub fn rmse(y: &[f64], yhat: &[f64]) -> Result<f64, MetricsError> {
    check(y, yhat, "", "")?;
    Ok((sse(y, yhat) / y.len() as f64).sqrt())
}

/// Fit % as MATLAB's `compare`: 100 (1 - ||y - yhat|| / ||y - mean(y)||).
/// 100 is perfect, 0 is no better than the mean, negative is worse.
/// `Ok(None)` when `y` is constant.
pub fn fit_percent(y: &[f64], yhat: &[f64]) -> Result<Option<f64>, MetricsError> {
    check(y, yhat, "", "")?;
    Ok(fit_percent_of(|| y.iter().zip(yhat)))
}

/// [`fit_percent`] over the `(measured, simulated)` pairs `pairs` yields,
/// walked rather than collected (a long record's copies cost as much as its
/// simulation): None for no pairs or a constant measurement.
pub(crate) fn fit_percent_of<'a, I>(pairs: impl Fn() -> I) -> Option<f64>
where
    I: Iterator<Item = (&'a f64, &'a f64)>,
{
    let n = pairs().count();
    if n == 0 {
        return None;
    }
    let mean = pairs().map(|(a, _)| a).sum::<f64>() / n as f64;
    let den = pairs()
        .map(|(a, _)| (a - mean) * (a - mean))
        .sum::<f64>()
        .sqrt();
    let sse: f64 = pairs().map(|(a, b)| (a - b) * (a - b)).sum();
    (den != 0.0).then(|| 100.0 * (1.0 - sse.sqrt() / den))
}

/// Compares measured experiments with simulated ones (same order, same
/// sample instants) on the named channels.
pub fn compare(
    measured: &[Experiment],
    simulated: &[Experiment],
    channels: &[&str],
) -> Result<FitReport, MetricsError> {
    if measured.len() != simulated.len() {
        return Err(MetricsError::ExperimentCount {
            measured: measured.len(),
            simulated: simulated.len(),
        });
    }
    let mut experiments = Vec::new();
    let (mut total_sse, mut total_n) = (0.0, 0usize);
    for (m, s) in measured.iter().zip(simulated) {
        let mut fits = BTreeMap::new();
        for &ch in channels {
            let (y, yhat) = channel_pair(m, s, ch)?;
            // a simulation starts at its first finite sample (a record
            // followed only after a release transient); one that could
            // not be finished from there is diverged, not an error of the
            // comparison (measured values must be finite)
            let first = simulated_from(y, yhat);
            let (y, yhat) = (&y[first..], &yhat[first..]);
            if y.len() == yhat.len()
                && y.iter().all(|v| v.is_finite())
                && yhat.iter().any(|v| !v.is_finite())
            {
                total_sse = f64::INFINITY;
                total_n += y.len();
                fits.insert(
                    ch.to_string(),
                    ChannelFit {
                        fit_percent: None,
                        rmse: f64::INFINITY,
                        diverged: true,
                    },
                );
                continue;
            }
            check(y, yhat, &m.name, ch)?;
            let e = sse(y, yhat);
            total_sse += e;
            total_n += y.len();
            let fit = fit_percent(y, yhat)?;
            fits.insert(
                ch.to_string(),
                ChannelFit {
                    fit_percent: fit,
                    rmse: (e / y.len() as f64).sqrt(),
                    diverged: fit.is_some_and(|f| f < -100.0),
                },
            );
        }
        experiments.push(ExperimentFit {
            file: m.file.display().to_string(),
            channels: fits,
        });
    }
    if total_n == 0 {
        return Err(MetricsError::Empty);
    }
    Ok(FitReport {
        experiments,
        rmse: (total_sse / total_n as f64).sqrt(),
    })
}

/// Where a simulation `yhat` of `y` starts: its first finite sample when
/// it has as many samples as `y` (a record followed only after a release
/// transient, [`crate::release`], is not simulated before it), else 0.
/// Comparisons, figures and where-it-fails look at the samples from there.
pub(crate) fn simulated_from(y: &[f64], yhat: &[f64]) -> usize {
    if y.len() == yhat.len() {
        yhat.iter().position(|v| v.is_finite()).unwrap_or(0)
    } else {
        0
    }
}

/// The measured and simulated values of one channel.
pub(crate) fn channel_pair<'a>(
    m: &'a Experiment,
    s: &'a Experiment,
    ch: &str,
) -> Result<(&'a [f64], &'a [f64]), MetricsError> {
    let y = m.values(ch).ok_or_else(|| MetricsError::MissingChannel {
        experiment: m.name.clone(),
        channel: ch.to_string(),
        side: "measured",
    })?;
    let yhat = s.values(ch).ok_or_else(|| MetricsError::MissingChannel {
        experiment: m.name.clone(),
        channel: ch.to_string(),
        side: "simulated",
    })?;
    Ok((y, yhat))
}
