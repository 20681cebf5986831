//! identify's report as one self-contained HTML file: inline CSS, inline
//! SVG drawn here, a few lines of inline JavaScript (toggle a series,
//! hover for values); no network, no external file. The `--json` summary
//! is embedded too (`<script type="application/json" id="plantc-summary">`).
//!
//! The figures are drawn here rather than by the browser so the file shows
//! its plots with scripts off and renders the same bytes every time (the
//! output is deterministic); the script only reads them back: each plot
//! `<svg>` carries its data window (`data-x0`...) and pixel box, each
//! series is a `<polyline>` in pixel coordinates, and hovering inverts the
//! mapping.

use std::fmt::Write as _;

use crate::report::{ExperimentFigure, OutputFigure, Report, StageRow, Trace};
use crate::residual_tests::ResidualTest;

/// The generator mark: a file with it was written by identify (and may be
/// replaced by it).
pub const GENERATOR: &str = "<meta name=\"generator\" content=\"plantc identify\">";

/// Width of a plot (px).
const W: f64 = 900.0;
/// Plot margins (px): left (y tick labels and label), right, top, bottom.
const ML: f64 = 78.0;
const MR: f64 = 12.0;
const MT: f64 = 26.0;
const MB: f64 = 40.0;

/// Colours: measured, then the stages in order (cycled).
const MEASURED: &str = "#222222";
const PALETTE: [&str; 8] = [
    "#9a9a9a", "#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2",
];

/// The report as HTML.
pub fn render_html(r: &Report) -> String {
    let mut h = String::new();
    h.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
    h.push_str(GENERATOR);
    let _ = writeln!(
        h,
        "\n<title>plantc identify: {}</title>\n<style>{CSS}</style>\n</head>\n<body>",
        esc(&r.model)
    );
    let _ = writeln!(
        h,
        "<h1>Identification of <code>{}</code></h1>",
        esc(&r.model)
    );
    let verdict = r
        .summary
        .get("verdict")
        .and_then(|v| v.as_str())
        .unwrap_or("");
    let stop = r.summary.get("stop").and_then(|v| v.as_str()).unwrap_or("");
    let _ = writeln!(
        h,
        "<p class=\"verdict\"><b>{}</b>: {}</p>",
        esc(&verdict.replace('_', " ")),
        esc(stop)
    );
    h.push_str("<nav>");
    for (id, t) in [
        ("table", "before/after"),
        ("figures", "figures"),
        ("residuals", "residual tests"),
        ("effects", "added effects"),
        ("rounds", "rounds"),
        ("story", "the story as printed"),
    ] {
        let _ = write!(h, "<a href=\"#{id}\">{t}</a> ");
    }
    h.push_str("</nav>\n");
    table(&mut h, &r.stages, r);
    figures(&mut h, r);
    residual_tests(&mut h, r);
    effects(&mut h, r);
    rounds(&mut h, r);
    let _ = writeln!(
        h,
        "<h2 id=\"story\">The story as printed</h2>\n<pre class=\"story\">{}</pre>",
        esc(&r.story)
    );
    let summary = serde_json::to_string(&r.summary).unwrap_or_else(|_| "null".into());
    // `</` cannot close the script element from inside the JSON
    let _ = writeln!(
        h,
        "<script type=\"application/json\" id=\"plantc-summary\">{}</script>",
        summary.replace("</", "<\\/")
    );
    let _ = writeln!(
        h,
        "<div id=\"tip\" class=\"tip\"></div>\n<script>{JS}</script>"
    );
    h.push_str("</body>\n</html>\n");
    h
}

