//! Issue 14 in `plantc-derive`: the energy swing-up written in the model
//! language (`energy(alpha)`, `sat`), the hybrid `swing_up` controller
//! (pump -> catch), sliding mode on a surface designed by its sliding poles,
//! and the sliding-dynamics analysis. Model: `models/rotary_pendulum.plant`,
//! its own values (gearbox dry friction Fg1 = 0.01 N m, simulated as
//! `tanh(v/1e-3)`) unless a test says otherwise.

use std::collections::HashMap;
use std::f64::consts::PI;
use std::path::Path;

use plantc_derive::analysis::sliding_analysis;
use plantc_derive::control::{resolve, Derivation, ResolvedController};
use plantc_derive::lang::ast::CmpOp;
use plantc_derive::linear::Pole;
use plantc_derive::mechanics::smooth_signs;
use plantc_derive::model::{
    load_model, load_model_text, ControllerSpec, Guard, Model, ParameterValues,
};
use plantc_derive::simulate::*;
use plantc_derive::sym::{Expr, Symbol};

fn model_text() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/rotary_pendulum.plant");
    std::fs::read_to_string(path).unwrap()
}

fn model() -> Model {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/rotary_pendulum.plant");
    load_model(&path).expect("model loads").model
}

/// Sampled (1 kHz, ZOH) or continuous simulation of a controller of `model`.
fn sim(
    model: &Model,
    set: Option<&str>,
    controller: &str,
    gains: &[(String, f64)],
    x0: [f64; 4],
    duration: f64,
    sample_rate: Option<f64>,
) -> Trajectory {
    let values = ParameterValues::new(model, set, &[]).unwrap();
    let derivation = Derivation::new(model).unwrap();
    let mut ctrl = resolve(model, &derivation, controller, &values).unwrap();
    set_gains(&mut ctrl, gains).unwrap();
    let control = Control::Feedback(ControllerEval::new(model, &ctrl).unwrap());
    let eqs = smooth_signs(&derivation.equations, 1e-3);
    let problem = SimProblem::new(model, &eqs, &values, control, x0.to_vec(), duration).unwrap();
    let options = SimOptions {
        sample_rate,
        ..SimOptions::default()
    };
    simulate(&problem, &options).unwrap()
}

#[test]
fn energy_is_the_pendulum_energy_zero_upright() {
    // Independent formula (shared/reference/rotary-pendulum.md: T with the
    // arm still, V = m2 g l2 cos(alpha)): E = J2h alpha'^2 / 2 + m2 g l2 (cos alpha - 1).
    let model = model();
    let ControllerSpec::Direct { laws, .. } = model.controller("energy_pump").unwrap() else {
        panic!("energy_pump is a direct law")
    };
    assert_eq!(laws.len(), 1);
    let text = model_text().replace(
        "Vm = Vmax*sat((kE*(E0 - energy(alpha))*sign(alpha'*cos(alpha)) - k_theta*theta)/Vmax)",
        "Vm = energy(alpha)",
    );
    let m = load_model_text("energy.plant", &text).unwrap().model;
    let ControllerSpec::Direct { laws, .. } = m.controller("energy_pump").unwrap() else {
        panic!()
    };
    let values = ParameterValues::new(&m, None, &[]).unwrap();
    let p = |n: &str| values.get(&m, n).unwrap();
    let (j2h, m2, g, l2) = (p("J2h"), p("m2"), p("g"), p("l2"));
    let mut env: HashMap<Symbol, f64> = values.symbol_map(&m);
    let mut s = 1u64;
    let mut r = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    for _ in 0..200 {
        let x = [3.0 * r(), 7.0 * r(), 20.0 * r(), 20.0 * r()];
        for (sym, v) in m.state_symbols().iter().zip(x) {
            env.insert(*sym, v);
        }
        let want = 0.5 * j2h * x[3] * x[3] + m2 * g * l2 * (x[1].cos() - 1.0);
        let got = laws[0].eval_map(&env);
        assert!(
            (got - want).abs() <= 1e-12 * want.abs().max(1.0),
            "{got} vs {want}"
        );
    }
    // hanging at rest: -2 m2 g l2 = -0.3887 J with the Table 3 values
    for (sym, v) in m.state_symbols().iter().zip([0.3, PI, 0.0, 0.0]) {
        env.insert(*sym, v);
    }
    let hanging = laws[0].eval_map(&env);
    assert!((hanging + 2.0 * m2 * g * l2).abs() < 1e-12);
    assert!((hanging + 0.388_7).abs() < 1e-4, "{hanging}");
}

