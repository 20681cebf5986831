//! Input-output decoupling of a square multi-input system (as many outputs as
//! inputs, `y = h(x)`, `x' = f(x) + g(x) u`):
//!
//! * the **vector relative degree** `(r_1, ..., r_m)`: `r_i - 1` is the first
//!   `k` for which the row `L_g L_f^k h_i = (L_{g_1} L_f^k h_i, ...,
//!   L_{g_m} L_f^k h_i)` is not identically zero;
//! * the **decoupling matrix** `A(x)`, row `i` = `L_g L_f^(r_i-1) h_i`, and
//!   `b(x) = (L_f^(r_1) h_1, ..., L_f^(r_m) h_m)`, so that
//!   `y_i^(r_i) = b_i(x) + A_i(x) u`;
//! * where `A` is singular, and the **decoupling (linearizing) law**
//!   `u = A^-1 (v - b)`, which makes `y_i^(r_i) = v_i` wherever `det A != 0`.
//!
//! Outputs of the coordinates, `h(q)`, go through the mechanical structure
//! `M q'' = r0 + B u` (`r0 = Q0 - bias`) as for one input
//! ([`super::mechanical_chain`]): `L_g h = 0`, `L_f h = J q'`, the row
//! `L_g L_f h = J M^-1 B` and `L_f^2 h = q'^T (d^2h/dq^2) q' + J M^-1 r0`,
//! with `J M^-1` one symbolic LDL^T solve for every output (an unexpanded
//! DAG). Whether a row vanishes is screened numerically at random states; a
//! row that vanishes there is confirmed exactly on the expanded form, and the
//! output then goes through the expanded control-affine form (relative degree
//! above 2), like an output that depends on velocities.
//!
//! Up to [`EXPLICIT_MAX_COORDINATES`] coordinates `A`, `b` and `det A` are
//! expanded (adjugate over determinant, canonical form, within
//! [`ANALYSIS_MAX_TERMS`]) and `det A = 0` is decided exactly; beyond, or when
//! the budget stops them, they stay structured, `det A` is screened
//! numerically at random states, and [`Decoupling::not_expanded`] says so.

use std::collections::HashMap;

use nalgebra::DMatrix;

use super::lie::{lie_derivative, singular_set_text, AnalysisError};
use super::mechanical::{
    budget_reason, is_position_output, position_output, split_singular_factors, PositionOutput,
    ANALYSIS_MAX_TERMS, EXPLICIT_MAX_COORDINATES, SCREEN_POINTS,
};
use crate::control::{output_expr, Derivation};
use crate::mechanics::{adjugate, determinant, ldl_solve, screening_points, ControlAffine};
use crate::model::Model;
use crate::sym::{is_zero, simplify, Canonicalizer, Evaluator, Expr, Symbol};

/// A row, a value or a determinant is taken as zero at a state when it is at
/// most this fraction of its scale (the sum of the magnitudes of the terms it
/// is made of; for `det A`, Hadamard's bound `prod_i |A_i|`). The values come
/// from evaluating a DAG of a few thousand operations, whose rounding is about
/// `1e3 * eps = 2e-13` of that scale; `1e-9` is four orders above it, and far
/// below the size of a decoupling term that is genuinely nonzero at a random
/// state (`1e-4` to `1` of its scale on the bundled models). The same
/// threshold as the single-input screening ([`super::mechanical_chain`]).
pub const SCREEN_ZERO: f64 = 1e-9;

/// One output's Lie derivatives in a decoupling analysis.
#[derive(Clone, Debug)]
pub struct OutputLie {
    /// The output's name.
    pub name: String,
    /// The relative degree `r_i`.
    pub relative_degree: usize,
    /// `[h, L_f h, ..., L_f^r h]`.
    pub lf: Vec<Expr>,
    /// `L_g L_f^k h` for `k = 0..r`, one entry per input (identically zero
    /// for `k < r - 1`).
    pub lg: Vec<Vec<Expr>>,
    /// For an output of the coordinates: `J = dh/dq` (else empty).
    pub gradient: Vec<Expr>,
    /// For an output of the coordinates: `q'^T (d^2 h/dq^2) q'`.
    pub curvature: Option<Expr>,
    /// `min` over the screening states of `max_j |A_ij| / scale_ij` (how far
    /// the decoupling row is from 0; `1` when it came from the expanded
    /// control-affine form, where it is nonzero exactly).
    pub screening_margin: f64,
}

