//! Numeric evaluation of the equations of motion without forming `M^-1`.
//!
//! One compiled [`Tape`] evaluates, for given state and parameters, the mass
//! matrix `M` (row-major, `n*n`), the input-free right-hand side
//! `r0 = Q0 - bias` (`n`) and the input matrix `B` (`n*m`, row-major). The
//! accelerations follow from `M a = r0 + B u`, solved by an in-place LU
//! factorisation with partial pivoting. Nothing allocates per call: the
//! buffers live in a [`Workspace`].
//!
//! Dry friction sticks: the equations are split by
//! [`super::dry_friction::decompose`], `r0` is the smooth part and the tape
//! adds the levels `D` (`n`) after `B`; the accelerations are those of the
//! stick-slip mode the state is in ([`super::stick_slip`]: a joint with
//! `v = 0.0` exactly and a holding force within its static level is held),
//! and [`NumericDynamics::rk4_step`] integrates with the switches located.
//! Equations without `sign()` (or smoothed by [`smooth_signs`]) evaluate as
//! before.

use std::fmt;

use super::dry_friction::decompose;
use super::small_lu::{lu_factor, lu_solve};
use super::stick_slip::{Mode, Rk4Events, SplitDynamics, StepError, StickSlip};
use super::Equations;
use crate::model::Model;
use std::collections::HashMap;

use crate::sym::{Expr, Func, Node, Symbol, Tape, TapeError};

/// Why numeric dynamics could not be built or evaluated.
#[derive(Clone, Debug, PartialEq)]
pub enum NumericError {
    /// The equations mention a symbol that is neither a state, an input nor a
    /// parameter of the model.
    UnknownSymbol(String),
    /// The equations do not match the model (sizes).
    Shape(String),
    /// The mass matrix is numerically singular at this state.
    SingularMass,
    /// More stick-slip switches within one step than
    /// [`super::stick_slip::MAX_EVENTS`].
    Chattering,
}

impl fmt::Display for NumericError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NumericError::UnknownSymbol(s) => {
                write!(
                    f,
                    "the equations mention `{s}`, which is not a state, input or parameter"
                )
            }
            NumericError::Shape(s) => write!(f, "equations and model disagree: {s}"),
            NumericError::SingularMass => write!(f, "the mass matrix is singular at this state"),
            NumericError::Chattering => write!(
                f,
                "the dry friction switched between sticking and sliding more than {} times within one step",
                super::stick_slip::MAX_EVENTS
            ),
        }
    }
}

impl std::error::Error for NumericError {}

/// Compiled `M(q)`, `r0(q, q') = Q0 - bias`, `B(q, q')` (and the dry
/// friction levels `D` when the model has dry friction) over
/// `[state symbols, parameter symbols]`.
#[derive(Clone)]
pub struct NumericDynamics {
    n: usize,
    m: usize,
    n_params: usize,
    tape: Tape,
    /// Which coordinates have a dry friction (empty: none has).
    dry: Vec<bool>,
    notes: Vec<String>,
}

impl fmt::Debug for NumericDynamics {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("NumericDynamics")
            .field("coordinates", &self.n)
            .field("inputs", &self.m)
            .field("parameters", &self.n_params)
            .field("instructions", &self.tape.instructions().len())
            .finish()
    }
}

/// Scratch buffers for [`NumericDynamics::derivatives`].
#[derive(Clone, Debug)]
pub struct Workspace {
    tape_in: Vec<f64>,
    tape_out: Vec<f64>,
    scratch: Vec<f64>,
    lu: Vec<f64>,
    rhs: Vec<f64>,
    piv: Vec<usize>,
    tmp: Vec<f64>,
    rules: StickSlip,
    mode: Mode,
    acc: Vec<f64>,
    stepper: Rk4Events,
}

/// Fallback width (rad/s or m/s) of a `sign()` that is not a dry friction
/// of one coordinate: the smooth law `tanh(v / 1e-3)` identification used
/// before friction stuck (a softer 1e-2 lets a held arm creep, notes trap 8).
pub const FALLBACK_SIGN_WIDTH: f64 = 1e-3;

