//! The comparison figure is a non-empty, deterministic SVG.

mod common;

use plantc_identify::{plot_comparison, render_comparison, Channel, Experiment, PlotError};

fn exp(values: impl Fn(f64) -> f64) -> Experiment {
    let t: Vec<f64> = (0..5000).map(|k| k as f64 * 0.002).collect();
    Experiment {
        name: "driven".into(),
        file: "driven.csv".into(),
        channels: ["theta", "alpha"]
            .iter()
            .map(|c| Channel {
                name: c.to_string(),
                unit_note: Some("rad".into()),
                values: t.iter().map(|&t| values(t)).collect(),
            })
            .collect(),
        t,
    }
}

#[test]
fn writes_non_empty_deterministic_svg() {
    let m = exp(|t| (3.0 * t).sin());
    let s = exp(|t| 0.95 * (3.0 * t).sin());
    let p = common::scratch("plot").join("fig.svg");
    plot_comparison(&p, &m, &s, &["theta", "alpha"]).unwrap();
    let text = std::fs::read_to_string(&p).unwrap();
    assert!(
        text.starts_with("<svg") && text.len() > 10_000,
        "{}",
        text.len()
    );
    assert!(text.contains("measured") && text.contains("residual"));
    let again = render_comparison(&m, &s, &["theta", "alpha"]).unwrap();
    assert_eq!(text, again);
}

#[test]
fn plot_errors() {
    let m = exp(|t| t);
    assert!(matches!(
        render_comparison(&m, &m, &["beta"]),
        Err(PlotError::MissingChannel { .. })
    ));
    assert!(matches!(
        render_comparison(&m, &m, &[]),
        Err(PlotError::NoChannels)
    ));
    let bad = common::scratch("plotbad").join("no/such/dir/f.svg");
    let e = plot_comparison(&bad, &m, &m, &["theta"]).unwrap_err();
    assert!(e.to_string().contains("f.svg"), "{e}");
}
