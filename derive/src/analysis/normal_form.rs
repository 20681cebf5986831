//! Byrnes-Isidori normal form of a mechanical system with respect to an output
//! of relative degree `r` (or, for `m` inputs, `m` outputs of vector relative
//! degree `(r_1, ..., r_m)`, `r = sum r_i`):
//! `xi = (h, L_f h, ..., L_f^(r-1) h)` (every output's, in turn) and `n - r`
//! complementary coordinates `eta` with `L_g eta = 0` (for every input
//! field), found among candidates suggested by the mechanical
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
//!    `c = B_j/B_k` (a function of the coordinates). With `m` inputs, `k`
//!    runs over `m` pivot rows `K` with `B_K` nonsingular and
//!    `c = B_j B_K^-1` (a row): `eta = p_j - c p_K`, `L_g eta = B_j - c B_K = 0`;
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

/// The first set of `m` rows of `b` (lexicographic order) whose `m x m`
/// block `B_K` is nonsingular as a function (its determinant is not
/// identically zero), with `B_K^-1` (adjugate over determinant); `None` if
/// there is none (`B` has rank below `m`).
fn pivot_rows(b: &[Vec<Expr>], m: usize) -> Option<(Vec<usize>, Vec<Vec<Expr>>)> {
    fn next(rows: &mut [usize], n: usize) -> bool {
        let m = rows.len();
        for i in (0..m).rev() {
            if rows[i] < n - m + i {
                rows[i] += 1;
                for k in i + 1..m {
                    rows[k] = rows[k - 1] + 1;
                }
                return true;
            }
        }
        false
    }
    let n = b.len();
    if m == 0 || m > n {
        return None;
    }
    let mut rows: Vec<usize> = (0..m).collect();
    loop {
        let block: Vec<Vec<Expr>> = rows.iter().map(|r| b[*r][..m].to_vec()).collect();
        let det = crate::mechanics::determinant(&block);
        if !(det.is_zero() || is_zero(det)) {
            let adj = crate::mechanics::adjugate(&block);
            let inverse = adj
                .iter()
                .map(|row| row.iter().map(|e| *e / det).collect())
                .collect();
            return Some((rows, inverse));
        }
        if !next(&mut rows, n) {
            return None;
        }
    }
}

/// Candidate complementary coordinates suggested by the mechanical structure,
/// with `L_f eta` (see the module docs); those rejected before the rank test,
/// with the reason.
pub fn candidates(
    model: &Model,
    derivation: &Derivation,
    chain: &LieChain,
) -> (Vec<Candidate>, Vec<String>) {
    candidates_for(
        model,
        derivation,
        &chain.lf[..chain.relative_degree],
        chain_explicit(chain),
    )
}

/// Whether the Lie chain's parts are expanded (small systems).
fn chain_explicit(chain: &LieChain) -> bool {
    chain
        .mechanical
        .as_ref()
        .is_none_or(|m| m.not_expanded.is_none())
}

