//! Records finer than plantc's own simulation: the floor includes the
//! integrator's error ([`plantc_identify::simulation_error`]).
//!
//! The case: the cart-pole (`models/cart_pole.plant`) with a Coulomb
//! friction on the cart the model lacks, synthesised with the smooth
//! dry-friction law (`tanh(v / 1e-3)`, as simulators that integrate that
//! law make) at `synth`'s 0.1 ms substep, and identified under the same
//! law. The cart's position is a length: no encoder grid, written with 9
//! decimals, so its noise floor is 2.6e-9 m. The identification simulates
//! at 1 ms, where the friction's slope near zero speed sits at RK4's
//! stability limit; its error on the cart is about 1e-5 m (measured by
//! step halving), thousands of times that floor.
//!
//! Before the floor held that error, the model with the true Coulomb
//! friction still missed the cart by ~90 noise RMS, and a cogging on the
//! cart, then an input delay were named from the integrator's own error
//! (51 s wall). Measured 2026-11-28 with the floor (release): the Coulomb
//! friction named alone, Fc 0.0499996 against 0.05, the residual at the
//! floor, 9.7 s wall, 17.4 s CPU.

mod common;

use plantc_identify::synth::{parse_effect_spec, parse_experiment_spec};
use plantc_identify::{
    synthesize, ChannelSpec, DryFriction, Kind, StoryOptions, SynthOptions, SynthSpec,
};

#[test]
fn smooth_law_records_name_the_friction_not_the_integrators_error() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/cart_pole.plant");
    let text = std::fs::read_to_string(path).expect("models/cart_pole.plant");
    let law = DryFriction::Smooth { width: 1e-3 };
    let spec = SynthSpec {
        case: "cart_pole_smooth_coulomb".into(),
        model_name: "cart_pole.plant".into(),
        effects: vec![parse_effect_spec("coulomb_friction:x=0.05").expect("effect")],
        parameter_set: None,
        values: Vec::new(),
        experiments: [
            "free_swing:th0=150deg,duration=10",
            "driven:th0=180deg,duration=10,rms=2,band=0.3-5,seed=2",
        ]
        .iter()
        .map(|e| parse_experiment_spec(e).expect("experiment"))
        .collect(),
        options: SynthOptions {
            seed: 1,
            friction: law,
            ..SynthOptions::default()
        },
    };
    let out = synthesize(&text, &spec).expect("synthesizes");
    let channels = ChannelSpec::new()
        .length("x")
        .angle("th")
        .input("F", Kind::Force);
    let exps = common::read_back("simulation_floor", &out, &channels);
    let mut opts = StoryOptions::default();
    opts.fit.sim.dry_friction = law;
    let t = std::time::Instant::now();
    let story = plantc_identify::identify(&text, &exps, &opts, &mut |_| {}).expect("identifies");
    common::show_rounds(&story);
    let effects = common::final_effects(&story);
    eprintln!(
        "{} in {:.1} s wall; final effects {effects:?}",
        story.stop,
        t.elapsed().as_secs_f64()
    );
    assert_eq!(effects, vec!["coulomb_friction@x".to_string()]);
    // the cart's floor is its noise and the integrator's error, stated
    let x = story
        .fit
        .weights
        .iter()
        .find(|w| w.name == "x")
        .expect("x weighed");
    eprintln!("x: noise {:.3e} ({})", x.noise, x.basis);
    let e = x
        .simulation_error
        .expect("the cart's floor holds the error");
    assert!(x.basis.contains("simulation's own error"), "{}", x.basis);
    // far above the 9-decimal floor, far below the cart's motion (0.39 m)
    assert!(e > 1e-7 && e < 1e-3, "{e}");
    let fc = common::final_value(&story, "Fc_x").expect("Fc_x in the final model");
    eprintln!("Fc_x = {fc} (truth 0.05)");
    assert!((fc / 0.05 - 1.0).abs() < 0.02, "Fc_x = {fc}");
}
