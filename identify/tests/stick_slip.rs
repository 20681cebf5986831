//! Sticking dry friction in the experiment simulation: the physics (a joint
//! held below its static level stays exactly where it is, breaks away above
//! it, stops and stays stopped) and the exactness of the sensitivities on
//! stick-slip trajectories (against central differences of the plain
//! simulation, which is the reference: the sensitivities are meant to be
//! the derivatives of that discrete simulation).

mod common;

use std::f64::consts::PI;

use common::simulated::{model, pendulum_text};
use plantc_derive::model::{Model, ParameterValues};
use plantc_identify::{
    BlockStart, DryFriction, ExtraColumn, SensitivitySimulator, Signals, SimOptions, Simulator,
};

/// A driven horizontal joint: inertia `J`, viscous `b`, a spring `k`, a dry
/// friction (`friction`, e.g. `coulomb_friction(Fc)`) and an input delay.
fn joint(friction: &str) -> Model {
    model(&format!(
        "model joint \"a driven joint with dry friction\"\n\
         coordinate q : angle\n\
         input tau [N*m] limits [-10, 10]\n\
         parameter J = 0.01 [kg*m^2] estimate [0.001, 0.1]\n\
         parameter b = 0.002 [N*m*s/rad] estimate [0, 0.1]\n\
         parameter k = 0.05 [N*m/rad] estimate [0, 1]\n\
         parameter Fc = 0.08 [N*m] estimate [0, 1]\n\
         parameter Fs = 0.12 [N*m] estimate [0, 1]\n\
         parameter vs = 0.05 [rad/s] estimate [0.001, 1]\n\
         parameter Td = 1.3e-3 [s] estimate [0, 0.01]\n\
         actuator tau = input_delay(Td)\n\
         kinetic T = 1/2*J*q'^2\n\
         force q = tau + viscous_friction(b) + spring(k) + {friction}\n"
    ))
}

/// `n` samples at 500 Hz of an input `u(t)`, the record starting at `q0`.
fn signals(n: usize, q0: &[f64], u: impl Fn(f64) -> Vec<f64>) -> Signals {
    let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.002).collect();
    let us: Vec<Vec<f64>> = t.iter().map(|&t| u(t)).collect();
    let m = us[0].len();
    Signals {
        name: "stick_slip".into(),
        t: t.clone(),
        q: q0.iter().map(|&v| vec![v; n]).collect(),
        u: (0..m).map(|j| us.iter().map(|v| v[j]).collect()).collect(),
        replay: None,
    }
}

fn base(m: &Model) -> Vec<f64> {
    m.parameters.iter().map(|p| p.value).collect()
}

fn full(m: &Model, b: &[f64]) -> Vec<f64> {
    ParameterValues::from_base(m, b.to_vec()).full
}

/// Runs of samples (at least `len` long) over which coordinate `i` does not
/// change at all: a stuck joint keeps its position to the bit.
fn held_runs(q: &[f64], len: usize) -> usize {
    let mut runs = 0;
    let mut count = 1;
    for k in 1..q.len() {
        if q[k].to_bits() == q[k - 1].to_bits() {
            count += 1;
            if count == len {
                runs += 1;
            }
        } else {
            count = 1;
        }
    }
    runs
}

