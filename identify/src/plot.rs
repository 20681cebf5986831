//! SVG figures: measured vs simulated overlay and residual, per channel.
//!
//! Rendering goes to a string (plotters' SVG backend, no fonts loaded: text is
//! emitted as SVG `<text>`), then written to the path, so output is
//! deterministic and I/O errors are reported. Long signals are reduced to the
//! minimum and maximum of each of at most [`MAX_BUCKETS`] time buckets, which
//! keeps peaks and keeps files small.

use std::fmt;
use std::path::{Path, PathBuf};

use plotters::prelude::*;

use crate::data::Experiment;

/// Most time buckets drawn per line (each gives two points).
pub const MAX_BUCKETS: usize = 1500;

/// Why a figure could not be made.
#[derive(Clone, Debug, PartialEq)]
pub enum PlotError {
    /// A channel is missing from one side.
    MissingChannel {
        /// Channel name.
        channel: String,
        /// `"measured"` or `"simulated"`.
        side: &'static str,
    },
    /// Measured and simulated lengths differ, or there are no samples.
    Length {
        /// Channel name.
        channel: String,
        /// Measured samples.
        measured: usize,
        /// Simulated samples.
        simulated: usize,
    },
    /// Nothing to draw.
    NoChannels,
    /// The drawing library failed.
    Draw(String),
    /// The file could not be written.
    Io {
        /// The path.
        file: PathBuf,
        /// The system's message.
        message: String,
    },
}

impl fmt::Display for PlotError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PlotError::MissingChannel { channel, side } => {
                write!(f, "cannot plot: no {side} channel `{channel}`")
            }
            PlotError::Length {
                channel,
                measured,
                simulated,
            } => write!(
                f,
                "cannot plot `{channel}`: {measured} measured vs {simulated} simulated samples"
            ),
            PlotError::NoChannels => write!(f, "cannot plot: no channels given"),
            PlotError::Draw(m) => write!(f, "plotting failed: {m}"),
            PlotError::Io { file, message } => {
                write!(f, "{}: cannot write figure: {message}", file.display())
            }
        }
    }
}

impl std::error::Error for PlotError {}

fn draw_err<E: std::fmt::Debug>(e: E) -> PlotError {
    PlotError::Draw(format!("{e:?}"))
}

