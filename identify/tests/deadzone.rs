//! The `deadzone(w)` actuator effect in the experiment simulation and its
//! sensitivities. Reference values come from the simulator itself on
//! transformed data (the nominal model driven by `dz(u)`, computed here
//! sample by sample from the definition `sign(u) * max(|u| - w, 0)`), and
//! from central finite differences of the plain simulation.

mod common;

use common::simulated::{
    check_sensitivities, driven_signals, max_diff, model, pendulum_text, pendulum_with, simulate,
};

use plantc_derive::model::{load_model_text, ParameterValues};
use plantc_identify::experiment_sim::deadzone;
use plantc_identify::{EffectInstance, EffectKind, SimError};
use plantc_identify::{SimOptions, Simulator};

/// `sign(u) * max(|u| - w, 0)` written as in the issue (the reference for
/// the simulator's [`deadzone`]).
fn dz_reference(u: f64, w: f64) -> f64 {
    u.signum() * (u.abs() - w).max(0.0)
}

#[test]
fn deadzone_function_matches_its_definition() {
    for &w in &[0.0, 0.3, 2.0] {
        for &u in &[-3.0, -2.0, -0.31, -0.3, -0.1, 0.0, 0.1, 0.3, 0.31, 2.0, 3.0] {
            let (a, b) = (deadzone(u, w), dz_reference(u, w));
            assert!((a - b).abs() < 1e-15, "dz({u}, {w}) = {a}, expected {b}");
        }
    }
    // w = 0 returns the input itself, bit for bit
    for &u in &[-1.7, 1e-300, 3.25] {
        assert_eq!(deadzone(u, 0.0).to_bits(), u.to_bits());
    }
}

#[test]
fn deadzone_on_u_equals_nominal_model_on_dz_u() {
    let w = 0.6;
    let with = pendulum_with("parameter w = 0.6 [V]\nactuator Vm = deadzone(w)\n");
    let base = model(&pendulum_text());
    let sig = driven_signals();
    let mut dz = sig.clone();
    dz.u[0].iter_mut().for_each(|u| *u = dz_reference(*u, w));
    let zeroed = dz.u[0].iter().filter(|u| **u == 0.0).count();
    assert!(zeroed > 50, "the deadzone should remove samples: {zeroed}");
    let d = max_diff(&simulate(&with, &sig), &simulate(&base, &dz));
    eprintln!("deadzone: max difference {d:.2e}");
    assert!(d < 1e-12, "{d}");
    // and the deadzone does change the motion
    assert!(max_diff(&simulate(&with, &sig), &simulate(&base, &sig)) > 1e-3);
}

/// The documented order: deadzone on the commanded samples, then the delay,
/// then the (folded) offset, whatever the order of the lines.
#[test]
fn deadzone_then_delay_then_offset() {
    let w = 0.6;
    let with = pendulum_with(
        "parameter w = 0.6 [V]\nparameter Td = 0.002 [s]\nparameter V0 = 0.25 [V]\n\
         actuator Vm = input_offset(V0)\nactuator Vm = input_delay(Td)\n\
         actuator Vm = deadzone(w)\n",
    );
    let base = pendulum_with("parameter V0 = 0.25 [V]\nactuator Vm = input_offset(V0)\n");
    let sig = driven_signals();
    let mut expected = sig.clone();
    let u = &sig.u[0];
    expected.u[0] = (0..u.len())
        .map(|k| dz_reference(u[k.saturating_sub(1)], w))
        .collect();
    let d = max_diff(&simulate(&with, &sig), &simulate(&base, &expected));
    eprintln!("deadzone + delay + offset: max difference {d:.2e}");
    assert!(d < 1e-12, "{d}");
}

#[test]
fn zero_width_is_bit_identical_to_no_deadzone() {
    let zero = pendulum_with("parameter w = 0 [V]\nactuator Vm = deadzone(w)\n");
    let base = model(&pendulum_text());
    let sig = driven_signals();
    let (a, b) = (simulate(&zero, &sig), simulate(&base, &sig));
    let bits = |q: &[Vec<f64>]| -> Vec<u64> { q.iter().flatten().map(|v| v.to_bits()).collect() };
    assert_eq!(bits(&a), bits(&b));
}

/// A width that evaluates negative in a parameter vector (the file checker
/// refuses a negative literal) is an error, not a panic.
#[test]
fn negative_width_in_the_parameter_vector_is_an_error() {
    assert!(load_model_text(
        "neg.plant",
        &(pendulum_text() + "\nparameter w = -0.1 [V]\nactuator Vm = deadzone(w)\n")
    )
    .is_err());
    let m = pendulum_with("parameter w = 0.1 [V]\nactuator Vm = deadzone(w)\n");
    let i = m.parameters.iter().position(|p| p.name == "w").unwrap();
    let mut base: Vec<f64> = m.parameters.iter().map(|p| p.value).collect();
    base[i] = -0.2;
    let full = ParameterValues::from_base(&m, base).full;
    let sig = driven_signals();
    let sim = Simulator::new(&m, SimOptions::default()).expect("compiles");
    match sim.simulate(&sig, &full, sig.len()) {
        Err(SimError::BadDeadzone { input, value }) => {
            assert_eq!(input, "Vm");
            assert_eq!(value, -0.2);
        }
        other => panic!("{other:?}"),
    }
}

/// The sensitivity to `w` is exact for the discrete simulation (the held
/// `dz(u[k])` is linear in `w` on each sample with `|u[k]| != w`), so
/// 1e-4 relative only covers the differences' truncation and rounding, as
/// in signal_effects.rs. No sample of the multisine lies within the step
/// 1e-6 V of `|u| = w`, where the held input has a kink in `w`.
#[test]
fn sensitivity_to_width_matches_finite_differences() {
    let sig = driven_signals();
    let near = sig.u[0]
        .iter()
        .map(|u| (u.abs() - 0.6).abs())
        .fold(f64::INFINITY, f64::min);
    assert!(near > 1e-5, "a sample lies at the kink: {near}");
    let m = pendulum_with("parameter w = 0.6 [V] estimate [0, 2]\nactuator Vm = deadzone(w)\n");
    check_sensitivities(&m, &sig, &["w", "J1"], &[1e-6, 1e-8], 1e-4);
    // with a delay and an offset on the same input, all estimated
    let m = pendulum_with(
        "parameter w = 0.6 [V] estimate [0, 2]\nparameter Td = 0.0013 [s] estimate [0, 0.05]\n\
         parameter V0 = 0.2 [V] estimate [-1, 1]\nactuator Vm = deadzone(w)\n\
         actuator Vm = input_delay(Td)\nactuator Vm = input_offset(V0)\n",
    );
    check_sensitivities(&m, &sig, &["w", "Td", "V0"], &[1e-6, 1e-7, 1e-6], 1e-4);
}

#[test]
fn deadzone_candidate_template() {
    let text = pendulum_text();
    let m = model(&text);
    let c = EffectInstance::candidate(&m, "deadzone", "Vm").expect("candidate");
    assert_eq!(c.kind, EffectKind::Actuator);
    assert_eq!(c.parameters[0].unit, "V");
    assert_eq!(c.parameters[0].estimate, Some((0.0, 2.0)));
    let inst =
        EffectInstance::with_values(&m, "deadzone", "Vm", &[("w".into(), 0.4)]).expect("instance");
    let e = model(&inst.apply(&text).expect("applies"));
    let values = e.parameters.iter().map(|p| (p.symbol, p.value)).collect();
    assert!((e.input_deadzone(0).eval_map(&values) - 0.4).abs() < 1e-15);
}
