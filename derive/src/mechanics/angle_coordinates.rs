//! The equations of motion in the coordinates of the trigonometric
//! arguments, for evaluation (generated code) rather than for reading.
//!
//! An n-link chain written in relative joint angles has `cos(q1 + ... + qk)`
//! everywhere: its mass matrix and bias, derived in `q`, have `O(n^3)` terms
//! even after collecting. In the absolute angles `theta = S q` (the arguments
//! of the sines and cosines, `S` a constant invertible matrix) the same
//! Lagrangian has `M_theta[a][b] = K_ab cos(theta_a - theta_b)`-like entries:
//! `O(n^2)` per-call terms in all. Since `q = S^-1 theta`, the Euler-Lagrange
//! equations transform as
//!
//! `M_theta theta'' + bias_theta = S^-T (Q0 + B u)`,  `q'' = S^-1 theta''`,
//!
//! with the generalised forces still evaluated in `q` (they are whatever the
//! model file says). [`angle_coordinates`] finds `S` (a basis of the
//! trigonometric arguments of `T` and `V`, most frequent first) and derives
//! `M_theta`, `bias_theta`; it returns `None` when `S` would be a permutation
//! (the coordinates already are the arguments) or an argument is not linear
//! in the coordinates.

use std::collections::HashMap;

use super::euler_lagrange::{derive_equations_from, Equations, MechanicsError};
use super::quadratic::quadratic_equations;
use crate::model::Model;
use crate::sym::{
    diff, substitute_symbols, Canonicalizer, CoordinateSymbols, Expr, Func, Node, Rational, Symbol,
};

/// Term budget of the canonical forms of `M_theta` and `bias_theta` (an
/// entry over budget stays as derived, which is exact but larger).
pub const CANONICAL_MAX_TERMS: usize = 40_000;

/// Term budget of the canonical form of the kinetic energy in the angle
/// coordinates (an n-link chain has about `n^3/6` terms: 20,825 at n = 50).
pub const CANONICAL_ENERGY_MAX_TERMS: usize = 400_000;

/// The equations of motion in the coordinates `theta = S q`.
#[derive(Clone, Debug)]
pub struct AngleCoordinates {
    /// `S` (row `k`: `theta_k` in terms of `q`).
    pub s: Vec<Vec<Rational>>,
    /// `S^-1`.
    pub s_inv: Vec<Vec<Rational>>,
    /// The symbols `theta_k`, `theta_k'`, `theta_k''` (internal names).
    pub coords: Vec<CoordinateSymbols>,
    /// `M_theta(theta)` and `bias_theta(theta, theta')`; its forces and input
    /// matrix are zero (the model's forces are applied as `S^-T (Q0 + B u)`).
    pub equations: Equations,
    /// `dV/dtheta` when the equations were read off the expanded energy
    /// with `T = theta'^T M_theta theta' / 2` exactly (then `bias_theta -
    /// dV/dtheta` is the Coriolis and centrifugal part of `M_theta` alone);
    /// `None` otherwise.
    pub potential_gradient: Option<Vec<Expr>>,
}

/// A trigonometric argument as rational coefficients on the coordinates
/// (the constant part dropped), or `None` if it is not linear in them.
fn linear_part(arg: Expr, coords: &[Symbol]) -> Option<Vec<Rational>> {
    let mut v = Vec::with_capacity(coords.len());
    for q in coords {
        let d = diff(arg, *q);
        v.push(d.as_rational()?);
    }
    Some(v)
}