/// The decoupling analysis of a square multi-input system.
#[derive(Clone, Debug)]
pub struct Decoupling {
    /// One entry per output, in the order given.
    pub outputs: Vec<OutputLie>,
    /// The input symbols (model order).
    pub inputs: Vec<Symbol>,
    /// The state symbols (model order).
    pub state: Vec<Symbol>,
    /// `A(x)`: row `i` = `L_g L_f^(r_i-1) h_i`.
    pub matrix: Vec<Vec<Expr>>,
    /// `b(x)`: entry `i` = `L_f^(r_i) h_i`.
    pub drift: Vec<Expr>,
    /// `det A` (simplified) when expanded.
    pub det: Option<Expr>,
    /// When expanded: the diagonal blocks of `M` (coordinate indices, one
    /// block if the coordinates all couple) and their determinants
    /// (simplified); `det M` is their product.
    pub mass_blocks: Vec<(Vec<usize>, Expr)>,
    /// Why `A` and `b` are not expanded (`None` if they are; `det A` may
    /// still be out of reach: [`Decoupling::det`] is `None` then).
    pub not_expanded: Option<String>,
    /// State-dependent factors of `det A`'s numerator whose zeros make `A`
    /// singular (principal minors of `M`, positive, are left out).
    pub singular_factors: Vec<Expr>,
    /// The singular set when it is not a list of factors.
    pub singular_note: Option<String>,
    /// `min` over the screening states of `|det A| / prod_i |A_i|` (`|A_i|`
    /// the Euclidean norm of row `i`; Hadamard: at most 1).
    pub det_margin: f64,
    /// For each output and input, terms whose sum is `A_ij` (`w_k B_kj` with
    /// `M w = J^T` for an output of the coordinates; the entry itself
    /// otherwise): the scale a vanishing entry is judged against.
    pub row_terms: Vec<Vec<Vec<Expr>>>,
}

impl Decoupling {
    /// The vector relative degree `(r_1, ..., r_m)`.
    pub fn vector_relative_degree(&self) -> Vec<usize> {
        self.outputs.iter().map(|o| o.relative_degree).collect()
    }

    /// `xi`: `h_i, L_f h_i, ..., L_f^(r_i-1) h_i` of every output in turn.
    pub fn xi(&self) -> Vec<Expr> {
        self.outputs
            .iter()
            .flat_map(|o| o.lf[..o.relative_degree].iter().copied())
            .collect()
    }

    /// `A` and `b` are expanded (small systems).
    pub fn expanded(&self) -> bool {
        self.not_expanded.is_none()
    }

    /// `A(x)` at `point` (state and parameter values by symbol).
    pub fn matrix_at(&self, point: &HashMap<Symbol, f64>) -> DMatrix<f64> {
        let mut ev = Evaluator::new(point);
        let m = self.matrix.len();
        DMatrix::from_fn(m, m, |i, j| ev.eval(self.matrix[i][j]))
    }

    /// `b(x)` at `point`.
    pub fn drift_at(&self, point: &HashMap<Symbol, f64>) -> Vec<f64> {
        let mut ev = Evaluator::new(point);
        self.drift.iter().map(|e| ev.eval(*e)).collect()
    }

    /// The decoupling law `u = A^-1 (v - b)` at `point`; `None` where `A` is
    /// singular.
    pub fn law_at(&self, point: &HashMap<Symbol, f64>, v: &[f64]) -> Option<Vec<f64>> {
        let a = self.matrix_at(point);
        let b = self.drift_at(point);
        let rhs = nalgebra::DVector::from_fn(b.len(), |i, _| v[i] - b[i]);
        a.lu().solve(&rhs).map(|u| u.iter().copied().collect())
    }

