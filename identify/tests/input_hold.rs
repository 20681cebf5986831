//! The records' input hold ([`plantc_identify::Diagnosis::continuous_inputs`]):
//! plantc's simulation holds each recorded input over its sample interval,
//! as a rig's converter does; a record made by integrating a continuous
//! input (another simulator), or by sampling one (a measured torque), holds
//! points of a signal that moves in between.
//!
//! The case: a clean rotary pendulum (`synth`, the model's nominal values,
//! a 0.3-6 Hz multisine on Vm and a free swing, 500 Hz, 4096 counts) whose
//! driven record is rewritten as a continuous-input simulator would have
//! recorded it: the input `synth` held over `[t_k, t_k+1)` is the mean of
//! the continuous signal there, so the value at `t_k` is, to second order,
//! the mean of the two held values around it, `(s_{k-1} + s_k) / 2`.
//! Measured 2026-11-28 (release, `plantc identify` on the 3-record bench
//! set of `bench/identify_cases.sh` so rewritten): held as recorded, a
//! Stribeck friction on the pendulum and two springs were named (44 s
//! wall); read as continuous, nothing (3.2 s), the baseline's weighted RMS
//! 2.30 held against 0.904 continuous.

mod common;

fn model_text() -> String {
    common::bundled_model("rotary_pendulum.plant")
}

fn clean_records(test: &str) -> Vec<plantc_identify::Experiment> {
    let experiments = [
        "driven:alpha0=180deg,band=0.3-6,rms=1.5,seed=3,duration=10,name=driven",
        "free_swing:alpha0=120deg,duration=10,name=swing",
    ]
    .map(String::from);
    common::synth_pendulum(test, &model_text(), "", Vec::new(), &experiments, 1)
}

/// Rewritten as sampled from a continuous input (see the module docs).
fn as_continuous_input(mut e: plantc_identify::Experiment) -> plantc_identify::Experiment {
    for c in e.channels.iter_mut().filter(|c| c.name == "Vm") {
        let s = c.values.clone();
        for k in 1..s.len() {
            c.values[k] = 0.5 * (s[k - 1] + s[k]);
        }
    }
    e
}

/// The story of the model on `exps`, default options.
fn identified(exps: &[plantc_identify::Experiment]) -> plantc_identify::Story {
    plantc_identify::identify(
        &model_text(),
        exps,
        &plantc_identify::StoryOptions::default(),
        &mut |_| {},
    )
    .expect("identifies")
}

#[test]
fn a_continuous_input_is_read_as_one_and_names_nothing() {
    let exps: Vec<_> = clean_records("input_hold_continuous")
        .into_iter()
        .map(as_continuous_input)
        .collect();
    let story = identified(&exps);
    common::show_rounds(&story);
    eprintln!(
        "{}; inputs {:?}; effects {:?}",
        story.stop,
        story.continuous_inputs,
        common::final_effects(&story)
    );
    let (_, reading) = story.continuous_inputs.clone().expect("read as continuous");
    let (held, continuous) = (reading.held, reading.continuous);
    assert!(continuous < held, "{continuous} vs {held}");
    assert!(common::final_effects(&story).is_empty());
    assert!(!story.unexplained, "{}", story.stop);
}

#[test]
fn a_held_input_stays_held() {
    let exps = clean_records("input_hold_held");
    let story = identified(&exps);
    eprintln!("{}; inputs {:?}", story.stop, story.continuous_inputs);
    assert_eq!(story.continuous_inputs, None);
    assert!(common::final_effects(&story).is_empty());
}
