//! The story on closed-loop recordings: the pendulum balanced upright by a
//! state-feedback law, an excitation voltage added to the law's output, a
//! hidden effect. Replayed open loop the upright pendulum falls within a
//! second, so the fit has to go to segments or simulate the law in the
//! loop.
//!
//! Without the law in the model, the story replays the logged input with
//! a stabilising feedback of its own ([`plantc_identify::stabilised_replay`]).
//!
//! The data are made here: the true model (the pendulum with the effect)
//! simulated with the law in the loop ([`Simulator::with_loop`]), the law's
//! output at every sample recomputed from the same trajectory (the applied
//! voltage a rig logs), then the angles rounded to a 4096-count encoder.
//! The law reads the unrounded angles (a rig's reads the rounded ones); the
//! logged voltage is still exactly the applied one. Gains: `plantc lqr
//! models/rotary_pendulum.plant --q 5,1,0.1,0.1 --r 1`.

mod common;

use common::simulated::{model, pendulum_text};
use std::fmt::Write as _;

use plantc_derive::model::ParameterValues;
use plantc_identify::{
    read_experiment, Channel, EffectInstance, Experiment, LoopLaw, Signals, SimOptions, Simulator,
    StoryOptions,
};

const LAW: &str = "
recorded controller balance \"LQR about upright, Q = [5, 1, 0.1, 0.1], R = 1\" {
    signal ff [V] \"injected excitation\"
    gain k1 = -2.236068 [V/rad]
    gain k2 = 20.162622 [V/rad]
    gain k3 = -2.012116 [V*s/rad]
    gain k4 = 2.652266 [V*s/rad]
    Vm = -k1*theta - k2*alpha - k3*derivative(theta, 100 [rad/s]) - k4*derivative(alpha, 100 [rad/s]) + ff
}
";

/// A sum of sines between 0.3 and 5 Hz with `rms` volts, phases from a
/// small generator seeded by `seed`.
fn excitation(t: &[f64], rms: f64, seed: u64) -> Vec<f64> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let freqs: Vec<f64> = (0..12).map(|k| 0.3 + k as f64 * 0.4).collect();
    let phases: Vec<f64> = freqs
        .iter()
        .map(|_| 2.0 * std::f64::consts::PI * next())
        .collect();
    let amp = rms * (2.0 / freqs.len() as f64).sqrt();
    t.iter()
        .map(|&tk| {
            freqs
                .iter()
                .zip(&phases)
                .map(|(f, p)| amp * (2.0 * std::f64::consts::PI * f * tk + p).sin())
                .sum()
        })
        .collect()
}

fn ch(name: &str, values: Vec<f64>) -> Channel {
    Channel {
        name: name.into(),
        unit_note: None,
        values,
    }
}

