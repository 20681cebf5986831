//! Spans: one RK4 step over several sample intervals where the inputs hold
//! (`experiment_sim::MAX_SPAN`). References: central differences of the
//! plain simulation (the sensitivities stay the exact derivatives of what
//! is simulated), the interval-by-interval simulation (an explicit 2 ms
//! substep takes no span) for the accuracy, and the bound the constant's
//! doc derives (1.1e-5 rad at most over 20 s of a pendulum swing).

mod common;

use std::f64::consts::PI;

use common::simulated::{
    check_sensitivities, max_diff, model, nominal, pendulum_text, pendulum_with, simulate,
};
use plantc_derive::model::{Model, ParameterValues};
use plantc_identify::{SensitivitySimulator, Signals, SimOptions, Simulator};

/// `secs` at 500 Hz from `alpha0`: no voltage, then `volts` over
/// `[1.0, 1.6)` s (two switches inside the record).
fn steps(secs: f64, alpha0: f64, volts: f64) -> Signals {
    let n = (secs * 500.0) as usize;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.002).collect();
    let u = t
        .iter()
        .map(|&t| if (1.0..1.6).contains(&t) { volts } else { 0.0 })
        .collect();
    Signals {
        name: "steps".into(),
        t,
        q: vec![vec![0.0; n], vec![alpha0; n]],
        u: vec![u],
        replay: None,
    }
}

/// The simulation with spans (the default options) and interval by
/// interval (`simulate`: an explicit substep of the record's interval takes
/// none), both at the nominal values.
fn spans_and_intervals(m: &Model, sig: &Signals) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let spans = Simulator::new(m, SimOptions::default())
        .expect("compiles")
        .simulate(sig, &nominal(m), sig.len())
        .expect("simulates")
        .q;
    (spans, simulate(m, sig))
}

/// Spans against one step per interval on a free swing with a voltage
/// pulse (the arm's gearbox friction sticks and releases): different
/// steps, within the bound of `MAX_SPAN`'s doc.
#[test]
fn spans_stay_within_their_accuracy_bound() {
    let m = model(&pendulum_text());
    let sig = steps(10.0, PI - 1.2, 1.5);
    let (spans, intervals) = spans_and_intervals(&m, &sig);
    let d = max_diff(&spans, &intervals);
    eprintln!("spans against 2 ms steps: max difference {d:.2e} rad");
    assert!(d > 0.0, "no span was taken");
    assert!(d < 1.1e-5, "{d}");
}

/// Sensitivities through spans (free swing, pulse, stick-slip of the arm)
/// against central differences.
#[test]
fn sensitivities_through_spans_match_central_differences() {
    let m = model(&pendulum_text());
    let sig = steps(3.0, PI - 1.0, 1.5);
    check_sensitivities(&m, &sig, &["J1", "b2", "l2"], &[1e-8, 1e-7, 1e-6], 1e-4);
}

/// A delayed input: the span ends where the delayed switch arrives (3 ms
/// after the sample that carries it), and the delay's sensitivity stays
/// exact.
#[test]
fn spans_end_at_delayed_switches() {
    let m = pendulum_with("parameter Td = 0.003 [s]\nactuator Vm = input_delay(Td)\n");
    let sig = steps(3.0, PI - 1.0, 1.5);
    check_sensitivities(&m, &sig, &["Td", "J1"], &[1e-7, 1e-8], 1e-4);
}

/// Dynamics ten times faster than the pendulum's (a 100 rad/s
/// oscillator): every span's error estimate is above the tolerance, so the
/// simulation is the interval-by-interval one to the bit.
#[test]
fn fast_dynamics_take_no_span() {
    let m = model(
        "model oscillator \"a fast oscillator\"\n\
         coordinate q : angle\n\
         input tau [N*m]\n\
         parameter J = 1e-3 [kg*m^2]\n\
         parameter k = 10 [N*m]\n\
         kinetic T = 1/2*J*q'^2\n\
         potential V = 1/2*k*q^2\n\
         force q = tau\n",
    );
    let n = 1000;
    let sig = Signals {
        name: "ring".into(),
        t: (0..n).map(|k| k as f64 * 0.002).collect(),
        q: vec![vec![0.5; n]],
        u: vec![vec![0.0; n]],
        replay: None,
    };
    let (spans, intervals) = spans_and_intervals(&m, &sig);
    let bits = |q: &[Vec<f64>]| -> Vec<u64> { q.iter().flatten().map(|v| v.to_bits()).collect() };
    assert!(spans[0].iter().any(|v| *v < 0.0), "it swings");
    assert_eq!(bits(&spans), bits(&intervals));
}

