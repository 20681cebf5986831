//! Acceptance tests of `plantc_derive::simulate` and the numeric dynamics on
//! the rotary pendulum (`models/rotary_pendulum.plant`, set `thesis`: Table 3
//! values, Fg1 = 0), against `/work/shared/reference/rotary-pendulum.md`
//! ("Feedback linearization", "Arm-feedback controller").

use std::collections::HashMap;
use std::path::Path;

use plantc_derive::control::{resolve, Derivation};
use plantc_derive::mechanics::NumericDynamics;
use plantc_derive::model::{load_model, Model, ParameterValues};
use plantc_derive::simulate::*;

fn model() -> Model {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/rotary_pendulum.plant");
    load_model(&path).expect("model loads").model
}

fn run(
    model: &Model,
    set: Option<&str>,
    controller: &str,
    gains: &[(String, f64)],
    alpha0_deg: f64,
    duration: f64,
    options: &SimOptions,
) -> Result<Trajectory, SimError> {
    let values = ParameterValues::new(model, set, &[]).unwrap();
    let derivation = Derivation::new(model).unwrap();
    let mut ctrl = resolve(model, &derivation, controller, &values).unwrap();
    set_gains(&mut ctrl, gains)?;
    let control = Control::Feedback(ControllerEval::new(model, &ctrl)?);
    let x0 = vec![0.0, alpha0_deg.to_radians(), 0.0, 0.0];
    let problem = SimProblem::new(model, &derivation.equations, &values, control, x0, duration)?;
    simulate(&problem, options)
}

/// Small deterministic generator in [-1, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
}

#[test]
fn numeric_dynamics_match_control_affine_form() {
    let model = model();
    let derivation = Derivation::new(&model).unwrap();
    let dynamics = NumericDynamics::new(&model, &derivation.equations).unwrap();
    let mut ws = dynamics.workspace();
    let states = model.state_symbols();
    let inputs = model.input_symbols();
    let mut rng = Lcg(7);
    let mut worst: f64 = 0.0;
    for set in [None, Some("thesis"), Some("quanser_manual")] {
        let values = ParameterValues::new(&model, set, &[]).unwrap();
        for _ in 0..50 {
            let x: Vec<f64> = (0..4)
                .map(|i| rng.next() * if i < 2 { 3.2 } else { 20.0 })
                .collect();
            let u = [rng.next() * 10.0];
            let mut dx = vec![0.0; 4];
            dynamics
                .derivatives(&x, &u, &values.full, &mut dx, &mut ws)
                .unwrap();
            let mut map: HashMap<_, f64> = values.symbol_map(&model);
            map.extend(states.iter().copied().zip(x.iter().copied()));
            map.extend(inputs.iter().copied().zip(u.iter().copied()));
            for (i, got) in dx.iter().enumerate() {
                let ca = derivation.affine().expect("control-affine form");
                let want = ca.f[i].eval_map(&map) + ca.g[i][0].eval_map(&map) * u[0];
                let err = (got - want).abs() / want.abs().max(1e-6);
                worst = worst.max(err);
                assert!(
                    err < 1e-10,
                    "component {i} at {x:?}: {got} vs {want} ({err:e})"
                );
            }
        }
    }
    eprintln!("numeric dynamics vs f + g u: worst relative error {worst:e}");
}

