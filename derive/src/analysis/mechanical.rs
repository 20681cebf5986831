//! Lie derivatives, relative degree and the linearizing law of an output
//! `h(q)` of a mechanical system, through the structure
//! `M(q) q'' = r0(q, q') + B(q, q') u` (`r0 = Q0 - bias`) instead of the
//! expanded control-affine form.
//!
//! With `x = (q, q')`, `f = (q', M^-1 r0)`, `g = (0, M^-1 B)` and `J = dh/dq`:
//!
//! * `L_g h = 0` (the input acts on accelerations only);
//! * `L_f h = J q'`;
//! * `L_g L_f h = J M^-1 B`;
//! * `L_f^2 h = q'^T (d^2 h/dq^2) q' + J M^-1 r0`.
//!
//! `J M^-1` is one solve `M w = J^T` ([`crate::mechanics::ldl_solve`], an
//! unexpanded expression DAG). Whether `L_g L_f h` vanishes is screened
//! numerically at random states (a value well above rounding proves it
//! nonzero); a vanishing value is confirmed exactly on the expanded form, which
//! is computed (with a term budget) for up to [`EXPLICIT_MAX_COORDINATES`]
//! coordinates. Beyond that the parts are reported unexpanded, with the reason.

use super::lie::{state_factors, AnalysisError, LieChain};
use crate::mechanics::{adjugate, determinant, ldl_solve, screening_points, Equations};
use crate::model::Model;
use crate::sym::{diff, try_simplify_within, CanonError, Canonicalizer, Expr, Symbol};

/// Largest number of coordinates for which `L_f^2 h` and `L_g L_f h` are
/// expanded (as `adj(M)/det(M)` products in canonical form).
pub const EXPLICIT_MAX_COORDINATES: usize = 3;

/// Term budget of every exact computation of the analysis: an intermediate
/// polynomial with more terms stops it with a reported reason.
pub const ANALYSIS_MAX_TERMS: usize = 40_000;

/// Number of random states of the numeric screening.
pub(crate) const SCREEN_POINTS: usize = 4;

/// The parts of the Lie derivatives of a mechanical output.
#[derive(Clone, Debug)]
pub struct MechanicalParts {
    /// `J = dh/dq`, one entry per coordinate (simplified).
    pub gradient: Vec<Expr>,
    /// `q'^T (d^2 h/dq^2) q'` (simplified).
    pub curvature: Expr,
    /// `det M` (simplified) when the expanded forms were computed.
    pub det_mass: Option<Expr>,
    /// Why `L_f^2 h` and `L_g L_f h` are not expanded (`None` if they are).
    pub not_expanded: Option<String>,
    /// `min |L_g L_f h| / scale` over the screening states (how far from 0).
    pub screening_margin: f64,
}

pub(crate) fn budget_reason(what: &str, e: CanonError) -> String {
    format!("{what}: {e} (budget {ANALYSIS_MAX_TERMS} terms)")
}

/// Expanded `(L_g L_f h, L_f^2 h, det M)`.
fn explicit(
    canon: &mut Canonicalizer,
    eqs: &Equations,
    grad: &[Expr],
    curvature: Expr,
    r0: &[Expr],
    b: &[Expr],
) -> Result<(Expr, Expr, Expr), String> {
    let n = grad.len();
    let mut simp = |e: Expr, what: &str| canon.try_simplify(e).map_err(|x| budget_reason(what, x));
    let mut m = vec![vec![Expr::zero(); n]; n];
    for (row, src) in m.iter_mut().zip(&eqs.mass_matrix) {
        for (e, s) in row.iter_mut().zip(src) {
            *e = simp(*s, "M")?;
        }
    }
    let det = simp(determinant(&m), "det M")?;
    let adj = adjugate(&m);
    let mut gnum = Vec::new();
    let mut fnum = Vec::new();
    for i in 0..n {
        if grad[i].is_zero() {
            continue;
        }
        for k in 0..n {
            gnum.push(grad[i] * adj[i][k] * b[k]);
            fnum.push(grad[i] * adj[i][k] * r0[k]);
        }
    }
    let lglf = simp(Expr::add_all(gnum) / det, "L_g L_f h")?;
    let lf2 = simp(curvature + Expr::add_all(fnum) / det, "L_f^2 h")?;
    Ok((lglf, lf2, det))
}

/// `Some(k)` if `v` has exactly one structurally nonzero entry, at `k`, and
/// it is free of the state.
pub(crate) fn unit_direction(v: &[Expr], state: &[Symbol]) -> Option<usize> {
    let nz: Vec<usize> = (0..v.len()).filter(|i| !v[*i].is_zero()).collect();
    match nz.as_slice() {
        [k] if state.iter().all(|s| !v[*k].contains(*s)) => Some(*k),
        _ => None,
    }
}

