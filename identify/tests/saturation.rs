//! The `saturation(L)` actuator effect in the experiment simulation and its
//! sensitivities, open and closed loop. Reference values come from the
//! simulator itself on transformed data (the nominal model driven by
//! `clip(u, -L, L)`, computed here sample by sample from the definition),
//! and from central finite differences of the plain simulation.

mod common;

use common::simulated::{
    check_sensitivities, check_sensitivities_in_loop, driven_signals, max_diff, model, nominal,
    pendulum_text, pendulum_with, simulate,
};
use std::path::PathBuf;

use plantc_derive::model::{load_model_text, ParameterValues};
use plantc_identify::experiment_sim::{deadzone, saturation};
use plantc_identify::{
    Channel, EffectInstance, EffectKind, Experiment, LoopLaw, Signals, SimError, SimOptions,
    Simulator,
};

/// `min(max(u, -L), L)` written out (the reference for [`saturation`]).
fn sat_reference(u: f64, l: f64) -> f64 {
    if u > l {
        l
    } else if u < -l {
        -l
    } else {
        u
    }
}

#[test]
fn saturation_function_matches_its_definition() {
    for &l in &[0.3, 2.0, f64::INFINITY] {
        for &u in &[-3.0, -2.0, -0.31, -0.3, -0.1, 0.0, 0.1, 0.3, 0.31, 2.0, 3.0] {
            assert_eq!(saturation(u, l), sat_reference(u, l), "sat({u}, {l})");
        }
    }
}

#[test]
fn saturation_on_u_equals_nominal_model_on_clipped_u() {
    let with = pendulum_with("parameter L = 1.2 [V]\nactuator Vm = saturation(L)\n");
    let base = model(&pendulum_text());
    let sig = driven_signals();
    let mut clipped = sig.clone();
    clipped.u[0]
        .iter_mut()
        .for_each(|u| *u = sat_reference(*u, 1.2));
    let n = sig.u[0].iter().filter(|u| u.abs() > 1.2).count();
    assert!(n > 50, "the limit should clip samples: {n}");
    let d = max_diff(&simulate(&with, &sig), &simulate(&base, &clipped));
    eprintln!("saturation: max difference {d:.2e}");
    assert!(d < 1e-12, "{d}");
    assert!(max_diff(&simulate(&with, &sig), &simulate(&base, &sig)) > 1e-3);
}

/// The documented order: deadzone on the commanded samples, then the
/// saturation, then the delay, then the (folded) offset, whatever the order
/// of the lines.
#[test]
fn deadzone_then_saturation_then_delay_then_offset() {
    let with = pendulum_with(
        "parameter w = 0.3 [V]\nparameter L = 1.1 [V]\nparameter Td = 0.002 [s]\n\
         parameter V0 = 0.25 [V]\n\
         actuator Vm = input_offset(V0)\nactuator Vm = saturation(L)\n\
         actuator Vm = input_delay(Td)\nactuator Vm = deadzone(w)\n",
    );
    let base = pendulum_with("parameter V0 = 0.25 [V]\nactuator Vm = input_offset(V0)\n");
    let sig = driven_signals();
    let mut expected = sig.clone();
    let u = &sig.u[0];
    expected.u[0] = (0..u.len())
        .map(|k| sat_reference(deadzone(u[k.saturating_sub(1)], 0.3), 1.1))
        .collect();
    let d = max_diff(&simulate(&with, &sig), &simulate(&base, &expected));
    eprintln!("deadzone + saturation + delay + offset: max difference {d:.2e}");
    assert!(d < 1e-12, "{d}");
}

#[test]
fn level_above_the_input_is_bit_identical_to_no_saturation() {
    let high = pendulum_with("parameter L = 10 [V]\nactuator Vm = saturation(L)\n");
    let base = model(&pendulum_text());
    let sig = driven_signals();
    let (a, b) = (simulate(&high, &sig), simulate(&base, &sig));
    let bits = |q: &[Vec<f64>]| -> Vec<u64> { q.iter().flatten().map(|v| v.to_bits()).collect() };
    assert_eq!(bits(&a), bits(&b));
}

/// A level that evaluates to zero or less in a parameter vector (the file
/// checker refuses such a literal) is an error, not a panic.
#[test]
fn nonpositive_level_in_the_parameter_vector_is_an_error() {
    assert!(load_model_text(
        "zero.plant",
        &(pendulum_text() + "\nparameter L = 0 [V]\nactuator Vm = saturation(L)\n")
    )
    .is_err());
    let m = pendulum_with("parameter L = 1 [V]\nactuator Vm = saturation(L)\n");
    let i = m.parameters.iter().position(|p| p.name == "L").unwrap();
    let sig = driven_signals();
    let sim = Simulator::new(&m, SimOptions::default()).expect("compiles");
    for bad in [0.0, -0.5, f64::NAN] {
        let mut base: Vec<f64> = m.parameters.iter().map(|p| p.value).collect();
        base[i] = bad;
        let full = ParameterValues::from_base(&m, base).full;
        match sim.simulate(&sig, &full, sig.len()) {
            Err(SimError::BadSaturation { input, value }) => {
                assert_eq!(input, "Vm");
                assert!(value.to_bits() == bad.to_bits(), "{value} vs {bad}");
            }
            other => panic!("{other:?}"),
        }
    }
}

