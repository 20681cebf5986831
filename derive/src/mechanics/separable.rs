//! The separable structure of a chain's mass matrix in its angle
//! coordinates, the structure its recursive algorithms exploit.
//!
//! In the absolute angles `theta` of an n-link chain (any serial chain of
//! bodies whose joint angles add up), an entry of `M_theta` couples two links
//! through the links between them only by their masses:
//! `M_theta[a][b] = alpha_a beta_b cos(theta_a - theta_b)` for `a < b`, with
//! `alpha_a = L_a` and `beta_b = c_b m_b + L_b (m_(b+1) + ... + m_n)`. Written
//! with single-angle factors, `cos(theta_a - theta_b) = cos theta_a cos
//! theta_b + sin theta_a sin theta_b`, the upper triangle is a sum of `R`
//! products of generators,
//!
//! `M_theta[a][b] = sum_r U_a^r V_b^r` (`a < b`), `U_a^r = alpha^r_a f_r(theta_a)`,
//! `V_b^r = beta^r_b g_r(theta_b)`, `f_r, g_r` each one of `1, cos, sin`,
//!
//! and the diagonal `D_a` depends on `theta_a` only: `M_theta` is
//! diagonal-plus-semiseparable. Then `M_theta y = r` is solved in `O(n R^2)`
//! (the Schur complements from the last index down are an `R x R` matrix:
//! the articulated-body recursion), and because `T = theta'^T M_theta
//! theta' / 2` exactly, its Coriolis and centrifugal terms are
//!
//! `c_a = 1/2 D_a' theta_a'^2 + U_a . sum_(b > a) V_b' theta_b'^2
//!        + V_a . sum_(b < a) U_b' theta_b'^2`
//!
//! (`'` on `D`, `U`, `V`: the derivative in their own angle), sums over the
//! links below and above `a` that cost `O(n R)` together.
//!
//! [`separable_mass`] finds the generators from the canonical entries of
//! `M_theta` (each written in single-angle factors, its parameter
//! coefficients factored `alpha_a beta_b` by monomial division) and checks
//! every entry exactly; `None` when an entry does not have this form.

use std::collections::HashMap;

use super::angle_coordinates::AngleCoordinates;
use crate::sym::{diff, Expr, Func, Node, Rational, Symbol};

/// A single-angle factor of a generator: `1`, `cos theta`, `sin theta`.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum AngleFactor {
    /// `1`.
    One,
    /// `cos theta`.
    Cos,
    /// `sin theta`.
    Sin,
}

impl AngleFactor {
    /// The factor at the angle `theta`.
    pub fn at(self, theta: Expr) -> Expr {
        match self {
            AngleFactor::One => Expr::one(),
            AngleFactor::Cos => theta.cos(),
            AngleFactor::Sin => theta.sin(),
        }
    }

    /// Its derivative in `theta`, at `theta`.
    pub fn derivative_at(self, theta: Expr) -> Expr {
        match self {
            AngleFactor::One => Expr::zero(),
            AngleFactor::Cos => -theta.sin(),
            AngleFactor::Sin => theta.cos(),
        }
    }
}

/// `M_theta = D + sum_r (U^r V^r^T upper + V^r U^r^T lower)` and the
/// potential gradient (see the module docs). Indices are those of the angle
/// coordinates.
#[derive(Clone, Debug)]
pub struct SeparableMass {
    /// `D_a(theta_a)`.
    pub diag: Vec<Expr>,
    /// The single-angle factors `(f_r, g_r)` of each generator pair.
    pub factors: Vec<(AngleFactor, AngleFactor)>,
    /// `alpha^r_a` (parameter-only), `[r][a]`.
    pub alpha: Vec<Vec<Expr>>,
    /// `beta^r_b` (parameter-only), `[r][b]`.
    pub beta: Vec<Vec<Expr>>,
    /// `dV/dtheta_a`.
    pub potential_gradient: Vec<Expr>,
}

impl SeparableMass {
    /// Number of coordinates.
    pub fn n(&self) -> usize {
        self.diag.len()
    }

    /// `U_a^r` at the angle symbol `theta_a`.
    pub fn u(&self, r: usize, a: usize, theta: Expr) -> Expr {
        self.alpha[r][a] * self.factors[r].0.at(theta)
    }

    /// `V_b^r` at the angle symbol `theta_b`.
    pub fn v(&self, r: usize, b: usize, theta: Expr) -> Expr {
        self.beta[r][b] * self.factors[r].1.at(theta)
    }

