//! A release transient at a record's start (`plantc_identify::release`):
//! synthetic records of the rotary pendulum, clean and with a "hand" that
//! holds both links still for the first 0.3 s while the motor pushes (or,
//! on a free swing, while gravity pulls), then lets go at rest, where the
//! record goes on as `synth` made it. The clean records are followed from
//! their first sample; the held ones from the first window after the hand,
//! and their simulation fit % over the rest is the clean record's.

mod common;

use common::simulated::{model, pendulum_text};
use plantc_identify::{validate, Experiment, ValidateOptions};

/// The hand's hold, s.
const HOLD: f64 = 0.3;

/// `e` with `HOLD` s prepended: every coordinate held at its first sample,
/// the voltage at `volts`, time shifted.
fn held(e: &Experiment, volts: f64) -> Experiment {
    let dt = e.t[1] - e.t[0];
    let k = (HOLD / dt).round() as usize;
    let mut out = e.clone();
    out.name = format!("{}_held", e.name);
    out.t = (0..k)
        .map(|i| e.t[0] + i as f64 * dt)
        .chain(e.t.iter().map(|t| t + k as f64 * dt))
        .collect();
    for c in &mut out.channels {
        let first = if c.name == "Vm" { volts } else { c.values[0] };
        c.values = std::iter::repeat_n(first, k)
            .chain(c.values.iter().copied())
            .collect();
    }
    out
}

#[test]
fn a_held_start_is_left_out_and_a_clean_one_is_not() {
    let text = pendulum_text();
    let m = model(&text);
    // the driven run from rest (the hand holds the arm against 2 V) and
    // the free swing from 120 degrees (the hand holds the pendulum up)
    let clean = common::short_pendulum_records("release", &text, "", Vec::new());
    let base: Vec<f64> = m.parameters.iter().map(|p| p.value).collect();
    let opts = ValidateOptions::default();
    let v_clean = validate(&m, &base, &clean, &opts).expect("validates");
    let holds: Vec<Experiment> = clean
        .iter()
        .zip([2.0, 0.0])
        .map(|(e, volts)| held(e, volts))
        .collect();
    let v_held = validate(&m, &base, &holds, &opts).expect("validates");
    for (c, h) in v_clean.experiments.iter().zip(&v_held.experiments) {
        let fit = |v: &plantc_identify::ExperimentValidation, ch: &str| {
            v.simulation
                .iter()
                .find(|s| s.channel == ch)
                .and_then(|s| s.fit_percent)
                .unwrap_or(f64::NAN)
        };
        eprintln!(
            "{}: followed from {:?}, fit theta {:.2} alpha {:.2}; held: from {:?}, fit theta {:.2} alpha {:.2}",
            c.name,
            c.nuisance.release,
            fit(c, "theta"),
            fit(c, "alpha"),
            h.nuisance.release,
            fit(h, "theta"),
            fit(h, "alpha"),
        );
        assert_eq!(c.nuisance.release, None, "{}", c.name);
        // a window boundary (every 0.25 s) at most one window after the
        // hand lets go
        let t = h.nuisance.release.expect("a release found");
        assert!((0.25..=HOLD + 0.25 + 1e-9).contains(&t), "{}: {t}", h.name);
        for ch in ["theta", "alpha"] {
            assert!(
                fit(h, ch) >= fit(c, ch) - 1.0,
                "{} {ch}: {} against {}",
                h.name,
                fit(h, ch),
                fit(c, ch)
            );
        }
    }
}
