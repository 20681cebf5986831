//! Symbolic differentiation and the total time derivative.

use super::fxhash::FxHashMap;

use super::expr::{Expr, Func, Node, Symbol};

/// `d e / d x`, memoised over the DAG. `sign` and `abs` follow the usual
/// almost-everywhere rules (`d sign(u) = 0`, `d abs(u) = sign(u) du`).
pub fn diff(e: Expr, x: Symbol) -> Expr {
    let mut memo = FxHashMap::default();
    diff_memo(e, x, &mut memo)
}

fn diff_memo(e: Expr, x: Symbol, memo: &mut FxHashMap<Expr, Expr>) -> Expr {
    if let Some(&d) = memo.get(&e) {
        return d;
    }
    let d = match e.node() {
        Node::Rational(_) | Node::Float(_) => Expr::zero(),
        Node::Symbol(s) => {
            if *s == x {
                Expr::one()
            } else {
                Expr::zero()
            }
        }
        Node::Add(ts) => Expr::add_all(ts.iter().map(|t| diff_memo(*t, x, memo))),
        Node::Mul(fs) => {
            let mut terms = Vec::with_capacity(fs.len());
            for i in 0..fs.len() {
                let di = diff_memo(fs[i], x, memo);
                if di.is_zero() {
                    continue;
                }
                let others = fs
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, f)| *f);
                terms.push(Expr::mul_all(others.chain(std::iter::once(di))));
            }
            Expr::add_all(terms)
        }
        Node::Pow(b, p) => {
            let db = diff_memo(*b, x, memo);
            if p.is_constant() {
                if db.is_zero() {
                    return memoise(memo, e, Expr::zero());
                }
                *p * b.pow(*p - 1) * db
            } else {
                let dp = diff_memo(*p, x, memo);
                if dp.is_zero() && db.is_zero() {
                    return memoise(memo, e, Expr::zero());
                }
                // d(b^p) = b^p * (dp*ln b + p*db/b)
                e * (dp * b.ln() + *p * db / *b)
            }
        }
        Node::Func(f, u) => {
            let du = diff_memo(*u, x, memo);
            if du.is_zero() {
                return memoise(memo, e, Expr::zero());
            }
            let outer = match f {
                Func::Sin => u.cos(),
                Func::Cos => -u.sin(),
                Func::Tan => 1 + e.powi(2),
                Func::Exp => e,
                Func::Ln => u.recip(),
                Func::Abs => u.sign(),
                Func::Sign => Expr::zero(),
                Func::Tanh => 1 - e.powi(2),
            };
            outer * du
        }
        Node::Named(_, d) => diff_memo(*d, x, memo),
        Node::Atan2(y, xx) => {
            let dy = diff_memo(*y, x, memo);
            let dx = diff_memo(*xx, x, memo);
            if dy.is_zero() && dx.is_zero() {
                return memoise(memo, e, Expr::zero());
            }
            (*xx * dy - *y * dx) / (xx.powi(2) + y.powi(2))
        }
    };
    memo.insert(e, d);
    d
}

fn memoise(memo: &mut FxHashMap<Expr, Expr>, e: Expr, d: Expr) -> Expr {
    memo.insert(e, d);
    d
}

/// One generalised coordinate with its velocity and acceleration symbols
/// (`theta`, `theta'`, `theta''`).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub struct CoordinateSymbols {
    /// Position `q`.
    pub q: Symbol,
    /// Velocity `q'`.
    pub qd: Symbol,
    /// Acceleration `q''`.
    pub qdd: Symbol,
}

impl CoordinateSymbols {
    /// The symbols `name`, `name'`, `name''`.
    pub fn new(name: &str) -> CoordinateSymbols {
        CoordinateSymbols {
            q: Symbol::new(name),
            qd: Symbol::new(&format!("{name}'")),
            qdd: Symbol::new(&format!("{name}''")),
        }
    }
}

/// Total time derivative over the coordinates:
/// `d/dt e = sum_i (de/dq_i) q_i' + (de/dq_i') q_i''`.
/// Other symbols (parameters, inputs) are taken as constant in time.
pub fn time_derivative(e: Expr, coords: &[CoordinateSymbols]) -> Expr {
    let mut terms = Vec::with_capacity(2 * coords.len());
    for c in coords {
        terms.push(diff(e, c.q) * Expr::symbol(c.qd));
        terms.push(diff(e, c.qd) * Expr::symbol(c.qdd));
    }
    Expr::add_all(terms)
}

/// Jacobian `d f_i / d x_j` of a vector of expressions.
pub fn jacobian(f: &[Expr], x: &[Symbol]) -> Vec<Vec<Expr>> {
    f.iter()
        .map(|fi| x.iter().map(|xj| diff(*fi, *xj)).collect())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basic_rules() {
        let x = Expr::sym("x");
        let s = Symbol::new("x");
        assert_eq!(diff(x.powi(3), s), 3 * x.powi(2));
        assert_eq!(diff(x.sin() * x, s), x.sin() + x * x.cos());
        assert_eq!(diff(Expr::sym("y"), s), Expr::zero());
    }

    #[test]
    fn time_derivative_of_kinetic_term() {
        let c = CoordinateSymbols::new("q");
        let q = Expr::symbol(c.q);
        let qd = Expr::symbol(c.qd);
        let qdd = Expr::symbol(c.qdd);
        // d/dt (cos(q) q') = -sin(q) q'^2 + cos(q) q''
        let e = q.cos() * qd;
        assert_eq!(
            time_derivative(e, &[c]),
            -q.sin() * qd.powi(2) + q.cos() * qdd
        );
    }
}
