//! Zero dynamics `eta' = q(0, eta) = L_f eta` on the manifold `xi = 0`, their
//! linearization at `eta = 0` and a classification (minimum phase or not).
//!
//! The state is expressed in `eta` coordinates on `xi = 0`:
//!
//! 1. components of `eta` that are a constant multiple of a state variable
//!    give it directly (`eta1 = theta`);
//! 2. position-level components of `xi` (no velocities, e.g. `h = q1 + q2 +
//!    q3`) are solved for a remaining coordinate in which they are linear;
//! 3. the remaining components (velocity level: `L_f h = J q'`, momenta
//!    `p = M q'`) must be linear in the remaining state variables; that linear
//!    system is solved by Cramer's rule (adjugate over determinant, canonical
//!    form) for up to [`EXPLICIT_MAX_COORDINATES`] coordinates, and beyond by
//!    a symbolic LU solve whose pivots are chosen at `eta = 0`
//!    ([`crate::mechanics::lu_solve_at`]), leaving the right-hand sides as
//!    unexpanded expressions: the linearization is then exact numerically, and
//!    the equations are reported by their parts.

use std::collections::HashMap;
use std::fmt;

use nalgebra::DMatrix;

use super::mechanical::{ANALYSIS_MAX_TERMS, EXPLICIT_MAX_COORDINATES};
use super::normal_form::NormalForm;
use crate::linear::{poles, Pole};
use crate::mechanics::{adjugate, determinant};
use crate::model::{Model, ParameterValues};
use crate::sym::{
    diff, eval_jacobian, is_zero, substitute_symbols, Canonicalizer, Expr, Node, Symbol,
};

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
    /// An exact computation hit its term budget.
    Budget {
        /// Why it stopped.
        reason: String,
    },
}

