//! Records of chaotic motion: the pendubot (`models/pendubot.plant`, an
//! underactuated double pendulum) driven at the shoulder into tumbling
//! (the elbow turns 6-15 revolutions, up to 67 rad/s), beside a free swing
//! near hanging. Synthetic (`synth`, sticking dry friction, 500 Hz, 4096-count
//! encoders), the rig off the model's values (`I1` 8e-4, `b2` 2e-4).
//!
//! Such a replay depends on the simulation step as much as on the
//! parameters: at the nominal values the replay at half the step parts
//! from the replay by 8.8 rad on `q1` (the channel's spread 5.3 rad).
//! Measured 2026-11-28 before the rule ([`replay_predictable`],
//! [`StepDifference::parts`]), `plantc identify` on these records:
//! - clean: the story replayed the records under a stabilising feedback
//!   (made for a plant a controller balanced) and named a cogging, an input
//!   delay and a Coulomb friction from a refit landscape full of local
//!   minima (185 s CPU); the open-loop fit reaches the noise floor;
//! - a Coulomb friction of 5e-4 N m on the elbow: the floor was raised by the
//!   step-halving difference (13,000 to 78,000 times the sensor noise) and
//!   the records called adequate at "the noise floor" with a whole-record
//!   RMSE of 5.9 rad.
//!
//! [`replay_predictable`]: plantc_identify::fit::replay_predictable
//! [`StepDifference::parts`]: plantc_identify::fit::StepDifference::parts

mod common;

use plantc_identify::{diagnose_with, synthesize, ChannelSpec, DiagnoseOptions, Experiment, Kind};

fn shipped() -> String {
    common::bundled_model("pendubot.plant")
}

/// The rig's records with `effects` hidden, read back as the CLI would.
fn records(test: &str, effects: &[&str]) -> Vec<Experiment> {
    let spec = common::synth_spec(
        test,
        "pendubot.plant",
        effects,
        &[("I1", 8e-4), ("b2", 2e-4)],
        &[
            "free_swing:q10=170deg,q20=30deg,duration=10,name=free_swing",
            "driven:q10=180deg,duration=10,rms=0.2,band=0.3-5,seed=2,name=driven",
        ],
        1,
    );
    let out = synthesize(&shipped(), &spec).expect("synthesizes");
    let channels = ChannelSpec::new()
        .angle("q1")
        .angle("q2")
        .input("tau", Kind::Torque);
    common::read_back(test, &out, &channels)
}

/// A clean rig names nothing: no stabilising feedback is designed for
/// records whose replay does not agree with itself, and the open-loop fit
/// reaches the floor (1.5 s CPU in release, on 0.25 s segments, measured
/// 2026-11-29; on 1 s segments, 2.1 s, while the automatic horizon still
/// went back to the whole records first and the diagnosis chose the
/// segments again at the values fitted there).
#[test]
fn clean_chaotic_records_name_nothing() {
    let exps = records("chaotic_clean", &[]);
    let story = common::identify(&shipped(), &exps);
    eprintln!("{}", story.stop);
    assert!(story.stabilised.is_none(), "a stabilised replay was used");
    assert!(
        common::final_effects(&story).is_empty(),
        "named {:?}: {}",
        common::final_effects(&story),
        story.stop
    );
}

/// A Coulomb friction on the elbow: the diagnosis judges on segments, says
/// so, and names the friction within 2 % (4.993e-4 N m against 5e-4,
/// measured 2026-11-29; 5.34e-4 while the segments' velocity priors ignored
/// the third derivative, and a deadzone and an input offset were named
/// after it). Which step sends it there depends on the integrator's last
/// digits, as the replay itself does: with spans over the driven record's
/// changing input the baseline's own automatic horizon takes the segments
/// (its replay at the start values parts at half the step); before, the
/// baseline went to the whole records and the diagnosis moved it to
/// segments with its note on unpredictable records.
#[test]
fn a_coulomb_friction_in_chaotic_records_is_named_on_segments() {
    let exps = records("chaotic_coulomb", &["coulomb_friction:q2=5e-4"]);
    let d = diagnose_with(&shipped(), &exps, &DiagnoseOptions::default()).expect("diagnoses");
    eprintln!("{}", d.verdict_line());
    for n in &d.notes {
        eprintln!("  note: {n}");
    }
    assert!(
        d.segments_caveat().is_some(),
        "the verdict does not say it is on segments (the whole records were judged)"
    );
    let v = d.verdict.as_ref().map(|c| c.label());
    assert_eq!(
        v.as_deref(),
        Some("coulomb_friction@q2"),
        "{}",
        d.verdict_line()
    );
    let fc = d.ranking[0]
        .parameters
        .iter()
        .find(|p| p.name == "Fc_q2")
        .map(|p| p.value)
        .expect("Fc_q2");
    eprintln!("Fc_q2 = {fc:.4e} (truth 5e-4)");
    assert!((fc / 5e-4 - 1.0).abs() < 0.02, "Fc_q2 = {fc}");
}