impl NumericDynamics {
    /// Compile the tape for `eqs` (as derived from `model`). Tape inputs are
    /// [`Model::state_symbols`] followed by [`Model::parameter_symbols`]
    /// (the order of [`crate::model::ParameterValues::full`]).
    pub fn new(model: &Model, eqs: &Equations) -> Result<NumericDynamics, NumericError> {
        let n = eqs.coords.len();
        let m = eqs.inputs.len();
        if n != model.coordinates.len() || m != model.inputs.len() {
            return Err(NumericError::Shape(format!(
                "{n} coordinates and {m} inputs in the equations, {} and {} in the model",
                model.coordinates.len(),
                model.inputs.len()
            )));
        }
        if eqs.mass_matrix.len() != n
            || eqs.mass_matrix.iter().any(|r| r.len() != n)
            || eqs.bias.len() != n
            || eqs.forces.len() != n
            || eqs.input_matrix.len() != n
            || eqs.input_matrix.iter().any(|r| r.len() != m)
        {
            return Err(NumericError::Shape("matrix sizes".into()));
        }
        let split = decompose(eqs, FALLBACK_SIGN_WIDTH);
        let mut outputs = flat_outputs(&split.smooth);
        let dry: Vec<bool> = if split.any() {
            outputs.extend(split.levels.iter().copied());
            (0..n).map(|i| split.has(i)).collect()
        } else {
            Vec::new()
        };
        let mut inputs: Vec<Symbol> = model.state_symbols();
        let params = model.parameter_symbols();
        inputs.extend(params.iter().copied());
        let tape = Tape::compile(&outputs, &inputs).map_err(|e| match e {
            TapeError::UnknownSymbol(s) => NumericError::UnknownSymbol(s.name().to_string()),
        })?;
        Ok(NumericDynamics {
            n,
            m,
            n_params: params.len(),
            tape,
            dry,
            notes: split.notes,
        })
    }

    /// Whether some coordinate has a dry friction that sticks.
    pub fn has_dry_friction(&self) -> bool {
        !self.dry.is_empty()
    }

    /// Which coordinates have a dry friction (all false without).
    pub fn dry_coordinates(&self) -> Vec<bool> {
        if self.dry.is_empty() {
            vec![false; self.n]
        } else {
            self.dry.clone()
        }
    }

    /// The `sign()` terms that are not a dry friction of one coordinate and
    /// were smoothed ([`super::dry_friction::DryFriction::notes`]).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Number of coordinates `n` (the state has `2n` entries).
    pub fn n_coordinates(&self) -> usize {
        self.n
    }

    /// Number of states `2n`.
    pub fn n_states(&self) -> usize {
        2 * self.n
    }

    /// Number of inputs `m`.
    pub fn n_inputs(&self) -> usize {
        self.m
    }

    /// Expected length of the parameter vector (parameters and derived).
    pub fn n_params(&self) -> usize {
        self.n_params
    }

    /// The compiled tape (outputs `[M row-major, r0, B row-major]`, then the
    /// dry-friction levels `D` when [`NumericDynamics::has_dry_friction`]).
    pub fn tape(&self) -> &Tape {
        &self.tape
    }

    /// Scratch buffers sized for this system.
    pub fn workspace(&self) -> Workspace {
        let dry = self.dry_coordinates();
        Workspace {
            tape_in: vec![0.0; 2 * self.n + self.n_params],
            tape_out: vec![0.0; self.tape.n_outputs()],
            scratch: vec![0.0; self.tape.scratch_len()],
            lu: vec![0.0; self.n * self.n],
            rhs: vec![0.0; self.n],
            piv: vec![0; self.n],
            tmp: vec![0.0; self.n],
            rules: StickSlip::new(&dry),
            mode: Mode::new(self.n),
            acc: vec![0.0; self.n],
            stepper: Rk4Events::new(&dry),
        }
    }

    /// `M`, `b = r0 + B u` (without dry friction) and the levels `D` (zero
    /// without dry friction) at `x`; false when not finite.
    pub fn split(
        &self,
        x: &[f64],
        u: &[f64],
        params_full: &[f64],
        (mm, b, d): (&mut [f64], &mut [f64], &mut [f64]),
        ws: &mut Workspace,
    ) -> bool {
        let n = self.n;
        ws.tape_in[..2 * n].copy_from_slice(&x[..2 * n]);
        ws.tape_in[2 * n..].copy_from_slice(params_full);
        self.tape
            .eval(&ws.tape_in, &mut ws.tape_out, &mut ws.scratch);
        let out = &ws.tape_out;
        mm[..n * n].copy_from_slice(&out[..n * n]);
        let bm = &out[n * n + n..n * n + n + n * self.m];
        for i in 0..n {
            let mut acc = out[n * n + i];
            for (j, uj) in u.iter().enumerate() {
                acc += bm[i * self.m + j] * uj;
            }
            b[i] = acc;
        }
        let off = n * n + n + n * self.m;
        for i in 0..n {
            d[i] = if self.dry.is_empty() {
                0.0
            } else {
                out[off + i]
            };
        }
        mm[..n * n]
            .iter()
            .chain(&b[..n])
            .chain(&d[..n])
            .all(|v| v.is_finite())
    }

