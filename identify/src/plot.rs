//! SVG figures: measured vs simulated overlay (fit % in the legend) and the
//! residual as an envelope, per channel, then the inputs; every axis with
//! its unit.
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

/// The channels of a comparison figure, each with its unit (drawn on its
/// axis).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FigureChannels {
    /// Outputs drawn measured vs simulated, then their residual:
    /// `(name, unit)`.
    pub outputs: Vec<(String, String)>,
    /// Inputs drawn in a panel of their own each (skipped when the
    /// measured experiment lacks them, e.g. computed by a recorded
    /// controller in the loop): `(name, unit)`.
    pub inputs: Vec<(String, String)>,
}

impl FigureChannels {
    /// A model's coordinates (SI units: rad or m) and inputs (units as
    /// written in the model file).
    pub fn of_model(model: &plantc_derive::model::Model) -> FigureChannels {
        use plantc_derive::model::CoordinateKind;
        FigureChannels {
            outputs: model
                .coordinates
                .iter()
                .map(|c| {
                    let unit = match c.kind {
                        CoordinateKind::Angle => "rad",
                        CoordinateKind::Length => "m",
                    };
                    (c.name.clone(), unit.to_string())
                })
                .collect(),
            inputs: model
                .inputs
                .iter()
                .map(|i| (i.name.clone(), i.unit.clone()))
                .collect(),
        }
    }

    /// Outputs `names`, all in `unit`, and no inputs.
    pub fn outputs(names: &[&str], unit: &str) -> FigureChannels {
        FigureChannels {
            outputs: names
                .iter()
                .map(|n| (n.to_string(), unit.to_string()))
                .collect(),
            inputs: Vec::new(),
        }
    }
}

/// `name [unit]`, or the name alone for a unitless channel.
pub fn axis_label(name: &str, unit: &str) -> String {
    if unit.is_empty() {
        name.to_string()
    } else {
        format!("{name} [{unit}]")
    }
}

/// The legend entry of a simulation: `label, fit 93.2 %` over the finite
/// samples; `diverged` when samples are not finite or fit % is below
/// -100 (as [`crate::ChannelFit::diverged`]).
pub fn fit_legend(label: &str, y: &[f64], yhat: &[f64]) -> String {
    // (from where the simulation starts: not over a release transient)
    let first = crate::metrics::simulated_from(y, yhat);
    let (y, yhat) = (&y[first..], &yhat[first..]);
    if yhat.iter().any(|v| !v.is_finite()) {
        return format!("{label}, diverged");
    }
    match crate::metrics::fit_percent(y, yhat) {
        Ok(Some(f)) if f < -100.0 => format!("{label}, diverged"),
        Ok(Some(f)) => format!("{label}, fit {f:.1} %"),
        _ => format!("{label}, fit - (constant channel)"),
    }
}

