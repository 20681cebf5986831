//! Issue 26 acceptance on the DFKI double pendulum
//! (`models/double_pendulum.plant`): synthetic records with sticking dry
//! friction (`synth`'s stick-slip law, the default), identified with the
//! model as shipped. The five cases of the rotary pendulum's acceptance:
//! a clean rig names nothing; Coulomb, spring, delay and Coulomb + spring
//! are named with their values within 2 %.
//!
//! The shipped model already has dry friction on both joints (`Fc1`,
//! `Fc2`, estimated), so "Coulomb" here is the rig's dry friction at values
//! the model does not start from (+30 % and -27 %): the right answer is no
//! missing effect and both levels recovered. Dry friction the model lacks
//! altogether is `dry_friction_the_model_lacks` below (a model without the
//! Coulomb terms; its path and measurement are in its doc).
//!
//! Every case: the rig off the model's nominal values (m1, r2, I1, I2, b1,
//! b2 and both dry frictions), a multisine on each torque (8 s each, the
//! shoulder 1.2 N m RMS over 0.3-5 Hz, the elbow 0.3 N m RMS) and a free
//! swing from (40, -20) deg that the dry friction stops and holds, at
//! 500 Hz with 4096-count encoders.
//!
//! Measured 2026-11-27 (`plantc identify` on the same records, release
//! build, `/usr/bin/time` user + sys): clean adequate, 0.63 s CPU; Coulomb
//! adequate, Fc1 +0.04 %, Fc2 -0.03 %, 0.74 s; spring on q2 named, k -0.24 %,
//! 2.36 s; 4 ms delay on tau1 named, Td +0.15 %, 1.57 s; Coulomb + spring:
//! the spring named, k -0.43 %, Fc1 -0.05 %, Fc2 +0.00 %, 2.10 s. The test
//! (identify at opt-level 3 in the test profile) takes 8.3 s CPU, 17 s wall
//! on this 2-core machine under a load of 9.

mod common;

use plantc_identify::{synthesize, ChannelSpec, Experiment, Kind, Story};

fn shipped() -> String {
    common::bundled_model("double_pendulum.plant")
}

/// The rig's values (SI) off the model's nominal ones, dry friction apart.
const RIG: &[(&str, f64)] = &[
    ("m1", 0.60),
    ("r2", 0.19),
    ("I1", 0.056),
    ("I2", 0.025),
    ("b1", 1.5e-3),
    ("b2", 8e-4),
];

/// Dry friction levels (N m): the clean rig's, near the model's 0.146 and
/// 0.1225, and the "Coulomb" rig's, far from them.
const FC_NEAR: (f64, f64) = (0.15, 0.12);
const FC_FAR: (f64, f64) = (0.19, 0.09);

/// Synthesise the rig's records (the shipped model's structure, `effects`
/// hidden, dry friction `fc`) and read them back as the CLI would.
fn records(test: &str, effects: &[&str], fc: (f64, f64)) -> Vec<Experiment> {
    let mut values = RIG.to_vec();
    values.push(("Fc1", fc.0));
    values.push(("Fc2", fc.1));
    let spec = common::synth_spec(
        test,
        "double_pendulum.plant",
        effects,
        &values,
        &[
            "driven:band=0.3-5,rms=1.2,input=tau1,seed=3,duration=8,name=drive1",
            "driven:band=0.3-5,rms=0.3,input=tau2,seed=4,duration=8,name=drive2",
            "free_swing:q10=40deg,q20=-20deg,duration=8,name=swing",
        ],
        1,
    );
    let out = synthesize(&shipped(), &spec).expect("synthesizes");
    assert_eq!(out.files.len(), 3);
    let channels = ChannelSpec::new()
        .angle("q1")
        .angle("q2")
        .input("tau1", Kind::Torque)
        .input("tau2", Kind::Torque);
    common::read_back(test, &out, &channels)
}