/// Draws, for each channel, measured and simulated against time and, below,
/// the residual (measured - simulated); writes one SVG to `path`.
/// Non-finite simulated samples are skipped in the drawing.
pub fn plot_comparison(
    path: &Path,
    measured: &Experiment,
    simulated: &Experiment,
    channels: &[&str],
) -> Result<(), PlotError> {
    let svg = render_comparison(measured, simulated, channels)?;
    // crash-safe: an existing figure is replaced whole or not at all
    plantc_fsio::write_atomic(path, svg).map_err(|e| PlotError::Io {
        file: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// The SVG text of [`plot_comparison`].
pub fn render_comparison(
    measured: &Experiment,
    simulated: &Experiment,
    channels: &[&str],
) -> Result<String, PlotError> {
    if channels.is_empty() {
        return Err(PlotError::NoChannels);
    }
    let mut pairs = Vec::new();
    for &ch in channels {
        let y = measured.values(ch).ok_or(PlotError::MissingChannel {
            channel: ch.into(),
            side: "measured",
        })?;
        let yhat = simulated.values(ch).ok_or(PlotError::MissingChannel {
            channel: ch.into(),
            side: "simulated",
        })?;
        if y.len() != yhat.len() || y.len() != measured.t.len() || y.is_empty() {
            return Err(PlotError::Length {
                channel: ch.into(),
                measured: y.len(),
                simulated: yhat.len(),
            });
        }
        pairs.push((ch, y, yhat));
    }
    let t = &measured.t;
    let (t0, t1) = (t[0], t[t.len() - 1].max(t[0] + f64::EPSILON));
    let panel_h = 240u32;
    let mut buf = String::new();
    {
        let rows = 2 * pairs.len();
        let root =
            SVGBackend::with_string(&mut buf, (1000, panel_h * rows as u32)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let areas = root.split_evenly((rows, 1));
        for (k, (ch, y, yhat)) in pairs.iter().enumerate() {
            let unit = measured
                .channel(ch)
                .and_then(|c| c.unit_note.clone())
                .unwrap_or_default();
            let r: Vec<f64> = y.iter().zip(yhat.iter()).map(|(a, b)| a - b).collect();
            // Overlay.
            let (lo, hi) = range(y.iter().chain(yhat.iter()));
            let mut chart = ChartBuilder::on(&areas[2 * k])
                .caption(
                    format!("{}: {ch} measured vs simulated", measured.name),
                    ("sans-serif", 16),
                )
                .margin(8)
                .x_label_area_size(28)
                .y_label_area_size(70)
                .build_cartesian_2d(t0..t1, lo..hi)
                .map_err(draw_err)?;
            chart
                .configure_mesh()
                .x_desc("t [s]")
                .y_desc(format!("{ch} {unit}"))
                .draw()
                .map_err(draw_err)?;
            chart
                .draw_series(LineSeries::new(decimate(t, y), &BLUE))
                .map_err(draw_err)?
                .label("measured")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
            chart
                .draw_series(LineSeries::new(decimate(t, yhat), &RED))
                .map_err(draw_err)?
                .label("simulated")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(draw_err)?;
            // Residual.
            let (lo, hi) = range(r.iter().chain(std::iter::once(&0.0)));
            let mut chart = ChartBuilder::on(&areas[2 * k + 1])
                .caption(
                    format!("{}: {ch} residual (measured - simulated)", measured.name),
                    ("sans-serif", 16),
                )
                .margin(8)
                .x_label_area_size(28)
                .y_label_area_size(70)
                .build_cartesian_2d(t0..t1, lo..hi)
                .map_err(draw_err)?;
            chart
                .configure_mesh()
                .x_desc("t [s]")
                .y_desc(format!("residual {unit}"))
                .draw()
                .map_err(draw_err)?;
            chart
                .draw_series(LineSeries::new(decimate(t, &r), &BLACK))
                .map_err(draw_err)?;
        }
        root.present().map_err(draw_err)?;
    }
    Ok(buf)
}

/// Finite range with a margin; a constant gives +-1e-9 around it.
fn range<'a>(vals: impl Iterator<Item = &'a f64>) -> (f64, f64) {
    let (lo, hi) = vals
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-9 * (1.0 + lo.abs().max(hi.abs())));
    (lo - pad, hi + pad)
}

/// Min-max decimation to at most [`MAX_BUCKETS`] buckets; non-finite samples dropped.
fn decimate(t: &[f64], x: &[f64]) -> Vec<(f64, f64)> {
    let n = t.len().min(x.len());
    let finite = |i: &usize| x[*i].is_finite();
    if n <= 2 * MAX_BUCKETS {
        return (0..n).filter(finite).map(|i| (t[i], x[i])).collect();
    }
    let mut out = Vec::with_capacity(2 * MAX_BUCKETS);
    for b in 0..MAX_BUCKETS {
        let (a, e) = (b * n / MAX_BUCKETS, (b + 1) * n / MAX_BUCKETS);
        let idx: Vec<usize> = (a..e).filter(finite).collect();
        let (Some(&imin), Some(&imax)) = (
            idx.iter().min_by(|&&i, &&j| x[i].total_cmp(&x[j])),
            idx.iter().max_by(|&&i, &&j| x[i].total_cmp(&x[j])),
        ) else {
            continue;
        };
        let (p, q) = if imin <= imax {
            (imin, imax)
        } else {
            (imax, imin)
        };
        out.push((t[p], x[p]));
        if q != p {
            out.push((t[q], x[q]));
        }
    }
    out
}