#[test]
fn sat_is_the_clamp_to_plus_minus_one() {
    let text = model_text().replace(
        "Vm = Vmax*sat((kE*(E0 - energy(alpha))*sign(alpha'*cos(alpha)) - k_theta*theta)/Vmax)",
        "Vm = sat(theta)",
    );
    let m = load_model_text("sat.plant", &text).unwrap().model;
    let ControllerSpec::Direct { laws, .. } = m.controller("energy_pump").unwrap() else {
        panic!()
    };
    let theta = Symbol::new("theta");
    for k in -3000..=3000 {
        let x = k as f64 * 1e-3;
        let got = laws[0].eval_map(&[(theta, x)].into());
        assert!(
            (got - x.clamp(-1.0, 1.0)).abs() <= 2e-16,
            "sat({x}) = {got}"
        );
    }
}

#[test]
fn switch_conditions_parse_with_and_binding_tighter_than_or() {
    let text = model_text().replace(
        "switch pump -> catch when abs(alpha) < 15 [deg]",
        "switch pump -> catch when theta > 1 or alpha' <= 2 [1/s] and alpha >= 3",
    );
    let m = load_model_text("guard.plant", &text).unwrap().model;
    let ControllerSpec::Hybrid {
        switches,
        modes,
        wrap,
        ..
    } = m.controller("swing_up").unwrap()
    else {
        panic!()
    };
    assert_eq!(modes.len(), 2);
    assert!(modes[0].swing_up && !modes[1].swing_up);
    assert_eq!(wrap, &vec![1]);
    let Guard::Or(a, b) = &switches[0].when else {
        panic!("{:?}", switches[0].when)
    };
    assert!(matches!(**a, Guard::Cmp { op: CmpOp::Gt, .. }));
    assert!(matches!(**b, Guard::And(..)));
    let ops: Vec<CmpOp> = switches[0].when.margins().iter().map(|m| m.0).collect();
    assert_eq!(ops, [CmpOp::Gt, CmpOp::Le, CmpOp::Ge]);
    // margins: theta - 1, alpha' - 2, alpha - 3
    let holds = |m: [f64; 3]| switches[0].when.holds(&m, &mut 0);
    assert!(holds([0.5, -1.0, -1.0]) && !holds([-0.5, -1.0, -1.0]));
    assert!(holds([-0.5, 0.0, 0.0]) && !holds([-0.5, 0.1, 0.0]));
    assert!(!holds([f64::NAN, f64::NAN, f64::NAN]));
    // the file's own condition: 15 deg in rad
    let m = model();
    let ControllerSpec::Hybrid { switches, .. } = m.controller("swing_up").unwrap() else {
        panic!()
    };
    let (_, margin) = &switches[0].when.margins()[0];
    let v = margin.eval_map(&[(Symbol::new("alpha"), 0.0)].into());
    assert!((v + 15f64.to_radians()).abs() < 1e-15, "{v}");
}

fn wrapped_alpha(traj: &Trajectory, k: usize) -> f64 {
    wrap_angle(traj.states[k][1])
}