impl fmt::Display for ZeroDynamicsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ZeroDynamicsError::CannotSolveOutput { xi } => write!(
                f,
                "cannot solve xi = 0 for the state: `{xi}` is not linear in a coordinate with a nonzero coefficient at the operating point"
            ),
            ZeroDynamicsError::CannotSolveEta { reason } => {
                write!(
                    f,
                    "cannot express the state in eta coordinates on xi = 0: {reason}"
                )
            }
            ZeroDynamicsError::NotFinite { entry } => write!(f, "{entry} is not finite at eta = 0"),
            ZeroDynamicsError::Eigen(e) => write!(f, "eigenvalues of the zero dynamics: {e}"),
            ZeroDynamicsError::Budget { reason } => write!(f, "zero dynamics stopped: {reason}"),
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
    /// True if `rhs` and `state_on_manifold` are expanded and simplified;
    /// false if they are unexpanded expressions (large systems), in which
    /// case [`ZeroDynamics::equations`] gives them by their parts.
    pub explicit: bool,
    text: Vec<String>,
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

    /// The equations as text, `eta1' = ...` (by their parts when not
    /// [`ZeroDynamics::explicit`]).
    pub fn equations(&self) -> Vec<String> {
        self.text.clone()
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

/// `e = c * s + rest` with `s` one of `vars` and `c` free of `s` and
/// nonzero at `point`: `(s, -rest/c)`.
fn linear_in_one(e: Expr, vars: &[Symbol], point: &HashMap<Symbol, f64>) -> Option<(Symbol, Expr)> {
    for s in vars {
        if !e.contains(*s) {
            continue;
        }
        let c = diff(e, *s);
        if c.contains(*s) {
            continue;
        }
        let cv = c.eval_map(point);
        if !cv.is_finite() || cv.abs() < 1e-12 {
            continue;
        }
        let mut z = HashMap::new();
        z.insert(*s, Expr::zero());
        let rest = substitute_symbols(e, &z);
        return Some((*s, -rest / c));
    }
    None
}

/// The zero dynamics of `nf`, linearized at `eta = 0` with parameter `values`.
pub fn zero_dynamics(
    model: &Model,
    nf: &NormalForm,
    values: &ParameterValues,
) -> Result<ZeroDynamics, ZeroDynamicsError> {
    let state = &nf.state;
    let n = model.coordinates.len();
    let explicit = n <= EXPLICIT_MAX_COORDINATES;
    let canon = std::cell::RefCell::new(Canonicalizer::new(ANALYSIS_MAX_TERMS));
    let tidy = |e: Expr| -> Result<Expr, ZeroDynamicsError> {
        if explicit {
            canon
                .borrow_mut()
                .try_simplify(e)
                .map_err(|x| ZeroDynamicsError::Budget {
                    reason: format!("{x} (budget {ANALYSIS_MAX_TERMS} terms)"),
                })
        } else {
            Ok(e)
        }
    };
    let velocities: Vec<Symbol> = model.coordinates.iter().map(|c| c.symbols.qd).collect();
    let moving = |e: Expr| velocities.iter().any(|v| e.contains(*v));
    let etas = eta_names(model, nf.eta.len());
    let mut point = values.symbol_map(model);
    for s in etas.iter().chain(state.iter()) {
        point.insert(*s, 0.0);
    }
    let mut map: HashMap<Symbol, Expr> = HashMap::new();
    let mut free: Vec<Symbol> = state.clone();
    // 1. eta components that are a multiple of one state variable
    let mut pending: Vec<(Expr, Expr)> = Vec::new(); // (expression, value on the manifold)
    for (e, sym) in nf.eta.iter().zip(&etas) {
        match scaled_symbol(*e, &free) {
            Some((k, s)) if !is_zero(k) && !k.symbols().iter().any(|v| state.contains(v)) => {
                map.insert(s, Expr::symbol(*sym) / k);
                free.retain(|v| *v != s);
            }
            _ => pending.push((*e, Expr::symbol(*sym))),
        }
    }
    // 2. position-level xi: solve for a remaining coordinate
    for x in &nf.xi {
        let e = tidy(substitute_symbols(*x, &map))?;
        if e.is_zero() {
            continue;
        }
        if moving(e) {
            pending.push((e, Expr::zero()));
            continue;
        }
        let coords: Vec<Symbol> = free
            .iter()
            .copied()
            .filter(|s| !velocities.contains(s))
            .collect();
        let Some((s, value)) = linear_in_one(e, &coords, &point) else {
            return Err(ZeroDynamicsError::CannotSolveOutput { xi: e.to_string() });
        };
        let value = tidy(value)?;
        for v in map.values_mut() {
            let mut one = HashMap::new();
            one.insert(s, value);
            *v = tidy(substitute_symbols(*v, &one))?;
        }
        map.insert(s, value);
        free.retain(|v| *v != s);
    }
    // 3. the rest: linear in the remaining state variables
    if pending.len() != free.len() {
        return Err(ZeroDynamicsError::CannotSolveEta {
            reason: format!("{} equations for {} unknowns", pending.len(), free.len()),
        });
    }
    if !explicit {
        return numeric_zero_dynamics(model, nf, etas, map, free, pending, point, velocities, n);
    }
    if !pending.is_empty() {
        let zero_free: HashMap<Symbol, Expr> = free.iter().map(|s| (*s, Expr::zero())).collect();
        let mut a = Vec::new();
        let mut rhs = Vec::new();
        for (e, value) in &pending {
            let e = tidy(substitute_symbols(*e, &map))?;
            let mut row = Vec::new();
            for u in &free {
                let c = diff(e, *u);
                if free.iter().any(|v| !is_zero(diff(c, *v))) {
                    return Err(ZeroDynamicsError::CannotSolveEta {
                        reason: format!("`{e}` is not linear in the remaining state variables"),
                    });
                }
                row.push(tidy(c)?);
            }
            a.push(row);
            rhs.push(*value - substitute_symbols(e, &zero_free));
        }
        let det = tidy(determinant(&a))?;
        if is_zero(det) {
            return Err(ZeroDynamicsError::CannotSolveEta {
                reason: "the remaining eta components are dependent on xi = 0".into(),
            });
        }
        let adj = adjugate(&a);
        for (k, u) in free.iter().enumerate() {
            let num: Expr = (0..free.len()).map(|j| adj[k][j] * rhs[j]).sum();
            map.insert(*u, tidy(num / det)?);
        }
    }
    let state_on_manifold: Vec<(Symbol, Expr)> = state
        .iter()
        .map(|s| (*s, map.get(s).copied().unwrap_or_else(|| Expr::symbol(*s))))
        .collect();
    let rhs: Vec<Expr> = nf
        .eta_dot
        .iter()
        .map(|e| tidy(substitute_symbols(*e, &map)))
        .collect::<Result<_, _>>()?;
    // Linearization at eta = 0.
    let m = etas.len();
    let (values0, jac) = eval_jacobian(&rhs, &etas, &point);
    let mut residual: f64 = 0.0;
    for i in 0..m {
        residual = residual.max(values0[i].abs());
        for j in 0..m {
            if !jac[i][j].is_finite() {
                return Err(ZeroDynamicsError::NotFinite {
                    entry: format!("d({}')/d{}", etas[i].name(), etas[j].name()),
                });
            }
        }
    }
    let (eigenvalues, tolerance, class) = classify(&jac)?;
    let equations = etas
        .iter()
        .zip(&rhs)
        .map(|(s, e)| format!("{}' = {e}", s.name()))
        .collect();
    Ok(ZeroDynamics {
        eta_symbols: etas,
        rhs,
        state_on_manifold,
        jacobian: jac,
        eigenvalues,
        equilibrium_residual: residual,
        tolerance,
        class,
        explicit,
        text: equations,
    })
}

/// The zero dynamics of a large system (more than
/// [`EXPLICIT_MAX_COORDINATES`] coordinates), linearized numerically: the
/// `pending` equations `E(eta, z) = value(eta)` are affine in the remaining
/// state variables `z` (`E = A(eta) z + c(eta)`), so at `eta = 0`
/// `z0 = A^-1 (value(0) - c(0))` and, by the implicit function theorem,
/// `dz/deta = A^-1 (dvalue/deta - dE/deta)`; the Jacobian of
/// `eta' = L_f eta (eta, z(eta))` is then `d/deta + d/dz dz/deta`. Forward
/// mode over the unexpanded expressions (no symbolic solve): exact up to
/// rounding. The equations are reported by their parts; `rhs` and the
/// velocities of `state_on_manifold` are left in terms of `z`.
#[allow(clippy::too_many_arguments)]
fn numeric_zero_dynamics(
    model: &Model,
    nf: &NormalForm,
    etas: Vec<Symbol>,
    map: HashMap<Symbol, Expr>,
    free: Vec<Symbol>,
    pending: Vec<(Expr, Expr)>,
    mut point: HashMap<Symbol, f64>,
    velocities: Vec<Symbol>,
    n: usize,
) -> Result<ZeroDynamics, ZeroDynamicsError> {
    let state = &nf.state;
    let m = etas.len();
    let k = free.len();
    let mut vars = etas.clone();
    vars.extend(free.iter().copied());
    let rows: Vec<Expr> = crate::sym::substitute_symbols_all(
        &pending.iter().map(|(e, _)| *e).collect::<Vec<_>>(),
        &map,
    );
    let values: Vec<Expr> = pending.iter().map(|(_, v)| *v).collect();
    let not_finite = |what: &str| ZeroDynamicsError::NotFinite {
        entry: what.to_string(),
    };
    let at = |point: &HashMap<Symbol, f64>, z: &[f64]| {
        let mut p = point.clone();
        for (s, v) in free.iter().zip(z) {
            p.insert(*s, *v);
        }
        eval_jacobian(&rows, &vars, &p)
    };
    // A and c(0) at z = 0
    let (e0, j0) = at(&point, &vec![0.0; k]);
    let a = DMatrix::from_fn(k, k, |i, j| j0[i][m + j]);
    if a.iter().chain(&e0).any(|v| !v.is_finite()) {
        return Err(not_finite("the equations of the state on xi = 0"));
    }
    let lu = a.clone().lu();
    let (val0, dval) = eval_jacobian(&values, &etas, &point);
    let b = nalgebra::DVector::from_fn(k, |i, _| val0[i] - e0[i]);
    let z0 = lu
        .solve(&b)
        .ok_or_else(|| ZeroDynamicsError::CannotSolveEta {
            reason: "the remaining eta components are dependent on xi = 0 (at eta = 0)".into(),
        })?;
    // affine in z: the same A at another point (a screening of the
    // structure: the pending rows are momenta and velocity-level outputs)
    let probe: Vec<f64> = (0..k).map(|i| 0.37 + 0.11 * i as f64).collect();
    let (_, jp) = at(&point, &probe);
    for i in 0..k {
        for j in 0..k {
            let (x, y) = (jp[i][m + j], j0[i][m + j]);
            if (x - y).abs() > 1e-9 * (1.0 + x.abs().max(y.abs())) {
                return Err(ZeroDynamicsError::CannotSolveEta {
                    reason: format!(
                        "`{}` is not linear in the remaining state variables",
                        pending[i].0
                    ),
                });
            }
        }
    }
    let z0: Vec<f64> = z0.iter().copied().collect();
    let (_, jz) = at(&point, &z0);
    let rhs_e = nalgebra::DMatrix::from_fn(k, m, |i, j| dval[i][j] - jz[i][j]);
    let dz = lu.solve(&rhs_e).ok_or_else(|| not_finite("dz/deta"))?;
    for (s, v) in free.iter().zip(&z0) {
        point.insert(*s, *v);
    }
    let rhs: Vec<Expr> = crate::sym::substitute_symbols_all(&nf.eta_dot, &map);
    let (r0, jr) = eval_jacobian(&rhs, &vars, &point);
    let mut jac = vec![vec![0.0; m]; m];
    let mut residual: f64 = 0.0;
    for i in 0..m {
        residual = residual.max(r0[i].abs());
        for j in 0..m {
            let v = jr[i][j] + (0..k).map(|l| jr[i][m + l] * dz[(l, j)]).sum::<f64>();
            if !v.is_finite() {
                return Err(ZeroDynamicsError::NotFinite {
                    entry: format!("d({}')/d{}", etas[i].name(), etas[j].name()),
                });
            }
            jac[i][j] = v;
        }
    }
    let (eigenvalues, tolerance, class) = classify(&jac)?;
    let state_on_manifold: Vec<(Symbol, Expr)> = state
        .iter()
        .map(|s| (*s, map.get(s).copied().unwrap_or_else(|| Expr::symbol(*s))))
        .collect();
    let mut text: Vec<String> = etas
        .iter()
        .zip(&nf.eta_dot_text)
        .map(|(s, t)| format!("{}' = {t}", s.name()))
        .collect();
    let coords: Vec<String> = state_on_manifold
        .iter()
        .filter(|(s, _)| !velocities.contains(s))
        .map(|(s, e)| format!("{} = {e}", s.name()))
        .collect();
    text.push(format!(
        "at {} and the velocities solving {} linear equations ({} components of xi and eta; not expanded for {n} coordinates)",
        coords.join(", "),
        pending.len(),
        pending.len()
    ));
    let _ = model;
    Ok(ZeroDynamics {
        eta_symbols: etas,
        rhs,
        state_on_manifold,
        jacobian: jac,
        eigenvalues,
        equilibrium_residual: residual,
        tolerance,
        class,
        explicit: false,
        text,
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