#[test]
fn feedback_linearization_acceptance() {
    let model = model();
    let started = std::time::Instant::now();
    let traj = run(
        &model,
        Some("thesis"),
        "feedback_linearization",
        &[],
        10.0,
        5.0,
        &SimOptions::default(),
    )
    .unwrap();
    let elapsed = started.elapsed();
    let alpha = traj.state("alpha").unwrap();
    let theta_dot = traj.state("theta_dot").unwrap();
    let vm = traj.input("Vm").unwrap();
    let i726 = traj.index_at(0.726);
    assert!((traj.t[i726] - 0.726).abs() < 1e-12);
    // Exact closed-loop output: y'' = -16 y - 5.6 y', y(0) = 10 deg, y'(0) = 0.
    let (a0, wd) = (10f64.to_radians(), (16.0f64 - 2.8 * 2.8).sqrt());
    let mut worst: f64 = 0.0;
    for (k, t) in traj.t.iter().enumerate() {
        let y = (-2.8 * t).exp() * a0 * ((wd * t).cos() + 2.8 / wd * (wd * t).sin());
        worst = worst.max((alpha[k] - y).abs());
    }
    let max_after = alpha[i726..].iter().fold(0.0f64, |m, a| m.max(a.abs()));
    let i4 = traj.index_at(4.0);
    let (lo, hi) = theta_dot[i4..]
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(*v), h.max(*v))
        });
    let values = ParameterValues::new(&model, Some("thesis"), &[]).unwrap();
    let p = |n: &str| values.get(&model, n).unwrap();
    let gain =
        p("Kg") * p("km") + p("b1") * p("Rm") / (p("eta_g") * p("Kg") * p("eta_m") * p("kt"));
    let last = traj.len() - 1;
    let rel = (vm[last] - gain * theta_dot[last]).abs() / vm[last].abs();
    eprintln!(
        "FL: alpha(0.726) = {:.4} deg, max |alpha| after = {:.4} deg, |alpha - exact| <= {worst:.2e} rad, \
         theta_dot(5) = {:.5} rad/s (spread {:.2e} over [4,5]), Vm(5) = {:.4} V, relation error {:.2e}, \
         max |Vm| = {:.3} V, {} steps ({} rejected, {} rhs), {elapsed:?}",
        alpha[i726].to_degrees(),
        max_after.to_degrees(),
        theta_dot[last],
        hi - lo,
        vm[last],
        rel,
        vm.iter().fold(0.0f64, |m, v| m.max(v.abs())),
        traj.stats.accepted,
        traj.stats.rejected,
        traj.stats.evaluations,
    );
    assert!(
        max_after.to_degrees() <= 0.5,
        "max |alpha| after 0.726 s = {} deg",
        max_after.to_degrees()
    );
    assert!(
        worst < 1e-6,
        "alpha deviates from the exact closed-loop output by {worst:e} rad"
    );
    assert!(
        (theta_dot[last] + 3.1).abs() < 0.15,
        "steady rate {}",
        theta_dot[last]
    );
    assert!(
        hi - lo < 1e-3,
        "theta_dot not constant over the last second: spread {}",
        hi - lo
    );
    assert!(rel < 0.01, "Vm relation error {rel}");
    assert!(!traj.saturated.iter().any(|s| *s));
}

#[test]
fn feedback_linearization_sampled_at_1khz() {
    let model = model();
    let options = SimOptions {
        sample_rate: Some(1000.0),
        ..SimOptions::default()
    };
    let traj = run(
        &model,
        Some("thesis"),
        "feedback_linearization",
        &[],
        10.0,
        1.0,
        &options,
    )
    .unwrap();
    let alpha = traj.state("alpha").unwrap();
    let a = alpha[traj.index_at(0.726)].to_degrees();
    eprintln!("ZOH 1 kHz: alpha(0.726) = {a:.4} deg");
    assert!(
        (a - 0.59).abs() < 0.02,
        "alpha(0.726) = {a} deg with the law held at 1 kHz"
    );
}

#[test]
fn arm_feedback_inside_and_outside_the_stable_interval() {
    let model = model();
    let gains = |v: f64| vec![("a".to_string(), v), ("b".to_string(), v)];
    let opts = SimOptions {
        output_rate: 100.0,
        ..SimOptions::default()
    };
    let good = run(
        &model,
        Some("thesis"),
        "fl_arm",
        &gains(0.5),
        10.0,
        30.0,
        &opts,
    )
    .unwrap();
    let last = good.states.last().unwrap();
    eprintln!("fl_arm a = b = 0.5: final state {last:?}");
    assert!(
        last.iter().all(|v| v.abs() < 1e-2),
        "a = b = 0.5 should converge: {last:?}"
    );
    match run(
        &model,
        Some("thesis"),
        "fl_arm",
        &gains(1.5),
        10.0,
        30.0,
        &opts,
    ) {
        Err(e) => eprintln!("fl_arm a = b = 1.5: {e}"),
        Ok(bad) => {
            let worst = bad.states.iter().fold(0.0f64, |m, x| {
                m.max(x[0].abs()).max(x[2].abs()).max(x[1].abs() * 100.0)
            });
            eprintln!(
                "fl_arm a = b = 1.5: final state {:?}",
                bad.states.last().unwrap()
            );
            assert!(worst > 100.0, "a = b = 1.5 should diverge or fall");
        }
    }
    let err = run(
        &model,
        Some("thesis"),
        "fl_arm",
        &[("c".into(), 1.0)],
        10.0,
        1.0,
        &opts,
    )
    .unwrap_err();
    assert!(err.to_string().contains("known: wn, zeta, a, b"), "{err}");
}

