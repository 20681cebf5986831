//! Numeric controllers and open-loop input signals.

use crate::control::ResolvedController;
use crate::model::{Guard, Model};
use crate::sym::{Expr, Symbol, Tape, TapeError};

use super::SimError;

/// A resolved controller compiled for fast evaluation.
///
/// Hybrid controllers have a current mode, kept in the
/// [`ControllerWorkspace`]: [`ControllerEval::update_mode`] applies the
/// switches at a sample instant, [`ControllerEval::eval`] evaluates the
/// current mode's law.
#[derive(Clone)]
pub struct ControllerEval {
    name: String,
    n_states: usize,
    n_inputs: usize,
    kind: Kind,
    modes: Vec<ModeInfo>,
}

/// Name and kind of a hybrid controller's mode.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ModeInfo {
    /// Mode name.
    pub name: String,
    /// Whether it is a swing-up mode (the pendulum anywhere).
    pub swing_up: bool,
}

#[derive(Clone)]
struct SwitchEval {
    from: usize,
    to: usize,
    guard: Guard,
    /// Index of the guard's first margin in the margin tape's outputs.
    first: usize,
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
    /// Laws (one per input) compiled over `[state, parameters, gains]`.
    Law {
        tape: Tape,
        gain_names: Vec<String>,
        gains: Vec<f64>,
    },
    /// Modes with switch conditions; the margins `lhs - rhs` of every
    /// comparison compiled over `[state, parameters]`.
    Hybrid {
        modes: Vec<ControllerEval>,
        switches: Vec<SwitchEval>,
        margins: Tape,
        wrap: Vec<usize>,
    },
}

impl std::fmt::Debug for ControllerEval {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ControllerEval")
            .field("name", &self.name)
            .field("gains", &self.gains())
            .field("modes", &self.modes)
            .finish()
    }
}

/// Scratch buffers (and a hybrid controller's current mode) for
/// [`ControllerEval::eval`].
#[derive(Clone, Debug)]
pub struct ControllerWorkspace {
    tape_in: Vec<f64>,
    scratch: Vec<f64>,
    mode: usize,
    wrapped: Vec<f64>,
    margins: Vec<f64>,
    modes: Vec<ControllerWorkspace>,
}

/// `a` wrapped into [-pi, pi): `a - 2 pi floor((a + pi) / (2 pi))`, the
/// formula generated code uses too.
pub fn wrap_angle(a: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    a - tau * ((a + std::f64::consts::PI) / tau).floor()
}

fn set_named(
    controller: &str,
    have: &mut [(Symbol, f64)],
    g: &str,
    v: f64,
) -> Result<(), SimError> {
    let Some(slot) = have.iter_mut().find(|(s, _)| s.name() == g) else {
        return Err(SimError::UnknownGain {
            controller: controller.to_string(),
            name: g.to_string(),
            known: have.iter().map(|(s, _)| s.name().to_string()).collect(),
        });
    };
    if !v.is_finite() {
        return Err(SimError::Setup(format!("gain `{g}` = {v} is not finite")));
    }
    slot.1 = v;
    Ok(())
}

/// Named gains of a resolved controller (`mode.gain` for a hybrid one).
pub fn gain_names(controller: &ResolvedController) -> Vec<String> {
    match controller {
        ResolvedController::StateFeedback { .. } => Vec::new(),
        ResolvedController::FeedbackLinearization { gains, .. }
        | ResolvedController::Direct { gains, .. }
        | ResolvedController::SlidingMode { gains, .. } => {
            gains.iter().map(|(s, _)| s.name().to_string()).collect()
        }
        ResolvedController::Hybrid { modes, .. } => modes
            .iter()
            .flat_map(|m| {
                gain_names(&m.controller)
                    .into_iter()
                    .map(move |g| format!("{}.{g}", m.name))
            })
            .collect(),
    }
}

/// Override named gains of a resolved controller (feedback linearization,
/// sliding mode, direct laws: `wn`, `zeta`, `kE`, ...). State feedback has no
/// named gains. For a hybrid controller a gain is `mode.gain`, or a bare
/// `gain` when only one mode has it.
pub fn set_gains(
    controller: &mut ResolvedController,
    gains: &[(String, f64)],
) -> Result<(), SimError> {
    let known = gain_names(controller);
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
        }
        | ResolvedController::Direct {
            name, gains: have, ..
        }
        | ResolvedController::SlidingMode {
            name, gains: have, ..
        } => {
            for (g, v) in gains {
                set_named(name, have, g, *v)?;
            }
            Ok(())
        }
        ResolvedController::Hybrid { name, modes, .. } => {
            for (g, v) in gains {
                let target =
                    mode_gain(name, g, modes.iter().map(|m| m.name.as_str()), |i, bare| {
                        gain_names(&modes[i].controller).iter().any(|k| k == bare)
                    })?;
                let Some((i, bare)) = target else {
                    return Err(SimError::UnknownGain {
                        controller: name.clone(),
                        name: g.clone(),
                        known,
                    });
                };
                set_gains(&mut modes[i].controller, &[(bare.to_string(), *v)])?;
            }
            Ok(())
        }
    }
}

