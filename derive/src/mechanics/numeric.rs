//! Numeric evaluation of the equations of motion without forming `M^-1`.
//!
//! One compiled [`Tape`] evaluates, for given state and parameters, the mass
//! matrix `M` (row-major, `n*n`), the input-free right-hand side
//! `r0 = Q0 - bias` (`n`) and the input matrix `B` (`n*m`, row-major). The
//! accelerations follow from `M a = r0 + B u`, solved by an in-place LU
//! factorisation with partial pivoting. Nothing allocates per call: the
//! buffers live in a [`Workspace`].

use std::fmt;

use super::small_lu::{lu_factor, lu_solve};
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
        }
    }
}

impl std::error::Error for NumericError {}

/// Compiled `M(q)`, `r0(q, q') = Q0 - bias`, `B(q, q')` over
/// `[state symbols, parameter symbols]`.
#[derive(Clone)]
pub struct NumericDynamics {
    n: usize,
    m: usize,
    n_params: usize,
    tape: Tape,
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
}

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
        let outputs = flat_outputs(eqs);
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
        })
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

    /// The compiled tape (outputs `[M row-major, r0, B row-major]`).
    pub fn tape(&self) -> &Tape {
        &self.tape
    }

    /// Scratch buffers sized for this system.
    pub fn workspace(&self) -> Workspace {
        Workspace {
            tape_in: vec![0.0; 2 * self.n + self.n_params],
            tape_out: vec![0.0; self.n * self.n + self.n + self.n * self.m],
            scratch: vec![0.0; self.tape.scratch_len()],
            lu: vec![0.0; self.n * self.n],
            rhs: vec![0.0; self.n],
            piv: vec![0; self.n],
            tmp: vec![0.0; self.n],
        }
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
    let mut map: HashMap<Expr, Expr> = HashMap::new();
    visit_signs(eqs, &mut |e| {
        if let Node::Func(Func::Sign, v) = e.node() {
            map.insert(e, (*v * Expr::float(1.0 / width)).tanh());
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