/// Closed-loop runs of the pendulum with `effect` (`(effect, target,
/// values)`; an empty effect name: none) hidden, written as CSV (`t, theta, alpha, Vm, ff`) and read
/// back as the CLI would.
fn closed_loop_runs(test: &str, effect: (&str, &str, &[(&str, f64)])) -> Vec<Experiment> {
    let text = pendulum_text();
    let m0 = model(&text);
    let values: Vec<(String, f64)> = effect.2.iter().map(|(n, v)| (n.to_string(), *v)).collect();
    let with_effect = if effect.0.is_empty() {
        text.clone()
    } else {
        let inst = EffectInstance::with_values(&m0, effect.0, effect.1, &values).expect("effect");
        inst.apply(&text).expect("applies")
    };
    let truth_text = format!("{with_effect}{LAW}");
    let truth = model(&truth_text);
    let law = LoopLaw::new(&truth, "balance").expect("law");
    let full = ParameterValues::new(&truth, None, &[])
        .expect("values")
        .full;
    let sim = Simulator::new(&truth, SimOptions::default())
        .expect("compiles")
        .with_loop(law.clone());
    let (rate, duration) = (500.0, 20.0);
    let n = (rate * duration) as usize;
    let t: Vec<f64> = (0..n).map(|k| k as f64 / rate).collect();
    let q_step = 2.0 * std::f64::consts::PI / 4096.0;
    let mut out = Vec::new();
    for (run, alpha0) in [(1u64, 0.04), (2, -0.03), (3, 0.02)] {
        let ff = excitation(&t, 0.6, run);
        let start = Experiment {
            name: format!("balance{run}"),
            file: format!("balance{run}.csv").into(),
            t: t.clone(),
            channels: vec![
                ch("theta", vec![0.0; n]),
                ch("alpha", vec![alpha0; n]),
                ch("ff", ff.clone()),
            ],
        };
        let sig = Signals::from_experiment_closed(&truth, &start, &law).expect("signals");
        let q = sim.simulate(&sig, &full, n).expect("simulates").q;
        assert!(
            q[1].iter().all(|a| a.abs() < 0.5),
            "the law keeps the pendulum up"
        );
        let vm = law.replay(&start, &q).expect("replays").u[0].clone();
        let mut csv = String::from("t,theta,alpha,Vm,ff\n");
        for k in 0..n {
            let round = |v: f64| q_step * (v / q_step).round();
            writeln!(
                csv,
                "{:.4},{:.9},{:.9},{:.6},{:.6}",
                t[k],
                round(q[0][k]),
                round(q[1][k]),
                vm[k],
                ff[k]
            )
            .expect("formats");
        }
        let p = common::write(test, &format!("balance{run}.csv"), &csv);
        out.push(
            read_experiment(&p, &common::pendulum_spec())
                .expect("reads")
                .0,
        );
    }
    out
}

fn story(text: &str, exps: &[Experiment]) -> plantc_identify::Story {
    let opts = StoryOptions {
        max_effects: 2,
        ..Default::default()
    };
    let s = plantc_identify::identify(text, exps, &opts, &mut |_| {}).expect("identifies");
    common::show_rounds(&s);
    for r in &s.rounds {
        for c in r.ranking.iter().take(4) {
            eprintln!(
                "    {:28} gain {:.2} ee rank {}",
                c.candidate.label(),
                c.gain,
                c.evidence.equation_error_rank
            );
        }
    }
    eprintln!(
        "stop: {}; floor {:.3e}, segments {:?}, final cost {:.3e}",
        s.stop,
        plantc_identify::weights::noise_cost(&s.fit.weights),
        s.fit.segments,
        s.fit.after_cost
    );
    for n in &s.fit.notes {
        eprintln!("  note: {n}");
    }
    s
}

/// `label` is the first effect named, or none is: true for the latter.
fn nothing_else_named(s: &plantc_identify::Story, label: &str) -> bool {
    let named = first_named(s);
    assert!(
        named.is_none() || named.as_deref() == Some(label),
        "{named:?}"
    );
    named.is_none()
}

/// The story's estimate of `name` is within `tol` (relative) of `truth`.
fn assert_estimate(s: &plantc_identify::Story, name: &str, truth: f64, tol: f64) {
    let p = s
        .fit
        .parameters
        .iter()
        .find(|p| p.name == name)
        .unwrap_or_else(|| panic!("no estimate of {name}"));
    eprintln!("{name} {:.4e} (true {truth:.1e})", p.value);
    assert!(
        (p.value / truth - 1.0).abs() < tol,
        "{name} {:.3e}",
        p.value
    );
}

fn first_named(s: &plantc_identify::Story) -> Option<String> {
    s.rounds
        .first()
        .and_then(|r| r.effect.as_ref())
        .map(|e| e.label())
}

