//! Numeric controllers and open-loop input signals.

use crate::control::ResolvedController;
use crate::model::Model;
use crate::sym::{Symbol, Tape, TapeError};

use super::SimError;

/// A resolved controller compiled for fast evaluation.
#[derive(Clone)]
pub struct ControllerEval {
    name: String,
    n_states: usize,
    n_inputs: usize,
    kind: Kind,
}

#[derive(Clone)]
enum Kind {
    /// `u = u0 - K (x - x0)`, `k` row-major `m x n`.
    StateFeedback {
        k: Vec<f64>,
        /// `k_<state>` (see [`crate::control::state_feedback_gain_name`]), row-major like `k`.
        k_names: Vec<String>,
        x0: Vec<f64>,
        u0: Vec<f64>,
    },
    /// A law compiled over `[state, parameters, gains]`.
    Law {
        tape: Tape,
        gain_names: Vec<String>,
        gains: Vec<f64>,
    },
}

impl std::fmt::Debug for ControllerEval {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ControllerEval")
            .field("name", &self.name)
            .field("gains", &self.gains())
            .finish()
    }
}

/// Scratch buffers for [`ControllerEval::eval`].
#[derive(Clone, Debug)]
pub struct ControllerWorkspace {
    tape_in: Vec<f64>,
    scratch: Vec<f64>,
}

/// Override named gains of a resolved controller (feedback linearization:
/// `wn`, `zeta`, `a`, `b`, ...). State feedback has no named gains.
pub fn set_gains(
    controller: &mut ResolvedController,
    gains: &[(String, f64)],
) -> Result<(), SimError> {
    match controller {
        ResolvedController::StateFeedback { name, .. } => match gains.first() {
            None => Ok(()),
            Some((g, _)) => Err(SimError::UnknownGain {
                controller: name.clone(),
                name: g.clone(),
                known: Vec::new(),
            }),
        },
        ResolvedController::FeedbackLinearization {
            name, gains: have, ..
        } => {
            for (g, v) in gains {
                let Some(slot) = have.iter_mut().find(|(s, _)| s.name() == g) else {
                    return Err(SimError::UnknownGain {
                        controller: name.clone(),
                        name: g.clone(),
                        known: have.iter().map(|(s, _)| s.name().to_string()).collect(),
                    });
                };
                if !v.is_finite() {
                    return Err(SimError::Setup(format!("gain `{g}` = {v} is not finite")));
                }
                slot.1 = *v;
            }
            Ok(())
        }
    }
}

impl ControllerEval {
    /// Compile `controller` for `model`. A linearizing law is compiled to a
    /// tape over the state symbols, the parameter symbols (in the order of
    /// [`crate::model::ParameterValues::full`]) and its gain symbols.
    pub fn new(model: &Model, controller: &ResolvedController) -> Result<ControllerEval, SimError> {
        let n = model.state_symbols().len();
        let m = model.inputs.len();
        let kind = match controller {
            ResolvedController::StateFeedback { k, x0, u0, .. } => {
                if k.len() != m || k.iter().any(|r| r.len() != n) || x0.len() != n || u0.len() != m
                {
                    return Err(SimError::Setup(format!(
                        "controller `{}`: gain is not {m} x {n}",
                        controller.name()
                    )));
                }
                Kind::StateFeedback {
                    k: k.iter().flatten().copied().collect(),
                    k_names: (0..m)
                        .flat_map(|i| {
                            (0..n)
                                .map(move |j| crate::control::state_feedback_gain_name(model, i, j))
                        })
                        .collect(),
                    x0: x0.clone(),
                    u0: u0.clone(),
                }
            }
            ResolvedController::FeedbackLinearization { law, gains, .. } => {
                if m != 1 {
                    return Err(SimError::Setup(
                        "a linearizing law needs a single-input model".into(),
                    ));
                }
                let mut inputs: Vec<Symbol> = model.state_symbols();
                inputs.extend(model.parameter_symbols());
                inputs.extend(gains.iter().map(|(s, _)| *s));
                let tape = Tape::compile(&[*law], &inputs).map_err(|e| match e {
                    TapeError::UnknownSymbol(s) => SimError::Setup(format!(
                        "controller `{}`: the law mentions `{s}`, which is not a state, parameter or gain",
                        controller.name()
                    )),
                })?;
                Kind::Law {
                    tape,
                    gain_names: gains.iter().map(|(s, _)| s.name().to_string()).collect(),
                    gains: gains.iter().map(|(_, v)| *v).collect(),
                }
            }
        };
        Ok(ControllerEval {
            name: controller.name().to_string(),
            n_states: n,
            n_inputs: m,
            kind,
        })
    }

    /// The controller's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Named gains and their values (state feedback: the entries of `K`,
    /// named by [`crate::control::state_feedback_gain_name`]).
    pub fn gains(&self) -> Vec<(String, f64)> {
        match &self.kind {
            Kind::StateFeedback { k, k_names, .. } => {
                k_names.iter().cloned().zip(k.iter().copied()).collect()
            }
            Kind::Law {
                gain_names, gains, ..
            } => gain_names
                .iter()
                .cloned()
                .zip(gains.iter().copied())
                .collect(),
        }
    }