/// Sensitivities of a block with initial-state columns against central
/// differences of the plain simulation, relative to the largest |S| of each
/// coordinate and column, from the record's positions and velocities `v0`.
/// Returns the worst relative error. (A dry joint starting at exactly zero
/// speed and breaking away at once is a kink of the simulation in its
/// initial velocity, where central differences average two one-sided
/// derivatives: the cases start their joints moving, or held.)
fn check(m: &Model, sig: &Signals, v0: &[f64], free: &[&str], rel_step: f64) -> f64 {
    let names: Vec<String> = free.iter().map(|s| s.to_string()).collect();
    let n = m.coordinates.len();
    let sens = SensitivitySimulator::new(m, &names, SimOptions::default()).expect("compiles");
    let sim = Simulator::new(m, SimOptions::default()).expect("compiles");
    let b0 = base(m);
    let p0 = full(m, &b0);
    let mut start =
        BlockStart::from_data(sig, plantc_identify::InitialVelocity::Zero, &vec![0.0; n]);
    start.x0[n..].copy_from_slice(v0);
    let extra: Vec<ExtraColumn> = (0..2 * n)
        .map(|c| {
            let mut s0 = vec![0.0; 2 * n];
            s0[c] = 1.0;
            ExtraColumn {
                s0,
                direct: vec![0.0; n],
            }
        })
        .collect();
    let tied = vec![false; n];
    let st = sens
        .simulate_block(sig, &p0, &start, &tied, &extra)
        .expect("simulates");
    let plain = sim.simulate_block(sig, &p0, &start).expect("simulates");
    for i in 0..n {
        for k in 0..sig.len() {
            assert_eq!(
                st.q[i][k].to_bits(),
                plain.q[i][k].to_bits(),
                "trajectories differ"
            );
        }
    }
    let mut worst_rel = 0.0f64;
    let mut compare = |label: &str, col: usize, yp: &[Vec<f64>], ym: &[Vec<f64>], h: f64| {
        for i in 0..n {
            let scale = st.dq[i][col].iter().fold(1e-300_f64, |a, v| a.max(v.abs()));
            let mut worst = 0.0_f64;
            for k in 0..sig.len() {
                let fd = (yp[i][k] - ym[i][k]) / (2.0 * h);
                worst = worst.max((fd - st.dq[i][col][k]).abs());
            }
            let rel = worst / scale;
            eprintln!("{label} coord {i}: max |S| {scale:.3e}, max error {worst:.3e} ({rel:.1e} relative)");
            if scale > 1e-9 {
                worst_rel = worst_rel.max(rel);
            }
        }
    };
    for (j, &pi) in sens.free_indices().iter().enumerate() {
        let h = rel_step * b0[pi].abs().max(1e-3);
        let run = |d: f64| {
            let mut b = b0.clone();
            b[pi] += d;
            sim.simulate_block(sig, &full(m, &b), &start)
                .expect("simulates")
                .q
        };
        compare(free[j], j, &run(h), &run(-h), h);
    }
    for c in 0..2 * n {
        let h = rel_step;
        let run = |d: f64| {
            let mut s = start.clone();
            s.x0[c] += d;
            sim.simulate_block(sig, &p0, &s).expect("simulates").q
        };
        compare(&format!("x0[{c}]"), free.len() + c, &run(h), &run(-h), h);
    }
    worst_rel
}

/// Central differences with a relative step of 1e-6 have a truncation
/// error near (1e-6)^2 = 1e-12 relative and a rounding error near
/// 1e-16 / 1e-6 = 1e-10 of the trajectory's scale per sample, amplified
/// where the trajectory is sensitive (measured worst: 7e-7 on the held arm);
/// the event times are located to a few ulps. A missed or wrong event term
/// is wrong by O(1) of the sensitivity (1e-3 for the kink of a released
/// start, see `check`), so 1e-5 of the largest value separates the two.
const TOLERANCE: f64 = 1e-5;

/// A Coulomb friction on a driven joint with a spring and an input delay:
/// it sticks at every reversal, breaks away and reverses; the sensitivities
/// to every parameter (inertia, viscous, spring, level, delay) and to the
/// initial state follow the discrete simulation through the events.
#[test]
fn coulomb_joint_sensitivities_through_stick_slip() {
    let m = joint("coulomb_friction(Fc)");
    // pulses of 0.12 N m against a level of 0.08 N m, with rests between
    // them: the joint slides, stops and sticks (spring below the level),
    // breaks away with the next pulse, reverses with the one after
    let sig = signals(1500, &[0.0], |t| {
        let phase = (t / 0.5).floor() as i64 % 4;
        vec![[0.12, 0.0, -0.12, 0.0][phase as usize]]
    });
    let sim = Simulator::new(&m, SimOptions::default()).expect("compiles");
    let q = sim
        .simulate(&sig, &full(&m, &base(&m)), sig.len())
        .expect("simulates")
        .q;
    let runs = held_runs(&q[0], 10);
    assert!(
        runs >= 3,
        "the joint should stick several times: {runs} runs"
    );
    let worst = check(&m, &sig, &[0.3], &["J", "b", "k", "Fc", "Td"], 1e-6);
    assert!(worst < TOLERANCE, "worst relative error {worst:.2e}");
}