/// The acceptance of issue 14 on the simulator of `plantc-derive`: from
/// alpha0 = pi - 0.05 with kE = 200, k_theta = 2, 10 V (the model's gains):
/// caught within 0.6 s with the arm within 100 deg, at 15 s |alpha| < 0.01
/// rad and |theta| < 3 deg.
fn check_swing_up(traj: &Trajectory, what: &str) {
    assert_eq!(traj.mode_names, ["pump", "catch"]);
    let (t_catch, from, to) = traj.switches[0];
    assert_eq!((from, to), (0, 1), "{what}: first switch pump -> catch");
    let k_catch = traj.index_at(t_catch);
    let arm: f64 = traj.states[..=k_catch]
        .iter()
        .fold(0.0, |m, x| m.max(x[0].abs()));
    let last = traj.len() - 1;
    let (alpha, theta) = (wrapped_alpha(traj, last), traj.states[last][0]);
    eprintln!(
        "{what}: caught at {t_catch:.3} s with the arm within {:.1} deg; at {} s alpha = {alpha:.2e} rad, theta = {:.3} deg; {} switch(es)",
        arm.to_degrees(),
        traj.t[last],
        theta.to_degrees(),
        traj.switches.len()
    );
    assert!(t_catch <= 0.6, "{what}: caught at {t_catch} s");
    assert!(
        arm.to_degrees() <= 100.0,
        "{what}: arm {} deg",
        arm.to_degrees()
    );
    assert_eq!(traj.switches.len(), 1, "{what}: stays caught");
    assert!(alpha.abs() < 0.01, "{what}: alpha {alpha}");
    assert!(
        theta.to_degrees().abs() < 3.0,
        "{what}: theta {}",
        theta.to_degrees()
    );
    assert_eq!(traj.modes[last], 1);
}

#[test]
fn swing_up_catches_from_hanging_continuous_and_sampled() {
    let m = model();
    let x0 = [0.0, PI - 0.05, 0.0, 0.0];
    let t = sim(&m, None, "swing_up", &[], x0, 15.0, None);
    check_swing_up(&t, "continuous");
    let t = sim(&m, None, "swing_up", &[], x0, 15.0, Some(1000.0));
    check_swing_up(&t, "sampled at 1 kHz");
}

#[test]
fn swing_up_at_5_volts_never_catches() {
    // the quick study: at 5-6 V the pump does not bring the pendulum up
    let m = model();
    let x0 = [0.0, PI - 0.05, 0.0, 0.0];
    for v in [5.0, 6.0] {
        let t = sim(
            &m,
            None,
            "swing_up",
            &[("Vmax".into(), v)],
            x0,
            8.0,
            Some(1000.0),
        );
        let vmax = t.inputs.iter().fold(0.0f64, |a, u| a.max(u[0].abs()));
        assert!(vmax <= v + 1e-12, "the law saturates at {v} V: {vmax}");
        assert!(t.switches.is_empty(), "{v} V: {:?}", t.switches);
    }
}

#[test]
fn swing_up_returns_to_the_pump_when_the_catch_fails() {
    // Inside the catch window but turning at 8 rad/s: pole placement cannot
    // hold it, the pendulum leaves 25 deg, the pump takes over and catches
    // again (at 1.48 s). Not every such start recovers: from alpha' = 4..7
    // rad/s the pump ends in a swing whose energy(alpha) (the pendulum's
    // energy with the arm still) is at E0 while the moving arm keeps it from
    // the top, and it does not catch within 15 s.
    let m = model();
    let t = sim(
        &m,
        None,
        "swing_up",
        &[],
        [0.0, 0.2, 0.0, 8.0],
        15.0,
        Some(1000.0),
    );
    let names: Vec<(&str, &str)> = t
        .switches
        .iter()
        .map(|(_, a, b)| (t.mode_names[*a].as_str(), t.mode_names[*b].as_str()))
        .collect();
    eprintln!("switches: {:?}", t.switches);
    assert_eq!(
        names,
        [("pump", "catch"), ("catch", "pump"), ("pump", "catch")],
        "caught at once (inside 15 deg), lost, caught again"
    );
    let last = t.len() - 1;
    assert!(wrapped_alpha(&t, last).abs() < 0.01);
}

