//! Property tests of the symbolic core: canonical form, differentiation and
//! compiled tapes agree numerically with tree evaluation.

use std::collections::HashMap;

use plantc_derive::sym::{canonical, diff, is_zero, try_canonical, Expr, Func, Node, Symbol, Tape};
use proptest::prelude::*;

const NAMES: [&str; 6] = ["x", "y", "a", "b", "theta", "theta'"];

fn syms() -> Vec<Symbol> {
    NAMES.iter().map(|n| Symbol::new(n)).collect()
}

fn leaf() -> impl Strategy<Value = Expr> {
    prop_oneof![
        4 => (0..NAMES.len()).prop_map(|i| Expr::sym(NAMES[i])),
        1 => (-3i64..=3).prop_map(Expr::int),
        1 => (1i64..=3, 2i64..=4).prop_map(|(n, d)| Expr::frac(n, d)),
    ]
}

fn expr() -> impl Strategy<Value = Expr> {
    leaf().prop_recursive(4, 32, 2, |inner| {
        prop_oneof![
            3 => (inner.clone(), inner.clone()).prop_map(|(a, b)| a + b),
            2 => (inner.clone(), inner.clone()).prop_map(|(a, b)| a - b),
            3 => (inner.clone(), inner.clone()).prop_map(|(a, b)| a * b),
            2 => (inner.clone(), inner.clone()).prop_map(|(a, b)| a / b),
            2 => (inner.clone(), -2i64..=3).prop_map(|(a, n)| a.powi(n)),
            2 => inner.clone().prop_map(|a| a.sin()),
            2 => inner.clone().prop_map(|a| a.cos()),
            1 => inner.clone().prop_map(|a| a.tan()),
            1 => inner.clone().prop_map(|a| (a / 4).exp()),
            1 => inner.clone().prop_map(|a| (a.powi(2) + 1).sqrt()),
        ]
    })
}

fn point() -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(-2.0f64..2.0, NAMES.len())
}

fn env(p: &[f64]) -> HashMap<Symbol, f64> {
    syms().into_iter().zip(p.iter().copied()).collect()
}

/// Value and a first-order bound on its floating-point rounding error
/// (forward error propagation with unit roundoff per operation). Large when the
/// value comes from cancellation or an ill-conditioned function.
fn value_and_error(
    e: Expr,
    vals: &HashMap<Symbol, f64>,
    memo: &mut HashMap<Expr, (f64, f64)>,
) -> (f64, f64) {
    const U: f64 = f64::EPSILON;
    if let Some(&v) = memo.get(&e) {
        return v;
    }
    let v = e.eval_map(vals);
    let err = match e.node() {
        Node::Symbol(_) => 0.0,
        Node::Rational(_) | Node::Float(_) => U * v.abs(),
        Node::Add(ts) => {
            let mut err = 0.0;
            let mut mag = 0.0;
            for t in ts.iter() {
                let (tv, te) = value_and_error(*t, vals, memo);
                err += te;
                mag += tv.abs();
            }
            err + U * mag
        }
        Node::Mul(fs) => {
            let parts: Vec<(f64, f64)> =
                fs.iter().map(|f| value_and_error(*f, vals, memo)).collect();
            let mut err = 0.0;
            for i in 0..parts.len() {
                let others: f64 = parts
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, p)| p.0.abs())
                    .product();
                err += parts[i].1 * others;
            }
            err + 2.0 * U * parts.len() as f64 * v.abs()
        }
        Node::Pow(b, x) => {
            let (bv, be) = value_and_error(*b, vals, memo);
            let (xv, xe) = value_and_error(*x, vals, memo);
            (xv * bv.powf(xv - 1.0)).abs() * be
                + (v * bv.abs().ln()).abs() * xe
                + 4.0 * U * (xv.abs() + 1.0) * v.abs()
        }
        Node::Func(f, u) => {
            let (uv, ue) = value_and_error(*u, vals, memo);
            // Analytic slopes for the periodic functions: a finite difference
            // over a step proportional to a large argument averages out.
            let slope = match f {
                Func::Sin | Func::Cos => 1.0,
                Func::Tan => 1.0 + v * v,
                _ => {
                    let h = 1e-6 * (1.0 + uv.abs());
                    ((f.eval(uv + h) - f.eval(uv - h)) / (2.0 * h)).abs()
                }
            };
            slope * ue + 2.0 * U * v.abs()
        }
        Node::Named(_, d) => value_and_error(*d, vals, memo).1,
        Node::Atan2(y, x) => {
            let (yv, ye) = value_and_error(*y, vals, memo);
            let (xv, xe) = value_and_error(*x, vals, memo);
            (xv.abs() * ye + yv.abs() * xe) / (xv * xv + yv * yv) + 2.0 * U * v.abs()
        }
    };
    memo.insert(e, (v, err));
    (v, err)
}

