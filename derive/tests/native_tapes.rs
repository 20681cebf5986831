//! The native code of a split tape's fast part (derive/src/sym/jit.rs, x86-64
//! Linux) against the interpreter: bit-identical outputs for random tapes
//! using every instruction kind (constants, inputs, the four operations,
//! negation, square root, powers, every elementary function, `atan2`, fused
//! `sin`/`cos`), and the same outputs left untouched.

use plantc_derive::sym::{Expr, Symbol, Tape};
use proptest::prelude::*;

const NAMES: [&str; 5] = ["x", "y", "p", "q", "v"];

fn syms() -> Vec<Symbol> {
    NAMES.iter().map(|n| Symbol::new(n)).collect()
}

fn leaf() -> impl Strategy<Value = Expr> {
    prop_oneof![
        4 => (0..NAMES.len()).prop_map(|i| Expr::sym(NAMES[i])),
        1 => (-3i64..=3).prop_map(Expr::int),
        1 => (1i64..=3, 2i64..=7).prop_map(|(n, d)| Expr::frac(n, d)),
    ]
}

fn expr() -> impl Strategy<Value = Expr> {
    leaf().prop_recursive(4, 40, 2, |inner| {
        prop_oneof![
            3 => (inner.clone(), inner.clone()).prop_map(|(a, b)| a + b),
            2 => (inner.clone(), inner.clone()).prop_map(|(a, b)| a - b),
            3 => (inner.clone(), inner.clone()).prop_map(|(a, b)| a * b),
            2 => (inner.clone(), inner.clone()).prop_map(|(a, b)| a / b),
            1 => inner.clone().prop_map(|a| -a),
            2 => (inner.clone(), -3i64..=4).prop_map(|(a, n)| a.powi(n)),
            1 => (inner.clone(), inner.clone()).prop_map(|(a, b)| (a.powi(2) + 1).pow(b / 3)),
            1 => inner.clone().prop_map(|a| (a.powi(2) + 1).sqrt()),
            2 => inner.clone().prop_map(|a| a.sin()),
            2 => inner.clone().prop_map(|a| a.cos()),
            1 => inner.clone().prop_map(|a| a.sin() * a.cos()),
            1 => inner.clone().prop_map(|a| a.tan()),
            1 => inner.clone().prop_map(|a| (a / 4).exp()),
            1 => inner.clone().prop_map(|a| (a.powi(2) + 1).ln()),
            1 => inner.clone().prop_map(|a| a.abs()),
            1 => inner.clone().prop_map(|a| a.sign()),
            2 => inner.clone().prop_map(|a| (a * 40).tanh()),
            1 => (inner.clone(), inner.clone()).prop_map(|(a, b)| Expr::atan2(a, b)),
        ]
    })
}

fn point() -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(
        prop_oneof![8 => -2.0f64..2.0, 1 => Just(0.0), 1 => Just(-0.0)],
        NAMES.len(),
    )
}

/// Is native code expected here: x86-64 Linux, unless the environment
/// asks for interpreted tapes (as `PLANTC_INTERPRET_TAPES=1` does)?
fn native_expected() -> bool {
    cfg!(all(target_arch = "x86_64", target_os = "linux"))
        && std::env::var_os("PLANTC_INTERPRET_TAPES").is_none_or(|v| v.is_empty() || v == "0")
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn native_code_is_bit_identical_to_the_interpreter(
        es in prop::collection::vec(expr(), 1..6),
        slow in prop::collection::vec(any::<bool>(), NAMES.len()),
        p in point(),
        fast_points in prop::collection::vec(point(), 1..4),
    ) {
        let tape = Tape::compile(&es, &syms()).unwrap();
        let native = tape.split_by_inputs(&slow);
        let interpreted = native.interpreted();
        prop_assert!(!interpreted.is_native());
        // (every tape translates where the target has the translation:
        // otherwise this would compare the interpreter with itself)
        prop_assert_eq!(native.is_native(), native_expected());
        let n = es.len();
        // both from NaN-filled buffers: a slot or output the code failed to
        // write (or wrote elsewhere) shows as a difference
        let (mut s1, mut s2) = (vec![f64::NAN; native.scratch_len()], vec![f64::NAN; native.scratch_len()]);
        let (mut o1, mut o2) = (vec![f64::NAN; n + 2], vec![f64::NAN; n + 2]);
        native.eval_slow_outputs(&p, &mut o1, &mut s1);
        interpreted.eval_slow_outputs(&p, &mut o2, &mut s2);
        for q in &fast_points {
            let x: Vec<f64> = (0..p.len()).map(|i| if slow[i] { p[i] } else { q[i] }).collect();
            native.eval_fast_changed(&x, &mut o1, &mut s1);
            interpreted.eval_fast_changed(&x, &mut o2, &mut s2);
            let b1: Vec<u64> = o1.iter().map(|v| v.to_bits()).collect();
            let b2: Vec<u64> = o2.iter().map(|v| v.to_bits()).collect();
            prop_assert_eq!(&b1, &b2, "{:?} at {:?}\n{:?}", es, x, tape);
            let b1: Vec<u64> = s1.iter().map(|v| v.to_bits()).collect();
            let b2: Vec<u64> = s2.iter().map(|v| v.to_bits()).collect();
            prop_assert_eq!(&b1, &b2, "scratch of {:?} at {:?}", es, x);
            // and eval_fast, which writes every output
            let (mut f1, mut f2) = (vec![f64::NAN; n], vec![f64::NAN; n]);
            native.eval_fast(&x, &mut f1, &mut s1);
            interpreted.eval_fast(&x, &mut f2, &mut s2);
            let b1: Vec<u64> = f1.iter().map(|v| v.to_bits()).collect();
            let b2: Vec<u64> = f2.iter().map(|v| v.to_bits()).collect();
            prop_assert_eq!(b1, b2);
        }
    }
}

/// Where the translation exists, split tapes use it (otherwise the property
/// above would compare the interpreter with itself).
#[test]
fn split_tapes_run_natively_on_x86_64_linux() {
    let (x, y) = (Expr::sym("x"), Expr::sym("y"));
    let tape = Tape::compile(&[x * y + x.sin()], &[Symbol::new("x"), Symbol::new("y")]).unwrap();
    let split = tape.split_by_inputs(&[false, true]);
    assert_eq!(split.is_native(), native_expected());
    let mut scratch = vec![0.0; split.scratch_len()];
    let mut out = [0.0];
    split.eval_slow_outputs(&[0.5, 3.0], &mut out, &mut scratch);
    split.eval_fast_changed(&[0.5, 3.0], &mut out, &mut scratch);
    assert_eq!(out[0].to_bits(), tape.eval_vec(&[0.5, 3.0])[0].to_bits());
}