#[test]
fn sliding_mode_balances_from_10_degrees_for_30_s() {
    let m = model();
    let x0 = [0.0, 10f64.to_radians(), 0.0, 0.0];
    let t = sim(&m, None, "sliding_mode", &[], x0, 30.0, Some(1000.0));
    let from = t.index_at(25.0);
    let tail = t.states[from..]
        .iter()
        .fold(0.0f64, |a, x| a.max(wrap_angle(x[1]).abs()));
    let arm = t.states.iter().fold(0.0f64, |a, x| a.max(x[0].abs()));
    eprintln!(
        "sliding mode: max |alpha| over the last 5 s {:.4} deg, max |theta| {:.1} deg",
        tail.to_degrees(),
        arm.to_degrees()
    );
    assert!(tail.to_degrees() < 0.5, "{}", tail.to_degrees());
    assert!(arm.to_degrees() < 90.0, "{}", arm.to_degrees());
}

#[test]
fn sliding_surface_from_poles_has_those_sliding_poles() {
    let m = model();
    let values = ParameterValues::new(&m, None, &[]).unwrap();
    let d = Derivation::new(&m).unwrap();
    let rc = resolve(&m, &d, "sliding_mode", &values).unwrap();
    let a = sliding_analysis(&m, &d, &rc, &values).unwrap();
    // Ackermann-Utkin: c B = 1, and the reduced dynamics (formed independently
    // by eliminating a state from x' = (I - B c) A x) have the designed poles
    assert!((a.reduced.cb - 1.0).abs() < 1e-9, "{}", a.reduced.cb);
    let want = [
        Pole::new(-3.0, 2.0),
        Pole::new(-3.0, -2.0),
        Pole::new(-6.0, 0.0),
    ];
    let err = plantc_derive::linear::pole_match_error(&want, &a.reduced.poles);
    assert!(err < 1e-9, "{:?}", a.reduced.poles);
    assert!(a.reduced.asymptotically_stable());
    // the law is the equivalent control plus v / L_g s
    let ResolvedController::SlidingMode { law, chain, .. } = &rc else {
        panic!()
    };
    assert_eq!(chain.relative_degree, 1);
    let mut env = values.symbol_map(&m);
    env.insert(Symbol::new("k"), 2.0);
    env.insert(Symbol::new("phi"), 0.05);
    for (s, v) in m.state_symbols().iter().zip([0.1, 0.05, -0.2, 0.3]) {
        env.insert(*s, v);
    }
    let s_val = a.surface.eval_map(&env);
    let v = -2.0 * (s_val / 0.05).clamp(-1.0, 1.0);
    let want = a.equivalent_control.eval_map(&env) + v / chain.lg[0].eval_map(&env);
    let got = law.eval_map(&env);
    assert!(
        (got - want).abs() < 1e-9 * want.abs().max(1.0),
        "{got} vs {want}"
    );
}

#[test]
fn a_pendulum_only_surface_leaves_the_arm_unstabilised() {
    // Khanesar et al. add an arm surface because the pendulum alone does not
    // determine the arm: with s = alpha' + 5 alpha the sliding dynamics keep
    // the arm's double integrator (two poles at 0): not asymptotically stable.
    // With both surfaces combined (s = s_alpha + 0.1 s_theta) they are.
    let text = model_text().replace(
        "surface s poles [-3+2i, -3-2i, -6]",
        "surface s = alpha' + 5*alpha",
    );
    let m = load_model_text("pend.plant", &text).unwrap().model;
    let values = ParameterValues::new(&m, None, &[]).unwrap();
    let d = Derivation::new(&m).unwrap();
    let rc = resolve(&m, &d, "sliding_mode", &values).unwrap();
    let a = sliding_analysis(&m, &d, &rc, &values).unwrap();
    eprintln!("pendulum only: {:?}", a.reduced.poles);
    assert!(!a.reduced.asymptotically_stable());
    let zeros = a.reduced.poles.iter().filter(|p| p.abs() < 1e-6).count();
    assert_eq!(zeros, 2, "{:?}", a.reduced.poles);
    let text = model_text().replace(
        "surface s poles [-3+2i, -3-2i, -6]",
        "surface s = alpha' + 8*alpha - 0.1*(theta' + 2*theta)",
    );
    let m = load_model_text("both.plant", &text).unwrap().model;
    let rc = resolve(&m, &d, "sliding_mode", &values).unwrap();
    let a = sliding_analysis(&m, &d, &rc, &values).unwrap();
    eprintln!("both surfaces: {:?}", a.reduced.poles);
    assert!(a.reduced.asymptotically_stable(), "{:?}", a.reduced.poles);
    assert_eq!(a.c, vec![-0.2, 8.0, -0.1, 1.0]);
}