/// The before/after table: one column per stage (and one per stage fitted
/// on segments, labelled), one row per experiment and output.
fn table(h: &mut String, stages: &[StageRow], r: &Report) {
    h.push_str("<h2 id=\"table\">Before and after</h2>\n<table class=\"fit\">\n<tr><th></th>");
    let mut cols: Vec<(&str, String)> = Vec::new();
    for s in stages {
        cols.push((s.label.as_str(), String::new()));
        if s.segments.is_some() {
            cols.push((s.label.as_str(), "segments as fitted".into()));
        }
    }
    for (label, extra) in &cols {
        if extra.is_empty() {
            let _ = write!(h, "<th>{}</th>", esc(label));
        } else {
            let _ = write!(h, "<th class=\"seg\">{} ({extra})</th>", esc(label));
        }
    }
    h.push_str("</tr>\n");
    let reports: Vec<&crate::FitReport> = stages
        .iter()
        .flat_map(|s| std::iter::once(&s.report).chain(s.segments.as_ref()))
        .collect();
    h.push_str("<tr><td>RMSE, all channels</td>");
    for rep in &reports {
        let _ = write!(h, "<td>{}</td>", num(rep.rmse));
    }
    h.push_str("</tr>\n");
    for (i, e) in r.experiments.iter().enumerate() {
        for o in &e.outputs {
            let _ = write!(
                h,
                "<tr><td>{} / {} [{}]</td>",
                esc(&e.name),
                esc(&o.channel),
                esc(&o.unit)
            );
            for rep in &reports {
                let cell = rep
                    .experiments
                    .get(i)
                    .and_then(|x| x.channels.get(&o.channel));
                match cell {
                    Some(c) if c.diverged => h.push_str("<td class=\"bad\">diverged</td>"),
                    Some(c) => {
                        let fit = c.fit_percent.map_or("-".into(), |f| format!("{f:.1} %"));
                        let _ = write!(h, "<td><b>{fit}</b> <small>{}</small></td>", num(c.rmse));
                    }
                    None => h.push_str("<td>-</td>"),
                }
            }
            h.push_str("</tr>\n");
        }
    }
    h.push_str("</table>\n<p class=\"note\">Cells: each stage's model simulated over the whole records from its estimated initial state; fit % as MATLAB's <code>compare</code>, then RMSE in SI units. <i>diverged</i>: the simulation could not be finished or left the data.</p>\n");
}

/// Per experiment: each output overlaid with every stage, the last stage's
/// residual, the inputs.
fn figures(h: &mut String, r: &Report) {
    let _ = writeln!(
        h,
        "<h2 id=\"figures\">Measured and simulated</h2>\n<p class=\"note\">Click a legend entry to hide or show that series in every figure; hover a plot for values. The residuals are those of the last stage, <code>{}</code>.</p>",
        esc(&r.residual_stage)
    );
    for e in &r.experiments {
        let _ = writeln!(h, "<h3>{}</h3>", esc(&e.name));
        for o in &e.outputs {
            overlay(h, e, o);
            residual(h, e, o);
        }
        for u in &e.inputs {
            let title = format!("{}: input {}", e.name, u.name);
            let series = [("input", u, "#2a8a2a", u.name.clone())];
            line_plot(h, &title, e.span, 170.0, (&u.name, &u.unit), &series, &[u]);
        }
    }
}

/// One output, measured and every stage, fit % in the legend.
fn overlay(h: &mut String, e: &ExperimentFigure, o: &OutputFigure) {
    let title = format!(
        "{}: {} measured and simulated by each stage",
        e.name, o.channel
    );
    let mut series: Vec<(String, &Trace, &str, String)> =
        vec![("measured".into(), &o.measured, MEASURED, "measured".into())];
    for (k, s) in o.stages.iter().enumerate() {
        let fit = if s.diverged {
            "diverged".to_string()
        } else {
            s.fit_percent
                .map_or("fit -".into(), |f| format!("fit {f:.1} %"))
        };
        series.push((
            format!("stage{k}"),
            &s.trace,
            PALETTE[k % PALETTE.len()],
            format!("{}: {fit}", s.label),
        ));
    }
    let refs: Vec<(&str, &Trace, &str, String)> = series
        .iter()
        .map(|(id, t, c, l)| (id.as_str(), *t, *c, l.clone()))
        .collect();
    // the window: the measured signal and the simulations that did not
    // diverge
    let window: Vec<&Trace> = std::iter::once(&o.measured)
        .chain(o.stages.iter().filter(|s| !s.diverged).map(|s| &s.trace))
        .collect();
    line_plot(
        h,
        &title,
        e.span,
        260.0,
        (&o.channel, &o.unit),
        &refs,
        &window,
    );
}

