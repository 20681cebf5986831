//! Zero dynamics `eta' = q(0, eta) = L_f eta` on the manifold `xi = 0`, their
//! linearization at `eta = 0` and a classification (minimum phase or not).
//!
//! The state is expressed in `eta` coordinates on `xi = 0` symbolically: each
//! `xi_k` must reduce (after the earlier ones are set to zero) to a constant
//! multiple of a state variable, which is set to zero; then `eta` components
//! that are a multiple of a state variable give it directly, and the remaining
//! state variables must enter the remaining `eta` linearly (momenta are linear
//! in the velocities); that linear system is solved by Cramer's rule through
//! the adjugate and the determinant.

use std::collections::HashMap;
use std::fmt;

use nalgebra::DMatrix;

use super::normal_form::NormalForm;
use crate::linear::{poles, Pole};
use crate::mechanics::{adjugate, determinant};
use crate::model::{Model, ParameterValues};
use crate::sym::{diff, is_zero, simplify, substitute_symbols, Expr, Node, Symbol};

/// Why the zero dynamics could not be formed.
#[derive(Clone, Debug, PartialEq)]
pub enum ZeroDynamicsError {
    /// `xi = 0` could not be solved for state variables.
    CannotSolveOutput {
        /// The `xi` component at fault (after substitution).
        xi: String,
    },
    /// The state could not be expressed in `eta` on `xi = 0`.
    CannotSolveEta {
        /// Explanation.
        reason: String,
    },
    /// The linearization is not finite at `eta = 0`.
    NotFinite {
        /// Which entry.
        entry: String,
    },
    /// The eigenvalue computation failed.
    Eigen(String),
}

impl fmt::Display for ZeroDynamicsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ZeroDynamicsError::CannotSolveOutput { xi } => write!(
                f,
                "cannot solve xi = 0 for the state: `{xi}` is not a multiple of one state variable"
            ),
            ZeroDynamicsError::CannotSolveEta { reason } => {
                write!(
                    f,
                    "cannot express the state in eta coordinates on xi = 0: {reason}"
                )
            }
            ZeroDynamicsError::NotFinite { entry } => write!(f, "{entry} is not finite at eta = 0"),
            ZeroDynamicsError::Eigen(e) => write!(f, "eigenvalues of the zero dynamics: {e}"),
        }
    }
}

impl std::error::Error for ZeroDynamicsError {}

/// Stability of the zero dynamics' linearization at `eta = 0`.
#[derive(Copy, Clone, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ZeroDynamicsClass {
    /// Every eigenvalue has a negative real part.
    AsymptoticallyStable,
    /// Some eigenvalue on the imaginary axis, none in the right half-plane.
    NotAsymptoticallyStable,
    /// Some eigenvalue has a positive real part.
    Unstable,
}

impl ZeroDynamicsClass {
    /// Human-readable classification.
    pub fn describe(self) -> &'static str {
        match self {
            ZeroDynamicsClass::AsymptoticallyStable => "asymptotically stable (minimum phase)",
            ZeroDynamicsClass::NotAsymptoticallyStable => {
                "not asymptotically stable (eigenvalues on the imaginary axis; not minimum phase)"
            }
            ZeroDynamicsClass::Unstable => "unstable (non-minimum phase)",
        }
    }
}

/// The zero dynamics of a normal form.
#[derive(Clone, Debug)]
pub struct ZeroDynamics {
    /// The symbols `eta1, eta2, ...` used in `rhs`.
    pub eta_symbols: Vec<Symbol>,
    /// `eta_i' = rhs_i(eta)` on `xi = 0` (simplified).
    pub rhs: Vec<Expr>,
    /// The state on `xi = 0` as functions of `eta` (model order).
    pub state_on_manifold: Vec<(Symbol, Expr)>,
    /// `d rhs / d eta` at `eta = 0`.
    pub jacobian: Vec<Vec<f64>>,
    /// Its eigenvalues.
    pub eigenvalues: Vec<Pole>,
    /// Largest `|rhs_i(0)|` (0 if `eta = 0` is an equilibrium).
    pub equilibrium_residual: f64,
    /// Tolerance used to decide "on the imaginary axis".
    pub tolerance: f64,
    /// The classification.
    pub class: ZeroDynamicsClass,
}