/// Rounding-error bound of evaluating `e` at `vals` (NaN-free, may be infinite).
fn err_bound(e: Expr, vals: &HashMap<Symbol, f64>) -> f64 {
    let b = value_and_error(e, vals, &mut HashMap::new()).1;
    if b.is_nan() {
        f64::INFINITY
    } else {
        b
    }
}

fn has_nonfinite(e: Expr) -> bool {
    matches!(e.node(), Node::Float(b) if !b.value().is_finite())
        || e.children().into_iter().any(has_nonfinite)
}

fn close(got: f64, want: f64, tol: f64) -> bool {
    (got - want).abs() <= tol
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: std::env::var("PROPTEST_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(400),
        ..ProptestConfig::default()
    })]

    #[test]
    fn canonical_preserves_value(e in expr(), p in point()) {
        let Ok(c) = try_canonical(e) else { return Ok(()) };
        let vals = env(&p);
        let (ve, vc) = (e.eval_map(&vals), c.eval_map(&vals));
        let tol = 100.0 * (err_bound(e, &vals) + err_bound(c, &vals)) + 1e-300;
        if !ve.is_finite() || !vc.is_finite() || !tol.is_finite() || tol > 1e-6 * (1.0 + ve.abs()) {
            return Ok(());
        }
        prop_assert!(close(vc, ve, tol), "e = {e}\ncanonical = {c}\n{ve} vs {vc} (tol {tol})");
    }

    #[test]
    fn canonical_is_self_consistent(e in expr()) {
        if has_nonfinite(e) { return Ok(()) }
        let Ok(c) = try_canonical(e) else { return Ok(()) };
        prop_assert!(is_zero(c - e), "e = {e}\ncanonical = {c}");
        prop_assert_eq!(canonical(c), c, "not idempotent: e = {}", e);
    }

    #[test]
    fn zero_means_zero(e in expr(), p in point()) {
        if !is_zero(e) { return Ok(()) }
        let vals = env(&p);
        let v = e.eval_map(&vals);
        let tol = 100.0 * err_bound(e, &vals);
        if v.is_finite() && tol < 1e-6 {
            prop_assert!(v.abs() <= tol, "is_zero({e}) but value {v}");
        }
    }

    #[test]
    fn diff_matches_finite_differences(e in expr(), p in point()) {
        let xs = Symbol::new("x");
        let d = diff(e, xs);
        let mut vals = env(&p);
        let x0 = vals[&xs];
        let f = |x: f64, vals: &mut HashMap<Symbol, f64>| {
            vals.insert(xs, x);
            e.eval_map(vals)
        };
        let fd = |h: f64, vals: &mut HashMap<Symbol, f64>| (f(x0 + h, vals) - f(x0 - h, vals)) / (2.0 * h);
        let (d1, d2) = (fd(1e-4, &mut vals), fd(5e-5, &mut vals));
        vals.insert(xs, x0);
        let dv = d.eval_map(&vals);
        if !(d1.is_finite() && d2.is_finite() && dv.is_finite()) {
            return Ok(());
        }
        let tol = 1e-5 * (1.0 + dv.abs());
        // Skip ill-conditioned points: the two step sizes disagree.
        if (d1 - d2).abs() > tol || dv.abs() > 1e6 {
            return Ok(());
        }
        prop_assert!(close(dv, d2, 10.0 * tol), "e = {e}\nd = {d}\n{dv} vs fd {d2}");
    }

    #[test]
    fn tape_matches_tree(es in prop::collection::vec(expr(), 1..4), p in point()) {
        let tape = Tape::compile(&es, &syms()).unwrap();
        let mut out = vec![0.0; es.len()];
        let mut scratch = vec![0.0; tape.scratch_len()];
        tape.eval(&p, &mut out, &mut scratch);
        let vals = env(&p);
        for (e, got) in es.iter().zip(&out) {
            let want = e.eval_map(&vals);
            if !want.is_finite() {
                continue;
            }
            // Both evaluations round differently; allow a multiple of the
            // rounding-error bound, and otherwise 1e-12 relative.
            let tol = (20.0 * err_bound(*e, &vals)).max(1e-12 * want.abs()) + 1e-300;
            if !tol.is_finite() {
                continue;
            }
            prop_assert!(close(*got, want, tol), "e = {e}\n{got} vs {want} (tol {tol})\n{tape:?}");
        }
    }

    /// A split tape (random slow-input mask) gives outputs bit-identical to
    /// the unsplit tape: same instructions on the same operands (repeats
    /// dropped). One slow
    /// evaluation serves several fast points (only fast inputs change), and
    /// the scratch starts as NaN so nothing relies on zero-initialised slots.
    #[test]
    fn split_tape_is_bit_identical(
        es in prop::collection::vec(expr(), 1..4),
        slow in prop::collection::vec(any::<bool>(), NAMES.len()),
        p in point(),
        fast_points in prop::collection::vec(point(), 1..4),
    ) {
        let tape = Tape::compile(&es, &syms()).unwrap();
        let split = tape.split_by_inputs(&slow);
        prop_assert!(
            split.slow_instructions().len() + split.fast_instructions().len()
                <= tape.instructions().len()
        );
        let mut scratch = vec![f64::NAN; split.scratch_len()];
        split.eval_slow(&p, &mut scratch);
        for q in &fast_points {
            // Slow inputs from `p`, fast ones from `q`.
            let x: Vec<f64> = (0..p.len()).map(|i| if slow[i] { p[i] } else { q[i] }).collect();
            let want = tape.eval_vec(&x);
            let mut got = vec![f64::NAN; es.len()];
            split.eval_fast(&x, &mut got, &mut scratch);
            for (k, (g, w)) in got.iter().zip(&want).enumerate() {
                prop_assert_eq!(
                    g.to_bits(), w.to_bits(),
                    "output {} of {:?}: {} vs {}\n{:?}\n{:?}", k, es, g, w, tape, split
                );
            }
        }
        // the same through eval_slow_outputs / eval_fast_changed, which
        // write the slow outputs once: the buffer starts as NaN, so an
        // output left unwritten shows
        let mut scratch = vec![f64::NAN; split.scratch_len()];
        let mut got = vec![f64::NAN; es.len()];
        split.eval_slow_outputs(&p, &mut got, &mut scratch);
        for q in &fast_points {
            let x: Vec<f64> = (0..p.len()).map(|i| if slow[i] { p[i] } else { q[i] }).collect();
            let want = tape.eval_vec(&x);
            split.eval_fast_changed(&x, &mut got, &mut scratch);
            for (k, (g, w)) in got.iter().zip(&want).enumerate() {
                prop_assert_eq!(
                    g.to_bits(), w.to_bits(),
                    "output {} of {:?} (changed only): {} vs {}\n{:?}\n{:?}", k, es, g, w, tape, split
                );
            }
        }
    }
}

