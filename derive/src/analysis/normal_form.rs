//! Byrnes-Isidori normal form of a single-input mechanical system with respect
//! to an output of relative degree `r`:
//! `xi = (h, L_f h, ..., L_f^(r-1) h)` and `n - r` complementary coordinates
//! `eta` with `L_g eta = 0`, found among candidates suggested by the mechanical
//! structure, with the Jacobian of `(xi, eta)` checked nonsingular at the
//! operating point. `L_g eta = 0` and `eta' = L_f eta` come from the structure
//! (`M q'' = Q0 - bias + B u`), never from the expanded `M^-1`:
//!
//! 1. coordinates `q_j` not already in `xi`: `L_g q_j = 0` (the input acts on
//!    accelerations only), `q_j' = L_f q_j`;
//! 2. momenta `p = dT/dq'` combined so that the input cancels,
//!    `eta = p_j - (B_j/B_k) p_k` (just `p_j` when row `j` of `B` is zero: the
//!    momentum conjugate to an unactuated coordinate): `L_g eta = B_j - B_j = 0`
//!    exactly, and by Euler-Lagrange `p' = dL/dq + Q0 + B u`, so
//!    `eta' = (dL/dq_j + Q0_j) - c (dL/dq_k + Q0_k) - (dc/dt) p_k` with
//!    `c = B_j/B_k` (a function of the coordinates);
//! 3. velocities `q_j'` not in `xi`, accepted only where `L_g q_j' = (M^-1 B)_j`
//!    is exactly zero (tried only when the expanded forms are within reach).

use std::collections::HashMap;
use std::fmt;

use nalgebra::DMatrix;

use super::lie::LieChain;
use super::mechanical::ANALYSIS_MAX_TERMS;
use crate::control::Derivation;
use crate::model::{Model, ParameterValues};
use crate::sym::{diff, eval_jacobian, is_zero, Canonicalizer, Expr, Symbol};

/// Why a normal form could not be built.
#[derive(Clone, Debug, PartialEq)]
pub enum NormalFormError {
    /// Fewer than `n - r` independent candidates with `L_g eta = 0` were found.
    NoComplement {
        /// How many complementary coordinates are needed (`n - r`).
        needed: usize,
        /// The ones accepted.
        found: Vec<String>,
        /// Every candidate tried, with the reason it was rejected.
        rejected: Vec<String>,
    },
    /// The `xi` coordinates are dependent at the operating point.
    DependentOutputChain {
        /// Numeric rank of `d xi / dx` at the operating point.
        rank: usize,
        /// The relative degree.
        relative_degree: usize,
    },
    /// The operating point has the wrong size.
    WrongSize {
        /// State dimension.
        expected: usize,
        /// Given.
        found: usize,
    },
    /// A Jacobian entry is not finite at the operating point.
    NotFinite {
        /// The entry.
        entry: String,
    },
}

impl fmt::Display for NormalFormError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NormalFormError::NoComplement { needed, found, rejected } => {
                write!(
                    f,
                    "no normal form found: {needed} complementary coordinates with L_g eta = 0 are needed, \
                     {} found",
                    found.len()
                )?;
                if !found.is_empty() {
                    write!(f, " ({})", found.join(", "))?;
                }
                if !rejected.is_empty() {
                    write!(f, "; rejected: {}", rejected.join("; "))?;
                }
                Ok(())
            }
            NormalFormError::DependentOutputChain { rank, relative_degree } => write!(
                f,
                "h, L_f h, ... are dependent at the operating point (rank {rank} < relative degree {relative_degree})"
            ),
            NormalFormError::WrongSize { expected, found } => {
                write!(f, "the operating point has {found} state values, the model has {expected}")
            }
            NormalFormError::NotFinite { entry } => write!(f, "{entry} is not finite at the operating point"),
        }
    }
}

impl std::error::Error for NormalFormError {}

/// Normal-form coordinates `z = (xi, eta)`.
#[derive(Clone, Debug)]
pub struct NormalForm {
    /// The state symbols `x` (model order).
    pub state: Vec<Symbol>,
    /// `xi = (h, L_f h, ..., L_f^(r-1) h)`.
    pub xi: Vec<Expr>,
    /// Complementary coordinates with `L_g eta = 0` (simplified).
    pub eta: Vec<Expr>,
    /// Where each `eta` came from, e.g. `coordinate theta`,
    /// `momentum conjugate to alpha`.
    pub eta_origin: Vec<String>,
    /// `L_f eta` (simplified): since `L_g eta = 0`, `eta' = L_f eta`.
    pub eta_dot: Vec<Expr>,
    /// `L_f eta` in words, e.g. `dL/dalpha + Q0[alpha]`.
    pub eta_dot_text: Vec<String>,
    /// The operating point the Jacobian was checked at.
    pub at: Vec<f64>,
    /// Singular values of `d(xi, eta)/dx` at the operating point.
    pub jacobian_singular_values: Vec<f64>,
}

