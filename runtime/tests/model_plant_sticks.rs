//! The runtime's simulated model plant (`plantc run` with the sim backend)
//! sticks: the rotary pendulum's arm at rest under a motor torque below its
//! gearbox friction stays at exactly zero speed, step after step, and breaks
//! away when the torque exceeds the friction.

#![cfg(feature = "model")]

use std::path::Path;

use plantc_derive::mechanics::derive_equations;
use plantc_derive::mechanics::NumericDynamics;
use plantc_derive::model::{load_model, ParameterValues};
use plantc_runtime::integrate::Rk4Scratch;
use plantc_runtime::{ModelPlant, Plant};

#[test]
fn arm_held_below_the_gearbox_friction_breaks_away_above() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/rotary_pendulum.plant");
    let m = load_model(&path).expect("model").model;
    // a gearbox friction of 0.1 N m
    let vals = ParameterValues::new(&m, None, &[("Fg1".into(), 0.1)]).expect("values");
    let eqs = derive_equations(&m).expect("equations");
    let dynamics = NumericDynamics::new(&m, &eqs).expect("dynamics");
    assert!(dynamics.has_dry_friction());
    let plant = ModelPlant::new(&m, dynamics, &vals);
    let mut scratch = Rk4Scratch::new(4);
    // hanging pendulum at rest; the runtime's default substep (1 ms / 10)
    let mut x = vec![0.0, std::f64::consts::PI, 0.0, 0.0];
    let h = 1e-4;
    // 0.5 V: eta_g Kg eta_m kt Vm / Rm = 0.064 N m at rest, below 0.1 N m
    for _ in 0..20_000 {
        plant.step(&mut x, &[0.5], h, &mut scratch);
        assert_eq!(x[0], 0.0, "the arm moved: {x:?}");
        assert_eq!(x[2], 0.0, "the arm's speed: {x:?}");
    }
    // 2 V: 0.26 N m, above the friction: the arm turns
    for _ in 0..1000 {
        plant.step(&mut x, &[2.0], h, &mut scratch);
    }
    assert!(x[2] > 0.1 && x[0] > 0.0, "the arm should break away: {x:?}");
    assert!(x.iter().all(|v| v.is_finite()));
}