/// Candidate complementary coordinates for the output coordinates `xi` (one
/// output's chain, or every output's of a square multi-input system), with
/// `L_g eta = 0` for every input field; `explicit`: the analysis is expanded
/// (candidates are simplified for printing, velocities are tried).
pub(crate) fn candidates_for(
    model: &Model,
    derivation: &Derivation,
    xi: &[Expr],
    explicit: bool,
) -> (Vec<Candidate>, Vec<String>) {
    let eqs = &derivation.equations;
    let n = eqs.coords.len();
    let mut out = Vec::new();
    let mut rejected = Vec::new();
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
        xi.iter().any(|h| {
            if eqs.coords.iter().any(|k| h.contains(k.qd)) {
                return false;
            }
            let d = diff(*h, c.q);
            !is_zero(d) && !positions.iter().any(|s| d.contains(*s))
        })
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
    let m = eqs.inputs.len();
    let zero = |e: Expr| e.is_zero() || is_zero(e);
    // m pivot rows K of B with B_K nonsingular (exactly, as functions):
    // the first such set in lexicographic order
    let pivots = pivot_rows(&eqs.input_matrix, m);
    for j in 0..n {
        let q = eqs.coords[j].q.name();
        if eqs.input_matrix[j].iter().all(|e| zero(*e)) {
            out.push((
                tidy(momentum[j]),
                tidy(rate[j]),
                format!("momentum conjugate to {q}"),
                format!("dL/d{q} + Q0[{q}]"),
            ));
            continue;
        }
        let Some((rows, inverse)) = pivots.as_ref() else {
            continue;
        };
        if rows.contains(&j) {
            continue;
        }
        // c = B_j B_K^-1: p_j - c p_K has L_g = B_j - B_j B_K^-1 B_K = 0
        let c: Vec<Expr> = (0..m)
            .map(|k| {
                tidy(Expr::add_all(
                    (0..m).map(|l| eqs.input_matrix[j][l] * inverse[l][k]),
                ))
            })
            .collect();
        let names: Vec<&str> = rows.iter().map(|k| eqs.coords[*k].q.name()).collect();
        if let Some(k) = (0..m).find(|k| velocities.iter().any(|v| c[*k].contains(*v))) {
            rejected.push(if m == 1 {
                format!(
                    "p_{q} - c p_{qk} (c = B[{q}]/B[{qk}] = {c} depends on velocities)",
                    qk = names[0],
                    c = c[0]
                )
            } else {
                format!(
                    "p_{q} - c p_K (c = B[{q}] B_K^-1, K = {}: c_{} = {} depends on velocities)",
                    names.join(", "),
                    names[k],
                    c[k]
                )
            });
            continue;
        }
        if m == 1 {
            let (k, qk) = (rows[0], names[0]);
            let dc: Expr = eqs
                .coords
                .iter()
                .map(|s| diff(c[0], s.q) * Expr::symbol(s.qd))
                .sum();
            out.push((
                tidy(momentum[j] - c[0] * momentum[k]),
                tidy(rate[j] - c[0] * rate[k] - dc * momentum[k]),
                format!(
                    "momentum combination p_{q} - ({})*p_{qk} (the input cancels)",
                    c[0]
                ),
                format!("dL/d{q} + Q0[{q}] - c (dL/d{qk} + Q0[{qk}]) - c' p_{qk}"),
            ));
            continue;
        }
        let mut eta = vec![momentum[j]];
        let mut dot = vec![rate[j]];
        let mut shown = Vec::new();
        for (k, row) in rows.iter().enumerate() {
            if zero(c[k]) {
                continue;
            }
            let dc: Expr = eqs
                .coords
                .iter()
                .map(|s| diff(c[k], s.q) * Expr::symbol(s.qd))
                .sum();
            eta.push(-(c[k] * momentum[*row]));
            dot.push(-(c[k] * rate[*row]) - dc * momentum[*row]);
            shown.push(match c[k].as_rational() {
                Some(r) if r.is_one() => format!("- p_{}", names[k]),
                Some(r) if r.abs().is_one() => format!("+ p_{}", names[k]),
                _ => format!("- ({})*p_{}", c[k], names[k]),
            });
        }
        out.push((
            tidy(Expr::add_all(eta)),
            tidy(Expr::add_all(dot)),
            format!(
                "momentum combination p_{q} {} (c = B[{q}] B_K^-1 with K = {}: the inputs cancel)",
                shown.join(" "),
                names.join(", ")
            ),
            format!("dL/d{q} + Q0[{q}] - sum over k in K of (c_k (dL/dq_k + Q0[q_k]) + c_k' p_k)"),
        ));
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
            Ok(ca) => match ca.g[n + i]
                .iter()
                .find(|gi| !(gi.is_zero() || is_zero(**gi)))
            {
                None => out.push((qd, ca.f[n + i], what, format!("{}''", c.q.name()))),
                Some(gi) => rejected.push(format!("{what} (L_g = {gi} is not 0)")),
            },
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
    normal_form_for(
        model,
        derivation,
        &chain.lf[..chain.relative_degree],
        chain_explicit(chain),
        values,
        at,
    )
}

/// The normal form with output coordinates `xi` (one output's
/// `h, ..., L_f^(r-1) h`, or those of every output of a square multi-input
/// system, `r = sum r_i` of them) and `n - r` complementary coordinates with
/// `L_g eta = 0` for every input; `explicit` as in [`candidates_for`].
pub fn normal_form_for(
    model: &Model,
    derivation: &Derivation,
    xi: &[Expr],
    explicit: bool,
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
    let r = xi.len();
    let xi: Vec<Expr> = xi.to_vec();
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
    let (cands, mut rejected) = candidates_for(model, derivation, &xi, explicit);
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