/// The sensitivity to `L` is exact for the discrete simulation (the held
/// `sat(u[k])` is `+-L` or `u[k]`, linear in `L`, on each sample with
/// `|u[k]| != L`): they agree with central differences to 1e-6 relative
/// (measured: 1e-7 at worst). No sample lies within the step of the kink
/// `|u| = L`.
#[test]
fn sensitivity_to_level_matches_finite_differences() {
    let sig = driven_signals();
    for l in [1.2, 0.3 + 1.1] {
        let near = sig.u[0]
            .iter()
            .map(|u| (u.abs() - l).abs())
            .fold(f64::INFINITY, f64::min);
        assert!(near > 1e-5, "a sample lies at the kink: {near}");
    }
    let m =
        pendulum_with("parameter L = 1.2 [V] estimate [0.1, 10]\nactuator Vm = saturation(L)\n");
    check_sensitivities(&m, &sig, &["L", "J1"], &[1e-6, 1e-8], 1e-6);
    // with a deadzone, a delay and an offset on the same input, all estimated
    let m = pendulum_with(
        "parameter L = 1.1 [V] estimate [0.1, 10]\nparameter w = 0.3 [V] estimate [0, 2]\n\
         parameter Td = 0.0013 [s] estimate [0, 0.05]\nparameter V0 = 0.2 [V] estimate [-1, 1]\n\
         actuator Vm = saturation(L)\nactuator Vm = deadzone(w)\n\
         actuator Vm = input_delay(Td)\nactuator Vm = input_offset(V0)\n",
    );
    check_sensitivities(
        &m,
        &sig,
        &["L", "w", "Td", "V0"],
        &[1e-6, 1e-6, 1e-7, 1e-6],
        1e-6,
    );
}

/// A recorded PD law on the arm in the loop, its output clipped by the
/// drive: where the limit clips, the law's own sensitivity does not reach
/// the plant and the level's does.
#[test]
fn closed_loop_sensitivity_with_saturation_matches_finite_differences() {
    let m = pendulum_with(
        "parameter L = 1.0 [V] estimate [0.1, 10]\nactuator Vm = saturation(L)\n\
         recorded controller pd \"PD on the arm\" {\n\
             signal target [rad] \"arm reference\"\n\
             gain kp = 8 [V/rad]\n\
             gain kd = 0.6 [V*s/rad]\n\
             Vm = -kp*(theta - target) - kd*derivative(theta, 50 [rad/s])\n\
         }\n",
    );
    let law = LoopLaw::new(&m, "pd").expect("law");
    let n = 600;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.002).collect();
    // reference steps of 0.4 rad: the law asks for about 3 V, the drive gives 1
    let target: Vec<f64> = t
        .iter()
        .map(|&t| if (t * 2.0) as i64 % 2 == 0 { 0.4 } else { -0.2 })
        .collect();
    let ch = |name: &str, values: Vec<f64>| Channel {
        name: name.into(),
        unit_note: None,
        values,
    };
    let exp = Experiment {
        name: "steps".into(),
        file: PathBuf::from("steps.csv"),
        t: t.clone(),
        channels: vec![
            ch("theta", vec![0.0; n]),
            ch("alpha", vec![std::f64::consts::PI - 0.2; n]),
            ch("target", target),
        ],
    };
    let sig = Signals::from_experiment_closed(&m, &exp, &law).expect("signals");
    // the law does hit the limit, and not always
    let sim = Simulator::new(&m, SimOptions::default())
        .expect("compiles")
        .with_loop(law.clone());
    let tr = sim.simulate(&sig, &nominal(&m), n).expect("simulates");
    assert!(
        tr.q[0].iter().any(|v| (v - 0.0).abs() > 0.05),
        "the arm moves"
    );
    check_sensitivities_in_loop(
        &m,
        &sig,
        &["L", "J1", "b1"],
        &[1e-6, 1e-8, 1e-7],
        1e-6,
        Some(&law),
    );
}

#[test]
fn saturation_candidate_template() {
    let text = pendulum_text();
    let m = model(&text);
    let c = EffectInstance::candidate(&m, "saturation", "Vm").expect("candidate");
    assert_eq!(c.kind, EffectKind::Actuator);
    assert_eq!(c.parameters[0].unit, "V");
    let inst = EffectInstance::with_values(&m, "saturation", "Vm", &[("L".into(), 1.5)])
        .expect("instance");
    let e = model(&inst.apply(&text).expect("applies"));
    let values = e.parameters.iter().map(|p| (p.symbol, p.value)).collect();
    let l = e.input_saturation(0).expect("a saturation line");
    assert!((l.eval_map(&values) - 1.5).abs() < 1e-15);
}