    /// How far `A` is from singular at `point`, between 0 (singular) and 1:
    /// the smallest of, for each row, `max_j |A_ij| / sum |terms of A_ij|`
    /// (a row that vanishes by cancellation, as the pitch row of a
    /// two-wheeled robot where `M_tt + M_tp = 0`), Hadamard's
    /// `|det A| / prod_i |A_i|` (dependent rows), and for each factor of
    /// [`Decoupling::singular_factors`] `|f| / sum |terms of f|`. Compared
    /// with [`SCREEN_ZERO`].
    pub fn singularity_at(&self, point: &HashMap<Symbol, f64>) -> f64 {
        let mut ev = Evaluator::new(point);
        let mut worst: f64 = 1.0;
        let ratio = |v: f64, scale: f64| {
            if scale > 0.0 && v.is_finite() && scale.is_finite() {
                (v.abs() / scale).min(1.0)
            } else {
                0.0
            }
        };
        for row in &self.row_terms {
            let mut best: f64 = 0.0;
            for terms in row {
                let values: Vec<f64> = terms.iter().map(|t| ev.eval(*t)).collect();
                let sum: f64 = values.iter().sum();
                let scale: f64 = values.iter().map(|v| v.abs()).sum();
                best = best.max(ratio(sum, scale));
            }
            worst = worst.min(best);
        }
        let m = self.matrix.len();
        let a = DMatrix::from_fn(m, m, |i, j| ev.eval(self.matrix[i][j]));
        worst = worst.min(hadamard_ratio(&a));
        for f in &self.singular_factors {
            let terms = match f.node() {
                crate::sym::Node::Add(ts) => ts.to_vec(),
                _ => vec![*f],
            };
            let values: Vec<f64> = terms.iter().map(|t| ev.eval(*t)).collect();
            let scale: f64 = values.iter().map(|v| v.abs()).sum();
            worst = worst.min(ratio(values.iter().sum(), scale));
        }
        worst
    }

    /// The singular set as text, e.g. `cos(psi) + c = 0`.
    pub fn singular_set(&self) -> String {
        singular_set_text(
            self.singular_note.as_deref(),
            &self.singular_factors,
            "det A",
        )
    }
}

/// `|det a| / prod_i |a_i|` (0 for a zero row; NaN-free).
pub fn hadamard_ratio(a: &DMatrix<f64>) -> f64 {
    let bound: f64 = a.row_iter().map(|r| r.norm()).product();
    let det = a.determinant().abs();
    if bound > 0.0 && det.is_finite() {
        det / bound
    } else {
        0.0
    }
}

/// `[h, L_f h, ..., L_f^r h]`, the rows `L_g L_f^k h` (`k < r`) and `r`.
type AffineRows = (Vec<Expr>, Vec<Vec<Expr>>, usize);

/// Lie derivatives of `h` along `f` and every input field of `ca` until a row
/// `L_g L_f^k h` is not identically zero.
fn affine_rows(ca: &ControlAffine, h: Expr) -> Result<AffineRows, AnalysisError> {
    let n = ca.state.len();
    let m = ca.inputs.len();
    let columns: Vec<Vec<Expr>> = (0..m)
        .map(|j| ca.g.iter().map(|row| row[j]).collect())
        .collect();
    let mut lf = vec![simplify(h)];
    let mut lg = Vec::new();
    for k in 0..n {
        let row: Vec<Expr> = columns
            .iter()
            .map(|g| lie_derivative(lf[k], g, &ca.state))
            .collect();
        lf.push(lie_derivative(lf[k], &ca.f, &ca.state));
        if row.iter().any(|e| !is_zero(*e)) {
            lg.push(row);
            return Ok((lf, lg, k + 1));
        }
        lg.push(vec![Expr::zero(); m]);
    }
    Err(AnalysisError::RelativeDegreeUndefined {
        at: "every state (no input reaches this output)".into(),
    })
}

