//! The equations of motion as printed by `plantc derive`: `M`, `bias`, `Q0`,
//! `B` in readable form ([`crate::sym::present`]), and the control-affine
//! `f = (q', M^-1 (Q0 - bias))`, `g = (0, M^-1 B)` expanded only when asked
//! for or when small, with `D = det M` named. Every budget that stops a
//! computation is reported in [`PresentedEquations::notes`], never hidden.

use super::{adjugate, determinant, Equations};
use crate::sym::{Canonicalizer, Expr, Name};

/// Largest number of coordinates whose control-affine form is expanded by
/// default.
pub const EXPAND_MAX_COORDINATES: usize = 3;

/// Term budget of the presentation of one entry.
pub const PRESENT_MAX_TERMS: usize = 40_000;

/// Term budget when the expansion is asked for explicitly.
pub const EXPAND_MAX_TERMS: usize = 200_000;

/// When to expand `M^-1` in the control-affine form.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Expand {
    /// Up to [`EXPAND_MAX_COORDINATES`] coordinates.
    Auto,
    /// Always (within [`EXPAND_MAX_TERMS`]).
    Always,
    /// Never: `f` and `g` are given by their structure.
    Never,
}

/// The presented equations.
#[derive(Clone, Debug)]
pub struct PresentedEquations {
    /// `M[i][j]`.
    pub mass_matrix: Vec<Vec<Expr>>,
    /// `bias[i]`.
    pub bias: Vec<Expr>,
    /// `Q0[i]`.
    pub forces: Vec<Expr>,
    /// `B[i][j]`.
    pub input_matrix: Vec<Vec<Expr>>,
    /// `det M` when the expansion was done.
    pub det_mass: Option<Expr>,
    /// The lower half of `f`, `(M^-1 (Q0 - bias))_i`, with `D = det M` named.
    pub f: Option<Vec<Expr>>,
    /// The lower half of `g`, `(M^-1 B)_ij`, with `D` named.
    pub g: Option<Vec<Vec<Expr>>>,
    /// Why something is not simplified or not expanded.
    pub notes: Vec<String>,
}

/// The symbol `D` used for `det M`.
pub fn det_name() -> Expr {
    Expr::sym("D")
}

/// Present `eqs` (see the module docs).
#[allow(clippy::needless_range_loop)] // row/column index loops over a matrix
pub fn present_equations(eqs: &Equations, expand: Expand) -> PresentedEquations {
    let n = eqs.coords.len();
    let mut notes = Vec::new();
    let (mut small, mut large) = (
        Canonicalizer::new(PRESENT_MAX_TERMS),
        Canonicalizer::new(EXPAND_MAX_TERMS),
    );
    let mut show = |e: Expr, what: String, names: &[Name], budget: usize| -> Option<Expr> {
        let c = if budget > PRESENT_MAX_TERMS {
            &mut large
        } else {
            &mut small
        };
        match c.try_present(e, names) {
            Ok(p) => Some(p),
            Err(x) => {
                notes.push(format!(
                    "{what} is not simplified: {x} (budget {budget} terms)"
                ));
                None
            }
        }
    };
    let mut mass_matrix = vec![vec![Expr::zero(); n]; n];
    for i in 0..n {
        for j in 0..n {
            let e = eqs.mass_matrix[i][j];
            mass_matrix[i][j] =
                show(e, format!("M[{i}][{j}]"), &[], PRESENT_MAX_TERMS).unwrap_or(e);
        }
    }
    let bias = (0..n)
        .map(|i| {
            show(eqs.bias[i], format!("bias[{i}]"), &[], PRESENT_MAX_TERMS).unwrap_or(eqs.bias[i])
        })
        .collect();
    let forces = (0..n)
        .map(|i| {
            show(eqs.forces[i], format!("Q0[{i}]"), &[], PRESENT_MAX_TERMS).unwrap_or(eqs.forces[i])
        })
        .collect();
    let input_matrix = (0..n)
        .map(|i| {
            eqs.input_matrix[i]
                .iter()
                .enumerate()
                .map(|(j, e)| {
                    show(*e, format!("B[{i}][{j}]"), &[], PRESENT_MAX_TERMS).unwrap_or(*e)
                })
                .collect()
        })
        .collect();
    let (do_expand, budget) = match expand {
        Expand::Auto => (n <= EXPAND_MAX_COORDINATES, PRESENT_MAX_TERMS),
        Expand::Always => (true, EXPAND_MAX_TERMS),
        Expand::Never => (false, 0),
    };
    let mut det_mass = None;
    let mut f = None;
    let mut g = None;
    if !do_expand {
        if expand == Expand::Auto {
            notes.push(format!(
                "f and g are not expanded for {n} coordinates (more than {EXPAND_MAX_COORDINATES}): \
                 f = (q', M^-1 (Q0 - bias)), g = (0, M^-1 B) with M, bias, Q0, B above \
                 (`--expand` expands them)"
            ));
        }
    } else if let Some(det) = show(determinant(&eqs.mass_matrix), "det M".into(), &[], budget) {
        let names = [Name {
            symbol: det_name(),
            definition: det,
        }];
        let adj = adjugate(&eqs.mass_matrix);
        let mut fs = Vec::new();
        let mut gs = Vec::new();
        let mut complete = true;
        for i in 0..n {
            let num: Expr = (0..n)
                .map(|k| adj[i][k] * (eqs.forces[k] - eqs.bias[k]))
                .sum();
            match show(num / det, format!("f[{i}]"), &names, budget) {
                Some(e) => fs.push(e),
                None => complete = false,
            }
            let mut row = Vec::new();
            for j in 0..eqs.inputs.len() {
                let num: Expr = (0..n).map(|k| adj[i][k] * eqs.input_matrix[k][j]).sum();
                match show(num / det, format!("g[{i}][{j}]"), &names, budget) {
                    Some(e) => row.push(e),
                    None => complete = false,
                }
            }
            gs.push(row);
        }
        det_mass = Some(det);
        if complete {
            f = Some(fs);
            g = Some(gs);
        }
    }
    PresentedEquations {
        mass_matrix,
        bias,
        forces,
        input_matrix,
        det_mass,
        f,
        g,
        notes,
    }
}