    /// Change a named gain.
    pub fn set_gain(&mut self, name: &str, value: f64) -> Result<(), SimError> {
        let known = self.gains().into_iter().map(|(n, _)| n).collect::<Vec<_>>();
        match &mut self.kind {
            Kind::Law {
                gain_names, gains, ..
            } => {
                if let Some(i) = gain_names.iter().position(|g| g == name) {
                    gains[i] = value;
                    return Ok(());
                }
            }
            Kind::StateFeedback { k, k_names, .. } => {
                if let Some(i) = k_names.iter().position(|g| g == name) {
                    k[i] = value;
                    return Ok(());
                }
            }
        }
        Err(SimError::UnknownGain {
            controller: self.name.clone(),
            name: name.to_string(),
            known,
        })
    }

    /// Buffers for [`ControllerEval::eval`]; `n_params` is the length of the
    /// full parameter vector.
    pub fn workspace(&self, n_params: usize) -> ControllerWorkspace {
        match &self.kind {
            Kind::StateFeedback { .. } => ControllerWorkspace {
                tape_in: Vec::new(),
                scratch: Vec::new(),
            },
            Kind::Law { tape, gains, .. } => ControllerWorkspace {
                tape_in: vec![0.0; self.n_states + n_params + gains.len()],
                scratch: vec![0.0; tape.scratch_len()],
            },
        }
    }

    /// The demanded input (before saturation). Does not allocate.
    pub fn eval(
        &self,
        x: &[f64],
        params_full: &[f64],
        u: &mut [f64],
        ws: &mut ControllerWorkspace,
    ) {
        debug_assert_eq!(u.len(), self.n_inputs);
        match &self.kind {
            Kind::StateFeedback { k, x0, u0, .. } => {
                let n = self.n_states;
                for (i, ui) in u.iter_mut().enumerate() {
                    let mut acc = u0[i];
                    for j in 0..n {
                        acc -= k[i * n + j] * (x[j] - x0[j]);
                    }
                    *ui = acc;
                }
            }
            Kind::Law { tape, gains, .. } => {
                let n = self.n_states;
                let p = params_full.len();
                ws.tape_in[..n].copy_from_slice(x);
                ws.tape_in[n..n + p].copy_from_slice(params_full);
                ws.tape_in[n + p..].copy_from_slice(gains);
                tape.eval(&ws.tape_in, u, &mut ws.scratch);
            }
        }
    }
}

/// An open-loop input as a function of time.
#[derive(Clone, Debug, PartialEq)]
pub enum InputSignal {
    /// The same input throughout.
    Constant(Vec<f64>),
    /// Sample `u[k]` acts over `[t[k], t[k+1])`; the last one holds to the
    /// end, the first one also before `t[0]`. `t` must increase strictly.
    /// (In identification data the voltage `V[k]` acts over `[t_k, t_k + T)`.)
    ZeroOrderHold {
        /// Sample instants (s), strictly increasing.
        t: Vec<f64>,
        /// Input vectors, one per instant.
        u: Vec<Vec<f64>>,
    },
}

impl InputSignal {
    pub(crate) fn check(&self, m: usize) -> Result<(), SimError> {
        match self {
            InputSignal::Constant(u) => {
                if u.len() != m || u.iter().any(|v| !v.is_finite()) {
                    return Err(SimError::Setup(format!(
                        "constant input needs {m} finite values"
                    )));
                }
            }
            InputSignal::ZeroOrderHold { t, u } => {
                if t.is_empty() || t.len() != u.len() {
                    return Err(SimError::Setup(
                        "zero-order-hold input: t and u must be non-empty and of equal length"
                            .into(),
                    ));
                }
                if t.windows(2).any(|w| w[1] <= w[0]) || t.iter().any(|v| !v.is_finite()) {
                    return Err(SimError::Setup(
                        "zero-order-hold input: sample times must increase strictly".into(),
                    ));
                }
                if u.iter()
                    .any(|r| r.len() != m || r.iter().any(|v| !v.is_finite()))
                {
                    return Err(SimError::Setup(format!(
                        "zero-order-hold input: every sample needs {m} finite values"
                    )));
                }
            }
        }
        Ok(())
    }

    /// Sample instants after which the input changes (empty for a constant).
    pub(crate) fn breakpoints(&self) -> &[f64] {
        match self {
            InputSignal::Constant(_) => &[],
            InputSignal::ZeroOrderHold { t, .. } => t,
        }
    }

    /// The input acting on `[breakpoint[j], breakpoint[j+1])`, `j = None`
    /// before the first breakpoint.
    pub(crate) fn sample(&self, j: Option<usize>) -> &[f64] {
        match self {
            InputSignal::Constant(u) => u,
            InputSignal::ZeroOrderHold { u, .. } => &u[j.unwrap_or(0)],
        }
    }
}
