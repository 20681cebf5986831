//! Where-it-fails diagnostics on synthetic signals with planted errors.

use plantc_identify::{
    residual_summary, where_it_fails, Channel, ChannelSpec, Experiment, FailOptions, FindingKind,
};

fn exp(name: &str, t: &[f64], ch: &str, v: Vec<f64>) -> Experiment {
    Experiment {
        name: name.into(),
        file: format!("{name}.csv").into(),
        t: t.to_vec(),
        channels: vec![Channel {
            name: ch.into(),
            unit_note: None,
            values: v,
        }],
    }
}

#[test]
fn residual_summary_hand_values() {
    let s = residual_summary(&[1.0, 2.0, 3.0, 4.0], &[0.0, 3.0, 2.0, 5.0]).unwrap();
    // residual [1, -1, 1, -1]: mean 0, std 1, max 1, lag-1 autocorrelation -3/4.
    assert_eq!(s.mean, 0.0);
    assert_eq!(s.std, 1.0);
    assert_eq!(s.rmse, 1.0);
    assert_eq!(s.max_abs, 1.0);
    assert!((s.lag1_autocorrelation.unwrap() + 0.75).abs() < 1e-15);
    assert_eq!(
        residual_summary(&[1.0, 2.0], &[1.0, 2.0])
            .unwrap()
            .lag1_autocorrelation,
        None
    );
}

/// A decaying swing about pi (20 s, 500 Hz) and its simulation with an error
/// that grows as the amplitude shrinks, as dry friction would give.
fn decaying_swing() -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let t: Vec<f64> = (0..10_000).map(|k| k as f64 * 0.002).collect();
    let w = 2.0 * std::f64::consts::PI * 1.4;
    let amp = |t: f64| (-0.2 * t).exp();
    let y: Vec<f64> = t
        .iter()
        .map(|&t| std::f64::consts::PI + amp(t) * (w * t).cos())
        .collect();
    let yhat: Vec<f64> = t
        .iter()
        .zip(&y)
        .map(|(&t, &y)| y - 3e-3 * (-amp(t) / 0.15).exp() * (w * t).sin())
        .collect();
    (t, y, yhat)
}

#[test]
fn planted_small_amplitude_error_is_reported() {
    let (t, y, yhat) = decaying_swing();
    let m = exp("free_swing", &t, "alpha", y);
    let s = exp("free_swing", &t, "alpha", yhat);
    let opts = FailOptions::for_spec(&ChannelSpec::new().angle("alpha"));
    let d = where_it_fails(&m, &s, &["alpha"], &opts).unwrap();
    let f = d[0]
        .findings
        .iter()
        .find(|f| f.kind == FindingKind::SmallAmplitude)
        .unwrap_or_else(|| panic!("no small-amplitude finding: {:#?}", d[0].findings));
    assert!(f.ratio > 2.0);
    assert!(
        f.sentence
            .starts_with("error grows at small swing amplitude: RMSE ")
            && f.sentence.contains(" rad at small amplitude vs ")
            && f.sentence.contains("at large ("),
        "{}",
        f.sentence
    );
    assert!(!d[0]
        .findings
        .iter()
        .any(|f| f.kind == FindingKind::LargeAmplitude));
    assert_eq!(d[0].segments.len(), 10);
    assert_eq!(d[0].amplitude.len(), 3);
    eprintln!("{}", f);
    // JSON-serialisable.
    let json = serde_json::to_string(&d).unwrap();
    assert!(json.contains("\"small_amplitude\""));
}

#[test]
fn uniform_error_reports_no_regime() {
    let (t, y, _) = decaying_swing();
    // An error with the same size everywhere: only the time-free noise-like term.
    let yhat: Vec<f64> = y
        .iter()
        .enumerate()
        .map(|(k, v)| v + 1e-3 * ((k * 7919 % 1000) as f64 / 500.0 - 1.0))
        .collect();
    let m = exp("e", &t, "alpha", y);
    let s = exp("e", &t, "alpha", yhat);
    let d = where_it_fails(&m, &s, &["alpha"], &FailOptions::default()).unwrap();
    assert!(d[0].findings.is_empty(), "{:#?}", d[0].findings);
}

#[test]
fn planted_turnaround_error_is_reported() {
    let t: Vec<f64> = (0..10_000).map(|k| k as f64 * 0.002).collect();
    let w = 2.0 * std::f64::consts::PI;
    let y: Vec<f64> = t.iter().map(|&t| (w * t).sin()).collect();
    // Error only where the velocity is near zero (|cos| small).
    let yhat: Vec<f64> = t
        .iter()
        .zip(&y)
        .map(|(&t, &y)| {
            y + if (w * t).cos().abs() < 0.03 {
                1e-2
            } else {
                1e-4
            }
        })
        .collect();
    let m = exp("s", &t, "theta", y);
    let s = exp("s", &t, "theta", yhat);
    let d = where_it_fails(&m, &s, &["theta"], &FailOptions::default()).unwrap();
    assert!(
        d[0].findings
            .iter()
            .any(|f| f.kind == FindingKind::Turnarounds),
        "{:#?}",
        d[0].findings
    );
}

#[test]
fn quantisation_floor_is_recognised() {
    let q = 2.0 * std::f64::consts::PI / 4096.0;
    let t: Vec<f64> = (0..5000).map(|k| k as f64 * 0.002).collect();
    let truth: Vec<f64> = t.iter().map(|&t| 0.5 * (3.0 * t).sin()).collect();
    let y: Vec<f64> = truth.iter().map(|v| (v / q).round() * q).collect();
    let m = exp("q", &t, "theta", y);
    let s = exp("q", &t, "theta", truth);
    let d = where_it_fails(&m, &s, &["theta"], &FailOptions::default()).unwrap();
    let floor = d[0].quantisation_floor.unwrap();
    assert!((floor - 4.35e-4).abs() < 1e-5, "{floor}");
    assert_eq!(d[0].findings.len(), 1, "{:#?}", d[0].findings);
    assert_eq!(d[0].findings[0].kind, FindingKind::AtFloor);
}

#[test]
fn length_mismatch_is_an_error() {
    let t: Vec<f64> = (0..20).map(|k| k as f64).collect();
    let m = exp("a", &t, "x", vec![0.0; 20]);
    let s = exp("a", &t[..10], "x", vec![0.0; 10]);
    assert!(where_it_fails(&m, &s, &["x"], &FailOptions::default()).is_err());
}
