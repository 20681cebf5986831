//! Fit % and RMSE against hand-computed values.

use plantc_identify::{compare, fit_percent, rmse, Channel, Experiment, FitReport, MetricsError};

fn exp(name: &str, chans: &[(&str, Vec<f64>)]) -> Experiment {
    let n = chans[0].1.len();
    Experiment {
        name: name.into(),
        file: format!("{name}.csv").into(),
        t: (0..n).map(|k| k as f64 * 0.002).collect(),
        channels: chans
            .iter()
            .map(|(c, v)| Channel {
                name: c.to_string(),
                unit_note: None,
                values: v.clone(),
            })
            .collect(),
    }
}

#[test]
fn fit_of_mean_is_zero_and_of_truth_is_hundred() {
    let y = [1.0, 2.0, 3.0, 6.0];
    assert_eq!(fit_percent(&y, &y).unwrap(), Some(100.0));
    let m = [3.0; 4];
    assert!(fit_percent(&y, &m).unwrap().unwrap().abs() < 1e-12);
    assert_eq!(rmse(&y, &y).unwrap(), 0.0);
}

#[test]
fn hand_computed_values() {
    // y = [0, 2], yhat = [1, 1]: residual [-1, 1], ||r|| = sqrt 2, rmse = 1;
    // mean 1, ||y - mean|| = sqrt 2, fit = 0.
    assert_eq!(rmse(&[0.0, 2.0], &[1.0, 1.0]).unwrap(), 1.0);
    // y = [0, 4], yhat = [1, 4]: ||r|| = 1, ||y - 2|| = sqrt 8, fit = 100 (1 - 1/sqrt 8).
    let f = fit_percent(&[0.0, 4.0], &[1.0, 4.0]).unwrap().unwrap();
    assert!((f - 100.0 * (1.0 - 1.0 / 8f64.sqrt())).abs() < 1e-12);
    // Worse than the mean: negative.
    assert!(fit_percent(&[0.0, 4.0], &[4.0, 0.0]).unwrap().unwrap() < 0.0);
}

#[test]
fn constant_measurement_has_no_fit() {
    assert_eq!(fit_percent(&[1.0, 1.0], &[1.0, 2.0]).unwrap(), None);
}

#[test]
fn bad_inputs_are_errors() {
    assert!(matches!(
        rmse(&[1.0, 2.0], &[1.0]),
        Err(MetricsError::LengthMismatch { .. })
    ));
    assert!(matches!(
        rmse(&[1.0, 2.0], &[1.0, f64::NAN]),
        Err(MetricsError::NotFinite { index: 1, .. })
    ));
    assert!(matches!(rmse(&[], &[]), Err(MetricsError::Empty)));
}

#[test]
fn report_pools_rmse_and_serialises_in_cli_shape() {
    let m1 = exp("a", &[("theta", vec![0.0, 2.0]), ("alpha", vec![0.0, 0.0])]);
    let s1 = exp("a", &[("theta", vec![1.0, 1.0]), ("alpha", vec![0.0, 0.0])]);
    let m2 = exp(
        "b",
        &[
            ("theta", vec![0.0, 0.0, 0.0, 0.0]),
            ("alpha", vec![1.0, 2.0, 3.0, 4.0]),
        ],
    );
    let s2 = exp(
        "b",
        &[
            ("theta", vec![2.0, 2.0, 2.0, 2.0]),
            ("alpha", vec![1.0, 2.0, 3.0, 4.0]),
        ],
    );
    let r = compare(&[m1, m2], &[s1, s2], &["theta", "alpha"]).unwrap();
    assert_eq!(r.experiments[0].channels["theta"].rmse, 1.0);
    assert_eq!(r.experiments[1].channels["theta"].rmse, 2.0);
    assert_eq!(r.experiments[1].channels["alpha"].fit_percent, Some(100.0));
    // Pooled: squared residuals 1+1 + 0+0 + 4*4 + 0 = 18 over 12 samples.
    assert!((r.rmse - (18.0f64 / 12.0).sqrt()).abs() < 1e-15);
    let json: serde_json::Value = serde_json::to_value(&r).unwrap();
    assert_eq!(json["experiments"][0]["file"], "a.csv");
    assert_eq!(json["experiments"][0]["channels"]["theta"]["rmse"], 1.0);
    assert!(json["experiments"][1]["channels"]["alpha"]["fit_percent"].is_number());
    assert!(json["rmse"].is_number());
    let back: FitReport = serde_json::from_value(json).unwrap();
    assert_eq!(back, r);
}

#[test]
fn compare_reports_missing_channel() {
    let m = exp("a", &[("theta", vec![0.0, 1.0])]);
    let s = exp("a", &[("alpha", vec![0.0, 1.0])]);
    let e = compare(&[m], &[s], &["theta"]).unwrap_err();
    assert!(
        e.to_string().contains("no simulated channel `theta`"),
        "{e}"
    );
}