#[test]
fn pole_placement_balances_from_5_degrees() {
    let model = model();
    let traj = run(
        &model,
        Some("thesis"),
        "pole_placement",
        &[],
        5.0,
        5.0,
        &SimOptions::default(),
    )
    .unwrap();
    let last = traj.states.last().unwrap();
    let vm = traj.input("Vm").unwrap();
    eprintln!(
        "pole placement: final {last:?}, max |Vm| = {:.3}, saturated {:.1} %",
        vm.iter().fold(0.0f64, |m, v| m.max(v.abs())),
        100.0 * traj.saturation_share()
    );
    assert!(last.iter().all(|v| v.abs() < 1e-2), "{last:?}");
}

#[test]
fn open_loop_zero_order_hold_input() {
    // Sample k acts over [t_k, t_k+1): a 1 V step from 0.5 s equals a constant
    // 1 V simulation started from the state reached at 0.5 s with 0 V.
    let model = model();
    let values = ParameterValues::new(&model, Some("thesis"), &[]).unwrap();
    let derivation = Derivation::new(&model).unwrap();
    let sim = |control: Control, x0: Vec<f64>, d: f64| {
        let p = SimProblem::new(&model, &derivation.equations, &values, control, x0, d).unwrap();
        simulate(&p, &SimOptions::default()).unwrap()
    };
    let x0 = vec![0.0, 3.0, 0.0, 0.0];
    let step = InputSignal::ZeroOrderHold {
        t: vec![0.0, 0.5],
        u: vec![vec![0.0], vec![1.0]],
    };
    let a = sim(Control::OpenLoop(step), x0.clone(), 1.0);
    let b = sim(Control::OpenLoop(InputSignal::Constant(vec![0.0])), x0, 0.5);
    let c = sim(
        Control::OpenLoop(InputSignal::Constant(vec![1.0])),
        b.states.last().unwrap().clone(),
        0.5,
    );
    assert_eq!(a.inputs[499][0], 0.0);
    assert_eq!(a.inputs[500][0], 1.0);
    for (xa, xc) in a
        .states
        .last()
        .unwrap()
        .iter()
        .zip(c.states.last().unwrap())
    {
        assert!((xa - xc).abs() < 1e-7, "{xa} vs {xc}");
    }
    // Outputs evaluate the model's `output alpha`.
    assert_eq!(a.outputs[300][0], a.states[300][1]);
}

#[test]
fn non_finite_control_is_an_error_with_its_time() {
    // A law that becomes NaN once the falling pendulum passes alpha = 0.3 rad.
    let model = model();
    let values = ParameterValues::new(&model, Some("thesis"), &[]).unwrap();
    let derivation = Derivation::new(&model).unwrap();
    let mut ctrl = resolve(&model, &derivation, "feedback_linearization", &values).unwrap();
    let alpha = plantc_derive::sym::Expr::symbol(model.coordinates[1].symbols.q);
    if let plantc_derive::control::ResolvedController::FeedbackLinearization { law, .. } = &mut ctrl
    {
        *law = (plantc_derive::sym::Expr::frac(3, 10) - alpha).sqrt();
    }
    let control = Control::Feedback(ControllerEval::new(&model, &ctrl).unwrap());
    let x0 = vec![0.0, 10f64.to_radians(), 0.0, 0.0];
    let problem =
        SimProblem::new(&model, &derivation.equations, &values, control, x0, 5.0).unwrap();
    let err = simulate(&problem, &SimOptions::default()).unwrap_err();
    match &err {
        SimError::NonFiniteControl { t, input } => {
            assert_eq!(input, "Vm");
            assert!(*t > 0.05 && *t < 5.0, "{err}");
        }
        other => panic!("expected a non-finite control error, got {other:?}"),
    }
    assert!(err.to_string().contains("non-finite `Vm` at t = "), "{err}");
}

