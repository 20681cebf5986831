//! Linearization of `M(q) q'' = r(q, q', u)` about an operating point, from
//! symbolic Jacobians evaluated with a parameter set.
//!
//! With `a = M^-1 r` the accelerations, `da/dx = M^-1 (dr/dx - sum_k dM/dx_k a)`,
//! so the mass matrix is never inverted symbolically here. Terms that are not
//! differentiable at the operating point (`sign(u)`, `abs(u)` with `u = 0`, as in
//! dry friction at rest) get the derivative 0 and are reported in `notes`.

use std::collections::{HashMap, HashSet};
use std::fmt;

use nalgebra::{DMatrix, DVector};

use crate::mechanics::Equations;
use crate::model::{Model, ParameterValues};
use crate::sym::{eval_jacobian, Expr, Func, Node, Symbol};

/// The state and input values to linearize about (SI units, model order).
#[derive(Clone, Debug, PartialEq)]
pub struct OperatingPoint {
    /// `x0 = (q, q')`.
    pub x: Vec<f64>,
    /// `u0`.
    pub u: Vec<f64>,
}

impl OperatingPoint {
    /// All states and inputs zero.
    pub fn zero(model: &Model) -> OperatingPoint {
        OperatingPoint {
            x: vec![0.0; 2 * model.coordinates.len()],
            u: vec![0.0; model.inputs.len()],
        }
    }
}

/// Why linearization failed.
#[derive(Clone, Debug, PartialEq)]
pub enum LinearizeError {
    /// The operating point has the wrong number of entries.
    WrongSize {
        /// What was expected.
        expected: usize,
        /// What was given.
        found: usize,
        /// `"state"` or `"input"`.
        what: &'static str,
    },
    /// The mass matrix is singular at the operating point.
    SingularMassMatrix,
    /// The model has no coordinates: there is nothing to linearize.
    NoCoordinates,
    /// A Jacobian entry is not finite at the operating point.
    NotFinite {
        /// Which entry, e.g. `dr_theta/dalpha`.
        entry: String,
    },
}

impl fmt::Display for LinearizeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LinearizeError::WrongSize {
                expected,
                found,
                what,
            } => {
                write!(
                    f,
                    "the operating point has {found} {what} values, the model has {expected}"
                )
            }
            LinearizeError::SingularMassMatrix => {
                write!(f, "the mass matrix is singular at the operating point")
            }
            LinearizeError::NoCoordinates => {
                write!(f, "the model has no coordinates: nothing to linearize")
            }
            LinearizeError::NotFinite { entry } => {
                write!(f, "{entry} is not finite at the operating point")
            }
        }
    }
}

impl std::error::Error for LinearizeError {}

/// `dx = A dx + B du` about an operating point.
#[derive(Clone, Debug)]
pub struct Linearization {
    /// State names (`theta, alpha, theta_dot, alpha_dot`).
    pub state: Vec<String>,
    /// Input names.
    pub inputs: Vec<String>,
    /// `A = df/dx`.
    pub a: DMatrix<f64>,
    /// `B = df/du`.
    pub b: DMatrix<f64>,
    /// Largest |acceleration| at the operating point (0 for an equilibrium).
    pub equilibrium_residual: f64,
    /// Remarks for the user (dropped non-differentiable terms, non-equilibrium).
    pub notes: Vec<String>,
}

fn find_nonsmooth(
    e: Expr,
    at: &HashMap<Symbol, f64>,
    out: &mut Vec<Expr>,
    seen: &mut HashSet<Expr>,
) {
    if !seen.insert(e) {
        return;
    }
    if let Node::Func(Func::Sign | Func::Abs, arg) = e.node() {
        let v = arg.eval_map(at);
        if v == 0.0 && !arg.is_constant() {
            out.push(e);
        }
    }
    for c in e.children() {
        find_nonsmooth(c, at, out, seen);
    }
}