/// The same with a Stribeck friction: the static level `Fs` decides
/// sticking and breakaway, the sliding level tends to `Fc`.
#[test]
fn stribeck_joint_sensitivities_through_stick_slip() {
    let m = joint("stribeck_friction(Fc, Fs, vs)");
    let sig = signals(1500, &[0.0], |t| vec![0.2 * (2.0 * PI * 0.7 * t).sin()]);
    let worst = check(&m, &sig, &[0.3], &["J", "k", "Fc", "Fs", "vs", "Td"], 1e-6);
    assert!(worst < TOLERANCE, "worst relative error {worst:.2e}");
}

/// The rotary pendulum with a gearbox friction that holds the arm while
/// the pendulum swings (and a small dry friction on the pendulum): the arm
/// sticks and breaks away under the pendulum's reaction, the pendulum
/// stops in the end.
#[test]
fn held_arm_and_swinging_pendulum_sensitivities() {
    let m = model(
        &(pendulum_text()
            .replace(
                "force alpha = viscous_friction(b2)",
                "force alpha = viscous_friction(b2) + coulomb_friction(Fc2)",
            )
            .replace(
                "parameter Fg1 = 0.01 [N*m]",
                "parameter Fc2 = 2e-4 [N*m] \"pendulum dry friction\" estimate [0, 0.01]\n\
                 parameter Fg1 = 0.02 [N*m]",
            )),
    );
    let sig = signals(2000, &[0.0, PI - 0.6], |t| {
        vec![if t < 0.3 { 0.4 } else { 0.0 }]
    });
    let sim = Simulator::new(&m, SimOptions::default()).expect("compiles");
    let q = sim
        .simulate(&sig, &full(&m, &base(&m)), sig.len())
        .expect("simulates")
        .q;
    assert!(held_runs(&q[0], 20) >= 2, "the arm should be held");
    let worst = check(
        &m,
        &sig,
        &[0.3, 0.5],
        &["J1", "b1", "l2", "b2", "Fg1", "Fc2"],
        1e-6,
    );
    assert!(worst < TOLERANCE, "worst relative error {worst:.2e}");
}

/// A joint held at the start (at rest under a torque below its level) has
/// no sensitivity to its initial velocity: a small initial speed either way
/// stops at once and sticks again (the position moves by O(speed^2)); the
/// stuck velocity's sensitivity row is zero, and so are the differences.
#[test]
fn a_held_start_has_no_initial_velocity_sensitivity() {
    let m = joint("coulomb_friction(Fc)");
    let sig = signals(500, &[0.0], |t| vec![if t < 0.5 { 0.05 } else { 0.15 }]);
    let sens = SensitivitySimulator::new(&m, &["Fc".to_string()], SimOptions::default())
        .expect("compiles");
    let sim = Simulator::new(&m, SimOptions::default()).expect("compiles");
    let p = full(&m, &base(&m));
    let start = BlockStart::from_data(&sig, plantc_identify::InitialVelocity::Zero, &[0.0]);
    let col = ExtraColumn {
        s0: vec![0.0, 1.0],
        direct: vec![0.0],
    };
    let st = sens
        .simulate_block(&sig, &p, &start, &[false], &[col])
        .expect("simulates");
    let h = 1e-6;
    let run = |d: f64| {
        let mut s = start.clone();
        s.x0[1] += d;
        sim.simulate_block(&sig, &p, &s).expect("simulates").q
    };
    let (yp, ym) = (run(h), run(-h));
    for k in 0..sig.len() {
        let fd = (yp[0][k] - ym[0][k]) / (2.0 * h);
        assert_eq!(st.dq[0][1][k], 0.0, "sample {k}");
        // O(h) from the O(speed^2) stop: 1e-6 / (2 x 3 rad/s^2) per 1e-6
        assert!(fd.abs() < 1e-5, "sample {k}: {fd}");
    }
}