fn trig_arguments(e: Expr, coords: &[Symbol], out: &mut HashMap<Vec<Rational>, usize>) -> bool {
    let mut seen = std::collections::HashSet::new();
    let mut stack = vec![e];
    while let Some(x) = stack.pop() {
        if !seen.insert(x) {
            continue;
        }
        if let Node::Func(Func::Sin | Func::Cos | Func::Tan, arg) = x.node() {
            if coords.iter().any(|q| arg.contains(*q)) {
                let Some(mut v) = linear_part(*arg, coords) else {
                    return false;
                };
                // direction only: primitive, first nonzero positive
                if let Some(first) = v.iter().find(|c| !c.is_zero()).copied() {
                    let inv = match Rational::ONE.checked_div(first) {
                        Some(i) => i,
                        None => return false,
                    };
                    for c in v.iter_mut() {
                        match c.checked_mul(inv) {
                            Some(x) => *c = x,
                            None => return false,
                        }
                    }
                    *out.entry(v).or_insert(0) += 1;
                }
            }
        }
        stack.extend(x.children());
    }
    true
}

/// The `n x n` identity matrix.
fn identity(n: usize) -> Vec<Vec<Rational>> {
    (0..n)
        .map(|i| {
            (0..n)
                .map(|j| {
                    if i == j {
                        Rational::ONE
                    } else {
                        Rational::ZERO
                    }
                })
                .collect()
        })
        .collect()
}

/// Inverse of a square rational matrix (`None` if singular or on overflow).
fn invert(m: &[Vec<Rational>]) -> Option<Vec<Vec<Rational>>> {
    let n = m.len();
    let mut a: Vec<Vec<Rational>> = m.to_vec();
    let mut inv = identity(n);
    for col in 0..n {
        let p = (col..n).find(|r| !a[*r][col].is_zero())?;
        a.swap(col, p);
        inv.swap(col, p);
        let piv = a[col][col];
        for j in 0..n {
            a[col][j] = a[col][j].checked_div(piv)?;
            inv[col][j] = inv[col][j].checked_div(piv)?;
        }
        for r in 0..n {
            if r == col || a[r][col].is_zero() {
                continue;
            }
            let f = a[r][col];
            for j in 0..n {
                a[r][j] = a[r][j].checked_sub(f.checked_mul(a[col][j])?)?;
                inv[r][j] = inv[r][j].checked_sub(f.checked_mul(inv[col][j])?)?;
            }
        }
    }
    Some(inv)
}

#[allow(clippy::needless_range_loop)] // row/column index loops over a matrix
fn rank(rows: &[Vec<Rational>]) -> usize {
    let mut a: Vec<Vec<Rational>> = rows.to_vec();
    let (mut r, cols) = (0, a.first().map_or(0, Vec::len));
    for c in 0..cols {
        let Some(p) = (r..a.len()).find(|i| !a[*i][c].is_zero()) else {
            continue;
        };
        a.swap(r, p);
        for i in 0..a.len() {
            if i != r && !a[i][c].is_zero() {
                let Some(f) = a[i][c].checked_div(a[r][c]) else {
                    return 0;
                };
                for j in 0..cols {
                    let Some(x) = f.checked_mul(a[r][j]).and_then(|x| a[i][j].checked_sub(x))
                    else {
                        return 0;
                    };
                    a[i][j] = x;
                }
            }
        }
        r += 1;
    }
    r
}