impl ZeroDynamics {
    /// All eigenvalues in the open left half-plane.
    pub fn asymptotically_stable(&self) -> bool {
        self.class == ZeroDynamicsClass::AsymptoticallyStable
    }

    /// Minimum phase: the zero dynamics are asymptotically stable (at `eta = 0`,
    /// judged on the linearization).
    pub fn minimum_phase(&self) -> bool {
        self.asymptotically_stable()
    }

    /// The equations as text, `eta1' = ...`.
    pub fn equations(&self) -> Vec<String> {
        self.eta_symbols
            .iter()
            .zip(&self.rhs)
            .map(|(s, e)| format!("{}' = {e}", s.name()))
            .collect()
    }
}

/// `e = k * s` with `s` one of `vars` and `k` free of `vars`: `(k, s)`.
fn scaled_symbol(e: Expr, vars: &[Symbol]) -> Option<(Expr, Symbol)> {
    let factors: Vec<Expr> = match e.node() {
        Node::Mul(fs) => fs.to_vec(),
        _ => vec![e],
    };
    let mut sym = None;
    let mut rest = Vec::new();
    for f in factors {
        match f.as_symbol() {
            Some(s) if vars.contains(&s) => {
                if sym.is_some() {
                    return None;
                }
                sym = Some(s);
            }
            _ => {
                if vars.iter().any(|v| f.contains(*v)) {
                    return None;
                }
                rest.push(f);
            }
        }
    }
    sym.map(|s| (Expr::mul_all(rest), s))
}

/// Names `eta1, eta2, ...` that clash with no symbol of the model.
fn eta_names(model: &Model, count: usize) -> Vec<Symbol> {
    let taken: Vec<String> = model
        .parameters
        .iter()
        .map(|p| p.name.clone())
        .chain(model.derived.iter().map(|d| d.name.clone()))
        .chain(model.state_symbols().iter().map(|s| s.name().to_string()))
        .chain(model.inputs.iter().map(|u| u.name.clone()))
        .collect();
    let mut prefix = "eta".to_string();
    while (1..=count).any(|i| taken.contains(&format!("{prefix}{i}"))) {
        prefix.push('_');
    }
    (1..=count)
        .map(|i| Symbol::new(&format!("{prefix}{i}")))
        .collect()
}

