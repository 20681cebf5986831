//! Sliding-mode analysis: the surface's coefficients, the equivalent
//! control, and the reduced (sliding) dynamics on `s = 0` linearized about
//! the origin with their stability.
//!
//! On the surface the input is the equivalent control `u_eq = -L_f s / L_g s`
//! (the input that keeps `s' = 0`), so the state moves by
//! `x' = f(x) + g(x) u_eq(x)` on the `(n - 1)`-dimensional set `s(x) = 0`.
//! For a linear surface `s = c x` one state is expressed by the others and
//! the remaining `n - 1` equations are the sliding dynamics; their
//! linearization about 0 is [`crate::linear::reduced_dynamics`] of the
//! model's linearization.

use std::collections::HashMap;
use std::fmt;

use crate::analysis::{linearize, LinearizeError, OperatingPoint};
use crate::control::{Derivation, ResolvedController};
use crate::linear::{reduced_dynamics, LinearError, ReducedDynamics};
use crate::model::{Model, ParameterValues};
use crate::sym::{diff, Expr, Symbol};

/// Why a sliding-mode analysis failed.
#[derive(Clone, Debug, PartialEq)]
pub enum SlidingError {
    /// The controller is not a sliding-mode controller.
    NotSliding {
        /// Its name.
        controller: String,
    },
    /// The linearization about 0 failed.
    Linearize(LinearizeError),
    /// The reduced dynamics could not be formed.
    Linear(LinearError),
    /// A coefficient of the surface is not a finite number.
    NotFinite {
        /// The state whose coefficient it is.
        state: String,
    },
}

impl fmt::Display for SlidingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SlidingError::NotSliding { controller } => {
                write!(
                    f,
                    "controller `{controller}` is not a sliding-mode controller"
                )
            }
            SlidingError::Linearize(e) => write!(f, "{e}"),
            SlidingError::Linear(e) => write!(f, "{e}"),
            SlidingError::NotFinite { state } => {
                write!(f, "the surface's coefficient of `{state}` is not finite")
            }
        }
    }
}

impl std::error::Error for SlidingError {}

/// What [`sliding_analysis`] finds.
#[derive(Clone, Debug)]
pub struct SlidingAnalysis {
    /// State names in order.
    pub states: Vec<String>,
    /// The surface `s(x)`.
    pub surface: Expr,
    /// Its coefficients `c` (`s = c x`), with parameters and gains evaluated.
    pub c: Vec<f64>,
    /// `u_eq = -L_f s / L_g s`.
    pub equivalent_control: Expr,
    /// Where `L_g s = 0` (the surface cannot be held there).
    pub singular_set: String,
    /// The sliding dynamics linearized about 0.
    pub reduced: ReducedDynamics,
}

/// `a*x - b*y + ...` from `(coefficient, name)` pairs (zeros dropped).
fn linear_text(terms: &[(f64, &str)]) -> String {
    let mut out = String::new();
    for (c, name) in terms.iter().filter(|(c, _)| *c != 0.0) {
        if out.is_empty() {
            out.push_str(&format!("{c:.6}*{name}"));
        } else if *c < 0.0 {
            out.push_str(&format!(" - {:.6}*{name}", -c));
        } else {
            out.push_str(&format!(" + {c:.6}*{name}"));
        }
    }
    if out.is_empty() {
        out.push('0');
    }
    out
}

impl SlidingAnalysis {
    /// The eliminated state on the surface, e.g.
    /// `alpha_dot = -(1.2*theta + ...)/0.5`.
    pub fn eliminated_text(&self) -> String {
        let k = self.reduced.eliminated;
        let terms: Vec<(f64, &str)> = (0..self.c.len())
            .filter(|&j| j != k)
            .map(|j| (-self.c[j] / self.c[k], self.states[j].as_str()))
            .collect();
        format!("{} = {}", self.states[k], linear_text(&terms))
    }

    /// The reduced equations `z_i' = sum_j A_r[i][j] z_j`, one per kept state.
    pub fn equations(&self) -> Vec<String> {
        let k = self.reduced.eliminated;
        let kept: Vec<&str> = (0..self.states.len())
            .filter(|&i| i != k)
            .map(|i| self.states[i].as_str())
            .collect();
        kept.iter()
            .enumerate()
            .map(|(row, name)| {
                let terms: Vec<(f64, &str)> = kept
                    .iter()
                    .enumerate()
                    .map(|(col, z)| (self.reduced.a_r[(row, col)], *z))
                    .collect();
                format!("d/dt {name} = {}", linear_text(&terms))
            })
            .collect()
    }
}

/// Analyse a resolved sliding-mode controller with parameter `values`.
pub fn sliding_analysis(
    model: &Model,
    derivation: &Derivation,
    controller: &ResolvedController,
    values: &ParameterValues,
) -> Result<SlidingAnalysis, SlidingError> {
    let ResolvedController::SlidingMode {
        surface,
        gains,
        chain,
        ..
    } = controller
    else {
        return Err(SlidingError::NotSliding {
            controller: controller.name().to_string(),
        });
    };
    let mut env: HashMap<Symbol, f64> = values.symbol_map(model);
    env.extend(gains.iter().copied());
    let state = model.state_symbols();
    let names = model.state_names();
    for s in &state {
        env.insert(*s, 0.0);
    }
    let mut c = Vec::new();
    for (x, name) in state.iter().zip(&names) {
        let v = diff(*surface, *x).eval_map(&env);
        if !v.is_finite() {
            return Err(SlidingError::NotFinite {
                state: name.clone(),
            });
        }
        c.push(v);
    }
    let lin = linearize(
        model,
        &derivation.equations,
        values,
        &OperatingPoint::zero(model),
    )
    .map_err(SlidingError::Linearize)?;
    let reduced = reduced_dynamics(&lin.a, &lin.b, &c).map_err(SlidingError::Linear)?;
    Ok(SlidingAnalysis {
        states: names,
        surface: *surface,
        c,
        equivalent_control: -(chain.lf[1] / chain.lg[0]),
        singular_set: chain.singular_set(),
        reduced,
    })
}
