//! The analysis of one output as `plantc analyze` reports it: Lie derivatives
//! by their parts (with `D = det M` named), the linearizing law as
//! `u = (v - L_f^r h) / (L_g L_f^(r-1) h)`, the singular set, the normal form
//! and the zero dynamics, with every unexpanded or budget-stopped part said;
//! and the same for the outputs of a square multi-input system
//! ([`analyze_outputs`]: vector relative degree, decoupling matrix, its law).

use std::fmt;

use super::decoupling::{decoupling, Decoupling, SCREEN_ZERO};
use super::lie::LieChain;
use super::normal_form::{normal_form, normal_form_for, NormalForm, NormalFormError};
use super::zero_dynamics::{zero_dynamics, ZeroDynamics, ZeroDynamicsError};
use super::AnalysisError;
use crate::control::{output_expr, Derivation};
use crate::mechanics::det_name;
use crate::model::{Model, ParameterValues};
use crate::sym::{present, Expr, Name};

/// Why an output could not be analysed.
#[derive(Clone, Debug, PartialEq)]
pub enum OutputAnalysisError {
    /// Lie derivatives or relative degree.
    Lie(AnalysisError),
    /// Normal form.
    NormalForm(NormalFormError),
    /// Zero dynamics.
    ZeroDynamics(ZeroDynamicsError),
}