/// A delay of exactly two sample intervals: each delayed switch lands on a
/// sample instant, where a span ends and leaves the switch to the interval
/// that starts there, which takes it with its jump of the delay's
/// sensitivity. (A delay a hair shorter ends the spans one sample earlier:
/// the outputs then move by the spans' own error, so the check is the
/// one-sided difference towards longer delays, the side whose spans are
/// these.)
#[test]
fn delayed_switches_on_sample_instants_keep_their_jump() {
    let m = pendulum_with("parameter Td = 0.004 [s]\nactuator Vm = input_delay(Td)\n");
    let sig = steps(3.0, PI - 1.0, 1.5);
    let free = vec!["Td".to_string()];
    let sens = SensitivitySimulator::new(&m, &free, SimOptions::default()).expect("compiles");
    let base: Vec<f64> = m.parameters.iter().map(|p| p.value).collect();
    let at = |td: f64| {
        let mut b = base.clone();
        b[sens.free_indices()[0]] = td;
        ParameterValues::from_base(&m, b).full
    };
    let st = sens
        .simulate(&sig, &at(0.004), sig.len())
        .expect("simulates");
    let h = 1e-8;
    let plain = Simulator::new(&m, SimOptions::default()).expect("compiles");
    let y0 = plain
        .simulate(&sig, &at(0.004), sig.len())
        .expect("simulates");
    let y1 = plain
        .simulate(&sig, &at(0.004 + h), sig.len())
        .expect("simulates");
    for i in 0..2 {
        let scale = st.dq[i][0].iter().fold(0.0_f64, |a, v| a.max(v.abs()));
        let worst = (0..sig.len())
            .map(|k| ((y1.q[i][k] - y0.q[i][k]) / h - st.dq[i][0][k]).abs())
            .fold(0.0, f64::max);
        eprintln!("Td coord {i}: max |S| {scale:.3e}, max error {worst:.3e}");
        assert!(scale > 0.1, "the delay's sensitivity was lost: {scale}");
        assert!(worst <= 1e-4 * scale, "coord {i}: {worst}");
    }
}

/// `secs` of the hanging pendulum at `rate` Hz driven by `volts(t)` (held
/// sample by sample: the input changes at every sample).
fn driven(secs: f64, rate: f64, volts: fn(f64) -> f64) -> Signals {
    driven_from(secs, rate, &[0.0, PI], &[&volts])
}

/// `secs` at `rate` Hz from the positions `q0` at rest, input `j` held at
/// `inputs[j](t)` sample by sample.
fn driven_from(secs: f64, rate: f64, q0: &[f64], inputs: &[&dyn Fn(f64) -> f64]) -> Signals {
    let n = (secs * rate) as usize;
    let t: Vec<f64> = (0..n).map(|k| k as f64 / rate).collect();
    Signals {
        name: "driven".into(),
        u: inputs
            .iter()
            .map(|f| t.iter().map(|&t| f(t)).collect())
            .collect(),
        q: q0.iter().map(|&q| vec![q; n]).collect(),
        t,
        replay: None,
    }
}

/// A multisine of about 1.5 V RMS over 0.3-6 Hz (as `plantc synth`'s
/// driven experiments).
fn multisine(t: f64) -> f64 {
    [0.3, 0.7, 1.3, 2.1, 3.4, 4.6, 6.0]
        .iter()
        .enumerate()
        .map(|(i, f)| 0.8 * (2.0 * PI * f * t + 1.7 * i as f64).sin())
        .sum()
}