/// The diagonal blocks of `m`: the connected components of the graph with
/// an edge `i - j` where `m[i][j]` is not identically zero, each sorted, in
/// the order of their first coordinate.
fn blocks(m: &[Vec<Expr>]) -> Vec<Vec<usize>> {
    let n = m.len();
    let mut block = vec![usize::MAX; n];
    let mut out: Vec<Vec<usize>> = Vec::new();
    for start in 0..n {
        if block[start] != usize::MAX {
            continue;
        }
        let id = out.len();
        let mut members = vec![start];
        block[start] = id;
        let mut k = 0;
        while k < members.len() {
            let i = members[k];
            for j in 0..n {
                if block[j] == usize::MAX && !(m[i][j].is_zero() || is_zero(m[i][j])) {
                    block[j] = id;
                    members.push(j);
                }
            }
            k += 1;
        }
        members.sort_unstable();
        out.push(members);
    }
    out
}

/// The expanded parts of the decoupling of position outputs.
struct Expanded {
    /// Rows `J M^-1 B`.
    rows: Vec<Vec<Expr>>,
    /// `q'^T H q' + J M^-1 r0`.
    drift: Vec<Expr>,
    /// The diagonal blocks of `M` (coordinate indices) and their
    /// determinants (simplified): `det M` is their product.
    blocks: Vec<(Vec<usize>, Expr)>,
}

/// Expanded rows `J M^-1 B` and `q'^T H q' + J M^-1 r0` of the position
/// outputs `parts`. `M^-1` is taken block by block (`M` is block diagonal
/// when coordinates do not couple kinetically, as the yaw of a two-wheeled
/// robot and its pitch): each block's adjugate over its own determinant, so
/// a row that only sees one block has only that block's determinant below.
fn explicit(
    canon: &mut Canonicalizer,
    eqs: &crate::mechanics::Equations,
    parts: &[&PositionOutput],
    r0: &[Expr],
) -> Result<Expanded, String> {
    let n = eqs.coords.len();
    let m = eqs.inputs.len();
    let mut simp = |e: Expr, what: &str| canon.try_simplify(e).map_err(|x| budget_reason(what, x));
    let mut mm = vec![vec![Expr::zero(); n]; n];
    for (row, src) in mm.iter_mut().zip(&eqs.mass_matrix) {
        for (e, s) in row.iter_mut().zip(src) {
            *e = simp(*s, "M")?;
        }
    }
    // M^-1 = adj(M_b) / det(M_b) on each diagonal block b, 0 elsewhere
    let mut inverse = vec![vec![Expr::zero(); n]; n];
    let mut dets = Vec::new();
    for b in blocks(&mm) {
        let sub: Vec<Vec<Expr>> = b
            .iter()
            .map(|i| b.iter().map(|j| mm[*i][*j]).collect())
            .collect();
        let det = simp(determinant(&sub), "det M")?;
        let adj = adjugate(&sub);
        for (x, i) in b.iter().enumerate() {
            for (y, j) in b.iter().enumerate() {
                inverse[*i][*j] = adj[x][y] / det;
            }
        }
        dets.push((b, det));
    }
    let mut rows = Vec::new();
    let mut drift = Vec::new();
    for p in parts {
        // J M^-1: one row
        let jinv: Vec<Expr> = (0..n)
            .map(|k| {
                Expr::add_all(
                    (0..n)
                        .filter(|i| !p.gradient[*i].is_zero() && !inverse[*i][k].is_zero())
                        .map(|i| p.gradient[i] * inverse[i][k]),
                )
            })
            .collect();
        let mut row = Vec::with_capacity(m);
        for j in 0..m {
            let e = Expr::add_all((0..n).map(|k| jinv[k] * eqs.input_matrix[k][j]));
            row.push(simp(e, "L_g L_f h")?);
        }
        rows.push(row);
        let e = Expr::add_all((0..n).map(|k| jinv[k] * r0[k]));
        drift.push(simp(p.curvature + e, "L_f^2 h")?);
    }
    Ok(Expanded {
        rows,
        drift,
        blocks: dets,
    })
}