#[test]
fn inputs_are_clipped_to_the_model_limits() {
    let model = model();
    for options in [
        SimOptions::default(),
        SimOptions {
            sample_rate: Some(500.0),
            ..SimOptions::default()
        },
    ] {
        let traj = run(
            &model,
            Some("thesis"),
            "pole_placement",
            &[],
            15.0,
            3.0,
            &options,
        )
        .unwrap();
        let vm = traj.input("Vm").unwrap();
        let max = vm.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        eprintln!(
            "pole placement from 15 deg ({:?} Hz): max |Vm| = {max}, saturated {:.1} %, final {:?}",
            options.sample_rate,
            100.0 * traj.saturation_share(),
            traj.states.last().unwrap()
        );
        assert!(max <= 10.0 && max > 9.999, "max |Vm| = {max}");
        assert!(traj.saturation_share() > 0.0);
        let unclipped = SimOptions {
            saturate: false,
            ..options
        };
        let free = run(
            &model,
            Some("thesis"),
            "pole_placement",
            &[],
            15.0,
            3.0,
            &unclipped,
        )
        .unwrap();
        let free_max = free
            .input("Vm")
            .unwrap()
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(free_max > 10.0, "{free_max}");
        assert_eq!(free.saturation_share(), 0.0);
    }
}

/// Dry friction sticks in `simulate` (events located in Dormand-Prince's
/// dense output): on a free swing from 2.5 rad at 0 V the gearbox friction
/// (nominal `Fg1 = 0.01 N m`) holds the arm at exactly one angle over long
/// stretches while the pendulum swings; the smooth law (still available)
/// lets it creep instead.
#[test]
fn dry_friction_sticks_and_holds_the_arm() {
    let model = model();
    let values = ParameterValues::new(&model, None, &[]).unwrap();
    let derivation = Derivation::new(&model).unwrap();
    let zero = || Control::OpenLoop(InputSignal::Constant(vec![0.0]));
    let x0 = vec![0.0, 2.5, 0.0, 0.0];
    let options = SimOptions {
        max_steps: 20_000,
        ..SimOptions::default()
    };
    let exact = SimProblem::new(
        &model,
        &derivation.equations,
        &values,
        zero(),
        x0.clone(),
        10.0,
    )
    .unwrap();
    let started = std::time::Instant::now();
    let traj = simulate(&exact, &options).unwrap();
    let theta = traj.state("theta").unwrap();
    let theta_dot = traj.state("theta_dot").unwrap();
    let max_theta = theta.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // samples (1 kHz) at which the arm is held: velocity exactly zero and
    // the angle the same bits as the sample before
    let held = (1..theta.len())
        .filter(|&k| theta_dot[k] == 0.0 && theta[k].to_bits() == theta[k - 1].to_bits())
        .count();
    eprintln!(
        "free swing with sticking friction: max |theta| = {max_theta:.4} rad, held at {held} of {} samples, {:?}, {:?}",
        theta.len(),
        traj.stats,
        started.elapsed()
    );
    assert!(max_theta < 0.2, "{max_theta}");
    assert!(held > theta.len() / 4, "{held}");
    let smooth = plantc_derive::mechanics::smooth_signs(&derivation.equations, 1e-3);
    assert!(!plantc_derive::mechanics::has_sign(&smooth));
    let problem = SimProblem::new(&model, &smooth, &values, zero(), x0, 10.0).unwrap();
    let traj = simulate(&problem, &options).unwrap();
    let theta_dot = traj.state("theta_dot").unwrap();
    assert!(
        theta_dot.iter().skip(1).all(|v| *v != 0.0),
        "the smooth law never holds the arm exactly"
    );
}