/// The last stage's residual as an envelope (min/max per column).
fn residual(h: &mut String, e: &ExperimentFigure, o: &OutputFigure) {
    if o.residual.is_empty() {
        return;
    }
    let title = format!(
        "{}: {} residual of the last stage (measured - simulated), min/max per pixel column",
        e.name, o.channel
    );
    let lo = o.residual.iter().map(|c| c.1).fold(0.0, f64::min);
    let hi = o.residual.iter().map(|c| c.2).fold(0.0, f64::max);
    let p = Panel::new(e.span, pad(lo, hi), 170.0);
    p.open(
        h,
        &title,
        "t [s]",
        &axis(&format!("residual {}", o.channel), &o.unit),
    );
    let mut d = String::new();
    for (k, &(t, _, v)) in o.residual.iter().enumerate() {
        let _ = write!(
            d,
            "{}{:.1},{:.1} ",
            if k == 0 { "M" } else { "L" },
            p.px(t),
            p.py(v)
        );
    }
    for &(t, v, _) in o.residual.iter().rev() {
        let _ = write!(d, "L{:.1},{:.1} ", p.px(t), p.py(v));
    }
    let _ = write!(
        h,
        "<path class=\"env\" d=\"{}Z\" fill=\"#555\" fill-opacity=\"0.55\" stroke=\"#222\" stroke-width=\"0.6\"/>",
        d.trim_end()
    );
    let _ = write!(
        h,
        "<line x1=\"{:.1}\" x2=\"{:.1}\" y1=\"{y:.1}\" y2=\"{y:.1}\" stroke=\"#1f77b4\" stroke-dasharray=\"4 3\"/>",
        p.px(e.span.0),
        p.px(e.span.1),
        y = p.py(0.0)
    );
    h.push_str("</svg></figure>\n");
}

/// A plot of `series` (`(id, trace, colour, legend)`) against time, its
/// window that of `window_of`, with a clickable legend.
fn line_plot(
    h: &mut String,
    title: &str,
    span: (f64, f64),
    height: f64,
    (name, unit): (&str, &str),
    series: &[(impl AsRef<str>, &Trace, &str, String)],
    window_of: &[&Trace],
) {
    let (lo, hi) = window_of
        .iter()
        .flat_map(|t| t.points.iter().map(|p| p.1))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(v), h.max(v))
        });
    let p = Panel::new(span, pad(lo, hi), height);
    p.open(h, title, "t [s]", &axis(name, unit));
    // the series clipped to the plot's frame (a diverged simulation leaves
    // the window, which is the measured signal's and the others')
    let (pw, ph) = (p.width - ML - MR, p.height - MT - MB);
    let _ = write!(
        h,
        "<svg x=\"{ML}\" y=\"{MT}\" width=\"{pw}\" height=\"{ph}\" viewBox=\"{ML} {MT} {pw} {ph}\">"
    );
    // the first series (measured) drawn last: on top of the simulations
    for (id, t, colour, legend) in series.iter().skip(1).chain(series.iter().take(1)) {
        let mut pts = String::new();
        for &(x, y) in &t.points {
            let _ = write!(pts, "{:.1},{:.1} ", p.px(x), p.py(y));
        }
        let _ = write!(
            h,
            "<polyline class=\"s s-{}\" data-label=\"{}\" data-unit=\"{}\" points=\"{}\" fill=\"none\" stroke=\"{colour}\" stroke-width=\"1.2\"/>",
            id.as_ref(),
            esc(legend.split(':').next().unwrap_or(legend)),
            esc(unit),
            pts.trim_end()
        );
    }
    h.push_str("</svg></svg>\n<div class=\"legend\">");
    for (id, _, colour, legend) in series {
        let _ = write!(
            h,
            "<label><input type=\"checkbox\" checked data-series=\"{}\"><span class=\"sw\" style=\"background:{colour}\"></span>{}</label>",
            id.as_ref(),
            esc(legend)
        );
    }
    h.push_str("</div></figure>\n");
}

