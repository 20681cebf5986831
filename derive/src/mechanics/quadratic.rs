//! The Euler-Lagrange equations read term by term off an expanded kinetic
//! energy, instead of differentiating it twice as one expression.
//!
//! A kinetic energy in canonical (expanded) form is a sum of terms
//! `R(q) nu(q')`, `nu` a monomial in the velocities. Each term contributes
//!
//! * to `M`: `M_ab += R d^2 nu / dq_a' dq_b'`;
//! * to `bias`: `bias_a += (sum_c dR/dq_c q_c') dnu/dq_a' - dR/dq_a nu`
//!
//! (`d/dt(dT/dq_a') - dT/dq_a` without the accelerations), and the potential
//! `bias_a += dV/dq_a`. The work is proportional to the number of terms (each
//! `R` is one product), where differentiating the whole energy costs a pass
//! over it per coordinate pair. Terms that cancel (the `q_a' q_b'` parts of
//! the Coriolis terms) are collected by the sums.

use std::collections::HashMap;

use super::euler_lagrange::Equations;
use crate::sym::{diff, CoordinateSymbols, Expr, Node, Symbol};

/// A term `R(q) nu(q')` of the energy: `R` and the velocity powers of `nu`
/// (coordinate index, power).
struct Term {
    r: Expr,
    nu: Vec<(usize, u32)>,
}

/// The factors of `c * q_a' * ... ` for the velocity powers `nu`, times `extra`.
fn product(c: i64, nu: &[(usize, u32)], qd: &[Expr], extra: &[Expr]) -> Expr {
    let mut fs: Vec<Expr> = Vec::with_capacity(extra.len() + nu.len() + 1);
    fs.extend_from_slice(extra);
    for &(k, p) in nu {
        fs.push(if p == 1 { qd[k] } else { qd[k].powi(p as i64) });
    }
    if c != 1 {
        fs.push(Expr::int(c));
    }
    Expr::mul_all(fs)
}

/// `d nu / d q_a'` as (coefficient, remaining monomial), or `None` if `q_a'`
/// does not occur.
fn d_velocity(nu: &[(usize, u32)], a: usize) -> Option<(u32, Vec<(usize, u32)>)> {
    let i = nu.iter().position(|&(k, _)| k == a)?;
    let p = nu[i].1;
    let mut rest = nu.to_vec();
    if p == 1 {
        rest.remove(i);
    } else {
        rest[i].1 = p - 1;
    }
    Some((p, rest))
}

/// Split an expanded energy into terms, or `None` if a term is not a product
/// of a velocity-free factor and integer powers of velocities.
fn terms(e: Expr, vel: &HashMap<Symbol, usize>) -> Option<Vec<Term>> {
    let parts: Vec<Expr> = match e.node() {
        Node::Add(ts) => ts.to_vec(),
        _ if e.is_zero() => Vec::new(),
        _ => vec![e],
    };
    let mut moving: HashMap<Expr, bool> = HashMap::new();
    let mut velocity_power = |f: Expr| -> Option<Option<(usize, u32)>> {
        let (b, x) = f.base_and_exp();
        if let Some(k) = b.as_symbol().and_then(|s| vel.get(&s)) {
            let p = x.as_rational()?;
            if !p.is_integer() || p.numer() < 1 || p.numer() > 2 {
                return None;
            }
            return Some(Some((*k, p.numer() as u32)));
        }
        let m = *moving
            .entry(f)
            .or_insert_with(|| f.symbols().iter().any(|s| vel.contains_key(s)));
        if m {
            return None;
        }
        Some(None)
    };
    let mut out = Vec::with_capacity(parts.len());
    for t in parts {
        let factors: Vec<Expr> = match t.node() {
            Node::Mul(fs) => fs.to_vec(),
            _ => vec![t],
        };
        let mut r = Vec::with_capacity(factors.len());
        let mut nu: Vec<(usize, u32)> = Vec::new();
        for f in factors {
            match velocity_power(f)? {
                Some((k, p)) => match nu.iter_mut().find(|(j, _)| *j == k) {
                    Some(x) => x.1 += p,
                    None => nu.push((k, p)),
                },
                None => r.push(f),
            }
        }
        if nu.iter().map(|(_, p)| p).sum::<u32>() > 2 {
            return None;
        }
        nu.sort_unstable();
        out.push(Term {
            r: Expr::mul_all(r),
            nu,
        });
    }
    Some(out)
}

/// The result of [`quadratic_equations`].
pub(crate) struct QuadraticEquations {
    /// `M` and `bias` (no forces, no inputs).
    pub equations: Equations,
    /// `dV/dq_a`, the part of `bias` from the potential.
    pub potential_gradient: Vec<Expr>,
    /// Every term of `T` is of degree exactly 2 in the velocities:
    /// `T = q'^T M q' / 2`, so `bias - dV/dq` is the Coriolis and
    /// centrifugal part of `M` alone.
    pub homogeneous: bool,
}

