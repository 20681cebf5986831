//! Euler-Lagrange derivation against the reference equations
//! (`shared/reference/rotary-pendulum.md`, restating the thesis' Cassolato &
//! Prime form) and against independent hand-written evaluations.

use std::collections::HashMap;
use std::path::Path;

use plantc_derive::mechanics::{control_affine, derive_equations};
use plantc_derive::model::{load_model, Model, ParameterValues};
use plantc_derive::sym::{is_zero, Expr, Symbol};

fn model(name: &str) -> Model {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../models")
        .join(name);
    load_model(&path).unwrap_or_else(|e| panic!("{e}")).model
}

fn s(name: &str) -> Expr {
    Expr::sym(name)
}

#[test]
fn rotary_pendulum_mass_matrix_and_bias_equal_the_reference_exactly() {
    let m = model("rotary_pendulum.plant");
    let eqs = derive_equations(&m).unwrap();
    let (a, ad, td) = (s("alpha"), s("alpha'"), s("theta'"));
    let (j0h, j2h, c) = (s("J0h"), s("J2h"), s("c"));
    let (m2, g, l2) = (s("m2"), s("g"), s("l2"));
    // Reference: M = [[J0h + J2h sin^2 a, -c cos a], [-c cos a, J2h]]
    let m_ref = [
        [j0h + j2h * a.sin().powi(2), -c * a.cos()],
        [-c * a.cos(), j2h],
    ];
    // bias = [2 J2h sin cos th' a' + c sin a a'^2, -J2h sin cos th'^2 - m2 g l2 sin a]
    let bias_ref = [
        2 * j2h * a.sin() * a.cos() * td * ad + c * a.sin() * ad.powi(2),
        -j2h * a.sin() * a.cos() * td.powi(2) - m2 * g * l2 * a.sin(),
    ];
    for i in 0..2 {
        for (j, &m_ij) in m_ref[i].iter().enumerate() {
            assert!(
                is_zero(eqs.mass_matrix[i][j] - m_ij),
                "M[{i}][{j}] = {} differs from {}",
                eqs.mass_matrix[i][j],
                m_ij
            );
        }
        assert!(
            is_zero(eqs.bias[i] - bias_ref[i]),
            "bias[{i}] = {} differs from {}",
            eqs.bias[i],
            bias_ref[i]
        );
    }
    // Generalised forces: tau - b1 th' - Fg1 sign(th'), -b2 a'.
    let tau0 = -s("eta_g") * s("Kg") * s("eta_m") * s("kt") * s("Kg") * s("km") * td / s("Rm");
    let q0_ref = [tau0 - s("b1") * td - s("Fg1") * td.sign(), -s("b2") * ad];
    let b_ref = [
        s("eta_g") * s("Kg") * s("eta_m") * s("kt") / s("Rm"),
        Expr::zero(),
    ];
    for i in 0..2 {
        assert!(
            is_zero(eqs.forces[i] - q0_ref[i]),
            "Q0[{i}] = {}",
            eqs.forces[i]
        );
        assert!(
            is_zero(eqs.input_matrix[i][0] - b_ref[i]),
            "B[{i}] = {}",
            eqs.input_matrix[i][0]
        );
    }
    // A wrong reference must not pass (the comparison can fail).
    assert!(!is_zero(
        eqs.mass_matrix[0][0] - (j0h + j2h * a.cos().powi(2))
    ));
}

/// Independent hand-written evaluation of the reference model's accelerations
/// (Cramer's rule on the 2x2 mass matrix), Table 3 and Table 1 values.
fn reference_accelerations(p: &HashMap<&str, f64>, x: [f64; 4], vm: f64) -> [f64; 2] {
    let [_, a, td, ad] = x;
    let j0h = p["J1"] + p["m1"] * p["l1"].powi(2) + p["m2"] * p["L1"].powi(2);
    let j2h = p["J2"] + p["m2"] * p["l2"].powi(2);
    let c = p["m2"] * p["L1"] * p["l2"];
    let tau = p["eta_g"] * p["Kg"] * p["eta_m"] * p["kt"] * (vm - p["Kg"] * p["km"] * td) / p["Rm"];
    let (sa, ca) = a.sin_cos();
    let m11 = j0h + j2h * sa * sa;
    let m12 = -c * ca;
    let m22 = j2h;
    let r1 = tau
        - p["b1"] * td
        - p["Fg1"] * td.signum()
        - 2.0 * j2h * sa * ca * td * ad
        - c * sa * ad * ad;
    let r2 = -p["b2"] * ad + j2h * sa * ca * td * td + p["m2"] * p["g"] * p["l2"] * sa;
    let det = m11 * m22 - m12 * m12;
    [(r1 * m22 - m12 * r2) / det, (m11 * r2 - m12 * r1) / det]
}