/// Coulomb friction of 6e-4 N m on the balanced pendulum, the law in the
/// model: simulated in the loop, fed by the recorded excitation, over the
/// whole records. The friction is named (4.1x when written) and the story
/// ends at the noise floor.
#[test]
fn coulomb_friction_in_closed_loop_with_the_law() {
    let exps = closed_loop_runs("cl_law", ("coulomb_friction", "alpha", &[("Fc", 6e-4)]));
    let text = format!("{}{LAW}", pendulum_text());
    let s = story(&text, &exps);
    assert_eq!(s.fit.closed_loop.as_deref(), Some("balance"));
    assert_eq!(s.fit.segments, None, "whole records in the loop");
    assert_eq!(first_named(&s).as_deref(), Some("coulomb_friction@alpha"));
    assert_estimate(&s, "Fc_alpha", 6e-4, 0.1);
    let floor = plantc_identify::weights::noise_cost(&s.fit.weights);
    assert!(s.fit.after_cost <= 1.25 * floor);
}

/// The same recordings with the plain model (no law): replayed open loop
/// the upright pendulum falls within a second (on 0.5 s segments the
/// friction gained 1.12x, under the noise); the story replays the logged
/// voltage with a stabilising feedback on the distance to the measured
/// angles (an LQR design of its own, not the rig's gains) and fits the
/// whole records: the friction is named (3.15x when written) and estimated
/// within 10 %. The model it writes has no trace of the feedback.
#[test]
#[ignore = "issue 26 open: Fc_alpha 5.39e-4 against 6e-4 (-10.1 %, the test asks 10 %) and a deadzone@Vm named in round 2 (1.735 -> 1.702), measured 2026-11-27"]
fn closed_loop_without_the_law_is_replayed_stabilised() {
    let exps = closed_loop_runs("cl_open", ("coulomb_friction", "alpha", &[("Fc", 6e-4)]));
    let s = story(&pendulum_text(), &exps);
    let note = s.stabilised.as_ref().map(|r| r.note()).unwrap_or_default();
    eprintln!("stabilised: {note}");
    assert!(note.contains("stabilising feedback"), "{note:?}");
    assert_eq!(s.fit.segments, None, "whole records");
    assert_eq!(first_named(&s).as_deref(), Some("coulomb_friction@alpha"));
    assert_estimate(&s, "Fc_alpha", 6e-4, 0.1);
    let floor = plantc_identify::weights::noise_cost(&s.fit.weights);
    assert!(
        s.fit.after_cost <= 1.5 * floor,
        "{:.3e} vs floor {floor:.3e}",
        s.fit.after_cost
    );
    for text in s.stages.iter().map(|st| &st.text).chain([&s.text]) {
        assert!(!text.contains("recorded controller"), "{text}");
    }
}

/// Told to fit on segments, the story does so, and the verdict says what
/// segments cannot see and how to let the whole records be fitted.
#[test]
fn on_segments_the_verdict_says_what_it_cannot_see() {
    let exps = closed_loop_runs("cl_seg", ("coulomb_friction", "alpha", &[("Fc", 6e-4)]));
    let opts = StoryOptions {
        max_effects: 1,
        fit: plantc_identify::FitOptions {
            horizon: plantc_identify::Horizon::Segments(0.5),
            ..Default::default()
        },
        ..Default::default()
    };
    let s =
        plantc_identify::identify(&pendulum_text(), &exps, &opts, &mut |_| {}).expect("identifies");
    eprintln!("stop: {}", s.stop);
    assert!(s.stabilised.is_none());
    if nothing_else_named(&s, "coulomb_friction@alpha") {
        assert!(
            s.stop.contains("segments") && s.stop.contains("recorded controller"),
            "{}",
            s.stop
        );
    }
}

/// Clean closed-loop records on the plain model: the stabilised replay
/// invents nothing.
#[test]
#[ignore = "issue 26 open: the stabilised replay of clean records ends 1.6x the noise floor and the rule names cogging@theta (1.622 -> 1.599) then added_inertia@alpha, measured 2026-11-27"]
fn clean_closed_loop_records_get_no_finding() {
    let exps = closed_loop_runs("cl_clean", ("", "", &[]));
    let s = story(&pendulum_text(), &exps);
    assert!(s.stabilised.is_some());
    assert_eq!(first_named(&s), None, "{}", s.stop);
    assert!(!s.unexplained, "{}", s.stop);
}