/// True if `f` is a constant multiple of a principal minor of `m` (positive
/// wherever `m` is positive definite).
fn is_principal_minor(f: Expr, m: &[Vec<Expr>], state: &[Symbol]) -> bool {
    let n = m.len();
    for mask in 1u32..(1 << n) - 1 {
        let idx: Vec<usize> = (0..n).filter(|i| mask & (1 << i) != 0).collect();
        let sub: Vec<Vec<Expr>> = idx
            .iter()
            .map(|i| idx.iter().map(|j| m[*i][*j]).collect())
            .collect();
        let Ok(ratio) = try_simplify_within(f / determinant(&sub), ANALYSIS_MAX_TERMS) else {
            continue;
        };
        if !ratio.is_zero() && state.iter().all(|s| !ratio.contains(*s)) {
            return true;
        }
    }
    false
}

/// The state-dependent factors of `e`'s numerator whose zeros make `e`
/// vanish, leaving out principal minors of `M` (positive wherever `M` is
/// positive definite); when only those were found, the note that says so
/// (`what` names `e` in it).
pub(crate) fn split_singular_factors(
    e: Expr,
    eqs: &Equations,
    state: &[Symbol],
    what: &str,
) -> (Vec<Expr>, Option<String>) {
    let m: Vec<Vec<Expr>> = eqs
        .mass_matrix
        .iter()
        .map(|row| row.iter().map(|x| crate::sym::simplify(*x)).collect())
        .collect();
    let (dropped, kept): (Vec<Expr>, Vec<Expr>) = state_factors(e, state)
        .into_iter()
        .partition(|f| is_principal_minor(*f, &m, state));
    let note = (kept.is_empty() && !dropped.is_empty()).then(|| {
        let several = dropped.len() > 1;
        format!(
            "none: the state-dependent factor{} of {what} ({}) {} principal minor{} of M, positive because M is positive definite",
            if several { "s" } else { "" },
            dropped.iter().map(|f| f.to_string()).collect::<Vec<_>>().join(", "),
            if several { "are" } else { "is a" },
            if several { "s" } else { "" },
        )
    });
    (kept, note)
}

/// A position-level output `h(q)` and the parts of its first derivatives.
pub(crate) struct PositionOutput {
    /// `h`, simplified.
    pub h: Expr,
    /// `J = dh/dq`.
    pub gradient: Vec<Expr>,
    /// `L_f h = J q'`.
    pub lfh: Expr,
    /// `q'^T (d^2 h/dq^2) q'`.
    pub curvature: Expr,
}

/// `h`, `J = dh/dq`, `L_f h = J q'` and `q'^T (d^2 h/dq^2) q'`, each
/// simplified within the analysis budget.
pub(crate) fn position_output(
    canon: &mut Canonicalizer,
    eqs: &Equations,
    h: Expr,
) -> Result<PositionOutput, AnalysisError> {
    let n = eqs.coords.len();
    let simp = |c: &mut Canonicalizer, e: Expr, what: &str| {
        c.try_simplify(e).map_err(|x| AnalysisError::Budget {
            reason: budget_reason(what, x),
        })
    };
    let h = simp(canon, h, "h")?;
    let grad: Vec<Expr> = eqs
        .coords
        .iter()
        .map(|c| simp(canon, diff(h, c.q), "dh/dq"))
        .collect::<Result<_, _>>()?;
    let qd: Vec<Expr> = eqs.coords.iter().map(|c| Expr::symbol(c.qd)).collect();
    let lfh = simp(
        canon,
        Expr::add_all((0..n).map(|i| grad[i] * qd[i])),
        "L_f h",
    )?;
    let mut curv = Vec::new();
    for i in 0..n {
        for k in 0..n {
            let d = diff(grad[i], eqs.coords[k].q);
            if !d.is_zero() {
                curv.push(d * qd[k] * qd[i]);
            }
        }
    }
    let curvature = simp(canon, Expr::add_all(curv), "q'^T H q'")?;
    Ok(PositionOutput {
        h,
        gradient: grad,
        lfh,
        curvature,
    })
}

/// True if `h` is a position-level output of `eqs` (free of velocities,
/// accelerations and inputs).
pub(crate) fn is_position_output(eqs: &Equations, h: Expr) -> bool {
    !eqs.coords
        .iter()
        .flat_map(|c| [c.qd, c.qdd])
        .chain(eqs.inputs.iter().copied())
        .any(|s| h.contains(s))
}