    /// One RK4 step of length `h` with `u` held, dry friction sticking and
    /// its switches located inside the step ([`Rk4Events`]); without dry
    /// friction the classical RK4 step. Does not allocate.
    pub fn rk4_step(
        &self,
        x: &mut [f64],
        u: &[f64],
        params_full: &[f64],
        h: f64,
        ws: &mut Workspace,
    ) -> Result<(), NumericError> {
        let mut stepper = std::mem::replace(&mut ws.stepper, Rk4Events::new(&[]));
        let r = stepper.step(
            &mut At {
                dynamics: self,
                u,
                params: params_full,
                ws,
            },
            x,
            h,
        );
        ws.stepper = stepper;
        r.map_err(|e| match e {
            StepError::Singular => NumericError::SingularMass,
            StepError::TooManyEvents => NumericError::Chattering,
        })
    }

    /// `dx = (q', M^-1 (r0 + B u))` for `x = (q, q')`. Does not allocate.
    /// Panics if a slice has the wrong length.
    pub fn derivatives(
        &self,
        x: &[f64],
        u: &[f64],
        params_full: &[f64],
        dx: &mut [f64],
        ws: &mut Workspace,
    ) -> Result<(), NumericError> {
        let n = self.n;
        assert_eq!(x.len(), 2 * n, "state length");
        assert_eq!(u.len(), self.m, "input length");
        assert_eq!(params_full.len(), self.n_params, "parameter length");
        assert_eq!(dx.len(), 2 * n, "derivative length");
        if !self.dry.is_empty() {
            return self.derivatives_sticking(x, u, params_full, dx, ws);
        }
        ws.tape_in[..2 * n].copy_from_slice(x);
        ws.tape_in[2 * n..].copy_from_slice(params_full);
        self.tape
            .eval(&ws.tape_in, &mut ws.tape_out, &mut ws.scratch);
        let (mm, rest) = ws.tape_out.split_at(n * n);
        let (r0, b) = rest.split_at(n);
        ws.lu.copy_from_slice(mm);
        for i in 0..n {
            let mut acc = r0[i];
            for (j, uj) in u.iter().enumerate() {
                acc += b[i * self.m + j] * uj;
            }
            ws.rhs[i] = acc;
        }
        lu_solve_in_place(&mut ws.lu, &mut ws.rhs, n, &mut ws.piv, &mut ws.tmp)?;
        dx[..n].copy_from_slice(&x[n..]);
        dx[n..].copy_from_slice(&ws.rhs);
        Ok(())
    }
}

impl NumericDynamics {
    /// [`NumericDynamics::derivatives`] with dry friction: the mode of the
    /// state (a joint at `v = 0.0` held while its static level allows).
    fn derivatives_sticking(
        &self,
        x: &[f64],
        u: &[f64],
        params_full: &[f64],
        dx: &mut [f64],
        ws: &mut Workspace,
    ) -> Result<(), NumericError> {
        let n = self.n;
        let (mut mm, mut b, mut d) = (
            std::mem::take(&mut ws.lu),
            std::mem::take(&mut ws.rhs),
            std::mem::take(&mut ws.tmp),
        );
        let mut rules = std::mem::replace(&mut ws.rules, StickSlip::new(&[]));
        let mut mode = std::mem::replace(&mut ws.mode, Mode::new(0));
        let mut acc = std::mem::take(&mut ws.acc);
        let ok = self.split(x, u, params_full, (&mut mm, &mut b, &mut d), ws)
            && rules.classify(&mm, &b, &d, &x[n..2 * n], None, &mut mode)
            && rules.accelerations(&mm, &b, &d, &mode, &mut acc);
        if ok {
            dx[..n].copy_from_slice(&x[n..]);
            dx[n..].copy_from_slice(&acc);
        }
        (ws.lu, ws.rhs, ws.tmp, ws.rules, ws.mode, ws.acc) = (mm, b, d, rules, mode, acc);
        if ok {
            Ok(())
        } else {
            Err(NumericError::SingularMass)
        }
    }
}

/// The dynamics with the input and parameters bound, for [`Rk4Events`].
struct At<'a> {
    dynamics: &'a NumericDynamics,
    u: &'a [f64],
    params: &'a [f64],
    ws: &'a mut Workspace,
}

impl SplitDynamics for At<'_> {
    fn split(&mut self, x: &[f64], m: &mut [f64], b: &mut [f64], d: &mut [f64]) -> bool {
        self.dynamics
            .split(x, self.u, self.params, (m, b, d), self.ws)
    }
}