/// A pseudo-random binary voltage of +-1.5 V that switches every 12 to 40
/// ms (jumps inside spans: the staircase's miss of the line at the
/// samples inside decides).
fn binary(t: f64) -> f64 {
    let slot = (t / 4e-3) as u64;
    let mut level = 1.0;
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
    let mut edge = 0u64;
    while edge <= slot {
        s = s
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        edge += 3 + (s >> 61);
        if edge <= slot {
            level = -level;
        }
    }
    1.5 * level
}

/// The simulation with spans against the interval-by-interval one on
/// driven records, where the spans replace the held input by a line
/// (`affine_input`): multisine and binary voltages at 500 Hz and 1 kHz,
/// with the arm's gearbox friction sticking at the reversals. Different
/// (spans were taken), within the bound of `MAX_SPAN`'s doc (1.1e-5 rad,
/// what the spans of a free swing may cost).
#[test]
fn spans_over_a_changing_input_stay_within_the_bound() {
    let m = model(&pendulum_text());
    for (rate, name, volts) in [
        (500.0, "multisine", multisine as fn(f64) -> f64),
        (1000.0, "multisine", multisine),
        (500.0, "binary", binary),
        (1000.0, "binary", binary),
    ] {
        let sig = driven(10.0, rate, volts);
        let (spans, steps) = spans_and_intervals(&m, &sig);
        let d = max_diff(&spans, &steps);
        let swing = steps[0].iter().fold(0.0f64, |a, v| a.max(v.abs()));
        eprintln!("{name} at {rate} Hz: arm swings {swing:.2} rad, spans against intervals max {d:.2e} rad");
        assert!(swing > 0.1, "the arm is driven");
        assert!(d > 0.0, "{name} at {rate} Hz: no span was taken");
        assert!(d < 1.1e-5, "{name} at {rate} Hz: {d}");
    }
}

/// Sensitivities through spans over a changing input (the line's values at
/// the stages) against central differences of the plain simulation.
#[test]
fn sensitivities_through_spans_over_a_changing_input() {
    let m = model(&pendulum_text());
    for volts in [multisine as fn(f64) -> f64, binary] {
        let sig = driven(3.0, 1000.0, volts);
        check_sensitivities(
            &m,
            &sig,
            &["J1", "b1", "l2", "Fg1"],
            &[1e-8, 1e-8, 1e-6, 1e-7],
            1e-4,
        );
    }
}

/// Two inputs and two sticking joints (`models/double_pendulum.plant`, the
/// DFKI rig: Coulomb friction of about 0.1 N m on both): multisine torques
/// of different phases on both joints at 500 Hz and 1 kHz, hanging start
/// (the elbow swings 0.52 rad and sticks for 344 of 5000 samples at 500
/// Hz; a torque 40 % larger swings it 1.3 rad, where the two simulations
/// part by 3.8e-6, and 2.4 times larger tumbles it, chaotic). Spans against
/// the interval-by-interval simulation, within the same bound (8.9e-7,
/// measured 2026-11-29).
#[test]
fn spans_over_two_changing_inputs_stay_within_the_bound() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/double_pendulum.plant");
    let m = model(&std::fs::read_to_string(path).expect("model text"));
    let shoulder = |t: f64| 0.25 * multisine(t);
    let elbow = |t: f64| 0.125 * multisine(t + 0.37);
    for rate in [500.0, 1000.0] {
        let sig = driven_from(10.0, rate, &[0.0, 0.0], &[&shoulder, &elbow]);
        let (spans, steps) = spans_and_intervals(&m, &sig);
        let d = max_diff(&spans, &steps);
        let swing = steps[1].iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let stops = steps[1]
            .windows(3)
            .filter(|w| w[0] == w[1] && w[1] == w[2])
            .count();
        eprintln!("double pendulum at {rate} Hz: elbow swings {swing:.2} rad, held {stops} samples; spans against intervals max {d:.2e} rad");
        assert!(swing > 0.3 && stops > 100, "the elbow swings and sticks");
        assert!(d > 0.0, "at {rate} Hz: no span was taken");
        assert!(d < 1.1e-5, "at {rate} Hz: {d}");
    }
}
