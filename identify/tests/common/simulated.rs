//! A simulated rotary pendulum for the effect tests (deadzone, saturation,
//! rig effects): the model file, a driven experiment, simulations and the
//! sensitivity check against central differences.

use std::path::Path;

use plantc_derive::model::{load_model_text, Model, ParameterValues};
use plantc_identify::{LoopLaw, SensitivitySimulator, Signals, SimOptions, Simulator};

pub fn pendulum_text() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/rotary_pendulum.plant");
    std::fs::read_to_string(path).expect("model text")
}

pub fn model(text: &str) -> Model {
    match load_model_text("test.plant", text) {
        Ok(m) => m.model,
        Err(e) => panic!("{}", e.render()),
    }
}

/// The pendulum with extra lines appended.
pub fn pendulum_with(extra: &str) -> Model {
    model(&(pendulum_text() + "\n" + extra))
}

pub fn nominal(m: &Model) -> Vec<f64> {
    ParameterValues::from_base(m, m.parameters.iter().map(|p| p.value).collect()).full
}

/// A driven experiment: pendulum hanging, a multisine voltage (peak about
/// 2.3 V, so a 0.6 V deadzone removes a good part of it), 1 s at 500 Hz.
pub fn driven_signals() -> Signals {
    let t: Vec<f64> = (0..500).map(|k| k as f64 * 0.002).collect();
    let u = t
        .iter()
        .map(|t| 1.5 * (2.0 * std::f64::consts::PI * 1.3 * t).sin() + 0.8 * (17.0 * t).cos())
        .collect();
    Signals {
        name: "synthetic".into(),
        t,
        q: vec![vec![0.0; 500], vec![std::f64::consts::PI - 0.3; 500]],
        u: vec![u],
        replay: None,
    }
}

pub fn max_diff(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| x.iter().zip(y).map(|(p, q)| (p - q).abs()))
        .fold(0.0, f64::max)
}

/// The plain simulation at the nominal values, one RK4 step per sample
/// interval (an explicit substep of the records' interval: no span). The
/// tests compare a model with an input effect (a delay, a deadzone or a
/// saturation: no span where the input changes) with the model without it
/// on inputs transformed by hand, which would otherwise take spans over the
/// changing input: the same steps for both.
pub fn simulate(m: &Model, sig: &Signals) -> Vec<Vec<f64>> {
    let opts = SimOptions {
        substep: Some(sig.t[1] - sig.t[0]),
        ..SimOptions::default()
    };
    Simulator::new(m, opts)
        .expect("compiles")
        .simulate(sig, &nominal(m), sig.len())
        .expect("simulates")
        .q
}

/// Sensitivities against central differences of the plain simulation; the
/// tolerance is relative to the largest |S| of each coordinate.
pub fn check_sensitivities(m: &Model, sig: &Signals, free: &[&str], steps: &[f64], tol: f64) {
    check_sensitivities_in_loop(m, sig, free, steps, tol, None);
}

/// [`check_sensitivities`] with a recorded controller `law` in the loop of
/// both simulators, if given.
pub fn check_sensitivities_in_loop(
    m: &Model,
    sig: &Signals,
    free: &[&str],
    steps: &[f64],
    tol: f64,
    law: Option<&LoopLaw>,
) {
    let free: Vec<String> = free.iter().map(|s| s.to_string()).collect();
    let mut sens = SensitivitySimulator::new(m, &free, SimOptions::default()).expect("compiles");
    let mut sim = Simulator::new(m, SimOptions::default()).expect("compiles");
    if let Some(l) = law {
        sens = sens.with_loop(l.clone());
        sim = sim.with_loop(l.clone());
    }
    let base: Vec<f64> = m.parameters.iter().map(|p| p.value).collect();
    let full = ParameterValues::from_base(m, base.clone()).full;
    let st = sens.simulate(sig, &full, sig.len()).expect("simulates");
    let plain = sim.simulate(sig, &full, sig.len()).expect("simulates");
    assert!(max_diff(&st.q, &plain.q) < 1e-12);
    for (j, &pi) in sens.free_indices().iter().enumerate() {
        let h = steps[j];
        let run = |delta: f64| {
            let mut b = base.clone();
            b[pi] += delta;
            sim.simulate(sig, &ParameterValues::from_base(m, b).full, sig.len())
                .expect("simulates")
        };
        let (yp, ym) = (run(h), run(-h));
        for i in 0..m.coordinates.len() {
            let scale = st.dq[i][j].iter().fold(1e-12_f64, |a, v| a.max(v.abs()));
            let mut worst = 0.0_f64;
            for k in 0..sig.len() {
                let fd = (yp.q[i][k] - ym.q[i][k]) / (2.0 * h);
                worst = worst.max((fd - st.dq[i][j][k]).abs());
            }
            eprintln!(
                "{} coord {i}: max |S| {scale:.3e}, max error {worst:.3e} ({:.1e} relative)",
                free[j],
                worst / scale
            );
            assert!(scale > 1e-6, "{} coord {i}: no sensitivity", free[j]);
            assert!(worst <= tol * scale, "{} coord {i}", free[j]);
        }
    }
}
