//! Dry friction sticks in the generated plant: the arm at rest under a
//! motor torque below its gearbox friction stays at exactly zero speed,
//! and breaks away above it; and the generated plant, plantc-derive's
//! `simulate` (Dormand-Prince, events in its dense output) and
//! plantc-identify's experiment simulation (RK4, events located in the
//! steps) give the same stick-slip trajectory.

use std::f64::consts::PI;
use std::path::Path;

use plantc_derive::control::Derivation;
use plantc_derive::model::{load_model, Model, ParameterValues};
use plantc_derive::simulate::{simulate, Control, InputSignal, SimOptions, SimProblem};
use plantc_identify::{Signals, Simulator};
use rotpen_controller::rotary_pendulum::{Params, Plant};

fn model() -> Model {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/rotary_pendulum.plant");
    load_model(&path).unwrap().model
}

/// The generated plant's parameters at `values` (base parameters by name).
fn params(m: &Model, values: &ParameterValues) -> Params {
    let mut p = Params::default();
    for (i, prm) in m.parameters.iter().enumerate() {
        assert!(p.set(&prm.name, values.full[i]), "{}", prm.name);
    }
    p
}

#[test]
fn generated_arm_held_below_the_gearbox_friction_breaks_away_above() {
    let m = model();
    let values = ParameterValues::new(&m, None, &[("Fg1".into(), 0.1)]).unwrap();
    let plant = Plant::new(params(&m, &values));
    // hanging pendulum at rest; 0.5 V gives 0.064 N m at rest
    // (eta_g Kg eta_m kt Vm / Rm), below the 0.1 N m friction
    let mut x = [0.0, PI, 0.0, 0.0];
    for _ in 0..20_000 {
        x = plant.rk4_step(&x, &[0.5], 1e-4);
        assert_eq!((x[0], x[2]), (0.0, 0.0), "the arm moved: {x:?}");
    }
    // the closed-loop step with a constant law holds it too
    let (y, _) = plant.closed_loop_rk4_step(&x, 1e-3, |_| [0.5]);
    assert_eq!((y[0], y[2]), (0.0, 0.0));
    // 2 V: 0.26 N m, above it
    for _ in 0..1000 {
        x = plant.rk4_step(&x, &[2.0], 1e-4);
    }
    assert!(x[2] > 0.1 && x[0] > 0.0, "the arm should break away: {x:?}");
}

/// The same record (rotary pendulum, gearbox friction 0.05 N m: 3 V for
/// 0.3 s swings the arm and the pendulum, after which the arm stops and is
/// held while the pendulum swings on) through the three simulators, at the
/// 500 Hz samples. RK4 at 0.1 ms has a global error near `(h w)^4 ~ 1e-12`
/// on these 10 rad/s motions and Dormand-Prince at rtol 1e-10 about 1e-10
/// of the 3 rad angles; the switches are located to a few ulps (RK4) and to
/// the dense output's accuracy (Dormand-Prince), and a breakaway or stop
/// time off by `dt` moves the angle by about `a dt^2 / 2` (from rest) or
/// `v dt` with `v ~ 0`: 1e-9 rad bounds the three apart (measured: 7.5e-15
/// between the two RK4s, 2.9e-13 to Dormand-Prince).
#[test]
fn three_simulators_agree_on_a_stick_slip_trajectory() {
    let m = model();
    let values = ParameterValues::new(&m, None, &[("Fg1".into(), 0.05)]).unwrap();
    let n = 1500;
    let dt = 2e-3;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
    let vm: Vec<f64> = t
        .iter()
        .map(|&t| if (0.2..0.5).contains(&t) { 3.0 } else { 0.0 })
        .collect();
    let x0 = [0.0, PI - 0.3, 0.0, 0.0];

    // identification's experiment simulation
    let sim = Simulator::new(
        &m,
        plantc_identify::SimOptions {
            substep: Some(1e-4),
            ..plantc_identify::SimOptions::default()
        },
    )
    .unwrap();
    let sig = Signals {
        name: "stick_slip".into(),
        t: t.clone(),
        q: vec![vec![x0[0]; n], vec![x0[1]; n]],
        u: vec![vm.clone()],
        replay: None,
    };
    let ident = sim.simulate(&sig, &values.full, n).unwrap().q;

    // derive's simulate
    let der = Derivation::new(&m).unwrap();
    let control = Control::OpenLoop(InputSignal::ZeroOrderHold {
        t: t.clone(),
        u: vm.iter().map(|v| vec![*v]).collect(),
    });
    let problem = SimProblem::new(
        &m,
        &der.equations,
        &values,
        control,
        x0.to_vec(),
        (n - 1) as f64 * dt,
    )
    .unwrap();
    let traj = simulate(
        &problem,
        &SimOptions {
            rtol: 1e-10,
            atol: 1e-12,
            output_rate: 1.0 / dt,
            ..SimOptions::default()
        },
    )
    .unwrap();
    assert_eq!(traj.len(), n);

    // the generated plant, 20 substeps per sample
    let plant = Plant::new(params(&m, &values));
    let mut x = x0;
    let mut gen = vec![[0.0; 2]; n];
    for k in 0..n {
        gen[k] = [x[0], x[1]];
        for _ in 0..20 {
            x = plant.rk4_step(&x, &[vm[k]], dt / 20.0);
        }
    }

    // the arm is held for a good part of the record
    let held = (1..n).filter(|&k| gen[k][0] == gen[k - 1][0]).count();
    assert!(
        held > n / 3,
        "the arm should be held: {held} of {n} samples"
    );
    let (mut d_ident, mut d_derive) = (0.0f64, 0.0f64);
    for k in 0..n {
        for i in 0..2 {
            d_ident = d_ident.max((ident[i][k] - gen[k][i]).abs());
            d_derive = d_derive.max((traj.states[k][i] - gen[k][i]).abs());
        }
    }
    eprintln!(
        "stick-slip record: arm held at {held} of {n} samples; generated vs identify {d_ident:.1e} rad, vs simulate {d_derive:.1e} rad"
    );
    assert!(d_ident < 1e-9, "{d_ident}");
    assert!(d_derive < 1e-9, "{d_derive}");
}
