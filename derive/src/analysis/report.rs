//! The analysis of one output as `plantc analyze` reports it: Lie derivatives
//! by their parts (with `D = det M` named), the linearizing law as
//! `u = (v - L_f^r h) / (L_g L_f^(r-1) h)`, the singular set, the normal form
//! and the zero dynamics, with every unexpanded or budget-stopped part said.

use std::fmt;

use super::lie::LieChain;
use super::normal_form::{normal_form, NormalForm, NormalFormError};
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