/// The equations of `model` in the coordinates of its trigonometric
/// arguments, or `None` if they are the model's coordinates already (see
/// the module docs).
pub fn angle_coordinates(model: &Model) -> Result<Option<AngleCoordinates>, MechanicsError> {
    let coords = model.coordinate_symbols();
    let n = coords.len();
    let qs: Vec<Symbol> = coords.iter().map(|c| c.q).collect();
    let mut counts = HashMap::new();
    if !trig_arguments(model.kinetic, &qs, &mut counts)
        || !trig_arguments(model.potential, &qs, &mut counts)
    {
        return Ok(None);
    }
    let mut args: Vec<(Vec<Rational>, usize)> = counts.into_iter().collect();
    let nnz = |v: &[Rational]| v.iter().filter(|c| !c.is_zero()).count();
    args.sort_by(|a, b| {
        b.1.cmp(&a.1)
            .then(nnz(&a.0).cmp(&nnz(&b.0)))
            .then_with(|| a.0.cmp(&b.0))
    });
    // the arguments, most frequent first, then the coordinates themselves
    let unit = identity(n);
    let mut s: Vec<Vec<Rational>> = Vec::new();
    for v in args.iter().map(|(v, _)| v).chain(&unit) {
        if s.len() == n {
            break;
        }
        s.push(v.clone());
        if rank(&s) < s.len() {
            s.pop();
        }
    }
    if s.len() < n || s.iter().all(|row| nnz(row) == 1) {
        return Ok(None);
    }
    let Some(s_inv) = invert(&s) else {
        return Ok(None);
    };
    let theta: Vec<CoordinateSymbols> = (0..n)
        .map(|k| CoordinateSymbols::new(&format!("theta\u{2032}{}", k + 1)))
        .collect();
    // q = S^-1 theta, q' = S^-1 theta'
    let mut map: HashMap<Symbol, Expr> = HashMap::new();
    for i in 0..n {
        let pos: Expr = (0..n)
            .map(|k| Expr::rational(s_inv[i][k]) * Expr::symbol(theta[k].q))
            .sum();
        let vel: Expr = (0..n)
            .map(|k| Expr::rational(s_inv[i][k]) * Expr::symbol(theta[k].qd))
            .sum();
        map.insert(coords[i].q, pos);
        map.insert(coords[i].qd, vel);
    }
    let kinetic = substitute_symbols(model.kinetic, &map);
    let potential = substitute_symbols(model.potential, &map);
    // the energy in canonical (Fourier) form, `cos(theta_a - theta_b)`
    // collected and `sin^2 + cos^2` gone: the equations are then read off it
    // term by term; otherwise derived from the energy as written and each
    // entry brought to canonical form (the raw entry kept where the budget is
    // exceeded)
    let mut canon = Canonicalizer::new(CANONICAL_MAX_TERMS);
    let expanded = Canonicalizer::new(CANONICAL_ENERGY_MAX_TERMS)
        .try_canonical(kinetic)
        .ok()
        .and_then(|t| {
            let v = canon.try_canonical(potential).ok()?;
            quadratic_equations(&theta, t, v)
        });
    if let Some(q) = expanded {
        return Ok(Some(AngleCoordinates {
            s,
            s_inv,
            coords: theta,
            equations: q.equations,
            potential_gradient: q.homogeneous.then_some(q.potential_gradient),
        }));
    }
    let zero_forces = vec![Expr::zero(); n];
    let mut equations = derive_equations_from(&theta, &[], kinetic, potential, &zero_forces)?;
    for row in equations.mass_matrix.iter_mut() {
        for e in row.iter_mut() {
            *e = canon.try_canonical(*e).unwrap_or(*e);
        }
    }
    for e in equations.bias.iter_mut() {
        *e = canon.try_canonical(*e).unwrap_or(*e);
    }
    Ok(Some(AngleCoordinates {
        s,
        s_inv,
        coords: theta,
        equations,
        potential_gradient: None,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{load_model_text, n_link_chain_source};

    #[test]
    fn chain_uses_absolute_angles() {
        let m = load_model_text("chain3.plant", &n_link_chain_source(3))
            .unwrap()
            .model;
        let ac = angle_coordinates(&m)
            .unwrap()
            .expect("a change of coordinates");
        // theta_k = q1 + ... + qk
        for k in 0..3 {
            for j in 0..3 {
                let want = if j <= k {
                    Rational::ONE
                } else {
                    Rational::ZERO
                };
                assert_eq!(ac.s[k][j], want);
            }
        }
        let rp = include_str!("../../../models/pendubot.plant");
        let m = load_model_text("pendubot.plant", rp).unwrap().model;
        assert!(angle_coordinates(&m).unwrap().is_none() || m.coordinates.len() == 2);
    }
}