/// The story of `text` on the records, with its final effects (those
/// named and not removed again) and a reader of its final values.
fn story(test: &str, text: &str, exps: &[Experiment]) -> (Story, Vec<String>) {
    let t = std::time::Instant::now();
    let story = common::identify(text, exps);
    let effects = common::final_effects(&story);
    eprintln!(
        "{test}: {} in {:.1} s wall; final effects {effects:?}",
        story.stop,
        t.elapsed().as_secs_f64()
    );
    (story, effects)
}

/// The final value of parameter `name` in `story`.
fn value(story: &Story, name: &str) -> f64 {
    common::final_value(story, name).unwrap_or_else(|| panic!("no `{name}` in the final model"))
}

/// Within 2 % of the truth (the acceptance's bound), printed.
fn within_2_percent(story: &Story, name: &str, truth: f64) {
    let v = value(story, name);
    let rel = v / truth - 1.0;
    eprintln!(
        "  {name} = {v:.5e} (truth {truth:.5e}, {:+.2} %)",
        100.0 * rel
    );
    assert!(rel.abs() < 0.02, "{name} = {v}, truth {truth}");
}

/// The five cases, each run in turn (a failing one names itself).
#[test]
fn five_sticking_cases_on_the_shipped_model() {
    let text = shipped();
    // (case, hidden effects, dry friction, the final effects expected,
    // the values to recover)
    type Case = (
        &'static str,
        &'static [&'static str],
        (f64, f64),
        &'static [&'static str],
        &'static [(&'static str, f64)],
    );
    let cases: &[Case] = &[
        (
            "clean",
            &[],
            FC_NEAR,
            &[],
            &[("Fc1", FC_NEAR.0), ("Fc2", FC_NEAR.1)],
        ),
        (
            "coulomb",
            &[],
            FC_FAR,
            &[],
            &[("Fc1", FC_FAR.0), ("Fc2", FC_FAR.1)],
        ),
        (
            "spring",
            &["spring:q2=0.05"],
            FC_NEAR,
            &["spring@q2"],
            &[("k_q2", 0.05)],
        ),
        (
            "delay",
            &["input_delay:tau1=4e-3"],
            FC_NEAR,
            &["input_delay@tau1"],
            &[("Td_tau1", 4e-3)],
        ),
        (
            "coulomb_spring",
            &["spring:q2=0.05"],
            FC_FAR,
            &["spring@q2"],
            &[("k_q2", 0.05), ("Fc1", FC_FAR.0), ("Fc2", FC_FAR.1)],
        ),
    ];
    for (name, effects, fc, want, values) in cases {
        let exps = records(name, effects, *fc);
        let (story, found) = story(name, &text, &exps);
        assert_eq!(&found, want, "{name}: {}", story.stop);
        assert!(!story.unexplained, "{name}: {}", story.stop);
        for (p, truth) in *values {
            within_2_percent(&story, p, *truth);
        }
    }
}

/// Dry friction the model lacks: the shipped model without its Coulomb
/// terms (as `real_dfki.rs`'s viscous-only model), the clean rig's records.
/// Both joints' dry friction should be named, within 2 %.
///
/// The path there (measured 2026-11-28, release): round 1 names a
/// Stribeck friction on q2, round 2 the Coulomb friction on q1 (ending
/// trapped at 31.6x the floor), round 3 a speed limit on q2 whose refit
/// escapes the trap; the end steps replace the Stribeck friction by the
/// Coulomb friction it is (Fc_q2 +0.04 %) and then remove the speed limit,
/// which the model as it now stands no longer needs (Fc_q1 -0.07 %).
/// About 40 s wall in release, so it runs in CI in the test profile's
/// opt-level (see `five_sticking_cases_on_the_shipped_model`).
#[test]
fn dry_friction_the_model_lacks() {
    let text = common::double_pendulum_without_dry_friction();
    let exps = records("lacks", &[], FC_NEAR);
    let (story, mut found) = story("lacks", &text, &exps);
    found.sort();
    assert_eq!(
        found,
        ["coulomb_friction@q1", "coulomb_friction@q2"],
        "{}",
        story.stop
    );
    within_2_percent(&story, "Fc_q1", FC_NEAR.0);
    within_2_percent(&story, "Fc_q2", FC_NEAR.1);
}