/// Relative tolerance for the numeric rank of `d(xi, eta)/dx`.
const RANK_TOL: f64 = 1e-9;

fn numeric_rank(rows: &[Vec<f64>]) -> (usize, Vec<f64>) {
    if rows.is_empty() {
        return (0, Vec::new());
    }
    let m = DMatrix::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j]);
    let sv: Vec<f64> = m.singular_values().iter().copied().collect();
    let max = sv.iter().copied().fold(0.0_f64, f64::max);
    let rank = sv
        .iter()
        .filter(|s| **s > RANK_TOL * max.max(1e-300))
        .count();
    (rank, sv)
}

/// The numeric gradient of `e` at `at` (forward-mode, exact up to rounding).
fn gradient(
    e: Expr,
    state: &[Symbol],
    at: &HashMap<Symbol, f64>,
    what: &str,
) -> Result<Vec<f64>, NormalFormError> {
    let (_, jac) = eval_jacobian(&[e], state, at);
    let row = jac.into_iter().next().unwrap_or_default();
    if let Some(k) = row.iter().position(|v| !v.is_finite()) {
        return Err(NormalFormError::NotFinite {
            entry: format!("d({what})/d{}", state[k].name()),
        });
    }
    Ok(row)
}

/// A candidate complementary coordinate: `(eta, L_f eta, origin, L_f eta in
/// words)`.
type Candidate = (Expr, Expr, String, String);

/// Candidate complementary coordinates suggested by the mechanical structure,
/// with `L_f eta` (see the module docs); those rejected before the rank test,
/// with the reason.
pub fn candidates(
    model: &Model,
    derivation: &Derivation,
    chain: &LieChain,
) -> (Vec<Candidate>, Vec<String>) {
    let eqs = &derivation.equations;
    let r = chain.relative_degree;
    let xi = &chain.lf[..r];
    let n = eqs.coords.len();
    let mut out = Vec::new();
    let mut rejected = Vec::new();
    let explicit = chain
        .mechanical
        .as_ref()
        .is_none_or(|m| m.not_expanded.is_none());
    // simplified for printing only when the analysis is expanded (small
    // systems); otherwise they stay as derived (exact)
    let mut canon = Canonicalizer::new(ANALYSIS_MAX_TERMS);
    let mut tidy = |e: Expr| {
        if explicit {
            canon.try_simplify(e).unwrap_or(e)
        } else {
            e
        }
    };
    // Coordinates in which a position-level output `h(q)` is linear (a
    // nonzero coefficient free of the coordinates, e.g. the cart position
    // `x` in a tip position `x + L1*sin(th1) + L2*sin(th2)`) come last, so
    // that `xi = 0` can be solved for one of them.
    let positions: Vec<Symbol> = eqs.coords.iter().map(|c| c.q).collect();
    let linear_in = |c: &crate::sym::CoordinateSymbols| {
        let h = xi[0];
        if eqs.coords.iter().any(|k| h.contains(k.qd)) {
            return false;
        }
        let d = diff(h, c.q);
        !is_zero(d) && !positions.iter().any(|s| d.contains(*s))
    };
    let (last, first): (Vec<&crate::sym::CoordinateSymbols>, Vec<_>) =
        eqs.coords.iter().partition(|c| linear_in(c));
    for c in first.into_iter().chain(last) {
        let q = Expr::symbol(c.q);
        if !xi.contains(&q) {
            out.push((
                q,
                Expr::symbol(c.qd),
                format!("coordinate {}", c.q.name()),
                c.qd.name().to_string(),
            ));
        }
    }
    let lagrangian = model.kinetic - model.potential;
    let momentum: Vec<Expr> = eqs
        .coords
        .iter()
        .map(|c| diff(model.kinetic, c.qd))
        .collect();
    let rate: Vec<Expr> = (0..n)
        .map(|j| diff(lagrangian, eqs.coords[j].q) + eqs.forces[j])
        .collect();
    let velocities: Vec<Symbol> = eqs.coords.iter().map(|c| c.qd).collect();
    if eqs.inputs.len() == 1 {
        let b: Vec<Expr> = eqs.input_matrix.iter().map(|row| row[0]).collect();
        let zero = |e: Expr| e.is_zero() || is_zero(e);
        let pivot = (0..n).find(|k| !zero(b[*k]));
        for j in 0..n {
            if zero(b[j]) {
                let q = eqs.coords[j].q.name();
                out.push((
                    tidy(momentum[j]),
                    tidy(rate[j]),
                    format!("momentum conjugate to {q}"),
                    format!("dL/d{q} + Q0[{q}]"),
                ));
                continue;
            }
            let Some(k) = pivot.filter(|k| *k != j) else {
                continue;
            };
            let c = tidy(b[j] / b[k]);
            let (qj, qk) = (eqs.coords[j].q.name(), eqs.coords[k].q.name());
            if velocities.iter().any(|v| c.contains(*v)) {
                rejected.push(format!(
                    "p_{qj} - c p_{qk} (c = B[{qj}]/B[{qk}] = {c} depends on velocities)"
                ));
                continue;
            }
            let dc: Expr = eqs
                .coords
                .iter()
                .map(|s| diff(c, s.q) * Expr::symbol(s.qd))
                .sum();
            out.push((
                tidy(momentum[j] - c * momentum[k]),
                tidy(rate[j] - c * rate[k] - dc * momentum[k]),
                format!("momentum combination p_{qj} - ({c})*p_{qk} (the input cancels)"),
                format!("dL/d{qj} + Q0[{qj}] - c (dL/d{qk} + Q0[{qk}]) - c' p_{qk}"),
            ));
        }
    }
    for (i, c) in eqs.coords.iter().enumerate() {
        let qd = Expr::symbol(c.qd);
        if xi.contains(&qd) {
            continue;
        }
        let what = format!("velocity {}", c.qd.name());
        if !explicit {
            rejected.push(format!(
                "{what} (L_g q' needs the expanded M^-1, not computed)"
            ));
            continue;
        }
        match derivation.affine() {
            Ok(ca) => {
                let gi = ca.g[n + i][0];
                if gi.is_zero() || is_zero(gi) {
                    out.push((qd, ca.f[n + i], what, format!("{}''", c.q.name())));
                } else {
                    rejected.push(format!("{what} (L_g = {gi} is not 0)"));
                }
            }
            Err(e) => rejected.push(format!("{what} ({e})")),
        }
    }
    (out, rejected)
}

