//! Forward sensitivities against central finite differences of the plain
//! simulation (the reference numbers come from `Simulator` itself).

mod common;

use common::simulated::driven_signals;

use std::path::{Path, PathBuf};

use plantc_derive::model::{load_model, Model, ParameterValues};
use plantc_identify::{
    estimated_parameters, read_experiments, ReadOptions, SensitivitySimulator, Signals, SimError,
    SimOptions, Simulator,
};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn pendulum() -> Model {
    load_model(&repo().join("models/rotary_pendulum.plant"))
        .expect("pendulum model loads")
        .model
}

#[test]
fn sensitivities_match_central_differences() {
    let model = pendulum();
    let free = estimated_parameters(&model);
    assert_eq!(free, ["J1", "b1", "l2", "b2", "Fg1"]);
    let opts = SimOptions::default();
    let sens = SensitivitySimulator::new(&model, &free, opts).expect("compiles");
    let sim = Simulator::new(&model, opts).expect("compiles");
    let sig = driven_signals();
    let base: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let p = ParameterValues::from_base(&model, base.clone());
    let st = sens.simulate(&sig, &p.full, sig.len()).expect("simulates");
    let plain = sim.simulate(&sig, &p.full, sig.len()).expect("simulates");
    for i in 0..2 {
        for k in 0..sig.len() {
            assert!((st.q[i][k] - plain.q[i][k]).abs() < 1e-12);
        }
    }
    for (j, &pi) in sens.free_indices().iter().enumerate() {
        let h = base[pi] * 1e-5;
        let mut bp = base.clone();
        bp[pi] += h;
        let mut bm = base.clone();
        bm[pi] -= h;
        let yp = sim
            .simulate(
                &sig,
                &ParameterValues::from_base(&model, bp).full,
                sig.len(),
            )
            .expect("simulates");
        let ym = sim
            .simulate(
                &sig,
                &ParameterValues::from_base(&model, bm).full,
                sig.len(),
            )
            .expect("simulates");
        for i in 0..2 {
            let scale = st.dq[i][j].iter().fold(1e-12_f64, |a, v| a.max(v.abs()));
            let mut worst = 0.0_f64;
            for k in 0..sig.len() {
                let fd = (yp.q[i][k] - ym.q[i][k]) / (2.0 * h);
                worst = worst.max((fd - st.dq[i][j][k]).abs());
            }
            eprintln!(
                "{} coord {i}: max |S| {scale:.3e}, max error {worst:.3e}",
                free[j]
            );
            assert!(worst < 1e-4 * scale, "{} coord {i}", free[j]);
        }
    }
}

#[test]
fn unknown_free_parameter_is_an_error() {
    let model = pendulum();
    let r = SensitivitySimulator::new(&model, &["l3".to_string()], SimOptions::default());
    assert!(matches!(r, Err(SimError::UnknownParameter { name }) if name == "l3"));
}

/// Speed of the sensitivity simulation on the shared clean data, if present.
#[test]
fn sensitivity_speed_on_shared_data() {
    let dir = repo().join("../shared/data/clean");
    if !dir.is_dir() {
        eprintln!("skipping: {} not present", dir.display());
        return;
    }
    let model = pendulum();
    let files = [dir.join("driven.csv")];
    let (exps, _) =
        read_experiments(&files, &common::pendulum_spec(), &ReadOptions::default()).expect("reads");
    let sig = Signals::from_experiment(&model, &exps[0]).expect("signals");
    let sens =
        SensitivitySimulator::new(&model, &estimated_parameters(&model), SimOptions::default())
            .expect("compiles");
    let p = ParameterValues::from_base(&model, model.parameters.iter().map(|p| p.value).collect());
    let t = std::time::Instant::now();
    let st = sens.simulate(&sig, &p.full, sig.len()).expect("simulates");
    eprintln!(
        "sensitivities, 10,000 samples x 5 parameters: {:?}",
        t.elapsed()
    );
    assert!(st.dq.iter().flatten().flatten().all(|v| v.is_finite()));
}