#[test]
fn control_affine_form_agrees_with_a_hand_written_evaluation() {
    let m = model("rotary_pendulum.plant");
    let eqs = derive_equations(&m).unwrap();
    let ca = control_affine(&eqs).unwrap();
    let values = ParameterValues::new(&m, None, &[]).unwrap();
    let by_name: HashMap<&str, f64> = m
        .parameters
        .iter()
        .map(|p| p.name.as_str())
        .zip(values.base.iter().copied())
        .collect();
    let mut env = values.symbol_map(&m);
    let state = m.state_symbols();
    let vm = Symbol::new("Vm");
    let mut seed = 0x2545F4914F6CDD1Du64;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    for _ in 0..200 {
        let x = [3.0 * rnd(), 3.0 * rnd(), 10.0 * rnd(), 10.0 * rnd()];
        let u = 10.0 * rnd();
        for (s, v) in state.iter().zip(x) {
            env.insert(*s, v);
        }
        env.insert(vm, u);
        let want = reference_accelerations(&by_name, x, u);
        for (k, &want_k) in want.iter().enumerate() {
            let got = ca.f[2 + k].eval_map(&env) + ca.g[2 + k][0].eval_map(&env) * u;
            let tol = 1e-10 * (1.0 + want_k.abs());
            assert!(
                (got - want_k).abs() < tol,
                "state {x:?}, u {u}: a{k} = {got}, reference {want_k}"
            );
        }
    }
}

#[test]
fn cart_pole_equations_match_hand_derivation() {
    let m = model("cart_pole.plant");
    let eqs = derive_equations(&m).unwrap();
    let (th, thd) = (s("th"), s("th'"));
    let (mc, mp, l, jp, g) = (s("mc"), s("mp"), s("l"), s("Jp"), s("g"));
    // T = 1/2 (mc+mp) x'^2 + mp l cos(th) x' th' + 1/2 (mp l^2 + Jp) th'^2, V = mp g l cos th
    let m_ref = [
        [mc + mp, mp * l * th.cos()],
        [mp * l * th.cos(), mp * l.powi(2) + jp],
    ];
    let bias_ref = [-mp * l * th.sin() * thd.powi(2), -mp * g * l * th.sin()];
    for i in 0..2 {
        for (j, &m_ij) in m_ref[i].iter().enumerate() {
            assert!(
                is_zero(eqs.mass_matrix[i][j] - m_ij),
                "M[{i}][{j}] = {}",
                eqs.mass_matrix[i][j]
            );
        }
        assert!(
            is_zero(eqs.bias[i] - bias_ref[i]),
            "bias[{i}] = {}",
            eqs.bias[i]
        );
    }
    assert!(is_zero(eqs.input_matrix[0][0] - 1));
    assert!(eqs.input_matrix[1][0].is_zero());
}

#[test]
fn pendubot_mass_matrix_matches_spong() {
    // Spong's pendubot/acrobot mass matrix with relative elbow angle:
    // d11 = m1 lc1^2 + m2 (l1^2 + lc2^2 + 2 l1 lc2 cos q2) + I1 + I2
    // d12 = m2 (lc2^2 + l1 lc2 cos q2) + I2, d22 = m2 lc2^2 + I2
    let m = model("pendubot.plant");
    let eqs = derive_equations(&m).unwrap();
    let q2 = s("q2");
    let (m1, m2, l1, lc1, lc2, i1, i2) = (
        s("m1"),
        s("m2"),
        s("l1"),
        s("lc1"),
        s("lc2"),
        s("I1"),
        s("I2"),
    );
    let d11 =
        m1 * lc1.powi(2) + m2 * (l1.powi(2) + lc2.powi(2) + 2 * l1 * lc2 * q2.cos()) + i1 + i2;
    let d12 = m2 * (lc2.powi(2) + l1 * lc2 * q2.cos()) + i2;
    let d22 = m2 * lc2.powi(2) + i2;
    let want = [[d11, d12], [d12, d22]];
    for (i, want_i) in want.iter().enumerate() {
        for (j, &want_ij) in want_i.iter().enumerate() {
            assert!(
                is_zero(eqs.mass_matrix[i][j] - want_ij),
                "M[{i}][{j}] = {}",
                eqs.mass_matrix[i][j]
            );
        }
    }
    // Gravity on q1 at q = 0 vanishes; the potential gradient has cos(q1 + q2) terms.
    let g1 = eqs.bias[0];
    assert!(!is_zero(g1));
}