/// The smooth law stays available and is what it was: `tanh(v / w)`, so a
/// joint under a torque below its level creeps.
#[test]
fn smooth_law_creeps_where_sticking_holds() {
    let m = joint("coulomb_friction(Fc)");
    // 0.05 N m against a static level of 0.08 N m (and the spring)
    let sig = signals(1500, &[0.0], |_| vec![0.05]);
    let p = full(&m, &base(&m));
    let sticking = Simulator::new(&m, SimOptions::default())
        .expect("compiles")
        .simulate(&sig, &p, sig.len())
        .expect("simulates");
    assert!(sticking.q[0].iter().all(|v| *v == 0.0), "held exactly");
    let smooth = Simulator::new(
        &m,
        SimOptions {
            dry_friction: DryFriction::Smooth { width: 1e-3 },
            ..SimOptions::default()
        },
    )
    .expect("compiles")
    .simulate(&sig, &p, sig.len())
    .expect("simulates");
    let crept = smooth.q[0].last().copied().unwrap();
    assert!(crept > 1e-4, "the smooth law creeps: {crept}");
}

/// The rotary pendulum's arm at rest under a motor torque below its
/// gearbox friction (0.5 V: 0.064 N m against 0.1 N m) stays at exactly its
/// position for 5 s.
#[test]
fn arm_below_its_static_friction_stays_put_for_seconds() {
    let m =
        model(&pendulum_text().replace("parameter Fg1 = 0.01 [N*m]", "parameter Fg1 = 0.1 [N*m]"));
    let sig = signals(2500, &[0.3, PI], |_| vec![0.5]);
    let q = Simulator::new(&m, SimOptions::default())
        .expect("compiles")
        .simulate(&sig, &full(&m, &base(&m)), sig.len())
        .expect("simulates")
        .q;
    assert!(q[0].iter().all(|v| *v == 0.3), "the arm crept");
    // 2 V (0.26 N m) moves it
    let sig = signals(250, &[0.3, PI], |_| vec![2.0]);
    let q = Simulator::new(&m, SimOptions::default())
        .expect("compiles")
        .simulate(&sig, &full(&m, &base(&m)), sig.len())
        .expect("simulates")
        .q;
    assert!(q[0][249] > 0.31, "{}", q[0][249]);
}

/// A pendulum with Coulomb friction swinging freely from 1 rad stops where
/// gravity is within the static level (`|m g l sin q| <= Fc`, i.e. `|q| <=
/// 0.034 rad` here) and stays exactly there; the smooth law instead creeps
/// on toward the bottom.
#[test]
fn free_swing_stops_and_stays_stopped() {
    let m = model(
        "model pendulum \"a pendulum with dry friction\"\n\
         coordinate q : angle\n\
         input tau [N*m]\n\
         parameter m = 0.5 [kg]\n\
         parameter l = 0.3 [m]\n\
         parameter g = 9.81 [m/s^2]\n\
         parameter Fc = 0.05 [N*m]\n\
         kinetic T = 1/2*m*l^2*q'^2\n\
         potential V = -m*g*l*cos(q)\n\
         force q = tau + coulomb_friction(Fc)\n",
    );
    let p = full(&m, &base(&m));
    let level = 0.05f64 / (0.5 * 9.81 * 0.3);
    let sig = signals(6000, &[1.0], |_| vec![0.0]);
    let q = Simulator::new(&m, SimOptions::default())
        .expect("compiles")
        .simulate(&sig, &p, sig.len())
        .expect("simulates")
        .q;
    // still from 10 s to 12 s, within the static band, not at the bottom
    let rest = q[0][5000];
    assert!(q[0][5000..].iter().all(|v| *v == rest), "it moved at rest");
    assert!(rest.abs() <= level.asin() && rest != 0.0, "rest at {rest}");
    let smooth = Simulator::new(
        &m,
        SimOptions {
            dry_friction: DryFriction::Smooth { width: 1e-3 },
            ..SimOptions::default()
        },
    )
    .expect("compiles")
    .simulate(&sig, &p, sig.len())
    .expect("simulates")
    .q;
    let drift = (smooth[0][5999] - smooth[0][5000]).abs();
    assert!(drift > 1e-5, "the smooth law creeps: {drift}");
    eprintln!("sticking rest at {rest:.5} rad; smooth law drifts {drift:.2e} rad in 2 s");
}

