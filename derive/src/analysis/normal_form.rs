//! Byrnes-Isidori normal form of a single-input mechanical system with respect
//! to an output of relative degree `r`:
//! `xi = (h, L_f h, ..., L_f^(r-1) h)` and `n - r` complementary coordinates
//! `eta` with `L_g eta = 0`, found among candidates suggested by the mechanical
//! structure and verified symbolically (`is_zero(L_g eta)`), with the Jacobian of
//! `(xi, eta)` checked nonsingular at the operating point.
//!
//! Candidates, in the order tried:
//! 1. coordinates `q_j` not already in `xi` (`L_g q_j = 0` because the input
//!    only acts on accelerations);
//! 2. momenta `p_j = dT/dq_j' = sum_k M_jk q_k'` conjugate to unactuated
//!    coordinates (row `j` of `B` zero): `L_g p_j = (M M^-1 B)_j = B_j = 0`;
//! 3. velocities `q_j'` not in `xi` (accepted only if `L_g q_j' = 0`).

use std::collections::HashMap;
use std::fmt;

use nalgebra::DMatrix;

use super::lie::{lie_derivative, LieChain};
use crate::control::Derivation;
use crate::model::{Model, ParameterValues};
use crate::sym::{diff, is_zero, simplify, Expr, Symbol};

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

/// The numeric gradient of `e` at `at`.
fn gradient(
    e: Expr,
    state: &[Symbol],
    at: &HashMap<Symbol, f64>,
    what: &str,
) -> Result<Vec<f64>, NormalFormError> {
    state
        .iter()
        .map(|s| {
            let v = diff(e, *s).eval_map(at);
            if v.is_finite() {
                Ok(v)
            } else {
                Err(NormalFormError::NotFinite {
                    entry: format!("d({what})/d{}", s.name()),
                })
            }
        })
        .collect()
}

/// Candidate complementary coordinates suggested by the mechanical structure.
pub fn candidates(derivation: &Derivation, chain: &LieChain) -> Vec<(Expr, String)> {
    let eqs = &derivation.equations;
    let r = chain.relative_degree;
    let xi = &chain.lf[..r];
    let n = eqs.coords.len();
    let mut out = Vec::new();
    for c in &eqs.coords {
        let q = Expr::symbol(c.q);
        if !xi.contains(&q) {
            out.push((q, format!("coordinate {}", c.q.name())));
        }
    }
    for j in 0..n {
        let unactuated = eqs.input_matrix[j]
            .iter()
            .all(|b| b.is_zero() || is_zero(*b));
        if unactuated {
            let p: Expr = (0..n)
                .map(|k| eqs.mass_matrix[j][k] * Expr::symbol(eqs.coords[k].qd))
                .sum();
            out.push((
                simplify(p),
                format!("momentum conjugate to {}", eqs.coords[j].q.name()),
            ));
        }
    }
    for c in &eqs.coords {
        let qd = Expr::symbol(c.qd);
        if !xi.contains(&qd) {
            out.push((qd, format!("velocity {}", c.qd.name())));
        }
    }
    out
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
    let ca = &derivation.affine;
    let state = ca.state.clone();
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
    let g: Vec<Expr> = ca.g.iter().map(|row| row[0]).collect();
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
    let mut origin = Vec::new();
    let mut rejected = Vec::new();
    for (cand, what) in candidates(derivation, chain) {
        if eta.len() == needed {
            break;
        }
        let lg = lie_derivative(cand, &g, &state);
        if !(lg.is_zero() || is_zero(lg)) {
            rejected.push(format!("{what} (L_g = {lg} is not 0)"));
            continue;
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
    let eta_dot = eta
        .iter()
        .map(|e| lie_derivative(*e, &ca.f, &state))
        .collect();
    Ok(NormalForm {
        state,
        xi,
        eta,
        eta_origin: origin,
        eta_dot,
        at: x0,
        jacobian_singular_values: sv,
    })
}
