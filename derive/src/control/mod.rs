//! Controllers declared in a model file, resolved into something that can be
//! evaluated, simulated or emitted as code.
//!
//! - `gains`, `place`, `lqr` become state feedback `u = u0 - K (x - x0)` with
//!   `K` designed on the linearization about the operating point (all zero).
//! - `linearize output y` becomes the feedback-linearizing law
//!   `u = (v - L_f^r h) / (L_g L_f^(r-1) h)` with the outer law `v` inlined.

use std::fmt;

use crate::analysis::{
    lie_chain, linearize, AnalysisError, LieChain, LinearizeError, OperatingPoint,
};
use crate::linear::{lqr, place, LinearError, Pole};
use crate::mechanics::{
    control_affine, derive_equations, ControlAffine, Equations, MechanicsError,
};
use crate::model::{ControllerSpec, Model, ParameterValues};
use crate::sym::{Expr, Symbol};

/// Why a controller could not be resolved.
#[derive(Clone, Debug, PartialEq)]
pub enum ControlError {
    /// No controller of that name.
    UnknownController {
        /// Name asked for.
        name: String,
        /// Names the model declares.
        known: Vec<String>,
    },
    /// The equations could not be formed.
    Mechanics(MechanicsError),
    /// Linearization failed.
    Linearize(LinearizeError),
    /// Linear design failed.
    Design(LinearError),
    /// Feedback linearization failed.
    Analysis(AnalysisError),
    /// Declared gains have the wrong size.
    GainSize {
        /// Expected number of entries.
        expected: usize,
        /// Given.
        found: usize,
    },
}

impl fmt::Display for ControlError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ControlError::UnknownController { name, known } => {
                write!(f, "unknown controller `{name}`")?;
                if known.is_empty() {
                    write!(f, " (the model declares no controllers)")
                } else {
                    write!(f, " (known: {})", known.join(", "))
                }
            }
            ControlError::Mechanics(e) => write!(f, "{e}"),
            ControlError::Linearize(e) => write!(f, "{e}"),
            ControlError::Design(e) => write!(f, "{e}"),
            ControlError::Analysis(e) => write!(f, "{e}"),
            ControlError::GainSize { expected, found } => {
                write!(f, "the gain has {found} entries, the state has {expected}")
            }
        }
    }
}

impl std::error::Error for ControlError {}

/// A controller ready to evaluate.
#[derive(Clone, Debug)]
pub enum ResolvedController {
    /// `u = u0 - K (x - x0)`.
    StateFeedback {
        /// Controller name.
        name: String,
        /// Gain rows, one per input, columns in state order.
        k: Vec<Vec<f64>>,
        /// Operating point state.
        x0: Vec<f64>,
        /// Operating point input.
        u0: Vec<f64>,
    },
    /// `u = (v - L_f^r h) / (L_g L_f^(r-1) h)` (single input).
    FeedbackLinearization {
        /// Controller name.
        name: String,
        /// Output linearized.
        output: String,
        /// The law over state symbols, parameters and gain symbols.
        law: Expr,
        /// Gain symbols and their values.
        gains: Vec<(Symbol, f64)>,
        /// The Lie chain of the output.
        chain: Box<LieChain>,
    },
}

impl ResolvedController {
    /// The controller's name.
    pub fn name(&self) -> &str {
        match self {
            ResolvedController::StateFeedback { name, .. }
            | ResolvedController::FeedbackLinearization { name, .. } => name,
        }
    }
}

/// Equations and control-affine form, derived once and shared.
#[derive(Clone, Debug)]
pub struct Derivation {
    /// Euler-Lagrange equations (unsimplified, exact).
    pub equations: Equations,
    /// `x' = f(x) + g(x) u`.
    pub affine: ControlAffine,
}

impl Derivation {
    /// Derive both for a model.
    pub fn new(model: &Model) -> Result<Derivation, MechanicsError> {
        let equations = derive_equations(model)?;
        let affine = control_affine(&equations)?;
        Ok(Derivation { equations, affine })
    }
}