impl fmt::Display for OutputAnalysisError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            OutputAnalysisError::Lie(e) => write!(f, "{e}"),
            OutputAnalysisError::NormalForm(e) => write!(f, "{e}"),
            OutputAnalysisError::ZeroDynamics(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for OutputAnalysisError {}

/// The analysis of an output.
#[derive(Clone, Debug)]
pub struct OutputReport {
    /// The output's name.
    pub output: String,
    /// Its expression.
    pub h: Expr,
    /// The relative degree.
    pub relative_degree: usize,
    /// Named definitions used below (`D = det M`).
    pub definitions: Vec<(String, String)>,
    /// `(name, value)`: `h`, `L_f h`, ..., `L_g h`, ... as printed.
    pub lie_derivatives: Vec<(String, String)>,
    /// The law by its parts, `u = (v - L_f^2 h)/(L_g L_f h)`.
    pub law: String,
    /// The law as one expression, when the parts are expanded.
    pub law_expanded: Option<String>,
    /// The singular set of the law.
    pub singular_set: String,
    /// Why parts are not expanded (empty if everything is).
    pub notes: Vec<String>,
    /// The Lie chain.
    pub chain: LieChain,
    /// The normal form.
    pub normal_form: NormalForm,
    /// The zero dynamics.
    pub zero_dynamics: ZeroDynamics,
}

fn lf_name(k: usize) -> String {
    match k {
        0 => "h".into(),
        1 => "L_f h".into(),
        _ => format!("L_f^{k} h"),
    }
}

fn lg_name(k: usize) -> String {
    match k {
        0 => "L_g h".into(),
        _ => format!("L_g {}", lf_name(k)),
    }
}

/// Analyse the output `name` of `model` with parameter `values` (used for the
/// normal form's rank test and the zero dynamics' linearization).
pub fn analyze_output(
    model: &Model,
    derivation: &Derivation,
    name: &str,
    values: &ParameterValues,
) -> Result<OutputReport, OutputAnalysisError> {
    let h = output_expr(model, name).map_err(OutputAnalysisError::Lie)?;
    let chain = derivation
        .lie_chain(model, h)
        .map_err(OutputAnalysisError::Lie)?;
    let nf = normal_form(model, derivation, &chain, values, None)
        .map_err(OutputAnalysisError::NormalForm)?;
    let zd = zero_dynamics(model, &nf, values).map_err(OutputAnalysisError::ZeroDynamics)?;
    let r = chain.relative_degree;
    let mut definitions = Vec::new();
    let mut names = Vec::new();
    let mut notes = Vec::new();
    let mut lie = Vec::new();
    let law = format!("u = (v - {})/({})", lf_name(r), lg_name(r - 1));
    let mut law_expanded = None;
    match &chain.mechanical {
        Some(parts) if parts.not_expanded.is_some() => {
            let grad: Vec<String> = parts.gradient.iter().map(|e| e.to_string()).collect();
            lie.push(("h".into(), chain.lf[0].to_string()));
            lie.push(("L_f h".into(), chain.lf[1].to_string()));
            lie.push((
                "L_f^2 h".into(),
                format!(
                    "q'^T (d^2h/dq^2) q' + J M^-1 (Q0 - bias), with J = dh/dq = [{}] and q'^T (d^2h/dq^2) q' = {}",
                    grad.join(", "),
                    parts.curvature
                ),
            ));
            lie.push(("L_g h".into(), "0".into()));
            lie.push((
                "L_g L_f h".into(),
                format!(
                    "J M^-1 B (nonzero: at least {:.2e} of its size at random states)",
                    parts.screening_margin
                ),
            ));
            if let Some(reason) = &parts.not_expanded {
                notes.push(reason.clone());
            }
            if !zd.explicit {
                notes.push(
                    "the zero dynamics are given by their parts (unexpanded); \
                     their linearization is exact"
                        .into(),
                );
            }
        }
        _ => {
            if let Some(d) = chain.mechanical.as_ref().and_then(|m| m.det_mass) {
                definitions.push((det_name().to_string(), format!("det M = {d}")));
                names.push(Name {
                    symbol: det_name(),
                    definition: d,
                });
            }
            let show = |e: Expr| present(e, &names).to_string();
            for k in 0..=r {
                lie.push((lf_name(k), show(chain.lf[k])));
            }
            for k in 0..r {
                lie.push((lg_name(k), show(chain.lg[k])));
            }
            law_expanded = Some(format!("u = {}", present(chain.law(Expr::sym("v")), &[])));
        }
    }
    Ok(OutputReport {
        output: name.to_string(),
        h,
        relative_degree: r,
        definitions,
        lie_derivatives: lie,
        law,
        law_expanded,
        singular_set: chain.singular_set(),
        notes,
        chain,
        normal_form: nf,
        zero_dynamics: zd,
    })
}

/// The decoupling analysis of a square multi-input system as `plantc
/// analyze` reports it: every output's Lie derivatives (with `D = det M`
/// named), the decoupling matrix `A(x)`, `b(x)`, `det A` and where it
/// vanishes, the law `u = A^-1 (v - b)`, `A` at the operating point, the
/// normal form and the zero dynamics.
#[derive(Clone, Debug)]
pub struct DecouplingReport {
    /// The outputs' names, in the order given.
    pub outputs: Vec<String>,
    /// The inputs' names (model order).
    pub inputs: Vec<String>,
    /// Named definitions used below (`D = det M`).
    pub definitions: Vec<(String, String)>,
    /// Per output: `(name, value)` of `h`, `L_f h`, ..., `L_g h`, ... as
    /// printed (rows as `[a, b]`).
    pub lie_derivatives: Vec<Vec<(String, String)>>,
    /// `A(x)` entries as printed.
    pub matrix_text: Vec<Vec<String>>,
    /// `b(x)` entries as printed.
    pub drift_text: Vec<String>,
    /// `det A` as printed, when expanded.
    pub det_text: Option<String>,
    /// `A` at the operating point (the state 0), numerically.
    pub matrix_at_operating_point: Vec<Vec<f64>>,
    /// The law by its parts.
    pub law: String,
    /// Where `A` is singular.
    pub singular_set: String,
    /// What is not expanded, and how identities were checked.
    pub notes: Vec<String>,
    /// The analysis.
    pub decoupling: Decoupling,
    /// The normal form (`xi` of every output in turn).
    pub normal_form: NormalForm,
    /// The zero dynamics.
    pub zero_dynamics: ZeroDynamics,
}

fn row_text(row: &[Expr], show: &dyn Fn(Expr) -> String) -> String {
    format!(
        "[{}]",
        row.iter().map(|e| show(*e)).collect::<Vec<_>>().join(", ")
    )
}

/// Analyse the outputs `names` of a model with as many inputs, with
/// parameter `values` (for `A` at the operating point, the normal form's
/// rank test and the zero dynamics' linearization). The operating point is
/// the state 0; `A` must be nonsingular there.
pub fn analyze_outputs(
    model: &Model,
    derivation: &Derivation,
    names: &[&str],
    values: &ParameterValues,
) -> Result<DecouplingReport, OutputAnalysisError> {
    let dec = decoupling(model, derivation, names).map_err(OutputAnalysisError::Lie)?;
    let mut point = values.symbol_map(model);
    for s in &dec.state {
        point.insert(*s, 0.0);
    }
    let a0 = dec.matrix_at(&point);
    let ratio = dec.singularity_at(&point);
    if ratio <= SCREEN_ZERO {
        return Err(OutputAnalysisError::Lie(
            AnalysisError::SingularDecoupling {
                reason: format!(
                    "at the operating point x = 0 (a row, a factor of det A or det A itself is \
                 {ratio:.2e} of its size, at most {SCREEN_ZERO:e})"
                ),
            },
        ));
    }
    let xi = dec.xi();
    let nf = normal_form_for(model, derivation, &xi, dec.expanded(), values, None)
        .map_err(OutputAnalysisError::NormalForm)?;
    let zd = zero_dynamics(model, &nf, values).map_err(OutputAnalysisError::ZeroDynamics)?;
    let mut notes = Vec::new();
    let mut definitions = Vec::new();
    let mut names_def = Vec::new();
    let coords: Vec<&str> = derivation
        .equations
        .coords
        .iter()
        .map(|c| c.q.name())
        .collect();
    let taken = |name: &str| {
        model.parameters.iter().any(|p| p.name == name)
            || model.derived.iter().any(|d| d.name == name)
            || model.coordinates.iter().any(|c| c.name == name)
            || model.inputs.iter().any(|u| u.name == name)
    };
    let several = dec.mass_blocks.len() > 1;
    for (k, (block, d)) in dec.mass_blocks.iter().enumerate() {
        if several && block.len() == 1 {
            continue; // a diagonal entry of M: printed as it is
        }
        let mut name = if several {
            format!("D{}", k + 1)
        } else {
            det_name().to_string()
        };
        while taken(&name) {
            name.push('_');
        }
        let what = if several {
            format!(
                "det M[{}]",
                block
                    .iter()
                    .map(|i| coords[*i])
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        } else {
            "det M".to_string()
        };
        definitions.push((name.clone(), format!("{what} = {d}")));
        names_def.push(Name {
            symbol: Expr::sym(&name),
            definition: *d,
        });
    }
    if several {
        let listed: Vec<String> = dec
            .mass_blocks
            .iter()
            .map(|(b, _)| {
                format!(
                    "[{}]",
                    b.iter().map(|i| coords[*i]).collect::<Vec<_>>().join(", ")
                )
            })
            .collect();
        notes.push(format!(
            "M is block diagonal ({}): M^-1 is taken block by block",
            listed.join(", ")
        ));
    }
    let expanded = dec.expanded();
    let show = |e: Expr| -> String {
        if expanded {
            present(e, &names_def).to_string()
        } else {
            e.to_string()
        }
    };
    let m = names.len();
    let mut lie = Vec::new();
    for o in &dec.outputs {
        let r = o.relative_degree;
        let mut rows = Vec::new();
        let structured = !expanded && o.curvature.is_some();
        for k in 0..r {
            rows.push((lf_name(k), show(o.lf[k])));
        }
        if structured {
            let grad: Vec<String> = o.gradient.iter().map(|e| e.to_string()).collect();
            rows.push((
                lf_name(r),
                format!(
                    "q'^T (d^2h/dq^2) q' + J M^-1 (Q0 - bias), with J = dh/dq = [{}] and q'^T (d^2h/dq^2) q' = {}",
                    grad.join(", "),
                    o.curvature.unwrap_or_else(Expr::zero)
                ),
            ));
        } else {
            rows.push((lf_name(r), show(o.lf[r])));
        }
        for k in 0..r {
            if structured && k == r - 1 {
                rows.push((
                    lg_name(k),
                    format!(
                        "J M^-1 B (nonzero: at least {:.2e} of its size at random states)",
                        o.screening_margin
                    ),
                ));
            } else if k + 1 < r {
                rows.push((lg_name(k), format!("[{}]", vec!["0"; m].join(", "))));
            } else {
                rows.push((lg_name(k), row_text(&o.lg[k], &show)));
            }
        }
        lie.push(rows);
    }
    let matrix_text: Vec<Vec<String>> = if expanded {
        dec.matrix
            .iter()
            .map(|row| row.iter().map(|e| show(*e)).collect())
            .collect()
    } else {
        dec.outputs
            .iter()
            .map(|o| {
                (0..m)
                    .map(|j| {
                        if o.curvature.is_some() {
                            format!("(J_{} M^-1 B)[{}]", o.name, j + 1)
                        } else {
                            o.lg[o.relative_degree - 1][j].to_string()
                        }
                    })
                    .collect()
            })
            .collect()
    };
    let drift_text: Vec<String> = dec
        .outputs
        .iter()
        .zip(&lie)
        .map(|(o, rows)| rows[o.relative_degree].1.clone())
        .collect();
    let det_text = dec.det.map(&show);
    if let Some(reason) = &dec.not_expanded {
        notes.push(reason.clone());
    }
    if !zd.explicit {
        notes.push(
            "the zero dynamics are given by their parts (unexpanded); their linearization is exact"
                .into(),
        );
    }
    if dec.det.is_none() {
        notes.push(format!(
            "det A is not expanded: A was checked nonsingular numerically at {} random states \
             and at the operating point, not exactly",
            super::mechanical::SCREEN_POINTS
        ));
    }
    let rd: Vec<String> = dec
        .outputs
        .iter()
        .map(|o| format!("L_f^{} h_{}", o.relative_degree, o.name))
        .collect();
    let law = format!(
        "u = A(x)^-1 (v - b(x)), b = ({}): y_i^(r_i) = v_i where det A != 0",
        rd.join(", ")
    );
    Ok(DecouplingReport {
        outputs: names.iter().map(|s| s.to_string()).collect(),
        inputs: dec.inputs.iter().map(|s| s.name().to_string()).collect(),
        definitions,
        lie_derivatives: lie,
        matrix_text,
        drift_text,
        det_text,
        matrix_at_operating_point: (0..m)
            .map(|i| (0..m).map(|j| a0[(i, j)]).collect())
            .collect(),
        law,
        singular_set: dec.singular_set(),
        notes,
        decoupling: dec,
        normal_form: nf,
        zero_dynamics: zd,
    })
}
