//! Values and first derivatives of expressions at a point by forward-mode
//! automatic differentiation over the DAG: one pass, no new expression nodes.
//!
//! The derivative rules are those of [`crate::sym::diff`] (`d sign(u) = 0`,
//! `d abs(u) = sign(u) du`), so `eval_jacobian` agrees with evaluating the
//! symbolic derivatives up to rounding, at a fraction of the cost on large
//! unexpanded expressions (a symbolic LDL^T solve, a zero-dynamics
//! right-hand side).

use std::collections::HashMap;

use super::expr::{Expr, Func, Node, Symbol};
use super::rational::Rational;

/// Values of `exprs` at `point` and their gradients with respect to `vars`
/// (`jac[i][j] = d exprs[i] / d vars[j]`). Symbols missing from `point` are NaN.
pub fn eval_jacobian(
    exprs: &[Expr],
    vars: &[Symbol],
    point: &HashMap<Symbol, f64>,
) -> (Vec<f64>, Vec<Vec<f64>>) {
    let m = vars.len();
    let width = m + 1;
    let var_index: HashMap<Symbol, usize> = vars.iter().enumerate().map(|(i, s)| (*s, i)).collect();
    let mut slot: super::fxhash::FxHashMap<Expr, usize> = Default::default();
    let mut data: Vec<f64> = Vec::new();
    let mut stack: Vec<(Expr, bool)> = exprs.iter().rev().map(|e| (*e, false)).collect();
    while let Some((e, ready)) = stack.pop() {
        if slot.contains_key(&e) {
            continue;
        }
        if !ready {
            stack.push((e, true));
            for c in e.children() {
                if !slot.contains_key(&c) {
                    stack.push((c, false));
                }
            }
            continue;
        }
        let base = data.len();
        data.resize(base + width, 0.0);
        let get = |c: Expr| slot[&c];
        match e.node() {
            Node::Rational(r) => data[base] = r.to_f64(),
            Node::Float(b) => data[base] = b.value(),
            Node::Symbol(s) => {
                data[base] = point.get(s).copied().unwrap_or(f64::NAN);
                if let Some(&j) = var_index.get(s) {
                    data[base + 1 + j] = 1.0;
                }
            }
            Node::Add(xs) => {
                for x in xs.iter() {
                    let o = get(*x);
                    for k in 0..width {
                        data[base + k] += data[o + k];
                    }
                }
            }
            Node::Mul(xs) => {
                // value and gradient by prefix products: (p, dp) <- (p*v, dp*v + p*dv)
                data[base] = 1.0;
                for x in xs.iter() {
                    let o = get(*x);
                    let (p, v) = (data[base], data[o]);
                    for k in 1..width {
                        data[base + k] = data[base + k] * v + p * data[o + k];
                    }
                    data[base] = p * v;
                }
            }
            Node::Pow(b, x) => {
                let ob = get(*b);
                let bv = data[ob];
                match x.as_rational() {
                    Some(r) => {
                        let (v, dv) = pow_rational(bv, r);
                        data[base] = v;
                        for k in 1..width {
                            data[base + k] = dv * data[ob + k];
                        }
                    }
                    None => {
                        let ox = get(*x);
                        let xv = data[ox];
                        let v = bv.powf(xv);
                        data[base] = v;
                        for k in 1..width {
                            let (db, dx) = (data[ob + k], data[ox + k]);
                            if db != 0.0 || dx != 0.0 {
                                data[base + k] = v * (dx * bv.ln() + xv * db / bv);
                            }
                        }
                    }
                }
            }
            Node::Func(f, u) => {
                let o = get(*u);
                let uv = data[o];
                let v = f.eval(uv);
                let slope = match f {
                    Func::Sin => uv.cos(),
                    Func::Cos => -uv.sin(),
                    Func::Tan => 1.0 + v * v,
                    Func::Exp => v,
                    Func::Ln => 1.0 / uv,
                    Func::Abs => Func::Sign.eval(uv),
                    Func::Sign => 0.0,
                    Func::Tanh => 1.0 - v * v,
                };
                data[base] = v;
                for k in 1..width {
                    let du = data[o + k];
                    if du != 0.0 {
                        data[base + k] = slope * du;
                    }
                }
            }
            Node::Named(_, d) => {
                let o = get(*d);
                for k in 0..width {
                    data[base + k] = data[o + k];
                }
            }
            Node::Atan2(y, x) => {
                let (oy, ox) = (get(*y), get(*x));
                let (yv, xv) = (data[oy], data[ox]);
                data[base] = yv.atan2(xv);
                let r2 = xv * xv + yv * yv;
                for k in 1..width {
                    let (dy, dx) = (data[oy + k], data[ox + k]);
                    if dy != 0.0 || dx != 0.0 {
                        data[base + k] = (xv * dy - yv * dx) / r2;
                    }
                }
            }
        }
        slot.insert(e, base);
    }
    let mut values = Vec::with_capacity(exprs.len());
    let mut jac = Vec::with_capacity(exprs.len());
    for e in exprs {
        let o = slot[e];
        values.push(data[o]);
        jac.push(data[o + 1..o + width].to_vec());
    }
    (values, jac)
}

/// `b^r` and its derivative `r b^(r-1)` (integer powers by `powi`, as
/// [`Expr::eval_with`] does).
fn pow_rational(b: f64, r: Rational) -> (f64, f64) {
    if r.is_integer() && r.numer().abs() <= i32::MAX as i128 {
        let n = r.numer() as i32;
        (
            b.powi(n),
            if n == 0 {
                0.0
            } else {
                n as f64 * b.powi(n - 1)
            },
        )
    } else {
        let x = r.to_f64();
        let v = if r == Rational::new(1, 2).expect("1/2") {
            b.sqrt()
        } else {
            b.powf(x)
        };
        (v, x * b.powf(x - 1.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sym::diff;

    #[test]
    fn matches_symbolic_derivatives() {
        let (x, y) = (Expr::sym("x"), Expr::sym("y"));
        let es = [
            x.sin() * y.powi(3) / (1 + x.powi(2)),
            Expr::atan2(y, x) + (x * y).exp().sqrt(),
            x.powi(-2) * y.cos().abs() + y.tanh() * x.ln(),
        ];
        let vars = [Symbol::new("x"), Symbol::new("y")];
        let mut p = HashMap::new();
        p.insert(vars[0], 0.7);
        p.insert(vars[1], -1.3);
        let (v, j) = eval_jacobian(&es, &vars, &p);
        for (i, e) in es.iter().enumerate() {
            assert!((v[i] - e.eval_map(&p)).abs() < 1e-12);
            for (k, s) in vars.iter().enumerate() {
                let want = diff(*e, *s).eval_map(&p);
                assert!(
                    (j[i][k] - want).abs() < 1e-11 * (1.0 + want.abs()),
                    "{i} {k}"
                );
            }
        }
    }
}
