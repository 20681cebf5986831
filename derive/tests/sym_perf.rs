//! Performance sanity of the canonical form on mechanics-sized expressions.
//! Ignored by default; run with `--ignored --nocapture` to see timings.
//! Nothing here asserts a timing.

use std::time::Instant;

use plantc_derive::sym::{
    canonical, diff, is_zero, simplify, time_derivative, CoordinateSymbols, Expr, Symbol, Tape,
};

fn s(n: &str) -> Expr {
    Expr::sym(n)
}

/// Double pendulum (point masses): Euler-Lagrange by hand from the Lagrangian,
/// accelerations by Cramer's rule, then checked exactly.
#[test]
#[ignore]
fn double_pendulum_accelerations() {
    let c1 = CoordinateSymbols::new("t1");
    let c2 = CoordinateSymbols::new("t2");
    let (t1, t2) = (Expr::symbol(c1.q), Expr::symbol(c2.q));
    let (w1, w2) = (Expr::symbol(c1.qd), Expr::symbol(c2.qd));
    let (m1, m2, l1, l2, g) = (s("m1"), s("m2"), s("l1"), s("l2"), s("g"));
    // Positions.
    let x1 = l1 * t1.sin();
    let y1 = -l1 * t1.cos();
    let x2 = x1 + l2 * t2.sin();
    let y2 = y1 - l2 * t2.cos();
    let coords = [c1, c2];
    let v = |p: Expr| time_derivative(p, &coords);
    let t = (m1 * (v(x1).powi(2) + v(y1).powi(2)) + m2 * (v(x2).powi(2) + v(y2).powi(2))) / 2;
    let u = m1 * g * y1 + m2 * g * y2;
    let lag = t - u;
    let start = Instant::now();
    // EL: d/dt dL/dq' - dL/dq = 0 -> M(q) q'' + h(q, q') = 0.
    let eqs: Vec<Expr> = coords
        .iter()
        .map(|c| canonical(time_derivative(diff(lag, c.qd), &coords) - diff(lag, c.q)))
        .collect();
    let qdd = [Expr::symbol(c1.qdd), Expr::symbol(c2.qdd)];
    let m: Vec<Vec<Expr>> = eqs
        .iter()
        .map(|e| {
            qdd.iter()
                .map(|a| canonical(diff(*e, a.as_symbol().unwrap())))
                .collect()
        })
        .collect();
    let zero_acc =
        std::collections::HashMap::from([(c1.qdd, Expr::zero()), (c2.qdd, Expr::zero())]);
    let h: Vec<Expr> = eqs
        .iter()
        .map(|e| canonical(plantc_derive::sym::substitute_symbols(*e, &zero_acc)))
        .collect();
    let t_el = start.elapsed();
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    let a1 = (-h[0] * m[1][1] + h[1] * m[0][1]) / det;
    let a2 = (-h[1] * m[0][0] + h[0] * m[1][0]) / det;
    let t0 = Instant::now();
    let a1c = simplify(a1);
    let a2c = simplify(a2);
    let t_solve = t0.elapsed();
    // Exact check: M a + h = 0.
    let t0 = Instant::now();
    let r1 = m[0][0] * a1c + m[0][1] * a2c + h[0];
    let r2 = m[1][0] * a1c + m[1][1] * a2c + h[1];
    assert!(is_zero(r1) && is_zero(r2));
    let t_check = t0.elapsed();
    let inputs: Vec<Symbol> = [t1, t2, w1, w2, m1, m2, l1, l2, g]
        .iter()
        .map(|e| e.as_symbol().unwrap())
        .collect();
    let tape = Tape::compile(&[a1c, a2c], &inputs).unwrap();
    println!("M11 = {}\nM12 = {}\nh1 = {}", m[0][0], m[0][1], h[0]);
    println!("a1 = {a1c}\na2 = {a2c}");
    println!(
        "EL {t_el:?}, solve+simplify {t_solve:?}, exact check {t_check:?}; tape {} instrs, {} slots",
        tape.instructions().len(),
        tape.scratch_len()
    );
}

#[test]
#[ignore]
fn furuta_mass_matrix_inverse_cost() {
    let (j0, j2, c, al) = (s("J0h"), s("J2h"), s("c"), s("alpha"));
    let m11 = j0 + j2 * al.sin().powi(2);
    let m12 = c * al.cos();
    let det = m11 * j2 - m12 * m12;
    let inv = [j2 / det, -m12 / det, -m12 / det, m11 / det];
    let n = 200;
    let t0 = Instant::now();
    for _ in 0..n {
        for e in inv {
            std::hint::black_box(canonical(e));
        }
    }
    println!(
        "2x2 Furuta mass-matrix inverse: {:?} per canonicalisation of all 4 entries",
        t0.elapsed() / n
    );
    let t0 = Instant::now();
    for _ in 0..n {
        std::hint::black_box(is_zero(m11 * inv[0] + m12 * inv[2] - 1));
    }
    println!(
        "is_zero(M11*Minv11 + M12*Minv21 - 1): {:?}",
        t0.elapsed() / n
    );
}