/// A Stribeck joint breaks away when the torque reaches the static level
/// `Fs` (a ramp of 0.1 N m/s against `Fs = 0.12`: at 1.2 s) and then slides
/// at the Coulomb level: held at 0.1 N m (below `Fs`, above `Fc = 0.08`) it
/// keeps accelerating at `(0.1 - 0.08) / J = 2 rad/s^2` once well above
/// the Stribeck speed.
#[test]
fn stribeck_joint_breaks_away_at_fs_and_slides_at_fc() {
    let m = joint("stribeck_friction(Fc, Fs, vs)");
    let mut b = base(&m);
    for (name, v) in [("k", 0.0), ("b", 0.0), ("Td", 0.0)] {
        let i = m.parameters.iter().position(|p| p.name == name).unwrap();
        b[i] = v;
    }
    let p = full(&m, &b);
    let sig = signals(2000, &[0.0], |t| vec![if t < 1.3 { 0.1 * t } else { 0.1 }]);
    let q = Simulator::new(&m, SimOptions::default())
        .expect("compiles")
        .simulate(&sig, &p, sig.len())
        .expect("simulates")
        .q;
    // the held sample u[k] = 0.1 t_k exceeds 0.12 from t = 1.202 s on
    let k_break = 601;
    assert!(
        q[0][..=k_break].iter().all(|v| *v == 0.0),
        "moved before Fs"
    );
    assert!(q[0][k_break + 2] > 0.0, "did not break away at Fs");
    // acceleration from the second difference over 2.5 .. 3.5 s
    let (k0, k1, k2) = (1250, 1500, 1750);
    let dt = 0.5;
    let acc = (q[0][k2] - 2.0 * q[0][k1] + q[0][k0]) / (dt * dt);
    assert!((acc - 2.0).abs() < 0.02, "sliding acceleration {acc}");
}

/// The DFKI double pendulum (models/double_pendulum.plant) near hanging,
/// where gravity is within both joints' dry friction (0.146 and 0.1225
/// N m), with small torques: both joints are held, exactly, for 3 s; a
/// shoulder torque above its level then moves both.
#[test]
fn double_pendulum_with_both_joints_held() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/double_pendulum.plant");
    let m = plantc_derive::model::load_model(&path)
        .expect("model")
        .model;
    let p = full(&m, &base(&m));
    let sim = Simulator::new(&m, SimOptions::default()).expect("compiles");
    assert_eq!(sim.sticking(), &[true, true]);
    let sig = signals(1500, &[0.03, 0.02], |_| vec![0.02, -0.01]);
    let q = sim.simulate(&sig, &p, sig.len()).expect("simulates").q;
    assert!(q[0].iter().all(|v| *v == 0.03) && q[1].iter().all(|v| *v == 0.02));
    let sig = signals(500, &[0.03, 0.02], |_| vec![0.5, 0.0]);
    let q = sim.simulate(&sig, &p, sig.len()).expect("simulates").q;
    assert!(
        q[0][499] > 0.05 && q[1][499] != 0.02,
        "{} {}",
        q[0][499],
        q[1][499]
    );
}

/// Sensitivities through the DFKI double pendulum's stick-slip: both
/// joints stop, stick (the coupled holding forces of two stuck joints),
/// break away under torque pulses and reverse.
#[test]
fn double_pendulum_sensitivities_through_stick_slip() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/double_pendulum.plant");
    let m = plantc_derive::model::load_model(&path)
        .expect("model")
        .model;
    let sig = signals(1500, &[0.02, -0.01], |t| {
        let phase = (t / 0.6).floor() as i64 % 4;
        let a = [0.25, 0.0, -0.25, 0.0][phase as usize];
        vec![a, -0.6 * a]
    });
    let sim = Simulator::new(&m, SimOptions::default()).expect("compiles");
    let q = sim
        .simulate(&sig, &full(&m, &base(&m)), sig.len())
        .expect("simulates")
        .q;
    assert!(held_runs(&q[0], 10) >= 2 && held_runs(&q[1], 10) >= 2);
    let worst = check(
        &m,
        &sig,
        &[0.3, -0.2],
        &["m2", "r2", "I1", "I2", "b1", "b2", "Fc1", "Fc2"],
        1e-6,
    );
    assert!(worst < TOLERANCE, "worst relative error {worst:.2e}");
}