    /// `dU_a^r / dtheta_a`.
    pub fn du(&self, r: usize, a: usize, theta: Expr) -> Expr {
        self.alpha[r][a] * self.factors[r].0.derivative_at(theta)
    }

    /// `dV_b^r / dtheta_b`.
    pub fn dv(&self, r: usize, b: usize, theta: Expr) -> Expr {
        self.beta[r][b] * self.factors[r].1.derivative_at(theta)
    }
}

/// `e` as `sum c_k x_k` over the angle symbols (the constant dropped), or
/// `None` if it is not linear in them with integer coefficients in `{-1, 0, 1}`
/// on exactly the two angles `a`, `b` (or one of them).
fn pair_coefficients(arg: Expr, a: Symbol, b: Symbol, all: &[Symbol]) -> Option<(i64, i64)> {
    for s in arg.symbols() {
        if s != a && s != b && all.contains(&s) {
            return None;
        }
    }
    let coef = |s: Symbol| -> Option<i64> {
        let d = diff(arg, s).as_rational()?;
        if !d.is_integer() || d.numer().abs() > 1 {
            return None;
        }
        Some(d.numer() as i64)
    };
    let (ca, cb) = (coef(a)?, coef(b)?);
    let rest = arg - Expr::int(ca) * Expr::symbol(a) - Expr::int(cb) * Expr::symbol(b);
    if !rest.is_zero() {
        return None;
    }
    Some((ca, cb))
}

/// `cos(c theta)` / `sin(c theta)` for `c` in `{-1, 0, 1}` as a signed factor.
fn single(c: i64, sin: bool) -> (i64, AngleFactor) {
    match (c, sin) {
        (0, false) => (1, AngleFactor::One),
        (0, true) => (0, AngleFactor::One),
        (_, false) => (1, AngleFactor::Cos),
        (c, true) => (c, AngleFactor::Sin),
    }
}

/// The entry `e` (`a < b`) as coefficients of `f(theta_a) g(theta_b)`, or
/// `None` if it has another form.
fn split_entry(
    e: Expr,
    a: Symbol,
    b: Symbol,
    all: &[Symbol],
    moving: &mut dyn FnMut(Expr) -> bool,
) -> Option<HashMap<(AngleFactor, AngleFactor), Vec<Expr>>> {
    let mut out: HashMap<(AngleFactor, AngleFactor), Vec<Expr>> = HashMap::new();
    let terms: Vec<Expr> = match e.node() {
        Node::Add(ts) => ts.to_vec(),
        _ if e.is_zero() => Vec::new(),
        _ => vec![e],
    };
    for t in terms {
        let factors: Vec<Expr> = match t.node() {
            Node::Mul(fs) => fs.to_vec(),
            _ => vec![t],
        };
        let mut trig = None;
        let mut coef = Vec::new();
        for f in factors {
            if let Node::Func(fun @ (Func::Sin | Func::Cos), arg) = f.node() {
                if moving(*arg) {
                    if trig.is_some() {
                        return None;
                    }
                    trig = Some((*fun == Func::Sin, *arg));
                    continue;
                }
            }
            if moving(f) {
                return None;
            }
            coef.push(f);
        }
        let coef = Expr::mul_all(coef);
        // cos(ca x + cb y) = cos(ca x) cos(cb y) - sin(ca x) sin(cb y)
        // sin(ca x + cb y) = sin(ca x) cos(cb y) + cos(ca x) sin(cb y)
        let pieces: Vec<(i64, AngleFactor, AngleFactor)> = match trig {
            None => vec![(1, AngleFactor::One, AngleFactor::One)],
            Some((is_sin, arg)) => {
                let (ca, cb) = pair_coefficients(arg, a, b, all)?;
                let prod = |x: (i64, AngleFactor), y: (i64, AngleFactor), s: i64| {
                    (s * x.0 * y.0, x.1, y.1)
                };
                if is_sin {
                    vec![
                        prod(single(ca, true), single(cb, false), 1),
                        prod(single(ca, false), single(cb, true), 1),
                    ]
                } else {
                    vec![
                        prod(single(ca, false), single(cb, false), 1),
                        prod(single(ca, true), single(cb, true), -1),
                    ]
                }
            }
        };
        for (s, f, g) in pieces {
            if s != 0 {
                out.entry((f, g)).or_default().push(Expr::int(s) * coef);
            }
        }
    }
    Some(out)
}

