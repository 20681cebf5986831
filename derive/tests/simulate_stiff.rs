//! Stiff models (reliability reproducer 16c): the reference pendulum with a
//! 1 uOhm armature resistance has a back-EMF mode near -5e7 1/s; the explicit
//! integrator needed 52-80 s (release) for 2 s. `Integrator::Auto` detects it
//! and integrates implicitly (Rosenbrock), agreeing with the explicit method.

use plantc_derive::control::{resolve, Derivation};
use plantc_derive::model::{load_model_text, ParameterValues};
use plantc_derive::simulate::{
    simulate, stiffness, Control, ControllerEval, Integrator, SimOptions, SimProblem,
};

const FIXTURE: &str = include_str!("fixtures/rotary_pendulum.plant");

fn problem(rm: f64, duration: f64) -> SimProblem {
    let model = load_model_text("rotpen.plant", FIXTURE).unwrap().model;
    let values = ParameterValues::new(&model, None, &[("Rm".into(), rm)]).unwrap();
    let derivation = Derivation::new(&model).unwrap();
    let ctrl = resolve(&model, &derivation, "hand", &values).unwrap();
    let control = Control::Feedback(ControllerEval::new(&model, &ctrl).unwrap());
    let x0 = vec![0.0, 5f64.to_radians(), 0.0, 0.0];
    SimProblem::new(
        &model,
        &derivation.equations,
        &values,
        control,
        x0,
        duration,
    )
    .unwrap()
}

fn sampled(integrator: Integrator) -> SimOptions {
    SimOptions {
        sample_rate: Some(1000.0),
        integrator,
        ..SimOptions::default()
    }
}

#[test]
fn stiffness_is_detected_and_the_nominal_model_is_not_stiff() {
    let s = stiffness(&problem(1e-6, 2.0), &sampled(Integrator::Auto)).unwrap();
    // back-EMF damping eta_g Kg^2 eta_m kt km / Rm = 1.8e5 N m s over an
    // inertia of a few 1e-3 kg m^2: order 5e7 1/s
    assert!(s.fastest_mode > 1e7 && s.is_stiff(), "{s:?}");
    let s = stiffness(&problem(2.6, 2.0), &sampled(Integrator::Auto)).unwrap();
    assert!(s.fastest_mode < 1e3 && !s.is_stiff(), "{s:?}");
    let t = simulate(&problem(2.6, 0.05), &sampled(Integrator::Auto)).unwrap();
    assert_eq!(t.integrator, Integrator::Explicit);
}

#[test]
fn auto_integrates_a_stiff_model_implicitly_and_agrees_with_explicit() {
    let stiff = simulate(&problem(1e-6, 0.2), &sampled(Integrator::Auto)).unwrap();
    assert_eq!(stiff.integrator, Integrator::Implicit);
    // the explicit method's stability bound alone needs ~1.4e7 steps here
    assert!(stiff.stats.accepted < 500_000, "{:?}", stiff.stats);
    // the first 3 ms both ways (explicit: ~45,000 steps)
    let a = simulate(&problem(1e-6, 0.003), &sampled(Integrator::Implicit)).unwrap();
    let b = simulate(&problem(1e-6, 0.003), &sampled(Integrator::Explicit)).unwrap();
    for (xa, xb) in a.states.iter().zip(&b.states) {
        for (p, q) in xa.iter().zip(xb) {
            assert!((p - q).abs() <= 1e-6 * (1.0 + q.abs()), "{xa:?} vs {xb:?}");
        }
    }
    // the back-EMF limit: theta' -> Vm / (Kg km) = +-10 / (70 * 7.68e-3) = +-18.6 rad/s
    let w = stiff.states.last().unwrap()[2].abs();
    assert!((w - 10.0 / (70.0 * 7.68e-3)).abs() < 0.1, "{w}");
}