/// A 4 ms input delay in the loop, the plain model: no other effect is
/// named in its place. A weak spot, measured: the delay refits to 1.78x
/// from 2.4x the noise floor and is not credited (not 3x, and the
/// stabilised replay's own floor, 1.25x the encoder's on clean records, is
/// above the 1.25x "to the floor" mark); the verdict is an unexplained
/// residual naming the delay as the best candidate.
#[test]
fn input_delay_in_closed_loop_without_the_law_is_not_mistaken() {
    let exps = closed_loop_runs("cl_delay", ("input_delay", "Vm", &[("Td", 4e-3)]));
    let s = story(&pendulum_text(), &exps);
    assert!(s.stabilised.is_some());
    if nothing_else_named(&s, "input_delay@Vm") {
        assert!(s.unexplained, "{}", s.stop);
        assert!(s.stop.contains("the best, input_delay@Vm"), "{}", s.stop);
    }
}

/// The block's own names (signals, errors, gains) keep clear of the
/// model's: with parameters called `err_alpha`, `kp_Vm_theta` and
/// `measured_alpha` the block is still a valid part of the model (it fell
/// back to segments before).
#[test]
fn the_replay_block_names_keep_clear_of_the_models() {
    let exps = closed_loop_runs("cl_names", ("", "", &[]));
    let text = pendulum_text()
        + "\nparameter err_alpha = 1 [1] \"a user's name\"\nparameter kp_Vm_theta = 2 [1] \"another\"\nparameter measured_alpha = 3 [1] \"and one more\"\n";
    let m = model(&text);
    let replay =
        plantc_identify::stabilised_replay::StabilisedReplay::design(&m, &exps).expect("designs");
    let with_block = format!("{text}{}", replay.block);
    let checked = plantc_identify::diagnose::model_from_text("with block", &with_block);
    assert!(checked.is_ok(), "{:?}\n{}", checked.err(), replay.block);
    for own in [
        "let err_alpha_ =",
        "gain kp_Vm_theta_ =",
        "signal measured_alpha_ ",
    ] {
        assert!(replay.block.contains(own), "{own}\n{}", replay.block);
    }
}

/// A record in which the pendulum turns through full revolutions, beside
/// the balanced ones: no loop held that one, the data's mean position is no
/// operating point, and no stabilising feedback is designed (the pendubot
/// driven into tumbling, whose angles span 8 revolutions, had been replayed
/// under an LQR designed at such a mean and an elbow spring went unnamed,
/// a deadzone, a saturation and an input offset named instead).
#[test]
fn a_tumbling_record_gets_no_stabilising_feedback() {
    use plantc_identify::stabilised_replay::{StabiliseError, StabilisedReplay};
    let mut exps = closed_loop_runs("cl_tumbling", ("", "", &[]));
    let m = model(&pendulum_text());
    assert!(StabilisedReplay::design(&m, &exps).is_ok());
    // the first record again, its pendulum turning 1.1 revolutions
    let mut spun = exps[0].clone();
    spun.name = "spun".into();
    let n = spun.t.len() as f64;
    for c in spun.channels.iter_mut().filter(|c| c.name == "alpha") {
        for (k, v) in c.values.iter_mut().enumerate() {
            *v += 1.1 * std::f64::consts::TAU * k as f64 / n;
        }
    }
    exps.push(spun);
    match StabilisedReplay::design(&m, &exps) {
        Err(StabiliseError::Tumbles {
            experiment,
            coordinate,
        }) => assert_eq!(
            (experiment.as_str(), coordinate.as_str()),
            ("spun", "alpha")
        ),
        other => panic!("{:?}", other.map(|r| r.poles)),
    }
}