/// The mode of a hybrid controller that has the gain `name` (`mode.gain`,
/// or a bare `gain` that only one mode has; `has(mode index, gain)` says
/// whether a mode has a gain) and the gain's name in that mode; `None` if
/// no mode has it, an error if several do.
fn mode_gain<'n, 'm>(
    controller: &str,
    name: &'n str,
    modes: impl IntoIterator<Item = &'m str>,
    has: impl Fn(usize, &str) -> bool,
) -> Result<Option<(usize, &'n str)>, SimError> {
    let mut targets = Vec::new();
    for (i, mode) in modes.into_iter().enumerate() {
        let bare = match name.split_once('.') {
            Some((m, gain)) if m == mode => gain,
            Some(_) => continue,
            None => name,
        };
        if has(i, bare) {
            targets.push((i, mode, bare));
        }
    }
    if targets.len() > 1 {
        return Err(SimError::Setup(format!(
            "controller `{controller}`: gain `{name}` is in several modes; write {}",
            targets
                .iter()
                .map(|(_, mode, g)| format!("`{mode}.{g}`"))
                .collect::<Vec<_>>()
                .join(" or ")
        )));
    }
    Ok(targets.pop().map(|(i, _, bare)| (i, bare)))
}

/// `x` into `out`, the coordinates `wrap` wrapped into [-pi, pi).
#[inline]
fn wrap_into(out: &mut [f64], x: &[f64], wrap: &[usize]) {
    out.copy_from_slice(x);
    for &i in wrap {
        out[i] = wrap_angle(out[i]);
    }
}

fn compile_laws(
    model: &Model,
    controller: &ResolvedController,
    laws: &[Expr],
    gains: &[(Symbol, f64)],
) -> Result<Kind, SimError> {
    let mut inputs: Vec<Symbol> = model.state_symbols();
    inputs.extend(model.parameter_symbols());
    inputs.extend(gains.iter().map(|(s, _)| *s));
    let tape = Tape::compile(laws, &inputs).map_err(|e| match e {
        TapeError::UnknownSymbol(s) => SimError::Setup(format!(
            "controller `{}`: the law mentions `{s}`, which is not a state, parameter or gain",
            controller.name()
        )),
    })?;
    Ok(Kind::Law {
        tape,
        gain_names: gains.iter().map(|(s, _)| s.name().to_string()).collect(),
        gains: gains.iter().map(|(_, v)| *v).collect(),
    })
}

