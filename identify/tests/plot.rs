//! The comparison figure is a non-empty, deterministic SVG with units on its
//! axes, fit % in its legend, the input in its own panel and the residual
//! as an envelope (a bounded number of drawn points, whatever the length).

mod common;

use plantc_identify::plot::envelope;
use plantc_identify::{
    plot_comparison, render_comparison, Channel, Experiment, FigureChannels, PlotError,
};

fn exp(n: usize, values: impl Fn(f64) -> f64) -> Experiment {
    let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.002).collect();
    let mut channels: Vec<Channel> = ["theta", "alpha"]
        .iter()
        .map(|c| Channel {
            name: c.to_string(),
            unit_note: Some("rad".into()),
            values: t.iter().map(|&t| values(t)).collect(),
        })
        .collect();
    channels.push(Channel {
        name: "Vm".into(),
        unit_note: Some("V".into()),
        values: t.iter().map(|&t| (7.0 * t).sin()).collect(),
    });
    Experiment {
        name: "driven".into(),
        file: "driven.csv".into(),
        channels,
        t,
    }
}

fn figure() -> FigureChannels {
    FigureChannels {
        outputs: vec![
            ("theta".into(), "rad".into()),
            ("alpha".into(), "rad".into()),
        ],
        inputs: vec![("Vm".into(), "V".into())],
    }
}

#[test]
fn writes_non_empty_deterministic_svg() {
    let m = exp(5000, |t| (3.0 * t).sin());
    let s = exp(5000, |t| 0.95 * (3.0 * t).sin());
    let p = common::scratch("plot").join("fig.svg");
    plot_comparison(&p, &m, &s, &figure()).unwrap();
    let text = std::fs::read_to_string(&p).unwrap();
    assert!(
        text.starts_with("<svg") && text.len() > 10_000,
        "{}",
        text.len()
    );
    assert!(text.contains("measured") && text.contains("residual"));
    // units on every axis, the input's panel
    for label in [
        "t [s]",
        "theta [rad]",
        "residual [rad]",
        "Vm [V]",
        "input Vm",
    ] {
        assert!(text.contains(label), "no `{label}`");
    }
    // fit % in the legend: 100 (1 - 0.05) = 95 % for a 5 % gain error
    // (||y - 0.95 y|| / ||y - mean y|| = 0.05 up to the small mean of the
    // sine over 10 s)
    assert!(
        text.contains("simulated, fit 95."),
        "no fit % in the legend"
    );
    let again = render_comparison(&m, &s, &figure()).unwrap();
    assert_eq!(text, again);
}

#[test]
fn residual_is_an_envelope_whatever_the_length() {
    // 10,000 and 100,000 samples give figures of about the same size: the
    // residual is min/max per pixel column, the lines min/max-decimated
    let small = {
        let m = exp(10_000, |t| (3.0 * t).sin());
        let s = exp(10_000, |t| 0.9 * (3.0 * t).sin() + 1e-3 * (900.0 * t).sin());
        render_comparison(&m, &s, &figure()).unwrap().len()
    };
    let large = {
        let m = exp(100_000, |t| (3.0 * t).sin());
        let s = exp(100_000, |t| {
            0.9 * (3.0 * t).sin() + 1e-3 * (900.0 * t).sin()
        });
        render_comparison(&m, &s, &figure()).unwrap().len()
    };
    assert!(
        (large as f64) < 1.3 * small as f64,
        "{small} bytes for 10,000 samples, {large} for 100,000"
    );
    // the envelope keeps each column's extremes
    let t: Vec<f64> = (0..1000).map(|k| k as f64).collect();
    let x: Vec<f64> = (0..1000)
        .map(|k| if k % 2 == 0 { 1.0 } else { -2.0 })
        .collect();
    let env = envelope(&t, &x, (0.0, 1000.0), 10);
    assert_eq!(env.len(), 10);
    assert!(env.iter().all(|&(_, lo, hi)| lo == -2.0 && hi == 1.0));
}

#[test]
fn a_diverged_simulation_says_so_in_the_legend() {
    let m = exp(1000, |t| (3.0 * t).sin());
    let mut s = exp(1000, |t| (3.0 * t).sin());
    s.channels[1].values[500] = f64::NAN;
    let text = render_comparison(&m, &s, &figure()).unwrap();
    assert!(text.contains("simulated, diverged"));
}

#[test]
fn plot_errors() {
    let m = exp(5000, |t| t);
    assert!(matches!(
        render_comparison(&m, &m, &FigureChannels::outputs(&["beta"], "rad")),
        Err(PlotError::MissingChannel { .. })
    ));
    assert!(matches!(
        render_comparison(&m, &m, &FigureChannels::default()),
        Err(PlotError::NoChannels)
    ));
    let bad = common::scratch("plotbad").join("no/such/dir/f.svg");
    let e = plot_comparison(&bad, &m, &m, &FigureChannels::outputs(&["theta"], "rad")).unwrap_err();
    assert!(e.to_string().contains("f.svg"), "{e}");
}