/// Coverage report for the generator (how many cases are actually checked).
#[test]
#[ignore]
fn coverage_report() {
    use proptest::strategy::ValueTree;
    use proptest::test_runner::TestRunner;
    let mut runner = TestRunner::deterministic();
    let (mut n, mut err, mut checked, mut zero) = (0, 0, 0, 0);
    let mut max_dag = 0;
    let t = std::time::Instant::now();
    for _ in 0..3000 {
        let e = expr().new_tree(&mut runner).unwrap().current();
        let p = point().new_tree(&mut runner).unwrap().current();
        n += 1;
        max_dag = max_dag.max(e.dag_size());
        match try_canonical(e) {
            Err(_) => err += 1,
            Ok(c) => {
                if is_zero(e) {
                    zero += 1;
                }
                let vals = env(&p);
                let (ve, vc) = (e.eval_map(&vals), c.eval_map(&vals));
                let tol = 100.0 * (err_bound(e, &vals) + err_bound(c, &vals));
                if ve.is_finite() && vc.is_finite() && tol <= 1e-6 * (1.0 + ve.abs()) {
                    checked += 1;
                }
            }
        }
    }
    println!("{n} cases, {err} canonical errors, {checked} checked, {zero} zero, max dag {max_dag}, {:?}", t.elapsed());
}