/// The residual tests of the last stage: autocorrelation with the white
/// band, cross-correlation with each input with its band.
fn residual_tests(h: &mut String, r: &Report) {
    let _ = writeln!(
        h,
        "<h2 id=\"residuals\">Residual tests of <code>{}</code></h2>\n<p class=\"note\">Autocorrelation of the residual (the shaded band: 99 % of a white residual's, 2.576/&radic;N) and its cross-correlation with each input (the band: 99 % for two independent series of the residual's and the input's own colour, Bartlett's formula). Stems outside the band are red. Lags in samples.</p>",
        esc(&r.residual_stage)
    );
    if r.residual_tests.is_empty() {
        h.push_str("<p>No residual (no stage simulated).</p>\n");
        return;
    }
    h.push_str("<div class=\"grid\">\n");
    for t in &r.residual_tests {
        let auto = t.autocorrelation_points();
        let title = format!(
            "{} / {}: autocorrelation, correlation time {:.1} samples{}",
            t.experiment,
            t.channel,
            t.correlation_time,
            if t.white { ", white" } else { "" }
        );
        stems(h, &title, &auto, t.band, (0.5, t.lags as f64 + 0.5));
        cross(h, t);
    }
    h.push_str("</div>\n");
}

/// The cross-correlation panels of one residual test.
fn cross(h: &mut String, t: &ResidualTest) {
    for x in &t.cross {
        let (l, pts) = (x.half_width(), x.points());
        let title = format!(
            "{} / {} vs input {}: {}, {} of {} lags outside",
            t.experiment,
            t.channel,
            x.input,
            x.verdict(),
            x.outside,
            x.values.len()
        );
        stems(h, &title, &pts, x.band, (-l - 0.5, l + 0.5));
    }
}

/// A stem plot with the band `+-band` shaded.
fn stems(h: &mut String, title: &str, pts: &[(f64, f64)], band: f64, x: (f64, f64)) {
    let top = pts
        .iter()
        .map(|p| p.1.abs())
        .fold(band * 1.5, f64::max)
        .clamp(1e-6, 1.05);
    let mut p = Panel::new(x, (-top, top), 220.0);
    p.width = 440.0;
    p.small_title = true;
    p.open(h, title, "lag [samples]", "correlation [-]");
    let _ = write!(
        h,
        "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#c8dcff\"/>",
        p.px(x.0),
        p.py(band),
        p.px(x.1) - p.px(x.0),
        p.py(-band) - p.py(band)
    );
    for &(lag, v) in pts {
        let colour = if v.abs() > band { "#d62728" } else { "#1f77b4" };
        let _ = write!(
            h,
            "<line x1=\"{x:.1}\" x2=\"{x:.1}\" y1=\"{:.1}\" y2=\"{:.1}\" stroke=\"{colour}\" stroke-width=\"2\"><title>lag {lag}: {v:.3} (band {band:.3})</title></line>",
            p.py(0.0),
            p.py(v),
            x = p.px(lag)
        );
    }
    h.push_str("</svg></figure>\n");
}

/// The added effects' snippets.
fn effects(h: &mut String, r: &Report) {
    h.push_str("<h2 id=\"effects\">Added effects</h2>\n");
    if r.snippets.is_empty() {
        h.push_str("<p>None: the nominal model was kept.</p>\n");
    }
    for s in &r.snippets {
        let _ = writeln!(
            h,
            "<h4>{}</h4>\n<pre class=\"snippet\">{}</pre>",
            esc(&s.title),
            esc(&s.text)
        );
    }
}