/// The zero dynamics of `nf`, linearized at `eta = 0` with parameter `values`.
pub fn zero_dynamics(
    model: &Model,
    nf: &NormalForm,
    values: &ParameterValues,
) -> Result<ZeroDynamics, ZeroDynamicsError> {
    let state = &nf.state;
    let mut map: HashMap<Symbol, Expr> = HashMap::new();
    let mut free: Vec<Symbol> = state.clone();
    for x in &nf.xi {
        let e = simplify(substitute_symbols(*x, &map));
        let Some((k, s)) = scaled_symbol(e, &free) else {
            return Err(ZeroDynamicsError::CannotSolveOutput { xi: e.to_string() });
        };
        if is_zero(k) {
            return Err(ZeroDynamicsError::CannotSolveOutput { xi: e.to_string() });
        }
        map.insert(s, Expr::zero());
        free.retain(|v| *v != s);
    }
    let etas = eta_names(model, nf.eta.len());
    // Components that are a multiple of one free state variable.
    let mut pending: Vec<(Expr, Symbol)> = Vec::new();
    for (e, sym) in nf.eta.iter().zip(&etas) {
        let e = simplify(substitute_symbols(*e, &map));
        match scaled_symbol(e, &free) {
            Some((k, s)) if !is_zero(k) => {
                map.insert(s, Expr::symbol(*sym) / k);
                free.retain(|v| *v != s);
            }
            _ => pending.push((e, *sym)),
        }
    }
    if pending.len() != free.len() {
        return Err(ZeroDynamicsError::CannotSolveEta {
            reason: format!("{} equations for {} unknowns", pending.len(), free.len()),
        });
    }
    if !pending.is_empty() {
        // pending_i = sum_k a_ik u_k + b_i, linear in the free variables u.
        let zero_free: HashMap<Symbol, Expr> = free.iter().map(|s| (*s, Expr::zero())).collect();
        let mut a = Vec::new();
        let mut rhs = Vec::new();
        for (e, sym) in &pending {
            let e = simplify(substitute_symbols(*e, &map));
            let mut row = Vec::new();
            for u in &free {
                let c = diff(e, *u);
                if free.iter().any(|v| !is_zero(diff(c, *v))) {
                    return Err(ZeroDynamicsError::CannotSolveEta {
                        reason: format!("`{e}` is not linear in the remaining state variables"),
                    });
                }
                row.push(simplify(c));
            }
            a.push(row);
            rhs.push(Expr::symbol(*sym) - substitute_symbols(e, &zero_free));
        }
        let det = simplify(determinant(&a));
        if is_zero(det) {
            return Err(ZeroDynamicsError::CannotSolveEta {
                reason: "the remaining eta components are dependent on xi = 0".into(),
            });
        }
        let adj = adjugate(&a);
        for (k, u) in free.iter().enumerate() {
            let num: Expr = (0..free.len()).map(|j| adj[k][j] * rhs[j]).sum();
            map.insert(*u, simplify(num / det));
        }
    }
    let state_on_manifold: Vec<(Symbol, Expr)> = state
        .iter()
        .map(|s| (*s, map.get(s).copied().unwrap_or_else(|| Expr::symbol(*s))))
        .collect();
    let rhs: Vec<Expr> = nf
        .eta_dot
        .iter()
        .map(|e| simplify(substitute_symbols(*e, &map)))
        .collect();
    // Linearization at eta = 0.
    let mut point = values.symbol_map(model);
    for s in &etas {
        point.insert(*s, 0.0);
    }
    let m = etas.len();
    let mut jac = vec![vec![0.0; m]; m];
    let mut residual: f64 = 0.0;
    for i in 0..m {
        residual = residual.max(rhs[i].eval_map(&point).abs());
        for j in 0..m {
            let v = diff(rhs[i], etas[j]).eval_map(&point);
            if !v.is_finite() {
                return Err(ZeroDynamicsError::NotFinite {
                    entry: format!("d({}')/d{}", etas[i].name(), etas[j].name()),
                });
            }
            jac[i][j] = v;
        }
    }
    let (eigenvalues, tolerance, class) = classify(&jac)?;
    Ok(ZeroDynamics {
        eta_symbols: etas,
        rhs,
        state_on_manifold,
        jacobian: jac,
        eigenvalues,
        equilibrium_residual: residual,
        tolerance,
        class,
    })
}

/// Eigenvalues of a square matrix and their classification. The tolerance for
/// "on the imaginary axis" is `1e-6 * max(1, |J|)`: a Jordan block of size 2
/// moves its eigenvalues by about `sqrt(eps |J|)` in floating point.
pub fn classify(
    jac: &[Vec<f64>],
) -> Result<(Vec<Pole>, f64, ZeroDynamicsClass), ZeroDynamicsError> {
    let m = jac.len();
    if m == 0 {
        return Ok((Vec::new(), 0.0, ZeroDynamicsClass::AsymptoticallyStable));
    }
    let a = DMatrix::from_fn(m, m, |i, j| jac[i][j]);
    let eig = poles(&a).map_err(|e| ZeroDynamicsError::Eigen(e.to_string()))?;
    let tol = 1e-6 * a.norm().max(1.0);
    let class = if eig.iter().any(|p| p.re > tol) {
        ZeroDynamicsClass::Unstable
    } else if eig.iter().any(|p| p.re >= -tol) {
        ZeroDynamicsClass::NotAsymptoticallyStable
    } else {
        ZeroDynamicsClass::AsymptoticallyStable
    };
    Ok((eig, tol, class))
}