/// The equations as one flat vector `[M (row-major, n*n), r0 = Q0 - bias (n),
/// B (row-major, n*m)]`: the outputs of the dynamics tape.
pub fn flat_outputs(eqs: &Equations) -> Vec<Expr> {
    let n = eqs.coords.len();
    let mut out: Vec<Expr> = Vec::with_capacity(n * n + n + n * eqs.inputs.len());
    for row in &eqs.mass_matrix {
        out.extend(row.iter().copied());
    }
    out.extend((0..n).map(|i| eqs.forces[i] - eqs.bias[i]));
    for row in &eqs.input_matrix {
        out.extend(row.iter().copied());
    }
    out
}

/// Whether any entry of the equations contains `sign(..)` (dry friction).
pub fn has_sign(eqs: &Equations) -> bool {
    let mut found = false;
    visit_signs(eqs, &mut |_| found = true);
    found
}

fn visit_signs(eqs: &Equations, f: &mut dyn FnMut(Expr)) {
    let mut seen = std::collections::HashSet::new();
    let mut stack: Vec<Expr> = eqs
        .mass_matrix
        .iter()
        .chain(&eqs.input_matrix)
        .flatten()
        .chain(&eqs.bias)
        .chain(&eqs.forces)
        .copied()
        .collect();
    while let Some(e) = stack.pop() {
        if !seen.insert(e) {
            continue;
        }
        if let Node::Func(Func::Sign, _) = e.node() {
            f(e);
        }
        stack.extend(e.children());
    }
}

/// The equations with every `sign(v)` replaced by `tanh(v / width)`: a
/// regularised dry friction that an explicit integrator can step through
/// (exact `sign` makes a sticking joint chatter and the step collapse). The
/// sticking velocity band is about `width`; a joint under a load below the
/// friction level creeps at roughly `width * atanh(load / friction)`.
pub fn smooth_signs(eqs: &Equations, width: f64) -> Equations {
    smooth_signs_with(eqs, |v| (v * Expr::float(1.0 / width)).tanh())
}

/// [`smooth_signs`] with `sign(v)` replaced by `law(v)` (e.g.
/// `tanh(v / w)` with `w` a parameter symbol, to fit the width).
pub fn smooth_signs_with(eqs: &Equations, law: impl Fn(Expr) -> Expr) -> Equations {
    let mut map: HashMap<Expr, Expr> = HashMap::new();
    visit_signs(eqs, &mut |e| {
        if let Node::Func(Func::Sign, v) = e.node() {
            map.insert(e, law(*v));
        }
    });
    let s = |e: &Expr| crate::sym::substitute(*e, &map);
    Equations {
        coords: eqs.coords.clone(),
        inputs: eqs.inputs.clone(),
        mass_matrix: eqs
            .mass_matrix
            .iter()
            .map(|r| r.iter().map(s).collect())
            .collect(),
        bias: eqs.bias.iter().map(s).collect(),
        forces: eqs.forces.iter().map(s).collect(),
        input_matrix: eqs
            .input_matrix
            .iter()
            .map(|r| r.iter().map(s).collect())
            .collect(),
        // the angle frame holds M and bias (from T and V): kept unless a sign
        // was smoothed in them
        angles: eqs.angles.clone().filter(|ac| !has_sign(&ac.equations)),
    }
}

/// Solve `A z = b` (`a` row-major `n*n`, overwritten by its LU factors; `b`
/// overwritten by `z`). A pivot below `1e-14 * max|A|` counts as singular.
fn lu_solve_in_place(
    a: &mut [f64],
    b: &mut [f64],
    n: usize,
    piv: &mut [usize],
    tmp: &mut [f64],
) -> Result<(), NumericError> {
    let scale = a.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    if !scale.is_finite() || scale == 0.0 || !lu_factor(a, n, piv, 1e-14 * scale) {
        return Err(NumericError::SingularMass);
    }
    lu_solve(a, n, piv, b, tmp);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lu_solves_with_pivoting() {
        let mut a = vec![0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        let x = [1.0, -2.0, 0.5];
        let orig = a.clone();
        let mut b: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|j| orig[i * 3 + j] * x[j]).sum())
            .collect();
        lu_solve_in_place(&mut a, &mut b, 3, &mut [0; 3], &mut [0.0; 3]).unwrap();
        for i in 0..3 {
            assert!((b[i] - x[i]).abs() < 1e-14, "{b:?}");
        }
        let mut s = vec![1.0, 2.0, 2.0, 4.0];
        let mut r = vec![1.0, 1.0];
        assert_eq!(
            lu_solve_in_place(&mut s, &mut r, 2, &mut [0; 2], &mut [0.0; 2]),
            Err(NumericError::SingularMass)
        );
    }
}