/// The monomial terms of a sum.
fn terms_of(e: Expr) -> Vec<Expr> {
    match e.node() {
        Node::Add(ts) => ts.to_vec(),
        _ if e.is_zero() => Vec::new(),
        _ => vec![e],
    }
}

/// `(rational, [(base, integer power)])` of a monomial, or `None`.
fn monomial(t: Expr) -> Option<(Rational, Vec<(Expr, i64)>)> {
    let (c, rest) = t.coeff_and_rest();
    let factors: Vec<Expr> = match rest.node() {
        Node::Mul(fs) => fs.to_vec(),
        _ if rest.is_one() => Vec::new(),
        _ => vec![rest],
    };
    let mut v = Vec::new();
    for f in factors {
        let (b, x) = f.base_and_exp();
        let p = x.as_rational()?;
        if !p.is_integer() {
            return None;
        }
        v.push((b, p.numer() as i64));
    }
    Some((c, v))
}

/// The greatest common monomial of the terms of `es` (positive rational
/// content 1), or `None` if a term is not a monomial.
fn monomial_gcd(es: &[Expr]) -> Option<Expr> {
    let mut common: Option<Vec<(Expr, i64)>> = None;
    for e in es {
        for t in terms_of(*e) {
            let (_, v) = monomial(t)?;
            common = Some(match common {
                None => v,
                Some(c) => c
                    .into_iter()
                    .filter_map(|(b, p)| {
                        let q = v.iter().find(|(b2, _)| *b2 == b).map(|(_, q)| *q)?;
                        let m = if p > 0 && q > 0 { p.min(q) } else { 0 };
                        (m > 0).then_some((b, m))
                    })
                    .collect(),
            });
        }
    }
    let c = common?;
    Some(Expr::mul_all(c.into_iter().map(|(b, p)| b.powi(p))))
}

/// `e / m` term by term (`m` a monomial dividing every term).
fn divide(e: Expr, m: Expr) -> Expr {
    Expr::add_all(terms_of(e).into_iter().map(|t| t / m))
}

/// `m * e` expanded term by term.
fn times(m: Expr, e: Expr) -> Expr {
    Expr::add_all(terms_of(e).into_iter().map(|t| m * t))
}

/// `k` with `k * d = e` for a monomial `k`, found from the ratio of a term of
/// `e` to each term of `d`; `None` if there is none.
fn monomial_ratio(e: Expr, d: Expr) -> Option<Expr> {
    let first = *terms_of(e).first()?;
    for t in terms_of(d) {
        let k = first / t;
        if monomial(k).is_some_and(|(_, v)| v.iter().all(|(_, p)| *p > 0)) && times(k, d) == e {
            return Some(k);
        }
    }
    None
}

/// `K[a][b] = alpha_a beta_b` for all `a < b` (entries over the strictly
/// upper triangle, `k[a][b]`, zero where absent), or `None`.
fn rank_one(k: &[Vec<Expr>]) -> Option<(Vec<Expr>, Vec<Expr>)> {
    let n = k.len();
    let nonzero = |a: usize, b: usize| !k[a][b].is_zero();
    let mut alpha: Vec<Option<Expr>> = vec![None; n];
    for a in 0..n {
        let row: Vec<Expr> = (a + 1..n)
            .filter(|b| nonzero(a, *b))
            .map(|b| k[a][b])
            .collect();
        if row.is_empty() {
            alpha[a] = Some(Expr::zero());
        } else if row.len() >= 2 {
            alpha[a] = Some(monomial_gcd(&row)?);
        }
    }
    let mut beta: Vec<Option<Expr>> = vec![None; n];
    for b in 0..n {
        let col: Vec<usize> = (0..b).filter(|a| nonzero(*a, b)).collect();
        if col.is_empty() {
            beta[b] = Some(Expr::zero());
            continue;
        }
        if let Some(a) = col
            .iter()
            .copied()
            .find(|a| alpha[*a].is_some_and(|x| !x.is_zero()))
        {
            beta[b] = Some(divide(k[a][b], alpha[a].expect("found")));
        } else {
            let entries: Vec<Expr> = col.iter().map(|a| k[*a][b]).collect();
            beta[b] = Some(monomial_gcd(&entries)?);
        }
    }
    for a in 0..n {
        if alpha[a].is_some() {
            continue;
        }
        let b = (a + 1..n).find(|b| nonzero(a, *b))?;
        let d = beta[b]?;
        if d.is_zero() {
            return None;
        }
        alpha[a] = Some(if terms_of(d).len() == 1 {
            divide(k[a][b], d)
        } else {
            monomial_ratio(k[a][b], d)?
        });
    }
    let alpha: Vec<Expr> = alpha.into_iter().collect::<Option<_>>()?;
    let beta: Vec<Expr> = beta.into_iter().collect::<Option<_>>()?;
    for a in 0..n {
        for b in a + 1..n {
            let want = k[a][b];
            let got = if terms_of(alpha[a]).len() == 1 {
                times(alpha[a], beta[b])
            } else {
                times(beta[b], alpha[a])
            };
            if got != want {
                return None;
            }
        }
    }
    Some((alpha, beta))
}