/// Each round's candidates with the decision rule's line.
fn rounds(h: &mut String, r: &Report) {
    h.push_str("<h2 id=\"rounds\">Rounds</h2>\n");
    for round in &r.rounds {
        let _ = writeln!(
            h,
            "<h4>Round {}: {}</h4>",
            round.round,
            round
                .effect
                .as_ref()
                .map_or("no effect added".to_string(), |e| format!(
                    "added {}",
                    esc(e)
                ))
        );
        if round.candidates.is_empty() {
            continue;
        }
        h.push_str("<table class=\"rounds\"><tr><th>candidate</th><th>refit RMSE</th><th>equation-error rank</th><th>decision rule</th></tr>\n");
        for c in &round.candidates {
            let _ = writeln!(
                h,
                "<tr class=\"{}\"><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                if c.passes { "pass" } else { "fail" },
                esc(&c.label),
                num(c.refit_rmse),
                c.rank,
                esc(&c.rule)
            );
        }
        h.push_str("</table>\n");
    }
}

/// A plot's data window and pixel box.
struct Panel {
    x: (f64, f64),
    y: (f64, f64),
    width: f64,
    height: f64,
    /// A narrow panel's title: smaller, from the left edge.
    small_title: bool,
}

impl Panel {
    fn new(x: (f64, f64), y: (f64, f64), height: f64) -> Panel {
        let x = if x.1 > x.0 { x } else { (x.0, x.0 + 1.0) };
        Panel {
            x,
            y,
            width: W,
            height,
            small_title: false,
        }
    }

    fn px(&self, x: f64) -> f64 {
        ML + (x - self.x.0) / (self.x.1 - self.x.0) * (self.width - ML - MR)
    }

    fn py(&self, y: f64) -> f64 {
        let v = self.height - MB - (y - self.y.0) / (self.y.1 - self.y.0) * (self.height - MT - MB);
        v.clamp(-1e4, 1e4)
    }

    /// Opens `<figure><svg>` with the frame, ticks, axis labels and title.
    fn open(&self, h: &mut String, title: &str, xlabel: &str, ylabel: &str) {
        let (w, ht) = (self.width, self.height);
        let _ = write!(
            h,
            "<figure><svg class=\"plot\" width=\"{w}\" height=\"{ht}\" viewBox=\"0 0 {w} {ht}\" data-x0=\"{}\" data-x1=\"{}\" data-y0=\"{}\" data-y1=\"{}\" data-l=\"{ML}\" data-r=\"{}\" data-t=\"{MT}\" data-b=\"{}\" data-xlabel=\"{}\">",
            self.x.0,
            self.x.1,
            self.y.0,
            self.y.1,
            w - MR,
            ht - MB,
            esc(xlabel)
        );
        let (x, class) = if self.small_title {
            (6.0, "title small")
        } else {
            (ML, "title")
        };
        let _ = write!(
            h,
            "<text x=\"{x}\" y=\"16\" class=\"{class}\">{}</text>",
            esc(title)
        );
        let _ = write!(
            h,
            "<rect x=\"{ML}\" y=\"{MT}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#fff\" stroke=\"#888\"/>",
            w - ML - MR,
            ht - MT - MB
        );
        for v in ticks(self.x) {
            let x = self.px(v);
            let _ = write!(
                h,
                "<line x1=\"{x:.1}\" x2=\"{x:.1}\" y1=\"{MT}\" y2=\"{:.1}\" class=\"grid\"/><text x=\"{x:.1}\" y=\"{:.1}\" class=\"tick\" text-anchor=\"middle\">{}</text>",
                ht - MB,
                ht - MB + 14.0,
                tick_label(v, self.x)
            );
        }
        for v in ticks(self.y) {
            let y = self.py(v);
            let _ = write!(
                h,
                "<line x1=\"{ML}\" x2=\"{:.1}\" y1=\"{y:.1}\" y2=\"{y:.1}\" class=\"grid\"/><text x=\"{:.1}\" y=\"{:.1}\" class=\"tick\" text-anchor=\"end\">{}</text>",
                w - MR,
                ML - 4.0,
                y + 4.0,
                tick_label(v, self.y)
            );
        }
        let _ = write!(
            h,
            "<text x=\"{:.1}\" y=\"{:.1}\" class=\"label\" text-anchor=\"middle\">{}</text>",
            (ML + w - MR) / 2.0,
            ht - 6.0,
            esc(xlabel)
        );
        let _ = write!(
            h,
            "<text transform=\"translate(14,{:.1}) rotate(-90)\" class=\"label\" text-anchor=\"middle\">{}</text>",
            (MT + ht - MB) / 2.0,
            esc(ylabel)
        );
    }
}