/// A spring of 1e-3 N m/rad in the elbow (5 % of its gravity stiffness,
/// `m2 g lc2`): named in round 1 and alone, within 2 %. Measured
/// 2026-11-29 with `plantc identify` (release): before, the fit went back
/// from segments to the whole records because the replay at the segments'
/// values stayed within the tumbling angles' spread (8 revolutions), the
/// whole-record fit moved to damped values where the motion is regular,
/// and a quadratic drag was named in round 1, the spring in round 2, the
/// drag removed at the end (25 s CPU); now the way back to whole records
/// also asks that the replay agree with itself at half the step, and the
/// spring is named at once (k 1.000e-3).
#[test]
fn an_elbow_spring_in_chaotic_records_is_named_alone() {
    let exps = records("chaotic_spring", &["spring:q2=1e-3"]);
    let story = common::identify(&shipped(), &exps);
    eprintln!("{}", story.stop);
    assert!(story.stabilised.is_none(), "a stabilised replay was used");
    let named: Vec<String> = story
        .rounds
        .iter()
        .filter_map(|r| r.effect.as_ref().map(|e| e.label()))
        .collect();
    assert_eq!(named, ["spring@q2"], "{}", story.stop);
    let k = common::final_value(&story, "k_q2").expect("k_q2");
    eprintln!("k_q2 = {k:.4e} (truth 1e-3)");
    assert!((k / 1e-3 - 1.0).abs() < 0.02, "k_q2 = {k}");
}

/// A tumbling 4-link chain (`models/chain4.plant`, clean, `b2` 3e-4 off
/// the model's 1e-4; a free swing from (170, 20) deg and a 0.3 N m RMS
/// multisine from hanging, 10 s each): nothing is named and the inputs
/// stay held, as synth made them. Measured 2026-11-29 with `plantc
/// identify` (release, user + sys): before, the inputs' continuous reading
/// was taken on a cost compared across horizons (the held fit on the whole
/// records at 1.1e4 noise RMS, the continuous refit on 0.25 s segments at
/// 3.4) and a 1 ms input delay was named, 197 s CPU; now adequate, 22 s.
#[test]
fn a_tumbling_chain_keeps_its_held_inputs_and_names_nothing() {
    let text = common::bundled_model("chain4.plant");
    let spec = common::synth_spec(
        "chain_clean",
        "chain4.plant",
        &[],
        &[("b2", 3e-4)],
        &[
            "free_swing:q10=170deg,q20=20deg,duration=10,name=free_swing",
            "driven:q10=180deg,duration=10,rms=0.3,band=0.3-5,seed=2,name=driven",
        ],
        1,
    );
    let out = synthesize(&text, &spec).expect("synthesizes");
    let channels = ChannelSpec::new()
        .angle("q1")
        .angle("q2")
        .angle("q3")
        .angle("q4")
        .input("tau", Kind::Torque);
    let exps = common::read_back("chain_clean", &out, &channels);
    let d = diagnose_with(&text, &exps, &DiagnoseOptions::default()).expect("diagnoses");
    eprintln!("{}", d.verdict_line());
    assert!(
        d.continuous_inputs.is_none(),
        "inputs read as continuous: {:?}",
        d.continuous_inputs
    );
    assert!(d.verdict.is_none(), "{}", d.verdict_line());
}