/// Draws, for each output channel, measured and simulated against time
/// (fit % in the legend) and, below, the residual (measured - simulated)
/// as an envelope: its minimum and maximum in each pixel column, filled;
/// then each input in a panel of its own. Every axis has its unit. Writes
/// one SVG to `path`. Non-finite simulated samples are skipped in the
/// drawing.
pub fn plot_comparison(
    path: &Path,
    measured: &Experiment,
    simulated: &Experiment,
    channels: &FigureChannels,
) -> Result<(), PlotError> {
    let svg = render_comparison(measured, simulated, channels)?;
    // crash-safe: an existing figure is replaced whole or not at all
    plantc_fsio::write_atomic(path, svg).map_err(|e| PlotError::Io {
        file: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// Heights of the panels (px): an overlay, a residual, an input.
const OVERLAY_H: u32 = 240;
const RESIDUAL_H: u32 = 170;
const INPUT_H: u32 = 170;

/// The SVG text of [`plot_comparison`].
pub fn render_comparison(
    measured: &Experiment,
    simulated: &Experiment,
    channels: &FigureChannels,
) -> Result<String, PlotError> {
    if channels.outputs.is_empty() {
        return Err(PlotError::NoChannels);
    }
    let mut pairs = Vec::new();
    for (ch, unit) in &channels.outputs {
        let ch = ch.as_str();
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
        pairs.push((ch, unit.as_str(), y, yhat));
    }
    let inputs: Vec<(&str, &str, &[f64])> = channels
        .inputs
        .iter()
        .filter_map(|(n, u)| {
            let v = measured.values(n)?;
            (v.len() == measured.t.len()).then_some((n.as_str(), u.as_str(), v))
        })
        .collect();
    let t = &measured.t;
    let (t0, t1) = (t[0], t[t.len() - 1].max(t[0] + f64::EPSILON));
    let mut heights = Vec::new();
    for _ in &pairs {
        heights.extend([OVERLAY_H, RESIDUAL_H]);
    }
    heights.extend(inputs.iter().map(|_| INPUT_H));
    let total: u32 = heights.iter().sum();
    let breaks: Vec<i32> = heights
        .iter()
        .scan(0u32, |acc, h| {
            *acc += h;
            Some(*acc as i32)
        })
        .take(heights.len() - 1)
        .collect();
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1000, total)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let areas = root.split_by_breakpoints(Vec::<i32>::new(), breaks);
        let time = "t [s]";
        for (k, (ch, unit, y, yhat)) in pairs.iter().enumerate() {
            let r: Vec<f64> = y.iter().zip(yhat.iter()).map(|(a, b)| a - b).collect();
            // Overlay.
            let (lo, hi) = range(y.iter().chain(yhat.iter()));
            let mut chart = ChartBuilder::on(&areas[2 * k])
                .caption(
                    format!("{}: {ch} measured vs simulated", measured.name),
                    ("sans-serif", 16),
                )
                .margin(8)
                .x_label_area_size(34)
                .y_label_area_size(70)
                .build_cartesian_2d(t0..t1, lo..hi)
                .map_err(draw_err)?;
            chart
                .configure_mesh()
                .x_desc(time)
                .y_desc(axis_label(ch, unit))
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
                .label(fit_legend("simulated", y, yhat))
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(draw_err)?;
            // Residual: an envelope of min/max per pixel column.
            let (lo, hi) = range(r.iter().chain(std::iter::once(&0.0)));
            let mut chart = ChartBuilder::on(&areas[2 * k + 1])
                .caption(
                    format!(
                        "{}: {ch} residual (measured - simulated), min/max per pixel column",
                        measured.name
                    ),
                    ("sans-serif", 14),
                )
                .margin(8)
                .x_label_area_size(34)
                .y_label_area_size(70)
                .build_cartesian_2d(t0..t1, lo..hi)
                .map_err(draw_err)?;
            chart
                .configure_mesh()
                .x_desc(time)
                .y_desc(axis_label("residual", unit))
                .draw()
                .map_err(draw_err)?;
            let columns = chart.plotting_area().dim_in_pixel().0.max(1) as usize;
            let env = envelope(t, &r, (t0, t1), columns);
            if !env.is_empty() {
                let upper: Vec<(f64, f64)> = env.iter().map(|&(t, _, hi)| (t, hi)).collect();
                let lower: Vec<(f64, f64)> = env.iter().map(|&(t, lo, _)| (t, lo)).collect();
                let ring: Vec<(f64, f64)> =
                    upper.iter().chain(lower.iter().rev()).copied().collect();
                chart
                    .draw_series(std::iter::once(Polygon::new(
                        ring,
                        RGBColor(60, 60, 60).mix(0.55).filled(),
                    )))
                    .map_err(draw_err)?;
                // the edges keep an envelope one pixel thin visible
                for edge in [upper, lower] {
                    chart
                        .draw_series(std::iter::once(PathElement::new(edge, BLACK)))
                        .map_err(draw_err)?;
                }
            }
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(t0, 0.0), (t1, 0.0)],
                    BLUE.mix(0.6),
                )))
                .map_err(draw_err)?;
        }
        // Inputs.
        for (j, (name, unit, u)) in inputs.iter().enumerate() {
            let area = &areas[2 * pairs.len() + j];
            let (lo, hi) = range(u.iter());
            let mut chart = ChartBuilder::on(area)
                .caption(
                    format!("{}: input {name}", measured.name),
                    ("sans-serif", 14),
                )
                .margin(8)
                .x_label_area_size(34)
                .y_label_area_size(70)
                .build_cartesian_2d(t0..t1, lo..hi)
                .map_err(draw_err)?;
            chart
                .configure_mesh()
                .x_desc(time)
                .y_desc(axis_label(name, unit))
                .draw()
                .map_err(draw_err)?;
            chart
                .draw_series(LineSeries::new(decimate(t, u), &RGBColor(0, 128, 0)))
                .map_err(draw_err)?;
        }
        root.present().map_err(draw_err)?;
    }
    Ok(buf)
}

