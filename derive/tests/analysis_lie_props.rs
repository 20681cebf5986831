//! Property: symbolic Lie derivatives equal finite-difference directional
//! derivatives `(h(x + eps f(x)) - h(x - eps f(x))) / (2 eps)` at random states,
//! with the model's parameter values.

use std::collections::HashMap;
use std::path::Path;

use plantc_derive::analysis::lie_derivative;
use plantc_derive::control::{output_expr, Derivation};
use plantc_derive::model::{load_model, ParameterValues};
use plantc_derive::sym::{Expr, Symbol};
use proptest::prelude::*;

struct Case {
    state: Vec<Symbol>,
    f: Vec<Expr>,
    g: Vec<Expr>,
    hs: Vec<Expr>,
    params: HashMap<Symbol, f64>,
}

fn case(file: &str, output: &str) -> Case {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../models")
        .join(file);
    let loaded = load_model(&path).unwrap_or_else(|e| panic!("{}", e.render()));
    let model = &loaded.model;
    let values = ParameterValues::new(model, None, &[]).expect("values");
    let d = Derivation::new(model).expect("derivation");
    let chain = d
        .lie_chain(model, output_expr(model, output).expect("output"))
        .expect("chain");
    let ca = d.affine().expect("control-affine form");
    let st = &ca.state;
    let x = |i: usize| Expr::symbol(st[i]);
    let mut hs = chain.lf.clone();
    hs.push(x(0).sin() * x(3).powi(2) + x(1).cos() * x(2));
    Case {
        state: st.clone(),
        f: ca.f.clone(),
        g: ca.g.iter().map(|r| r[0]).collect(),
        hs,
        params: values.symbol_map(model),
    }
}

fn check(c: &Case, x: &[f64]) -> Result<(), TestCaseError> {
    let mut at = c.params.clone();
    for (s, v) in c.state.iter().zip(x) {
        at.insert(*s, *v);
    }
    for field in [&c.f, &c.g] {
        let fx: Vec<f64> = field.iter().map(|e| e.eval_map(&at)).collect();
        let scale = fx.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
        let eps = 1e-6 / scale;
        for h in &c.hs {
            let symbolic = lie_derivative(*h, field, &c.state).eval_map(&at);
            let shifted = |sign: f64| {
                let mut p = at.clone();
                for ((s, v), fv) in c.state.iter().zip(x).zip(&fx) {
                    p.insert(*s, v + sign * eps * fv);
                }
                h.eval_map(&p)
            };
            let fd = (shifted(1.0) - shifted(-1.0)) / (2.0 * eps);
            let tol = 1e-5 * (1.0 + symbolic.abs());
            prop_assert!(
                (symbolic - fd).abs() <= tol,
                "h = {h}: symbolic {symbolic} vs fd {fd} at {x:?}"
            );
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn rotary_pendulum_lie_matches_finite_differences(
        // theta' kept away from 0: the nominal set has sign(theta') friction.
        x in (-3.0..3.0f64, -1.2..1.2f64, 0.1..5.0f64, -5.0..5.0f64),
        neg in any::<bool>(),
    ) {
        let c = case("rotary_pendulum.plant", "alpha");
        let thd = if neg { -x.2 } else { x.2 };
        check(&c, &[x.0, x.1, thd, x.3])?;
    }

    #[test]
    fn pendubot_lie_matches_finite_differences(
        x in (-3.0..3.0f64, -3.0..3.0f64, -5.0..5.0f64, -5.0..5.0f64),
    ) {
        let c = case("pendubot.plant", "q1");
        check(&c, &[x.0, x.1, x.2, x.3])?;
    }
}