/// The separable structure of `ac`'s mass matrix (see the module docs), or
/// `None` if its entries do not have that form or `T` is not exactly
/// `theta'^T M_theta theta' / 2` in the expanded energy.
pub fn separable_mass(ac: &AngleCoordinates) -> Option<SeparableMass> {
    let potential_gradient = ac.potential_gradient.clone()?;
    let n = ac.coords.len();
    let angles: Vec<Symbol> = ac.coords.iter().map(|c| c.q).collect();
    let states: Vec<Symbol> = ac.coords.iter().flat_map(|c| [c.q, c.qd]).collect();
    let mut memo: HashMap<Expr, bool> = HashMap::new();
    let mut moving = |e: Expr| -> bool {
        *memo
            .entry(e)
            .or_insert_with(|| e.symbols().iter().any(|s| states.contains(s)))
    };
    let m = &ac.equations.mass_matrix;
    let mut diag = Vec::with_capacity(n);
    for (a, row) in m.iter().enumerate() {
        let d = row[a];
        if d.symbols()
            .iter()
            .any(|s| states.contains(s) && *s != angles[a])
        {
            return None;
        }
        diag.push(d);
    }
    // coefficients of f(theta_a) g(theta_b), a < b
    let mut groups: HashMap<(AngleFactor, AngleFactor), Vec<Vec<Expr>>> = HashMap::new();
    for a in 0..n {
        for b in a + 1..n {
            let parts = split_entry(m[b][a], angles[a], angles[b], &angles, &mut moving)?;
            for (fg, ts) in parts {
                let k = groups
                    .entry(fg)
                    .or_insert_with(|| vec![vec![Expr::zero(); n]; n]);
                k[a][b] = Expr::add_all(ts);
            }
        }
    }
    let mut keys: Vec<(AngleFactor, AngleFactor)> = groups
        .iter()
        .filter(|(_, k)| k.iter().flatten().any(|e| !e.is_zero()))
        .map(|(fg, _)| *fg)
        .collect();
    keys.sort();
    let mut factors = Vec::new();
    let mut alpha = Vec::new();
    let mut beta = Vec::new();
    for fg in keys {
        let (al, be) = rank_one(&groups[&fg])?;
        factors.push(fg);
        alpha.push(al);
        beta.push(be);
    }
    Some(SeparableMass {
        diag,
        factors,
        alpha,
        beta,
        potential_gradient,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mechanics::angle_coordinates;
    use crate::model::{load_model_text, n_link_chain_source};
    use crate::sym::is_zero;

    #[test]
    fn chain_mass_matrix_is_separable_and_exact() {
        for n in [2, 5] {
            let m = load_model_text("chain.plant", &n_link_chain_source(n))
                .unwrap()
                .model;
            let ac = angle_coordinates(&m).unwrap().expect("angle frame");
            let sm = separable_mass(&ac).expect("separable");
            // cos*cos and sin*sin with the same coefficients
            assert_eq!(
                sm.factors,
                vec![
                    (AngleFactor::Cos, AngleFactor::Cos),
                    (AngleFactor::Sin, AngleFactor::Sin)
                ]
            );
            let th: Vec<Expr> = ac.coords.iter().map(|c| Expr::symbol(c.q)).collect();
            for a in 0..n {
                for b in a + 1..n {
                    let rebuilt: Expr = (0..sm.factors.len())
                        .map(|r| sm.u(r, a, th[a]) * sm.v(r, b, th[b]))
                        .sum();
                    let entry = ac.equations.mass_matrix[b][a];
                    assert!(is_zero(rebuilt - entry), "M[{b}][{a}] = {entry}");
                }
            }
            // alpha_a = L_a (link a's length couples it to every link below)
            if n > 2 {
                assert_eq!(sm.alpha[0][0], Expr::sym("L1"));
            }
        }
    }
}
