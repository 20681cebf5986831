//! Controllers declared in a model file, resolved into something that can be
//! evaluated, simulated or emitted as code.
//!
//! - `gains`, `place`, `lqr` become state feedback `u = u0 - K (x - x0)` with
//!   `K` designed on the linearization about the operating point (all zero).
//! - `linearize output y` becomes the feedback-linearizing law
//!   `u = (v - L_f^r h) / (L_g L_f^(r-1) h)` with the outer law `v` inlined.
//! - `surface s ...` becomes the sliding-mode law `u = (v - L_f s) / L_g s`
//!   (equivalent control plus reaching law), the surface designed by
//!   Ackermann's formula when given by its poles.
//! - direct laws `u = ...` stay as written.
//! - `mode` / `switch` controllers resolve every mode's controller.

use std::fmt;

use std::sync::OnceLock;

use crate::analysis::{
    lie_chain, linearize, mechanical_chain, AnalysisError, LieChain, LinearizeError,
    OperatingPoint, ANALYSIS_MAX_TERMS,
};
use crate::linear::{lqr, place, LinearError, Pole};
use crate::mechanics::{
    control_affine_within, derive_equations, mass_matrix_conditioning, ControlAffine, Equations,
    MechanicsError,
};
use crate::model::{ControllerSpec, Model, ParameterValues, SurfaceSpec, SwitchSpec};
use crate::sym::{diff, is_zero, Expr, Symbol};

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
    /// A sliding surface that cannot be used.
    Surface {
        /// The controller.
        controller: String,
        /// Why.
        reason: String,
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
            ControlError::Surface { controller, reason } => {
                write!(f, "controller `{controller}`: {reason}")
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
    /// Laws for every input written directly in the model file.
    Direct {
        /// Controller name.
        name: String,
        /// One law per input, over state symbols, parameters and gain symbols.
        laws: Vec<Expr>,
        /// Gain symbols and their values.
        gains: Vec<(Symbol, f64)>,
    },
    /// Sliding mode `u = (v - L_f s) / L_g s` on a surface `s` (single input).
    SlidingMode {
        /// Controller name.
        name: String,
        /// The surface over state symbols, parameters and gain symbols.
        surface: Expr,
        /// The law, with the surface and the reaching law `v` inlined.
        law: Expr,
        /// Gain symbols and their values.
        gains: Vec<(Symbol, f64)>,
        /// The Lie chain of the surface (relative degree 1).
        chain: Box<LieChain>,
    },
    /// Modes (resolved controllers) with switch conditions.
    Hybrid {
        /// Controller name.
        name: String,
        /// Modes in file order; the first is the initial mode.
        modes: Vec<ResolvedMode>,
        /// Switches in file order.
        switches: Vec<SwitchSpec>,
        /// Coordinates (indices) wrapped into (-pi, pi] for modes and conditions.
        wrap: Vec<usize>,
    },
}

/// A mode of a hybrid controller.
#[derive(Clone, Debug)]
pub struct ResolvedMode {
    /// Mode name.
    pub name: String,
    /// Whether the mode is a swing-up mode (pendulum anywhere).
    pub swing_up: bool,
    /// The controller driving the input in this mode.
    pub controller: ResolvedController,
}

impl ResolvedController {
    /// The controller's name.
    pub fn name(&self) -> &str {
        match self {
            ResolvedController::StateFeedback { name, .. }
            | ResolvedController::FeedbackLinearization { name, .. }
            | ResolvedController::Direct { name, .. }
            | ResolvedController::SlidingMode { name, .. }
            | ResolvedController::Hybrid { name, .. } => name,
        }
    }
}

/// The equations of motion, derived once and shared; the expanded
/// control-affine form only when asked for ([`Derivation::affine`]).
#[derive(Clone, Debug)]
pub struct Derivation {
    /// Euler-Lagrange equations (unsimplified, exact).
    pub equations: Equations,
    affine: OnceLock<Result<ControlAffine, MechanicsError>>,
}

/// Screening states used to check that the mass matrix is nonsingular.
const MASS_SCREEN_POINTS: usize = 3;

impl Derivation {
    /// Derive the equations of a model and check that its mass matrix is
    /// nonsingular (numerically at random states; exactly, through the
    /// determinant, when it looks singular at all of them).
    pub fn new(model: &Model) -> Result<Derivation, MechanicsError> {
        let equations = derive_equations(model)?;
        if mass_matrix_conditioning(model, &equations, MASS_SCREEN_POINTS) < 1e-13 {
            let det = crate::sym::try_simplify_within(
                crate::mechanics::determinant(&equations.mass_matrix),
                ANALYSIS_MAX_TERMS,
            )
            .map_err(|e| MechanicsError::Budget {
                what: "det M (the mass matrix looks singular at random states)".into(),
                reason: e.to_string(),
            })?;
            if det.is_zero() {
                return Err(MechanicsError::SingularMassMatrix);
            }
        }
        Ok(Derivation {
            equations,
            affine: OnceLock::new(),
        })
    }

    /// `x' = f(x) + g(x) u` with `M^-1` expanded (computed on first use, with
    /// the analysis term budget: [`MechanicsError::Budget`] says why when it
    /// is out of reach).
    pub fn affine(&self) -> Result<&ControlAffine, MechanicsError> {
        self.affine
            .get_or_init(|| control_affine_within(&self.equations, ANALYSIS_MAX_TERMS))
            .as_ref()
            .map_err(Clone::clone)
    }

    /// The Lie chain of the output `h`: through the mechanical structure for
    /// an output of the coordinates ([`mechanical_chain`]), otherwise from the
    /// expanded control-affine form ([`lie_chain`]).
    pub fn lie_chain(&self, model: &Model, h: Expr) -> Result<LieChain, AnalysisError> {
        if let Some(c) = mechanical_chain(model, &self.equations, h)? {
            return Ok(c);
        }
        let ca = self.affine().map_err(|e| AnalysisError::Budget {
            reason: format!(
                "the output needs the expanded control-affine form (it depends on velocities, \
                 or L_g L_f h vanishes identically), and {e}"
            ),
        })?;
        lie_chain(ca, h)
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

/// The names of all entries of a state-feedback gain with `inputs` rows,
/// row-major (see [`state_feedback_gain_name`]).
pub fn state_feedback_gain_names(model: &Model, inputs: usize) -> Vec<String> {
    let states = model.state_names().len();
    (0..inputs)
        .flat_map(|i| (0..states).map(move |j| state_feedback_gain_name(model, i, j)))
        .collect()
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
        ControllerSpec::Direct { gains, laws, .. } => {
            return Ok(ResolvedController::Direct {
                name: name.to_string(),
                laws: laws.clone(),
                gains: gains.iter().map(|(g, x)| (Symbol::new(g), *x)).collect(),
            });
        }
        ControllerSpec::SlidingMode {
            surface_name,
            surface,
            gains,
            v,
            ..
        } => {
            let bad = |reason: String| ControlError::Surface {
                controller: name.to_string(),
                reason,
            };
            let state = model.state_symbols();
            let s = match surface {
                SurfaceSpec::Expr(e) => {
                    for x in &state {
                        let dx = diff(*e, *x);
                        if let Some(y) = state.iter().find(|y| !is_zero(diff(dx, **y))) {
                            return Err(bad(format!(
                                "the surface must be linear in the state; it is not in `{}` and `{}`",
                                x.name(),
                                y.name()
                            )));
                        }
                    }
                    *e
                }
                SurfaceSpec::Poles(p) => {
                    let desired: Vec<Pole> = p.iter().map(|(re, im)| Pole::new(*re, *im)).collect();
                    let lin = linearize(model, &derivation.equations, values, &op)
                        .map_err(ControlError::Linearize)?;
                    let surf = crate::linear::sliding_surface(&lin.a, &lin.b, &desired)
                        .map_err(ControlError::Design)?;
                    Expr::add_all(
                        surf.c
                            .iter()
                            .zip(&state)
                            .map(|(c, x)| Expr::float(*c) * Expr::symbol(*x)),
                    )
                }
            };
            let chain = derivation
                .lie_chain(model, s)
                .map_err(ControlError::Analysis)?;
            if chain.relative_degree != 1 {
                return Err(bad(format!(
                    "the input reaches the surface only in derivative {} (relative degree {}); \
                     a sliding surface needs relative degree 1: include the velocities",
                    chain.relative_degree, chain.relative_degree
                )));
            }
            let map = [(Expr::sym(surface_name), s)].into_iter().collect();
            let law = chain.law(crate::sym::substitute(*v, &map));
            return Ok(ResolvedController::SlidingMode {
                name: name.to_string(),
                surface: s,
                law,
                gains: gains.iter().map(|(g, x)| (Symbol::new(g), *x)).collect(),
                chain: Box::new(chain),
            });
        }
        ControllerSpec::Hybrid {
            modes,
            switches,
            wrap,
            ..
        } => {
            let modes = modes
                .iter()
                .map(|m| {
                    Ok(ResolvedMode {
                        name: m.name.clone(),
                        swing_up: m.swing_up,
                        controller: resolve(model, derivation, &m.controller, values)?,
                    })
                })
                .collect::<Result<Vec<_>, ControlError>>()?;
            return Ok(ResolvedController::Hybrid {
                name: name.to_string(),
                modes,
                switches: switches.clone(),
                wrap: wrap.clone(),
            });
        }
        ControllerSpec::FeedbackLinearization {
            output, gains, v, ..
        } => {
            let h = output_expr(model, output).map_err(ControlError::Analysis)?;
            let chain = derivation
                .lie_chain(model, h)
                .map_err(ControlError::Analysis)?;
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
