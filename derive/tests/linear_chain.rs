//! Controllability and LQR of the n-link chain (`n_link_chain_source`,
//! torque at joint 1), n = 2..10: the chain is controllable for every n (the
//! torque at the first joint reaches every link through the coupling of the
//! mass matrix; a PBH test on the balanced realisation gives a margin well
//! above its tolerance, while the controllability matrix's singular values
//! span 15-34 orders of magnitude and its rank test says "not controllable"
//! from n = 5), and LQR with Q = I, R = 1 must return a stabilizing gain with
//! a small CARE residual (scipy's CARE solver stabilises the n = 10 chain,
//! cond(P) about 2.4e13, issue 16).

use nalgebra::DMatrix;
use plantc_derive::analysis::{linearize, OperatingPoint};
use plantc_derive::linear::{care_residual, controllability, lqr};
use plantc_derive::mechanics::derive_equations;
use plantc_derive::model::{load_model_text, n_link_chain_source, ParameterValues};

fn chain(n: usize) -> (DMatrix<f64>, DMatrix<f64>) {
    let loaded = load_model_text("chain.plant", &n_link_chain_source(n)).expect("chain model");
    let model = &loaded.model;
    let eqs = derive_equations(model).expect("equations");
    let values = ParameterValues::new(model, None, &[]).expect("values");
    let lin = linearize(model, &eqs, &values, &OperatingPoint::zero(model)).expect("linearize");
    (lin.a, lin.b)
}

#[test]
fn chains_are_controllable_by_pbh_and_lqr_stabilises_them() {
    for n in 2..=10 {
        let (a, b) = chain(n);
        let c = controllability(&a, &b).unwrap();
        eprintln!(
            "n = {n}: PBH margin {:.3e} (tolerance {:.1e}), controllability-matrix rank {} of {}",
            c.pbh_margin,
            c.pbh_tolerance,
            c.rank,
            2 * n
        );
        assert!(c.controllable, "n = {n}: margin {}", c.pbh_margin);
        assert!(
            c.pbh_margin > 10.0 * c.pbh_tolerance,
            "n = {n}: margin {}",
            c.pbh_margin
        );
        if n == 10 {
            let q = DMatrix::<f64>::identity(2 * n, 2 * n);
            let r = DMatrix::<f64>::identity(1, 1);
            let l = lqr(&a, &b, &q, &r).expect("lqr of the 10-link chain");
            let g = &b * b.transpose();
            let res = care_residual(&a, &g, &q, &l.p);
            eprintln!("n = 10: LQR residual {res:.3e}");
            assert!(res < 1e-8, "residual {res}");
            // the closed loop, recomputed here: every eigenvalue in the left half plane
            let acl = &a - &b * &l.k;
            let eig = acl.complex_eigenvalues();
            assert!(eig.iter().all(|z| z.re < 0.0), "{eig}");
        }
    }
}

#[test]
fn an_uncoupled_mode_is_not_controllable() {
    // the 3-link chain next to an undamped oscillator the input does not reach
    let (a3, b3) = chain(3);
    let mut a = DMatrix::<f64>::zeros(8, 8);
    a.view_mut((0, 0), (6, 6)).copy_from(&a3);
    a[(6, 7)] = 1.0;
    a[(7, 6)] = -4.0;
    let mut b = DMatrix::<f64>::zeros(8, 1);
    b.view_mut((0, 0), (6, 1)).copy_from(&b3);
    let c = controllability(&a, &b).unwrap();
    assert!(!c.controllable, "margin {}", c.pbh_margin);
    assert!(c.pbh_margin < c.pbh_tolerance);
    assert!(c.pbh_eigenvalue.0.abs() < 1e-9 && (c.pbh_eigenvalue.1.abs() - 2.0).abs() < 1e-9);
}
