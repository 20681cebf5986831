//! Adapters from a plantc model (compiled tapes of `plantc-derive`) to the
//! runtime's [`Plant`] and [`Controller`] traits, so `plantc run` can drive any
//! model file without generating code first.

use std::cell::RefCell;

use plantc_derive::control::ResolvedController;
use plantc_derive::mechanics::{NumericDynamics, Workspace};
use plantc_derive::model::{Model, ParameterValues};
use plantc_derive::simulate::{ControllerEval, ControllerWorkspace};

use crate::controller::{Controller, Mode};
use crate::integrate::Rk4Scratch;
use crate::plant::Plant;

fn leak_names(names: Vec<String>) -> Vec<&'static str> {
    // Names live for the whole run; a few bytes leaked once per process.
    names
        .into_iter()
        .map(|s| &*Box::leak(s.into_boxed_str()))
        .collect()
}

/// A model's dynamics evaluated through its compiled tape (`M a = r + B u`
/// solved numerically each call; no allocation). Dry friction sticks: a
/// joint at rest stays at rest (velocity exactly 0.0) while the force on
/// it is below its static level, and breaks away above it; [`Plant::step`]
/// locates the switches inside each substep
/// ([`NumericDynamics::rk4_step`]).
pub struct ModelPlant {
    dynamics: NumericDynamics,
    params: Vec<f64>,
    workspace: RefCell<Workspace>,
    state_names: Vec<&'static str>,
    input_names: Vec<&'static str>,
    limits: Vec<(f64, f64)>,
}

impl ModelPlant {
    /// Wrap compiled dynamics with parameter values.
    pub fn new(model: &Model, dynamics: NumericDynamics, values: &ParameterValues) -> ModelPlant {
        let workspace = RefCell::new(dynamics.workspace());
        ModelPlant {
            params: values.full.clone(),
            workspace,
            state_names: leak_names(model.state_names()),
            input_names: leak_names(model.inputs.iter().map(|u| u.name.clone()).collect()),
            limits: model
                .inputs
                .iter()
                .map(|u| u.limits.unwrap_or((f64::NEG_INFINITY, f64::INFINITY)))
                .collect(),
            dynamics,
        }
    }
}

impl Plant for ModelPlant {
    fn state_names(&self) -> &[&str] {
        &self.state_names
    }

    fn input_names(&self) -> &[&str] {
        &self.input_names
    }

    fn derivatives(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let ok = x.len() == dx.len()
            && dx.len() == self.dynamics.n_states()
            && u.len() == self.dynamics.n_inputs();
        let mut ws = self.workspace.borrow_mut();
        if !ok
            || self
                .dynamics
                .derivatives(x, u, &self.params, dx, &mut ws)
                .is_err()
        {
            dx.fill(f64::NAN);
        }
    }

    fn input_limits(&self) -> &[(f64, f64)] {
        &self.limits
    }

    fn step(&self, x: &mut [f64], u: &[f64], h: f64, scratch: &mut Rk4Scratch) {
        if !self.dynamics.has_dry_friction() {
            crate::integrate::rk4_step(self, x, u, h, scratch);
            return;
        }
        let ok = x.len() == self.dynamics.n_states() && u.len() == self.dynamics.n_inputs();
        let mut ws = self.workspace.borrow_mut();
        if !ok
            || self
                .dynamics
                .rk4_step(x, u, &self.params, h, &mut ws)
                .is_err()
        {
            x.fill(f64::NAN);
        }
    }
}

/// A resolved model controller (state feedback, a law, or a hybrid
/// controller's modes and switches) evaluated through its compiled tapes.
pub struct ModelController {
    eval: ControllerEval,
    params: Vec<f64>,
    workspace: ControllerWorkspace,
}

impl ModelController {
    /// Compile a resolved controller.
    pub fn new(
        model: &Model,
        controller: &ResolvedController,
        values: &ParameterValues,
    ) -> Result<ModelController, plantc_derive::simulate::SimError> {
        let eval = ControllerEval::new(model, controller)?;
        let workspace = eval.workspace(values.full.len());
        Ok(ModelController {
            eval,
            params: values.full.clone(),
            workspace,
        })
    }

    /// Override a named gain (`mode.gain` or a bare gain for a hybrid controller).
    pub fn set_gain(
        &mut self,
        name: &str,
        value: f64,
    ) -> Result<(), plantc_derive::simulate::SimError> {
        self.eval.set_gain(name, value)
    }
}

impl Controller for ModelController {
    fn control(&mut self, _t: f64, x: &[f64], u: &mut [f64]) {
        self.eval.update_mode(x, &self.params, &mut self.workspace);
        self.eval.eval(x, &self.params, u, &mut self.workspace);
    }

    fn reset(&mut self) {
        self.eval.reset(&mut self.workspace);
    }

    fn mode_names(&self) -> Vec<String> {
        self.eval.modes().iter().map(|m| m.name.clone()).collect()
    }

    fn has_swing_up_mode(&self) -> bool {
        self.eval.modes().iter().any(|m| m.swing_up)
    }

    fn mode(&self) -> Option<Mode> {
        let modes = self.eval.modes();
        let index = self.eval.mode(&self.workspace);
        modes.get(index).map(|m| Mode {
            index,
            swing_up: m.swing_up,
        })
    }
}