/// `name [unit]`.
fn axis(name: &str, unit: &str) -> String {
    crate::plot::axis_label(name, unit)
}

/// A window around `lo..hi` with a 5 % margin (a constant or empty one
/// gets a unit or relative width).
fn pad(lo: f64, hi: f64) -> (f64, f64) {
    if !lo.is_finite() || !hi.is_finite() {
        return (-1.0, 1.0);
    }
    let scale = lo.abs().max(hi.abs());
    if hi - lo <= 1e-9 * scale || hi - lo < f64::MIN_POSITIVE {
        // a constant (an input at zero through a free swing): a window
        // around it that does not magnify rounding into ticks
        let m = if scale > 0.0 { 0.1 * scale } else { 1.0 };
        return (lo - m, hi + m);
    }
    let m = (hi - lo) * 0.05;
    (lo - m, hi + m)
}

/// Round tick values (1, 2 or 5 times a power of ten apart) inside `r`.
fn ticks(r: (f64, f64)) -> Vec<f64> {
    let span = r.1 - r.0;
    if span.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) || !span.is_finite() {
        return Vec::new();
    }
    let step = step_of(span);
    let first = (r.0 / step).ceil() as i64;
    let last = (r.1 / step).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// The tick step for a span: about six ticks.
fn step_of(span: f64) -> f64 {
    let raw = span / 6.0;
    let p = 10f64.powf(raw.log10().floor());
    let m = raw / p;
    p * if m < 1.5 {
        1.0
    } else if m < 3.5 {
        2.0
    } else if m < 7.5 {
        5.0
    } else {
        10.0
    }
}

/// A tick's text with as many decimals as its step needs.
fn tick_label(v: f64, r: (f64, f64)) -> String {
    let step = step_of(r.1 - r.0);
    let v = if v.abs() < step * 1e-9 { 0.0 } else { v };
    if (1e-3..1e5).contains(&step) {
        let d = (-step.log10().floor()).max(0.0) as usize;
        format!("{v:.d$}")
    } else {
        format!("{v:.1e}")
    }
}

/// A number in the tables: three significant digits, `-` when not finite.
fn num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3e}")
    } else {
        "-".into()
    }
}

/// HTML-escaped text.
fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