/// Build the normal form of the output whose Lie chain is `chain`, checking
/// the coordinate change at the state `at` (model order; `None` = origin) with
/// the parameter `values`.
pub fn normal_form(
    model: &Model,
    derivation: &Derivation,
    chain: &LieChain,
    values: &ParameterValues,
    at: Option<&[f64]>,
) -> Result<NormalForm, NormalFormError> {
    let state = model.state_symbols();
    let nx = state.len();
    let x0: Vec<f64> = match at {
        Some(x) if x.len() != nx => {
            return Err(NormalFormError::WrongSize {
                expected: nx,
                found: x.len(),
            })
        }
        Some(x) => x.to_vec(),
        None => vec![0.0; nx],
    };
    let mut point = values.symbol_map(model);
    for (s, v) in state.iter().zip(&x0) {
        point.insert(*s, *v);
    }
    let r = chain.relative_degree;
    let xi: Vec<Expr> = chain.lf[..r].to_vec();
    let mut rows = Vec::with_capacity(nx);
    for (k, e) in xi.iter().enumerate() {
        rows.push(gradient(*e, &state, &point, &format!("L_f^{k} h"))?);
    }
    let (rank, _) = numeric_rank(&rows);
    if rank < r {
        return Err(NormalFormError::DependentOutputChain {
            rank,
            relative_degree: r,
        });
    }
    let needed = nx - r;
    let mut eta = Vec::new();
    let mut eta_dot = Vec::new();
    let mut eta_dot_text = Vec::new();
    let mut origin = Vec::new();
    let (cands, mut rejected) = candidates(model, derivation, chain);
    for (cand, dot, what, text) in cands {
        if eta.len() == needed {
            break;
        }
        let row = gradient(cand, &state, &point, &what)?;
        rows.push(row);
        let (rk, _) = numeric_rank(&rows);
        if rk < rows.len() {
            rows.pop();
            rejected.push(format!(
                "{what} (dependent on the others at the operating point)"
            ));
            continue;
        }
        eta.push(cand);
        eta_dot.push(dot);
        eta_dot_text.push(text);
        origin.push(what);
    }
    if eta.len() < needed {
        return Err(NormalFormError::NoComplement {
            needed,
            found: origin,
            rejected,
        });
    }
    let (_, sv) = numeric_rank(&rows);
    Ok(NormalForm {
        state,
        xi,
        eta,
        eta_origin: origin,
        eta_dot,
        eta_dot_text,
        at: x0,
        jacobian_singular_values: sv,
    })
}
