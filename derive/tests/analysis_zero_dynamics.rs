//! Acceptance tests of the normal form and zero dynamics against the rotary
//! pendulum thesis (Ch. VI, as restated in the reference notes "Zero dynamics"),
//! the cart-pole and the pendubot.

use std::path::Path;

use plantc_derive::analysis::{normal_form, zero_dynamics, ZeroDynamicsClass};
use plantc_derive::control::{output_expr, Derivation};
use plantc_derive::model::{load_model, LoadedModel, ParameterValues};
use plantc_derive::sym::{is_zero, Expr};

fn load(name: &str) -> LoadedModel {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../models")
        .join(name);
    load_model(&path).unwrap_or_else(|e| panic!("{name}: {}", e.render()))
}

struct Analysed {
    xi: Vec<Expr>,
    eta: Vec<Expr>,
    zd: plantc_derive::analysis::ZeroDynamics,
    relative_degree: usize,
    lg: Vec<Expr>,
}

fn analyse(file: &str, output: &str, set: Option<&str>) -> Analysed {
    let loaded = load(file);
    let model = &loaded.model;
    let values = ParameterValues::new(model, set, &[]).expect("values");
    let d = Derivation::new(model).expect("derivation");
    let h = output_expr(model, output).expect("output");
    let chain = d.lie_chain(model, h).expect("chain");
    let nf = normal_form(model, &d, &chain, &values, None).expect("normal form");
    let zd = zero_dynamics(model, &nf, &values).expect("zero dynamics");
    Analysed {
        xi: nf.xi,
        eta: nf.eta,
        zd,
        relative_degree: chain.relative_degree,
        lg: chain.lg,
    }
}

fn s(name: &str) -> Expr {
    Expr::sym(name)
}

/// True if `e = k * reference` for a nonzero constant `k` (checked with
/// `is_zero(e * k - reference)` for `k` found from the ratio).
fn proportional(e: Expr, reference: Expr) -> bool {
    let ratio = plantc_derive::sym::simplify(reference / e);
    let constant = ratio.symbols().iter().all(|v| {
        !v.name().contains('\'') && !["theta", "alpha", "x", "th", "q1", "q2"].contains(&v.name())
    });
    constant && !is_zero(ratio) && is_zero(e * ratio - reference)
}

#[test]
fn rotary_pendulum_normal_form_and_double_integrator() {
    let a = analyse("rotary_pendulum.plant", "alpha", Some("thesis"));
    assert_eq!(a.relative_degree, 2);
    // L_g h is recognised as exactly zero.
    assert!(a.lg[0].is_zero());
    assert_eq!(a.xi, vec![s("alpha"), s("alpha'")]);
    assert_eq!(a.eta.len(), 2);
    assert_eq!(a.eta[0], s("theta"));
    // eta2 = J2h*alpha' - c*cos(alpha)*theta', the momentum conjugate to alpha,
    // up to a nonzero constant factor.
    let reference = s("J2h") * s("alpha'") - s("c") * s("alpha").cos() * s("theta'");
    assert!(proportional(a.eta[1], reference), "eta2 = {}", a.eta[1]);
    // Zero dynamics: eta1' = -eta2/c, eta2' = 0 (double integrator).
    assert!(
        is_zero(a.zd.rhs[0] + s("eta2") / s("c")),
        "eta1' = {}",
        a.zd.rhs[0]
    );
    assert!(is_zero(a.zd.rhs[1]), "eta2' = {}", a.zd.rhs[1]);
    for p in &a.zd.eigenvalues {
        assert!(p.re.abs() < 1e-9 && p.im.abs() < 1e-9, "eigenvalue {p:?}");
    }
    assert_eq!(a.zd.eigenvalues.len(), 2);
    assert_eq!(a.zd.class, ZeroDynamicsClass::NotAsymptoticallyStable);
    assert!(!a.zd.asymptotically_stable());
    assert!(!a.zd.minimum_phase());
}

#[test]
fn rotary_pendulum_with_gear_friction_still_double_integrator() {
    // The nominal set has Coulomb friction sign(theta') on the arm; it acts on
    // theta, not on the momentum conjugate to alpha, so it cancels exactly.
    let a = analyse("rotary_pendulum.plant", "alpha", None);
    assert!(is_zero(a.zd.rhs[1]), "eta2' = {}", a.zd.rhs[1]);
    assert_eq!(a.zd.class, ZeroDynamicsClass::NotAsymptoticallyStable);
}

#[test]
fn cart_pole_zero_dynamics_double_integrator() {
    // Output th (unactuated): eta = (x, p_th), p_th = mp*l*cos(th)*x' + (mp*l^2 + Jp)*th'.
    // On th = th' = 0: x' = eta2/(mp*l), and p_th' = dL/dth + Q_th = 0 there
    // (gravity torque mp*g*l*sin(th) = 0, no force on th). The cart friction
    // bx acts on x only and does not enter p_th': a double integrator, both
    // eigenvalues 0, not asymptotically stable.
    let a = analyse("cart_pole.plant", "th", None);
    assert_eq!(a.relative_degree, 2);
    assert_eq!(a.eta[0], s("x"));
    let reference = s("mp") * s("l") * s("th").cos() * s("x'")
        + (s("mp") * s("l").powi(2) + s("Jp")) * s("th'");
    assert!(proportional(a.eta[1], reference), "eta2 = {}", a.eta[1]);
    assert!(is_zero(a.zd.rhs[1]), "eta2' = {}", a.zd.rhs[1]);
    for p in &a.zd.eigenvalues {
        assert!(p.re.abs() < 1e-9, "eigenvalue {p:?}");
    }
    assert_eq!(a.zd.class, ZeroDynamicsClass::NotAsymptoticallyStable);
}

#[test]
fn pendubot_zero_dynamics_unstable() {
    // Output q1 (actuated shoulder): eta = (q2, p2), p2 = dT/dq2'. With the
    // shoulder held at q1 = q1' = 0 the elbow link is an inverted pendulum:
    // p2 = (m2*lc2^2 + I2)*q2', p2' = m2*g*lc2*sin(q2) - b2*q2'. Linearized:
    // s^2 + b2/I s - m2*g*lc2/I with I = m2*lc2^2 + I2: one real positive root.
    let a = analyse("pendubot.plant", "q1", None);
    assert_eq!(a.relative_degree, 2);
    assert_eq!(a.eta[0], s("q2"));
    assert_eq!(a.zd.class, ZeroDynamicsClass::Unstable);
    let (m2, lc2, i2, b2, g): (f64, f64, f64, f64, f64) = (0.1, 0.1, 3e-4, 1e-4, 9.81);
    let inertia = m2 * lc2 * lc2 + i2;
    let (bb, cc) = (b2 / inertia, -m2 * g * lc2 / inertia);
    let positive = (-bb + (bb * bb - 4.0 * cc).sqrt()) / 2.0;
    let max_re =
        a.zd.eigenvalues
            .iter()
            .map(|p| p.re)
            .fold(f64::MIN, f64::max);
    assert!(
        (max_re - positive).abs() < 1e-9 * positive.max(1.0),
        "{max_re} vs {positive}"
    );
}