/// Linearize the equations of `model` about `op` with parameter `values`.
pub fn linearize(
    model: &Model,
    eqs: &Equations,
    values: &ParameterValues,
    op: &OperatingPoint,
) -> Result<Linearization, LinearizeError> {
    let n = eqs.coords.len();
    let m = eqs.inputs.len();
    if n == 0 {
        return Err(LinearizeError::NoCoordinates);
    }
    if op.x.len() != 2 * n {
        return Err(LinearizeError::WrongSize {
            expected: 2 * n,
            found: op.x.len(),
            what: "state",
        });
    }
    if op.u.len() != m {
        return Err(LinearizeError::WrongSize {
            expected: m,
            found: op.u.len(),
            what: "input",
        });
    }
    let mut at = values.symbol_map(model);
    let state = model.state_symbols();
    for (s, v) in state.iter().zip(&op.x) {
        at.insert(*s, *v);
    }
    for (s, v) in eqs.inputs.iter().zip(&op.u) {
        at.insert(*s, *v);
    }
    let rhs = eqs.rhs();
    let mut notes = Vec::new();
    let mut nonsmooth = Vec::new();
    let mut seen = HashSet::new();
    for r in &rhs {
        find_nonsmooth(*r, &at, &mut nonsmooth, &mut seen);
    }
    for e in nonsmooth {
        notes.push(format!(
            "`{e}` is not differentiable at the operating point (its argument is 0); \
             its derivative is taken as 0, so the term drops out of the linearization"
        ));
    }
    // values and first derivatives of M and r = Q0 - bias + B u in one
    // forward-mode pass (exact up to rounding, no symbolic derivatives)
    let mut vars = state.clone();
    vars.extend(eqs.inputs.iter().copied());
    let mut outs: Vec<Expr> = Vec::with_capacity(n * n + n);
    for row in &eqs.mass_matrix {
        outs.extend(row.iter().copied());
    }
    outs.extend(rhs.iter().copied());
    let (vals, jac) = eval_jacobian(&outs, &vars, &at);
    let finite = |v: f64, entry: &dyn Fn() -> String| -> Result<f64, LinearizeError> {
        if v.is_finite() {
            Ok(v)
        } else {
            Err(LinearizeError::NotFinite { entry: entry() })
        }
    };
    let mut mass = DMatrix::zeros(n, n);
    for i in 0..n {
        for j in 0..n {
            mass[(i, j)] = finite(vals[i * n + j], &|| format!("M[{i}][{j}]"))?;
        }
    }
    let mut r0 = DVector::zeros(n);
    for i in 0..n {
        r0[i] = finite(vals[n * n + i], &|| {
            format!("the right-hand side of equation {i}")
        })?;
    }
    let lu = mass.clone().lu();
    let acc = lu.solve(&r0).ok_or(LinearizeError::SingularMassMatrix)?;
    let residual = acc.amax();
    if residual > 1e-9 {
        notes.push(format!(
            "the operating point is not an equilibrium (largest acceleration {residual:.3e}); \
             the linearization is about a moving point"
        ));
    }
    // d r / d x - sum_k dM/dx_k a
    let mut drdx = DMatrix::zeros(n, 2 * n);
    for (k, s) in state.iter().enumerate() {
        let name = s.name();
        for i in 0..n {
            let mut v = finite(jac[n * n + i][k], &|| format!("d r{i} / d {name}"))?;
            for j in 0..n {
                let dm = jac[i * n + j][k];
                if dm != 0.0 {
                    v -= finite(dm, &|| format!("d M[{i}][{j}] / d {name}"))? * acc[j];
                }
            }
            drdx[(i, k)] = v;
        }
    }
    let mut drdu = DMatrix::zeros(n, m);
    for (k, u) in eqs.inputs.iter().enumerate() {
        for i in 0..n {
            drdu[(i, k)] = finite(jac[n * n + i][2 * n + k], &|| {
                format!("d r{i} / d {}", u.name())
            })?;
        }
    }
    let lower_a = lu.solve(&drdx).ok_or(LinearizeError::SingularMassMatrix)?;
    let lower_b = lu.solve(&drdu).ok_or(LinearizeError::SingularMassMatrix)?;
    let mut a = DMatrix::zeros(2 * n, 2 * n);
    let mut b = DMatrix::zeros(2 * n, m);
    for i in 0..n {
        a[(i, n + i)] = 1.0;
        for k in 0..2 * n {
            a[(n + i, k)] = lower_a[(i, k)];
        }
        for k in 0..m {
            b[(n + i, k)] = lower_b[(i, k)];
        }
    }
    Ok(Linearization {
        state: model.state_names(),
        inputs: model.inputs.iter().map(|u| u.name.clone()).collect(),
        a,
        b,
        equilibrium_residual: residual,
        notes,
    })
}