impl ControllerEval {
    /// Compile `controller` for `model`. A law is compiled to a tape over the
    /// state symbols, the parameter symbols (in the order of
    /// [`crate::model::ParameterValues::full`]) and its gain symbols; a hybrid
    /// controller compiles every mode and the margins of its conditions.
    pub fn new(model: &Model, controller: &ResolvedController) -> Result<ControllerEval, SimError> {
        let n = model.state_symbols().len();
        let m = model.inputs.len();
        let single = |what: &str| {
            if m != 1 {
                return Err(SimError::Setup(format!(
                    "{what} needs a single-input model"
                )));
            }
            Ok(())
        };
        let mut modes = Vec::new();
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
                    k_names: crate::control::state_feedback_gain_names(model, m),
                    x0: x0.clone(),
                    u0: u0.clone(),
                }
            }
            ResolvedController::FeedbackLinearization { law, gains, .. } => {
                single("a linearizing law")?;
                compile_laws(model, controller, &[*law], gains)?
            }
            ResolvedController::SlidingMode { law, gains, .. } => {
                single("a sliding-mode law")?;
                compile_laws(model, controller, &[*law], gains)?
            }
            ResolvedController::Direct { laws, gains, .. } => {
                if laws.len() != m {
                    return Err(SimError::Setup(format!(
                        "controller `{}`: {} laws for {m} inputs",
                        controller.name(),
                        laws.len()
                    )));
                }
                compile_laws(model, controller, laws, gains)?
            }
            ResolvedController::Hybrid {
                modes: rmodes,
                switches,
                wrap,
                ..
            } => {
                let evals = rmodes
                    .iter()
                    .map(|md| ControllerEval::new(model, &md.controller))
                    .collect::<Result<Vec<_>, _>>()?;
                modes = rmodes
                    .iter()
                    .map(|md| ModeInfo {
                        name: md.name.clone(),
                        swing_up: md.swing_up,
                    })
                    .collect();
                let mut margins = Vec::new();
                let mut sw = Vec::new();
                for s in switches {
                    sw.push(SwitchEval {
                        from: s.from,
                        to: s.to,
                        guard: s.when.clone(),
                        first: margins.len(),
                    });
                    margins.extend(s.when.margins().into_iter().map(|(_, e)| e));
                }
                let mut inputs: Vec<Symbol> = model.state_symbols();
                inputs.extend(model.parameter_symbols());
                let tape = Tape::compile(&margins, &inputs).map_err(|e| match e {
                    TapeError::UnknownSymbol(s) => SimError::Setup(format!(
                        "controller `{}`: a switch condition mentions `{s}`, which is not a state or parameter",
                        controller.name()
                    )),
                })?;
                Kind::Hybrid {
                    modes: evals,
                    switches: sw,
                    margins: tape,
                    wrap: wrap.clone(),
                }
            }
        };
        Ok(ControllerEval {
            name: controller.name().to_string(),
            n_states: n,
            n_inputs: m,
            kind,
            modes,
        })
    }

    /// The controller's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// A hybrid controller's modes (empty otherwise); mode indices refer to it.
    pub fn modes(&self) -> &[ModeInfo] {
        &self.modes
    }

    /// Named gains and their values (state feedback: the entries of `K`,
    /// named by [`crate::control::state_feedback_gain_name`]; a hybrid
    /// controller: `mode.gain`).
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
            Kind::Hybrid { modes, .. } => modes
                .iter()
                .zip(&self.modes)
                .flat_map(|(c, info)| {
                    c.gains()
                        .into_iter()
                        .map(move |(g, v)| (format!("{}.{g}", info.name), v))
                })
                .collect(),
        }
    }

    /// Change a named gain (`mode.gain`, or a bare `gain` that only one mode
    /// has, for a hybrid controller).
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
            Kind::Hybrid { modes, .. } => {
                let target = mode_gain(
                    &self.name,
                    name,
                    self.modes.iter().map(|m| m.name.as_str()),
                    |i, bare| modes[i].gains().iter().any(|(g, _)| g == bare),
                )?;
                if let Some((i, bare)) = target {
                    return modes[i].set_gain(bare, value);
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

    /// Buffers for [`ControllerEval::eval`] (a hybrid controller starts in
    /// its first mode); `n_params` is the length of the full parameter vector.
    pub fn workspace(&self, n_params: usize) -> ControllerWorkspace {
        let empty = || ControllerWorkspace {
            tape_in: Vec::new(),
            scratch: Vec::new(),
            mode: 0,
            wrapped: Vec::new(),
            margins: Vec::new(),
            modes: Vec::new(),
        };
        match &self.kind {
            Kind::StateFeedback { .. } => empty(),
            Kind::Law { tape, gains, .. } => ControllerWorkspace {
                tape_in: vec![0.0; self.n_states + n_params + gains.len()],
                scratch: vec![0.0; tape.scratch_len()],
                ..empty()
            },
            Kind::Hybrid { modes, margins, .. } => ControllerWorkspace {
                tape_in: vec![0.0; self.n_states + n_params],
                scratch: vec![0.0; margins.scratch_len()],
                wrapped: vec![0.0; self.n_states],
                margins: vec![0.0; margins.n_outputs()],
                modes: modes.iter().map(|c| c.workspace(n_params)).collect(),
                ..empty()
            },
        }
    }

    /// The current mode (index into [`ControllerEval::modes`]; 0 if not hybrid).
    pub fn mode(&self, ws: &ControllerWorkspace) -> usize {
        ws.mode
    }

    /// Back to the first mode.
    pub fn reset(&self, ws: &mut ControllerWorkspace) {
        ws.mode = 0;
    }

    /// Applies the switches of a hybrid controller at state `x`: from the
    /// current mode, the first switch (in file order) whose condition holds
    /// is taken, and again from the new mode (at most one round per mode).
    /// Returns `(from, to)` when the mode changed. Does nothing for other
    /// controllers. Does not allocate.
    pub fn update_mode(
        &self,
        x: &[f64],
        params_full: &[f64],
        ws: &mut ControllerWorkspace,
    ) -> Option<(usize, usize)> {
        let Kind::Hybrid {
            modes,
            switches,
            margins,
            wrap,
        } = &self.kind
        else {
            return None;
        };
        let n = self.n_states;
        wrap_into(&mut ws.wrapped, x, wrap);
        ws.tape_in[..n].copy_from_slice(&ws.wrapped);
        ws.tape_in[n..].copy_from_slice(params_full);
        margins.eval(&ws.tape_in, &mut ws.margins, &mut ws.scratch);
        let start = ws.mode;
        for _ in 0..modes.len() {
            let next = switches.iter().find(|s| {
                let mut k = s.first;
                s.from == ws.mode && s.guard.holds(&ws.margins, &mut k)
            });
            match next {
                Some(s) => ws.mode = s.to,
                None => break,
            }
        }
        (ws.mode != start).then_some((start, ws.mode))
    }

    /// The demanded input (before saturation) of the current mode. Does not allocate.
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
            Kind::Hybrid { modes, wrap, .. } => {
                let ControllerWorkspace {
                    wrapped,
                    modes: wss,
                    mode,
                    ..
                } = ws;
                wrap_into(wrapped, x, wrap);
                modes[*mode].eval(wrapped, params_full, u, &mut wss[*mode]);
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