/// The decoupling analysis of the outputs `names` of `model` (as many as it
/// has inputs).
pub fn decoupling(
    model: &Model,
    derivation: &Derivation,
    names: &[&str],
) -> Result<Decoupling, AnalysisError> {
    let eqs = &derivation.equations;
    let m = eqs.inputs.len();
    let n = eqs.coords.len();
    if names.len() != m {
        return Err(AnalysisError::NotSquare {
            outputs: names.len(),
            inputs: m,
        });
    }
    let hs: Vec<Expr> = names
        .iter()
        .map(|name| output_expr(model, name))
        .collect::<Result<_, _>>()?;
    let state = model.state_symbols();
    let mut canon = Canonicalizer::new(ANALYSIS_MAX_TERMS);

    // outputs of the coordinates: through the structure
    let mut parts: Vec<Option<PositionOutput>> = Vec::with_capacity(m);
    for h in &hs {
        parts.push(if is_position_output(eqs, *h) {
            Some(position_output(&mut canon, eqs, *h)?)
        } else {
            None
        });
    }
    let mech: Vec<usize> = (0..m).filter(|i| parts[*i].is_some()).collect();
    let mech_parts: Vec<&PositionOutput> = mech.iter().filter_map(|i| parts[*i].as_ref()).collect();
    let r0: Vec<Expr> = (0..n).map(|i| eqs.forces[i] - eqs.bias[i]).collect();
    let grads: Vec<Vec<Expr>> = mech_parts.iter().map(|p| p.gradient.clone()).collect();
    let ws = if grads.is_empty() {
        Vec::new()
    } else {
        ldl_solve(&eqs.mass_matrix, &grads)
    };
    let dag_rows: Vec<Vec<Expr>> = ws
        .iter()
        .map(|w| {
            (0..m)
                .map(|j| Expr::add_all((0..n).map(|k| w[k] * eqs.input_matrix[k][j])))
                .collect()
        })
        .collect();
    let dag_drift: Vec<Expr> = ws
        .iter()
        .zip(&mech_parts)
        .map(|(w, p)| p.curvature + Expr::add_all((0..n).map(|k| w[k] * r0[k])))
        .collect();
    let points = screening_points(model, eqs, SCREEN_POINTS);
    let mut margins = vec![f64::INFINITY; mech.len()];
    for p in &points {
        let mut ev = Evaluator::new(p);
        for (a, (w, row)) in ws.iter().zip(&dag_rows).enumerate() {
            let mut best: f64 = 0.0;
            for (j, entry) in row.iter().enumerate() {
                let scale: f64 = (0..n)
                    .map(|k| (ev.eval(w[k]) * ev.eval(eqs.input_matrix[k][j])).abs())
                    .sum();
                let v = ev.eval(*entry).abs();
                let rel = if scale > 0.0 { v / scale } else { 0.0 };
                if rel.is_finite() {
                    best = best.max(rel);
                }
            }
            margins[a] = margins[a].min(best);
        }
    }
    let mut not_expanded = None;
    let mut expanded_parts = None;
    if !mech.is_empty() {
        if n <= EXPLICIT_MAX_COORDINATES {
            match explicit(&mut canon, eqs, &mech_parts, &r0) {
                Ok(e) => expanded_parts = Some(e),
                Err(reason) => not_expanded = Some(reason),
            }
        } else {
            not_expanded = Some(format!(
                "not expanded for {n} coordinates (more than {EXPLICIT_MAX_COORDINATES}): \
                 A and b computed through M, Q0 - bias and B by a symbolic LDL^T solve"
            ));
        }
    }

    let mut outputs: Vec<Option<OutputLie>> = vec![None; m];
    let mut through_affine: Vec<usize> = (0..m).filter(|i| parts[*i].is_none()).collect();
    for (a, &i) in mech.iter().enumerate() {
        let p = &mech_parts[a];
        let (row, drift) = match &expanded_parts {
            Some(e) => (e.rows[a].clone(), e.drift[a]),
            None => (dag_rows[a].clone(), dag_drift[a]),
        };
        if margins[a] <= SCREEN_ZERO {
            match &expanded_parts {
                Some(_) => {
                    let mut zero = true;
                    for e in &row {
                        zero &= canon.try_is_zero(*e).map_err(|x| AnalysisError::Budget {
                            reason: budget_reason("exact test of L_g L_f h = 0", x),
                        })?;
                    }
                    if zero {
                        // relative degree above 2: the expanded control-affine form
                        through_affine.push(i);
                        continue;
                    }
                }
                None => {
                    return Err(AnalysisError::Budget {
                        reason: format!(
                            "L_g L_f {} vanished at {SCREEN_POINTS} random states and the exact \
                             test is out of reach: {}",
                            names[i],
                            not_expanded.clone().unwrap_or_default()
                        ),
                    })
                }
            }
        }
        outputs[i] = Some(OutputLie {
            name: names[i].to_string(),
            relative_degree: 2,
            lf: vec![p.h, p.lfh, drift],
            lg: vec![vec![Expr::zero(); m], row],
            gradient: p.gradient.clone(),
            curvature: Some(p.curvature),
            screening_margin: margins[a],
        });
    }
    through_affine.sort_unstable();
    if !through_affine.is_empty() {
        let ca = derivation.affine().map_err(|e| AnalysisError::Budget {
            reason: format!(
                "output {} needs the expanded control-affine form (it depends on velocities, \
                 or L_g L_f h vanishes identically), and {e}",
                names[through_affine[0]]
            ),
        })?;
        for &i in &through_affine {
            let (lf, lg, r) = affine_rows(ca, hs[i])?;
            outputs[i] = Some(OutputLie {
                name: names[i].to_string(),
                relative_degree: r,
                lf,
                lg,
                gradient: Vec::new(),
                curvature: None,
                screening_margin: 1.0,
            });
        }
    }
    let outputs: Vec<OutputLie> = outputs
        .into_iter()
        .map(|o| o.expect("every output"))
        .collect();
    let row_terms: Vec<Vec<Vec<Expr>>> = (0..m)
        .map(|i| match mech.iter().position(|k| *k == i) {
            Some(a) if outputs[i].curvature.is_some() => (0..m)
                .map(|j| {
                    (0..n)
                        .map(|k| ws[a][k] * eqs.input_matrix[k][j])
                        .filter(|t| !t.is_zero())
                        .collect()
                })
                .collect(),
            _ => outputs[i].lg[outputs[i].relative_degree - 1]
                .iter()
                .map(|e| vec![*e])
                .collect(),
        })
        .collect();
    let matrix: Vec<Vec<Expr>> = outputs
        .iter()
        .map(|o| o.lg[o.relative_degree - 1].clone())
        .collect();
    let drift: Vec<Expr> = outputs.iter().map(|o| o.lf[o.relative_degree]).collect();

    // det A: screened at random states, exact when expanded
    let mut det_margin = f64::INFINITY;
    for p in &points {
        let mut ev = Evaluator::new(p);
        let a = DMatrix::from_fn(m, m, |i, j| ev.eval(matrix[i][j]));
        det_margin = det_margin.min(hadamard_ratio(&a));
    }
    let mut det = None;
    let mut det_note = None;
    if not_expanded.is_none() {
        match canon.try_simplify(determinant(&matrix)) {
            Ok(d) => det = Some(d),
            Err(x) => det_note = Some(budget_reason("det A", x)),
        }
    }
    let (singular_factors, singular_note) = match det {
        Some(d) => {
            if d.is_zero() || is_zero(d) {
                return Err(AnalysisError::SingularDecoupling {
                    reason: "everywhere (det A = 0 identically)".into(),
                });
            }
            split_singular_factors(d, eqs, &state, "det A")
        }
        None => {
            if det_margin <= SCREEN_ZERO {
                return Err(AnalysisError::SingularDecoupling {
                    reason: format!(
                        "at {SCREEN_POINTS} random states (|det A| <= {SCREEN_ZERO:e} of its \
                         Hadamard bound at each; the exact test is out of reach)"
                    ),
                });
            }
            let why = det_note.map(|r| format!(": {r}")).unwrap_or_default();
            let note = format!(
                "where det A(x) = 0 (not expanded{why}; at {SCREEN_POINTS} random states |det A| is \
                 at least {det_margin:.2e} of its Hadamard bound)"
            );
            (Vec::new(), Some(note))
        }
    };
    let mass_blocks = expanded_parts.map(|e| e.blocks).unwrap_or_default();
    Ok(Decoupling {
        outputs,
        inputs: eqs.inputs.clone(),
        state,
        matrix,
        drift,
        det,
        mass_blocks,
        not_expanded,
        singular_factors,
        singular_note,
        det_margin,
        row_terms,
    })
}