/// The Euler-Lagrange equations (no forces, no inputs) of the expanded
/// kinetic energy `kinetic` and the potential `potential` in the coordinates
/// `coords`, or `None` if `kinetic` is not a sum of velocity-free factors
/// times velocity monomials of degree at most 2 (then differentiate it as a
/// whole, [`super::derive_equations_from`]).
pub(crate) fn quadratic_equations(
    coords: &[CoordinateSymbols],
    kinetic: Expr,
    potential: Expr,
) -> Option<QuadraticEquations> {
    let n = coords.len();
    let vel: HashMap<Symbol, usize> = coords.iter().enumerate().map(|(i, c)| (c.qd, i)).collect();
    let pos: HashMap<Symbol, usize> = coords.iter().enumerate().map(|(i, c)| (c.q, i)).collect();
    let qd: Vec<Expr> = coords.iter().map(|c| Expr::symbol(c.qd)).collect();
    if vel.keys().any(|s| potential.contains(*s)) {
        return None;
    }
    let terms = terms(kinetic, &vel)?;
    let mut m: Vec<Vec<Vec<Expr>>> = vec![vec![Vec::new(); n]; n];
    let mut bias: Vec<Vec<Expr>> = vec![Vec::new(); n];
    for t in &terms {
        // the coordinates R depends on, with dR/dq_c
        let mut deps: Vec<(usize, Expr)> =
            t.r.symbols()
                .into_iter()
                .filter_map(|s| pos.get(&s).map(|&c| (c, diff(t.r, s))))
                .filter(|(_, d)| !d.is_zero())
                .collect();
        deps.sort_unstable_by_key(|(c, _)| *c);
        for &(a, _) in &t.nu {
            let (pa, rest) = d_velocity(&t.nu, a).expect("a occurs in nu");
            for &(b, _) in &rest {
                let (pb, rest2) = d_velocity(&rest, b).expect("b occurs in the rest");
                m[a][b].push(product((pa * pb) as i64, &rest2, &qd, &[t.r]));
            }
            for (c, dr) in &deps {
                bias[a].push(product(pa as i64, &rest, &qd, &[*dr, qd[*c]]));
            }
        }
        for (c, dr) in &deps {
            bias[*c].push(product(-1, &t.nu, &qd, &[*dr]));
        }
    }
    let homogeneous = terms
        .iter()
        .all(|t| t.nu.iter().map(|(_, p)| p).sum::<u32>() == 2);
    let potential_gradient: Vec<Expr> = coords.iter().map(|c| diff(potential, c.q)).collect();
    for (a, dv) in potential_gradient.iter().enumerate() {
        if !dv.is_zero() {
            bias[a].push(*dv);
        }
    }
    let equations = Equations {
        coords: coords.to_vec(),
        inputs: Vec::new(),
        mass_matrix: m
            .into_iter()
            .map(|row| row.into_iter().map(Expr::add_all).collect())
            .collect(),
        bias: bias.into_iter().map(Expr::add_all).collect(),
        forces: vec![Expr::zero(); n],
        input_matrix: vec![Vec::new(); n],
        angles: None,
    };
    Some(QuadraticEquations {
        equations,
        potential_gradient,
        homogeneous,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mechanics::derive_equations_from;
    use crate::sym::is_zero;

    #[test]
    fn agrees_with_differentiating_the_whole_energy() {
        // a double pendulum in absolute angles, expanded by hand
        let c = [CoordinateSymbols::new("a"), CoordinateSymbols::new("b")];
        let (a, b) = (Expr::symbol(c[0].q), Expr::symbol(c[1].q));
        let (ad, bd) = (Expr::symbol(c[0].qd), Expr::symbol(c[1].qd));
        let (k1, k2, k3, g) = (
            Expr::sym("k1"),
            Expr::sym("k2"),
            Expr::sym("k3"),
            Expr::sym("g"),
        );
        let t = Expr::frac(1, 2) * k1 * ad.powi(2)
            + Expr::frac(1, 2) * k2 * bd.powi(2)
            + k3 * (a - b).cos() * ad * bd
            + Expr::sym("k4") * a.sin() * bd;
        let v = g * (a.cos() + b.cos());
        let fast = quadratic_equations(&c, t, v).expect("quadratic");
        assert!(!fast.homogeneous);
        let fast = fast.equations;
        let slow = derive_equations_from(&c, &[], t, v, &[Expr::zero(), Expr::zero()]).unwrap();
        for i in 0..2 {
            for j in 0..2 {
                assert!(is_zero(fast.mass_matrix[i][j] - slow.mass_matrix[i][j]));
            }
            assert!(is_zero(fast.bias[i] - slow.bias[i]), "{}", fast.bias[i]);
        }
        // a velocity inside a function is not a quadratic form
        assert!(quadratic_equations(&c, (ad * a).cos(), v).is_none());
    }
}
