//! The initial state of a held-out record (`plantc_identify::validate`,
//! which `plantc compare` runs): a double pendulum on a cart
//! (`models/double_pendulum_cart.plant`) released from rest at 170 deg on
//! both links, 10 s at 500 Hz, 4096-count encoders on the links, made by
//! `synth` with the model's own values. The first samples measure the
//! link angles only to half a quantum; observed with the positions held
//! there, the observer's velocities made up for that error over its
//! window and the 10 s simulation drifted away (fit 82.8 / 71.8 % on the
//! links at the true values). Observed in full (the positions within their
//! noise prior) the simulation follows the record at the noise floor.

mod common;

use plantc_derive::model::{load_model, ParameterValues};
use plantc_identify::synth::parse_experiment_spec;
use plantc_identify::{
    read_experiment, synthesize, validate, ChannelSpec, Kind, SynthOptions, SynthSpec,
    ValidateOptions,
};

#[test]
fn a_release_from_rest_is_followed_at_the_true_values() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../models/double_pendulum_cart.plant");
    let text = std::fs::read_to_string(&path).expect("models/double_pendulum_cart.plant");
    let model = load_model(&path).expect("model loads").model;
    let spec = SynthSpec {
        case: "validate_start".into(),
        model_name: "double_pendulum_cart.plant".into(),
        effects: Vec::new(),
        parameter_set: None,
        values: Vec::new(),
        experiments: vec![parse_experiment_spec(
            "free_swing:th10=170deg,th20=170deg,duration=10,name=swing",
        )
        .expect("experiment")],
        options: SynthOptions::default(),
    };
    let out = synthesize(&text, &spec).expect("synthesizes");
    let channels = ChannelSpec::new()
        .length("x")
        .angle("th1")
        .angle("th2")
        .input("F", Kind::Force);
    let exps: Vec<_> = out
        .files
        .iter()
        .map(|f| {
            let p = common::write("validate_start", &f.file_name, &f.text);
            read_experiment(&p, &channels).expect("reads").0
        })
        .collect();
    let base = ParameterValues::new(&model, None, &[])
        .expect("values")
        .base;
    let v = validate(&model, &base, &exps, &ValidateOptions::default()).expect("validates");
    let e = &v.experiments[0];
    for ch in ["th1", "th2"] {
        let s = e
            .simulation
            .iter()
            .find(|c| c.channel == ch)
            .expect("channel");
        eprintln!(
            "{ch}: fit {:.1} %, RMSE {:.3e} (quantum / sqrt(12) = 4.43e-4)",
            s.fit_percent.unwrap_or(f64::NAN),
            s.rmse
        );
        // the link angles' noise floor is the encoder's rounding,
        // 2 pi / 4096 / sqrt(12) = 4.43e-4 rad: twice that at most
        assert!(s.rmse < 8.9e-4, "{ch}: RMSE {:.3e}", s.rmse);
    }
}