#[test]
fn a_surface_without_velocities_or_nonlinear_is_refused() {
    for (surface, why) in [
        ("surface s = alpha + theta", "relative degree"),
        ("surface s = alpha'*alpha", "linear in the state"),
    ] {
        let text = model_text().replace("surface s poles [-3+2i, -3-2i, -6]", surface);
        let m = load_model_text("bad.plant", &text).unwrap().model;
        let values = ParameterValues::new(&m, None, &[]).unwrap();
        let d = Derivation::new(&m).unwrap();
        let e = resolve(&m, &d, "sliding_mode", &values).unwrap_err();
        assert!(e.to_string().contains(why), "{surface}: {e}");
    }
    let _ = Expr::zero();
}

/// The names of the hybrid and sliding-mode syntax are in `lang::visit`, so
/// editors' rename (and references, hover) follow them: renaming a
/// controller used as a mode, a coordinate in switch conditions and `wrap`,
/// a mode, or a surface gives a file that still checks and means the same.
#[test]
fn rename_follows_modes_switches_wraps_and_surfaces() {
    use plantc_derive::lang::edit::rename;
    use plantc_derive::lang::visit::{occurrences, Role, SymbolRef};
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/rotary_pendulum.plant");
    let src = std::fs::read_to_string(path).unwrap();
    let (file, _) = plantc_derive::lang::parser::parse(&src);
    let index = |name: &str| {
        file.controllers
            .iter()
            .position(|c| c.name.name == name)
            .unwrap()
    };
    let loads = |text: &str, what: &str| {
        let m = load_model_text("renamed.plant", text)
            .unwrap_or_else(|e| panic!("{what}: {e:?}"))
            .model;
        let d = Derivation::new(&m).unwrap();
        let v = ParameterValues::new(&m, Some("thesis"), &[]).unwrap();
        for c in ["swing_up", "sliding_mode"] {
            resolve(&m, &d, c, &v).unwrap_or_else(|e| panic!("{what}: {c}: {e}"));
        }
    };
    let out = rename(&src, &SymbolRef::Block("pole_placement".into()), "pp").unwrap();
    assert!(out.contains("mode catch = pp\n"), "{out}");
    loads(&out, "controller");
    let out = rename(&src, &SymbolRef::Model("alpha".into()), "phi_p").unwrap();
    assert!(out.contains("wrap phi_p\n"));
    assert!(out.contains("switch pump -> catch when abs(phi_p) < 15 [deg]"));
    loads(&out, "coordinate");
    let su = index("swing_up");
    let out = rename(&src, &SymbolRef::Mode(su, "catch".into()), "balance").unwrap();
    assert!(out.contains("mode balance = pole_placement"));
    assert!(out.contains("switch pump -> balance when") && out.contains("switch balance -> pump"));
    loads(&out, "mode");
    let smc = index("sliding_mode");
    let out = rename(&src, &SymbolRef::Surface(smc, "s".into()), "sigma").unwrap();
    assert!(out.contains("surface sigma poles") && out.contains("v = -k*sat(sigma/phi)"));
    loads(&out, "surface");
    // a direct law's left-hand side is a use of the input
    let occ = occurrences(&file);
    let vm_uses = occ
        .iter()
        .filter(|o| o.symbol == SymbolRef::Model("Vm".into()) && o.role == Role::Reference)
        .count();
    assert!(vm_uses >= 1);
}
