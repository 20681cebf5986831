//! analyze of the 4-link chain (`n_link_chain_source(4)`, torque at joint 1)
//! for the outputs `q1` and `tip = q1 + q2 + q3 + q4`, checked against
//! numbers computed here independently of the symbolic analysis:
//! - `L_f^2 h` and `L_g L_f h` against nested central finite differences of
//!   `h` along the numeric vector fields `f(x) = F(x, 0)` and
//!   `g(x) = F(x, 1) - F(x, 0)` (`F` the numeric forward dynamics, an LU
//!   solve of the derived `M q'' = Q0 - bias + B u`);
//! - the linearizing law `u = (v - L_f^2 h) / (L_g L_f h)` with
//!   `v = -6 y - 5 y'`: the closed loop linearized numerically (central
//!   differences of `F(x, u(x))` at the upright equilibrium) must have the
//!   output poles -2, -3 and, for the other 2n - 2 eigenvalues, exactly the
//!   zero-dynamics eigenvalues that analyze reports.

use nalgebra::DMatrix;
use plantc_derive::analysis::{normal_form, zero_dynamics};
use plantc_derive::control::{output_expr, Derivation};
use plantc_derive::mechanics::NumericDynamics;
use plantc_derive::model::{load_model_text, n_link_chain_source, ParameterValues};
use plantc_derive::sym::{Expr, Symbol};

const N: usize = 4;

#[test]
fn four_link_chain_outputs_q1_and_tip() {
    let loaded = load_model_text("chain4.plant", &n_link_chain_source(N)).expect("model");
    let model = &loaded.model;
    let values = ParameterValues::new(model, None, &[]).expect("values");
    let d = Derivation::new(model).expect("derivation");
    let eqs = &d.equations;
    let num = NumericDynamics::new(model, eqs).expect("numeric dynamics");
    let mut ws = num.workspace();
    let mut dyn_at = |x: &[f64], u: f64| {
        let mut dx = vec![0.0; 2 * N];
        num.derivatives(x, &[u], &values.full, &mut dx, &mut ws)
            .expect("dynamics");
        dx
    };
    let params = values.symbol_map(model);
    let state: Vec<Symbol> = eqs
        .coords
        .iter()
        .map(|c| c.q)
        .chain(eqs.coords.iter().map(|c| c.qd))
        .collect();
    let eval = |e: Expr, x: &[f64]| {
        e.eval_with(&mut |s| {
            if let Some(i) = state.iter().position(|t| *t == s) {
                x[i]
            } else {
                *params
                    .get(&s)
                    .unwrap_or_else(|| panic!("unbound symbol {}", s.name()))
            }
        })
    };
    let states: Vec<Vec<f64>> = (0..3)
        .map(|k| {
            (0..2 * N)
                .map(|i| 0.3 * (((k * 7 + i * 3) % 11) as f64 / 5.0 - 1.0))
                .collect()
        })
        .collect();

    for output in ["q1", "tip"] {
        let h = output_expr(model, output).expect("output");
        let chain = d.lie_chain(model, h).expect("Lie chain");
        assert_eq!(chain.relative_degree, 2, "{output}");

        // L_f^2 h and L_g L_f h against finite differences
        let e = 1e-4;
        for x in &states {
            let along = |x: &[f64], v: &[f64], s: f64| -> Vec<f64> {
                x.iter().zip(v).map(|(a, b)| a + s * b).collect()
            };
            let lfh = |x: &[f64], dyn_at: &mut dyn FnMut(&[f64], f64) -> Vec<f64>| {
                let f = dyn_at(x, 0.0);
                (eval(h, &along(x, &f, e)) - eval(h, &along(x, &f, -e))) / (2.0 * e)
            };
            let f0 = dyn_at(x, 0.0);
            let g: Vec<f64> = dyn_at(x, 1.0).iter().zip(&f0).map(|(a, b)| a - b).collect();
            let lf2 = (lfh(&along(x, &f0, e), &mut dyn_at) - lfh(&along(x, &f0, -e), &mut dyn_at))
                / (2.0 * e);
            let lglf = (lfh(&along(x, &g, e), &mut dyn_at) - lfh(&along(x, &g, -e), &mut dyn_at))
                / (2.0 * e);
            let (s_lf2, s_lglf) = (eval(chain.lf[2], x), eval(chain.lg[1], x));
            assert!(eval(chain.lg[0], x).abs() < 1e-12, "{output}: L_g h");
            let scale = lf2.abs().max(1.0);
            assert!(
                (s_lf2 - lf2).abs() < 1e-5 * scale,
                "{output}: L_f^2 h {s_lf2} vs {lf2}"
            );
            assert!(
                (s_lglf - lglf).abs() < 1e-6 * lglf.abs(),
                "{output}: L_g L_f h {s_lglf} vs {lglf}"
            );
        }

        // closed loop under the law, linearized numerically at the equilibrium
        let v = Expr::int(-6) * Expr::sym("y") + Expr::int(-5) * Expr::sym("y'");
        let law = chain.law(v);
        let nf = normal_form(model, &d, &chain, &values, None).expect("normal form");
        let zd = zero_dynamics(model, &nf, &values).expect("zero dynamics");
        assert_eq!(zd.eigenvalues.len(), 2 * N - 2, "{output}");
        let x0 = vec![0.0; 2 * N];
        let ecl = 1e-6;
        let acl = DMatrix::from_fn(2 * N, 2 * N, |i, j| {
            let mut xp = x0.clone();
            let mut xm = x0.clone();
            xp[j] += ecl;
            xm[j] -= ecl;
            let fp = dyn_at(&xp, eval(law, &xp));
            let fm = dyn_at(&xm, eval(law, &xm));
            (fp[i] - fm[i]) / (2.0 * ecl)
        });
        let mut eig: Vec<(f64, f64)> = acl
            .complex_eigenvalues()
            .iter()
            .map(|z| (z.re, z.im))
            .collect();
        let mut expected: Vec<(f64, f64)> = vec![(-2.0, 0.0), (-3.0, 0.0)];
        expected.extend(zd.eigenvalues.iter().map(|p| (p.re, p.im)));
        eprintln!("{output}: zero-dynamics eigenvalues {:?}", &expected[2..]);
        for (re, im) in expected {
            let (k, dist) = eig
                .iter()
                .enumerate()
                .map(|(k, z)| (k, ((z.0 - re).powi(2) + (z.1 - im).powi(2)).sqrt()))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .expect("eigenvalues left");
            assert!(
                dist < 1e-4 * (re * re + im * im).sqrt().max(1.0),
                "{output}: eigenvalue {re} + {im}i of the closed loop: nearest {:?}",
                eig[k]
            );
            eig.remove(k);
        }
    }
}