/// The Lie chain of an output `h(q)` through the mechanical structure, or
/// `None` if the structure does not apply (an output depending on velocities
/// or inputs, or `L_g L_f h` identically zero: relative degree above 2).
pub fn mechanical_chain(
    model: &Model,
    eqs: &Equations,
    h: Expr,
) -> Result<Option<LieChain>, AnalysisError> {
    if eqs.inputs.len() != 1 {
        return Err(AnalysisError::MultiInput {
            inputs: eqs.inputs.len(),
        });
    }
    if !is_position_output(eqs, h) {
        return Ok(None);
    }
    let n = eqs.coords.len();
    let mut state: Vec<Symbol> = eqs.coords.iter().map(|c| c.q).collect();
    state.extend(eqs.coords.iter().map(|c| c.qd));
    let mut canon = Canonicalizer::new(ANALYSIS_MAX_TERMS);
    let PositionOutput {
        h,
        gradient: grad,
        lfh,
        curvature,
    } = position_output(&mut canon, eqs, h)?;
    let r0: Vec<Expr> = (0..n).map(|i| eqs.forces[i] - eqs.bias[i]).collect();
    let b: Vec<Expr> = eqs.input_matrix.iter().map(|r| r[0]).collect();
    // numeric screening of L_g L_f h = w . B with M w = J^T
    let w = ldl_solve(&eqs.mass_matrix, std::slice::from_ref(&grad)).remove(0);
    let lglf_dag = Expr::add_all((0..n).map(|i| w[i] * b[i]));
    let mut margin = f64::INFINITY;
    for p in screening_points(model, eqs, SCREEN_POINTS) {
        let mut ev = crate::sym::Evaluator::new(&p);
        let mut scale = 0.0;
        for i in 0..n {
            scale += (ev.eval(w[i]) * ev.eval(b[i])).abs();
        }
        let v = ev.eval(lglf_dag).abs();
        let rel = if scale > 0.0 { v / scale } else { 0.0 };
        margin = margin.min(if rel.is_finite() { rel } else { 0.0 });
    }
    let screened_nonzero = margin > 1e-9;
    let explicit = if n <= EXPLICIT_MAX_COORDINATES {
        explicit(&mut canon, eqs, &grad, curvature, &r0, &b)
    } else {
        Err(format!(
            "not expanded for {n} coordinates (more than {EXPLICIT_MAX_COORDINATES}): \
             computed through M, Q0 - bias and B by a symbolic LDL^T solve"
        ))
    };
    let (lglf, lf2, det, not_expanded) = match explicit {
        Ok((lglf, lf2, det)) => {
            if !screened_nonzero {
                let zero = canon.try_is_zero(lglf).map_err(|x| AnalysisError::Budget {
                    reason: budget_reason("exact test of L_g L_f h = 0", x),
                })?;
                if zero {
                    return Ok(None);
                }
            }
            (lglf, lf2, Some(det), None)
        }
        Err(reason) => {
            if !screened_nonzero {
                return Err(AnalysisError::Budget {
                    reason: format!(
                        "L_g L_f h vanished at {SCREEN_POINTS} random states and the exact \
                         test is out of reach: {reason}"
                    ),
                });
            }
            let lf2 = curvature + Expr::add_all((0..n).map(|i| w[i] * r0[i]));
            (lglf_dag, lf2, None, Some(reason))
        }
    };
    // singular set
    let mut singular_note = None;
    let mut singular_factors = Vec::new();
    if let (Some(k), Some(kb)) = (unit_direction(&grad, &state), unit_direction(&b, &state)) {
        if k == kb {
            let q = eqs.coords[k].q.name();
            singular_note = Some(format!(
                "none: L_g L_f h = (dh/d{q}) B[{q}] (M^-1)[{q}][{q}], and (M^-1)[{q}][{q}] > 0 because M is positive definite"
            ));
        }
    }
    if singular_note.is_none() {
        if not_expanded.is_some() {
            singular_note = Some("where J M^-1 B = 0 (not expanded)".into());
        } else {
            (singular_factors, singular_note) =
                split_singular_factors(lglf, eqs, &state, "L_g L_f h");
        }
    }
    Ok(Some(LieChain {
        lf: vec![h, lfh, lf2],
        lg: vec![Expr::zero(), lglf],
        relative_degree: 2,
        singular_factors,
        singular_note,
        mechanical: Some(MechanicalParts {
            gradient: grad,
            curvature,
            det_mass: det,
            not_expanded,
            screening_margin: margin,
        }),
    }))
}