/// The output expression `h` of a named output.
pub fn output_expr(model: &Model, name: &str) -> Result<Expr, AnalysisError> {
    model
        .outputs
        .iter()
        .find(|o| o.name == name)
        .map(|o| o.expr)
        .ok_or_else(|| AnalysisError::UnknownOutput {
            name: name.to_string(),
            known: model.outputs.iter().map(|o| o.name.clone()).collect(),
        })
}

/// The name of the state-feedback gain entry `K[input][state]`, as
/// `--gain` accepts it: `k_<state>` for a single-input model (`k_alpha`,
/// `k_theta_dot`), `k_<input>_<state>` otherwise. Shared by the interpreted
/// controllers and the generated code.
pub fn state_feedback_gain_name(model: &Model, input: usize, state: usize) -> String {
    let states = model.state_names();
    let s = states.get(state).map(String::as_str).unwrap_or("?");
    if model.inputs.len() == 1 {
        format!("k_{s}")
    } else {
        let u = model
            .inputs
            .get(input)
            .map(|u| u.name.as_str())
            .unwrap_or("?");
        format!("k_{u}_{s}")
    }
}

/// Resolve the controller `name` of `model` with parameter `values`.
pub fn resolve(
    model: &Model,
    derivation: &Derivation,
    name: &str,
    values: &ParameterValues,
) -> Result<ResolvedController, ControlError> {
    let spec = model
        .controller(name)
        .ok_or_else(|| ControlError::UnknownController {
            name: name.to_string(),
            known: model
                .controllers
                .iter()
                .map(|c| c.name().to_string())
                .collect(),
        })?;
    let op = OperatingPoint::zero(model);
    let n = op.x.len();
    /// A gain design from (A, B).
    type DesignFn<'a> = dyn Fn(
            &nalgebra::DMatrix<f64>,
            &nalgebra::DMatrix<f64>,
        ) -> Result<nalgebra::DMatrix<f64>, LinearError>
        + 'a;
    let design = |f: &DesignFn<'_>| {
        let lin = linearize(model, &derivation.equations, values, &op)
            .map_err(ControlError::Linearize)?;
        let k = f(&lin.a, &lin.b).map_err(ControlError::Design)?;
        Ok::<_, ControlError>(crate::linear::matrix_to_rows(&k))
    };
    let k = match spec {
        ControllerSpec::Gains { k, .. } => {
            if let Some(row) = k.iter().find(|r| r.len() != n) {
                return Err(ControlError::GainSize {
                    expected: n,
                    found: row.len(),
                });
            }
            k.clone()
        }
        ControllerSpec::Place { poles, .. } => {
            let desired: Vec<Pole> = poles.iter().map(|(re, im)| Pole::new(*re, *im)).collect();
            design(&|a, b| place(a, b, &desired).map(|p| p.k))?
        }
        ControllerSpec::Lqr { q, r, .. } => {
            let qm = nalgebra::DMatrix::from_diagonal(&nalgebra::DVector::from_vec(q.clone()));
            let rm = nalgebra::DMatrix::from_diagonal(&nalgebra::DVector::from_vec(r.clone()));
            design(&|a, b| lqr(a, b, &qm, &rm).map(|l| l.k))?
        }
        ControllerSpec::FeedbackLinearization {
            output, gains, v, ..
        } => {
            let h = output_expr(model, output).map_err(ControlError::Analysis)?;
            let chain = lie_chain(&derivation.affine, h).map_err(ControlError::Analysis)?;
            let law = chain.law(*v);
            return Ok(ResolvedController::FeedbackLinearization {
                name: name.to_string(),
                output: output.clone(),
                law,
                gains: gains.iter().map(|(g, x)| (Symbol::new(g), *x)).collect(),
                chain: Box::new(chain),
            });
        }
    };
    Ok(ResolvedController::StateFeedback {
        name: name.to_string(),
        k,
        x0: op.x,
        u0: op.u,
    })
}