/// The minimum and maximum of `x` in each of `columns` equal time columns
/// over `t0..t1`: `(column centre, min, max)` for every column with a
/// finite sample.
pub fn envelope(
    t: &[f64],
    x: &[f64],
    (t0, t1): (f64, f64),
    columns: usize,
) -> Vec<(f64, f64, f64)> {
    let columns = columns.max(1);
    let width = (t1 - t0).max(f64::MIN_POSITIVE);
    let mut cols = vec![(f64::INFINITY, f64::NEG_INFINITY); columns];
    for (&ti, &xi) in t.iter().zip(x) {
        if !xi.is_finite() {
            continue;
        }
        let c = (((ti - t0) / width) * columns as f64).floor();
        let c = (c.max(0.0) as usize).min(columns - 1);
        cols[c].0 = cols[c].0.min(xi);
        cols[c].1 = cols[c].1.max(xi);
    }
    cols.iter()
        .enumerate()
        .filter(|(_, (lo, hi))| lo <= hi)
        .map(|(c, &(lo, hi))| (t0 + (c as f64 + 0.5) / columns as f64 * width, lo, hi))
        .collect()
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
    min_max(t, x, MAX_BUCKETS)
}

/// `x` over `t` reduced to the minimum and maximum of each of `buckets`
/// equal index ranges, in time order (all samples when there are at most
/// two per bucket); non-finite samples dropped.
pub fn min_max(t: &[f64], x: &[f64], buckets: usize) -> Vec<(f64, f64)> {
    let n = t.len().min(x.len());
    let finite = |i: &usize| x[*i].is_finite();
    let buckets = buckets.max(1);
    if n <= 2 * buckets {
        return (0..n).filter(finite).map(|i| (t[i], x[i])).collect();
    }
    let mut out = Vec::with_capacity(2 * buckets);
    for b in 0..buckets {
        let (a, e) = (b * n / buckets, (b + 1) * n / buckets);
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

/// Draws, for each residual test, the residual's autocorrelation and its
/// cross-correlation with each input against the lag, as stems, with the
/// 99 % band shaded; writes one SVG to `path`.
pub fn plot_residual_tests(path: &Path, tests: &[crate::ResidualTest]) -> Result<(), PlotError> {
    let svg = render_residual_tests(tests)?;
    plantc_fsio::write_atomic(path, svg).map_err(|e| PlotError::Io {
        file: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// The SVG text of [`plot_residual_tests`].
pub fn render_residual_tests(tests: &[crate::ResidualTest]) -> Result<String, PlotError> {
    if tests.is_empty() {
        return Err(PlotError::NoChannels);
    }
    let cols = 1 + tests.iter().map(|t| t.cross.len()).max().unwrap_or(0);
    let panel = (480u32, 240u32);
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(
            &mut buf,
            (panel.0 * cols as u32, panel.1 * tests.len() as u32),
        )
        .into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let areas = root.split_evenly((tests.len(), cols));
        for (r, t) in tests.iter().enumerate() {
            let auto = t.autocorrelation_points();
            let title = format!(
                "{}: {} autocorrelation (correlation time {:.1} samples)",
                t.experiment, t.channel, t.correlation_time
            );
            stems(&areas[r * cols], &title, &auto, t.band, 0.0, t.lags as f64)?;
            for (c, x) in t.cross.iter().enumerate() {
                let (l, pts) = (x.half_width(), x.points());
                let title = format!(
                    "{}: {} vs {} ({})",
                    t.experiment,
                    t.channel,
                    x.input,
                    x.verdict()
                );
                stems(&areas[r * cols + 1 + c], &title, &pts, x.band, -l, l)?;
            }
        }
        root.present().map_err(draw_err)?;
    }
    Ok(buf)
}

/// One stem panel with the band `+-band` shaded.
fn stems(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    title: &str,
    pts: &[(f64, f64)],
    band: f64,
    x0: f64,
    x1: f64,
) -> Result<(), PlotError> {
    let top = pts
        .iter()
        .map(|p| p.1.abs())
        .fold(band * 1.5, f64::max)
        .clamp(1e-6, 1.05);
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 13))
        .margin(6)
        .x_label_area_size(24)
        .y_label_area_size(48)
        .build_cartesian_2d((x0 - 0.5)..(x1 + 0.5), -top..top)
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc("lag [samples]")
        .y_desc("normalised correlation [-]")
        .draw()
        .map_err(draw_err)?;
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(x0 - 0.5, -band), (x1 + 0.5, band)],
            RGBColor(200, 220, 255).filled(),
        )))
        .map_err(draw_err)?;
    chart
        .draw_series(pts.iter().map(|&(x, y)| {
            let color = if y.abs() > band { RED } else { BLUE };
            PathElement::new(vec![(x, 0.0), (x, y)], color.stroke_width(2))
        }))
        .map_err(draw_err)?;
    Ok(())
}
