//! Timing of one simulation of the 20 s driven experiment (shared clean
//! data), plain and with sensitivities. Run with
//! `cargo test -p plantc-identify --release --test sim_timing -- --ignored --nocapture`.

mod common;

use std::path::{Path, PathBuf};
use std::time::Instant;

use plantc_derive::model::{load_model_text, ParameterValues};
use plantc_identify::{
    estimated_parameters, read_experiments, ReadOptions, SensitivitySimulator, Signals, SimOptions,
    Simulator,
};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn time_model(label: &str, text: &str, sig_of: &dyn Fn(&plantc_derive::model::Model) -> Signals) {
    let model = load_model_text(label, text).expect("loads").model;
    let sig = sig_of(&model);
    let p = ParameterValues::from_base(&model, model.parameters.iter().map(|p| p.value).collect());
    let sim = Simulator::new(&model, SimOptions::default()).expect("compiles");
    let free = estimated_parameters(&model);
    let sens = SensitivitySimulator::new(&model, &free, SimOptions::default()).expect("compiles");
    let reps = 5;
    let t = Instant::now();
    for _ in 0..reps {
        sim.simulate(&sig, &p.full, sig.len()).expect("simulates");
    }
    let plain = t.elapsed() / reps;
    let t = Instant::now();
    for _ in 0..reps {
        sens.simulate(&sig, &p.full, sig.len()).expect("simulates");
    }
    let with_sens = t.elapsed() / reps;
    eprintln!(
        "{label}: {} samples, plain {plain:?}, with {} sensitivities {with_sens:?}",
        sig.len(),
        free.len()
    );
}

#[test]
#[ignore]
fn driven_experiment_timing() {
    let file = repo().join("../shared/data/clean/driven.csv");
    if !file.is_file() {
        eprintln!("skipping: {} not present", file.display());
        return;
    }
    let (exps, _) = read_experiments(&[file], &common::pendulum_spec(), &ReadOptions::default())
        .expect("reads");
    let base = std::fs::read_to_string(repo().join("models/rotary_pendulum.plant")).expect("model");
    let sig_of =
        |m: &plantc_derive::model::Model| Signals::from_experiment(m, &exps[0]).expect("signals");
    time_model("nominal", &base, &sig_of);
    let extra = "\nparameter d_alpha = 0.01 [rad] estimate [-0.2, 0.2]\nparameter Td_Vm = 1.3e-3 [s] estimate [0, 0.05]\nsensor alpha = sensor_offset(d_alpha)\nactuator Vm = input_delay(Td_Vm)\n";
    if load_model_text("x", &(base.clone() + extra)).is_ok() {
        time_model("offset+delay", &(base + extra), &sig_of);
    }
}
