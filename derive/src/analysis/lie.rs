//! Lie derivatives, relative degree and the input-output linearizing law of a
//! single-input control-affine system `x' = f(x) + g(x) u`.

use std::fmt;

use crate::mechanics::ControlAffine;
use crate::sym::{diff, is_zero, simplify, Expr, Node, Symbol};

/// Why an output could not be analysed.
#[derive(Clone, Debug, PartialEq)]
pub enum AnalysisError {
    /// `L_g L_f^k h` vanishes identically for every `k < n`: the input never
    /// reaches the output (e.g. an output that only depends on a decoupled
    /// coordinate).
    RelativeDegreeUndefined {
        /// Where it was checked (`"every state"` for identically zero).
        at: String,
    },
    /// Only single-input systems are supported here.
    MultiInput {
        /// Number of inputs.
        inputs: usize,
    },
    /// An exact computation hit its term budget; the reason says which and why.
    Budget {
        /// What stopped, and why.
        reason: String,
    },
    /// A square (decoupling) analysis needs as many outputs as inputs.
    NotSquare {
        /// Outputs given.
        outputs: usize,
        /// Inputs of the model.
        inputs: usize,
    },
    /// The decoupling matrix `A(x) = [L_g L_f^(r_i-1) h_i]` is singular
    /// (identically, or at the operating point): the vector relative degree
    /// is not defined there.
    SingularDecoupling {
        /// Where, and how it was found.
        reason: String,
    },
    /// The output named is not declared in the model.
    UnknownOutput {
        /// The name.
        name: String,
        /// Outputs the model declares.
        known: Vec<String>,
    },
}

impl fmt::Display for AnalysisError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AnalysisError::RelativeDegreeUndefined { at } => write!(
                f,
                "the relative degree is undefined at {at}: L_g L_f^k h vanishes for every k < n"
            ),
            AnalysisError::MultiInput { inputs } => write!(
                f,
                "input-output linearization is implemented for one input; the model has {inputs}"
            ),
            AnalysisError::Budget { reason } => write!(f, "analysis stopped: {reason}"),
            AnalysisError::NotSquare { outputs, inputs } => write!(
                f,
                "a decoupling analysis needs as many outputs as inputs: {outputs} output{} for {inputs} inputs",
                if *outputs == 1 { "" } else { "s" }
            ),
            AnalysisError::SingularDecoupling { reason } => write!(
                f,
                "the decoupling matrix A(x) = [L_g L_f^(r_i-1) h_i] is singular {reason}: \
                 the vector relative degree is not defined (static feedback cannot decouple these outputs)"
            ),
            AnalysisError::UnknownOutput { name, known } => {
                write!(
                    f,
                    "unknown output `{name}` (the model declares: {})",
                    known.join(", ")
                )
            }
        }
    }
}

impl std::error::Error for AnalysisError {}

/// `L_v h = sum_i dh/dx_i v_i`, simplified.
pub fn lie_derivative(h: Expr, field: &[Expr], state: &[Symbol]) -> Expr {
    let terms: Vec<Expr> = state
        .iter()
        .zip(field)
        .filter(|(_, v)| !v.is_zero())
        .map(|(x, v)| diff(h, *x) * *v)
        .collect();
    simplify(Expr::add_all(terms))
}

/// The Lie-derivative chain of an output.
#[derive(Clone, Debug)]
pub struct LieChain {
    /// `[h, L_f h, ..., L_f^r h]` (length `r + 1`), simplified.
    pub lf: Vec<Expr>,
    /// `L_g L_f^k h` for `k = 0..r` (the last one is nonzero).
    pub lg: Vec<Expr>,
    /// The relative degree `r`.
    pub relative_degree: usize,
    /// State-dependent factors of `L_g L_f^(r-1) h` whose zeros make the law
    /// singular (e.g. `cos(alpha)`), and the full decoupling term.
    pub singular_factors: Vec<Expr>,
    /// What the singular set is when it is not a list of factors (e.g. none
    /// because the decoupling term is a diagonal entry of `M^-1`).
    pub singular_note: Option<String>,
    /// The parts of a mechanical output's derivatives (`h(q)` through `M`,
    /// `Q0 - bias`, `B`), when computed that way.
    pub mechanical: Option<super::mechanical::MechanicalParts>,
}

impl LieChain {
    /// `L_g L_f^(r-1) h`.
    pub fn decoupling(&self) -> Expr {
        self.lg[self.relative_degree - 1]
    }

    /// The singular set as text, e.g. `cos(alpha) = 0`.
    pub fn singular_set(&self) -> String {
        singular_set_text(
            self.singular_note.as_deref(),
            &self.singular_factors,
            "L_g L_f^(r-1) h",
        )
    }

    /// The linearizing law `u = (v - L_f^r h) / (L_g L_f^(r-1) h)`, where `v`
    /// may use `y`, `y'`, ..., `y^(r-1)` (replaced by `h`, `L_f h`, ...).
    pub fn law(&self, v: Expr) -> Expr {
        let mut map = std::collections::HashMap::new();
        for k in 0..self.relative_degree {
            map.insert(Expr::sym(&format!("y{}", "'".repeat(k))), self.lf[k]);
        }
        let v = crate::sym::substitute(v, &map);
        (v - self.lf[self.relative_degree]) / self.decoupling()
    }
}

/// A singular set as text: `note` if given, else `f1 = 0 or f2 = 0`, else
/// none (`what` has no state-dependent factor).
pub(crate) fn singular_set_text(note: Option<&str>, factors: &[Expr], what: &str) -> String {
    if let Some(note) = note {
        return note.to_string();
    }
    if factors.is_empty() {
        return format!("none ({what} has no state-dependent factor)");
    }
    factors
        .iter()
        .map(|f| format!("{f} = 0"))
        .collect::<Vec<_>>()
        .join(" or ")
}

/// Factors of `e`'s numerator that depend on the state.
pub(crate) fn state_factors(e: Expr, state: &[Symbol]) -> Vec<Expr> {
    let depends = |x: Expr| state.iter().any(|s| x.contains(*s));
    let factors: Vec<Expr> = match e.node() {
        Node::Mul(fs) => fs.to_vec(),
        _ => vec![e],
    };
    factors
        .into_iter()
        .filter(|f| {
            let (_, ex) = f.base_and_exp();
            let negative = ex.as_rational().is_some_and(|r| r.is_negative());
            !negative && depends(*f)
        })
        .map(|f| f.base_and_exp().0)
        .collect()
}

/// Lie derivatives of `h` until the input appears: the relative degree.
pub fn lie_chain(ca: &ControlAffine, h: Expr) -> Result<LieChain, AnalysisError> {
    if ca.inputs.len() != 1 {
        return Err(AnalysisError::MultiInput {
            inputs: ca.inputs.len(),
        });
    }
    let g: Vec<Expr> = ca.g.iter().map(|row| row[0]).collect();
    let n = ca.state.len();
    let mut lf = vec![simplify(h)];
    let mut lg = Vec::new();
    for k in 0..n {
        let lgk = lie_derivative(lf[k], &g, &ca.state);
        let next = lie_derivative(lf[k], &ca.f, &ca.state);
        lf.push(next);
        lg.push(lgk);
        if !is_zero(lgk) {
            return Ok(LieChain {
                singular_factors: state_factors(lgk, &ca.state),
                singular_note: None,
                mechanical: None,
                lf,
                lg,
                relative_degree: k + 1,
            });
        }
        lg[k] = Expr::zero();
    }
    Err(AnalysisError::RelativeDegreeUndefined {
        at: "every state".into(),
    })
}