const CSS: &str = r#"
body{font-family:system-ui,sans-serif;margin:1.5em auto;max-width:1000px;color:#222;padding:0 1em}
h1{font-size:1.5em}h2{margin-top:1.6em;border-bottom:1px solid #ddd}
nav a{margin-right:1em}
table{border-collapse:collapse;font-size:.85em}td,th{border:1px solid #ccc;padding:3px 6px;text-align:right}
td{white-space:nowrap}td:first-child{text-align:left}th.seg{color:#666;font-weight:normal}td.bad{color:#b00}
table.rounds td{text-align:left}tr.pass td{background:#eef8ee}
.note{color:#555;font-size:.85em}
figure{margin:.8em 0}svg.plot{display:block;background:#fafafa}
svg .title{font-size:13px;font-weight:600}svg .title.small{font-size:11px}svg .tick{font-size:11px;fill:#444}svg .label{font-size:12px}
svg .grid{stroke:#e4e4e4}
.legend{font-size:.85em}.legend label{margin-right:1.2em;cursor:pointer;white-space:nowrap}
.sw{display:inline-block;width:18px;height:3px;margin:0 4px 3px 2px;vertical-align:middle}
.grid{display:flex;flex-wrap:wrap;gap:0 12px}
pre{background:#f4f4f4;padding:.6em;overflow-x:auto;font-size:.8em}
.tip{position:absolute;display:none;background:#fff;border:1px solid #888;padding:3px 6px;font-size:12px;pointer-events:none;white-space:pre}
"#;

/// Toggle a series (every figure) from its legend; hover a plot for the
/// values of its visible series at the cursor's time.
const JS: &str = r#"
(function(){
"use strict";
var tip=document.getElementById("tip");
function toggle(id,on){
  var els=document.querySelectorAll("polyline.s-"+id);
  for(var i=0;i<els.length;i++){els[i].style.display=on?"":"none";}
  var boxes=document.querySelectorAll("input[data-series='"+id+"']");
  for(var j=0;j<boxes.length;j++){boxes[j].checked=on;}
}
var boxes=document.querySelectorAll(".legend input[data-series]");
for(var i=0;i<boxes.length;i++){
  boxes[i].addEventListener("change",function(e){toggle(e.target.getAttribute("data-series"),e.target.checked);});
}
function num(v){var a=Math.abs(v);return (a!==0&&(a<1e-3||a>=1e5))?v.toExponential(3):v.toPrecision(4);}
function pointsOf(pl){
  if(!pl._pts){
    var raw=pl.getAttribute("points").trim(),pts=[];
    if(raw.length){var pairs=raw.split(/\s+/);for(var k=0;k<pairs.length;k++){var c=pairs[k].split(",");pts.push([+c[0],+c[1]]);}}
    pl._pts=pts;
  }
  return pl._pts;
}
function nearest(pts,x){
  var lo=0,hi=pts.length-1;
  if(hi<0){return null;}
  while(hi-lo>1){var m=(lo+hi)>>1;if(pts[m][0]<x){lo=m;}else{hi=m;}}
  return Math.abs(pts[lo][0]-x)<=Math.abs(pts[hi][0]-x)?pts[lo]:pts[hi];
}
var plots=document.querySelectorAll("svg.plot");
for(var p=0;p<plots.length;p++){
  (function(svg){
    var d=function(n){return parseFloat(svg.getAttribute("data-"+n));};
    var x0=d("x0"),x1=d("x1"),y0=d("y0"),y1=d("y1"),L=d("l"),R=d("r"),T=d("t"),B=d("b");
    var series=svg.querySelectorAll("polyline.s");
    if(!series.length){return;}
    svg.addEventListener("mousemove",function(ev){
      var box=svg.getBoundingClientRect();
      var px=(ev.clientX-box.left)*(svg.viewBox.baseVal.width/box.width);
      if(px<L||px>R){tip.style.display="none";return;}
      var t=x0+(px-L)/(R-L)*(x1-x0);
      var lines=["t = "+num(t)+" s"];
      for(var s=0;s<series.length;s++){
        var pl=series[s];
        if(pl.style.display==="none"){continue;}
        var q=nearest(pointsOf(pl),px);
        if(!q){continue;}
        var v=y0+(B-q[1])/(B-T)*(y1-y0);
        lines.push(pl.getAttribute("data-label")+": "+num(v)+" "+pl.getAttribute("data-unit"));
      }
      tip.textContent=lines.join("\n");
      tip.style.display="block";
      tip.style.left=(ev.pageX+14)+"px";
      tip.style.top=(ev.pageY+10)+"px";
    });
    svg.addEventListener("mouseleave",function(){tip.style.display="none";});
  })(plots[p]);
}
document.body.setAttribute("data-ready","1");
})();
"#;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::{ChannelFit, ExperimentFit, FitReport};
    use crate::report::{Snippet, StageTrace};

    fn trace(name: &str, f: impl Fn(f64) -> f64) -> Trace {
        let t: Vec<f64> = (0..5000).map(|k| k as f64 * 1e-3).collect();
        let x: Vec<f64> = t.iter().map(|&t| f(t)).collect();
        Trace::reduced(name, "rad", &t, &x)
    }

    fn report() -> Report {
        let fit = |f: f64| FitReport {
            experiments: vec![ExperimentFit {
                file: "swing.csv".into(),
                channels: [(
                    "alpha".to_string(),
                    ChannelFit {
                        fit_percent: Some(f),
                        rmse: 1e-3,
                        diverged: false,
                    },
                )]
                .into_iter()
                .collect(),
            }],
            rmse: 1e-3,
        };
        Report {
            model: "models/<odd> & \"name\".plant".into(),
            story: "1. nominal model\n   candidate a < b".into(),
            summary: serde_json::json!({"verdict": "missing_effect", "stop": "x </script> y"}),
            stages: vec![
                StageRow {
                    label: "nominal".into(),
                    report: fit(40.0),
                    segments: None,
                    cost: None,
                },
                StageRow {
                    label: "+ coulomb_friction@alpha, fitted".into(),
                    report: fit(97.5),
                    segments: Some(fit(99.0)),
                    cost: Some(1.0),
                },
            ],
            rounds: Vec::new(),
            experiments: vec![ExperimentFigure {
                name: "swing".into(),
                span: (0.0, 4.999),
                outputs: vec![OutputFigure {
                    channel: "alpha".into(),
                    unit: "rad".into(),
                    measured: trace("alpha", |t| t.sin()),
                    stages: vec![
                        StageTrace {
                            label: "nominal".into(),
                            fit_percent: Some(40.0),
                            diverged: false,
                            trace: trace("alpha", |t| 0.6 * t.sin()),
                        },
                        StageTrace {
                            label: "gone".into(),
                            fit_percent: Some(-1e6),
                            diverged: true,
                            trace: trace("alpha", |t| 1e6 * t),
                        },
                    ],
                    residual: vec![(0.5, -0.1, 0.1), (1.5, -0.2, 0.05)],
                }],
                inputs: vec![trace("Vm", |t| t.cos())],
            }],
            residual_tests: Vec::new(),
            residual_stage: "nominal".into(),
            snippets: vec![Snippet {
                title: "round 1".into(),
                text: "parameter Fc_alpha = 1e-3 N*m".into(),
            }],
        }
    }

    #[test]
    fn self_contained_escaped_deterministic() {
        let r = report();
        let h = render_html(&r);
        assert_eq!(h, render_html(&r));
        assert!(h.starts_with("<!DOCTYPE html>") && h.contains(GENERATOR));
        // no URL of any kind: nothing to fetch
        assert!(!h.contains("://"));
        // text is escaped, and the embedded JSON cannot close its script
        assert!(h.contains("models/&lt;odd&gt; &amp; &quot;name&quot;.plant"));
        assert!(h.contains("a &lt; b"));
        assert!(h.contains("x <\\/script> y"));
        // fit % per stage in the legend, units on the axes, the input
        assert!(h.contains("nominal: fit 40.0 %"));
        assert!(h.contains("alpha [rad]") && h.contains("t [s]") && h.contains("Vm [rad]"));
        // a diverged stage says so and does not set the window: the
        // measured sine's +-1 (with 5 % margin) does
        assert!(h.contains("gone: diverged"));
        let y1 = h
            .split("data-y1=\"")
            .nth(1)
            .and_then(|r| r.split('"').next())
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap();
        assert!(y1 < 1.2, "window up to {y1}");
        // the segment column is labelled as such
        assert!(h.contains("(segments as fitted)"));
        // reduced to at most 2 points per column
        let n = r.experiments[0].outputs[0].measured.points.len();
        assert!(n <= 2 * crate::report::COLUMNS, "{n}");
    }

    #[test]
    fn ticks_are_round_and_inside() {
        // steps of 1, 2 or 5 times a power of ten, about six per window
        assert_eq!(ticks((0.0, 10.0)), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        let t = ticks((-0.013, 0.021));
        assert!(t.iter().all(|v| (-0.013..=0.021).contains(v)), "{t:?}");
        assert_eq!(tick_label(0.005, (-0.013, 0.021)), "0.005");
        assert!(ticks((1.0, 1.0)).is_empty());
    }
}
