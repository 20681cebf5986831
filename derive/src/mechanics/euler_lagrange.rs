//! The Euler-Lagrange equations `d/dt(dL/dq') - dL/dq = Q` of a [`Model`].

use std::fmt;

use std::collections::HashMap;
use std::sync::Arc;

use super::angle_coordinates::{angle_coordinates, AngleCoordinates};
use super::matrix::{adjugate, determinant};
use crate::model::Model;
use crate::sym::{diff, CoordinateSymbols, Expr, Symbol};

/// Why the equations of motion could not be formed.
#[derive(Clone, Debug, PartialEq)]
pub enum MechanicsError {
    /// A generalised force is not affine in an input (e.g. `Vm^2`).
    NotControlAffine {
        /// Coordinate whose force is at fault.
        coordinate: String,
        /// The input that enters nonlinearly.
        input: String,
    },
    /// The kinetic energy depends on an input or an acceleration.
    KineticDependsOn {
        /// The offending symbol.
        symbol: String,
    },
    /// The mass matrix is identically singular (e.g. a coordinate without inertia).
    SingularMassMatrix,
    /// An exact computation hit its term budget (e.g. the expanded `M^-1` of
    /// a large system).
    Budget {
        /// What was being computed.
        what: String,
        /// Why it stopped.
        reason: String,
    },
}

impl fmt::Display for MechanicsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MechanicsError::NotControlAffine { coordinate, input } => write!(
                f,
                "the force on `{coordinate}` is not affine in the input `{input}`; \
                 plantc needs M(q) q'' + bias = Q0 + B(q, q') u"
            ),
            MechanicsError::KineticDependsOn { symbol } => {
                write!(f, "the kinetic energy must not depend on `{symbol}`")
            }
            MechanicsError::SingularMassMatrix => write!(
                f,
                "the mass matrix is singular for every state: does every coordinate carry inertia in T?"
            ),
            MechanicsError::Budget { what, reason } => {
                write!(f, "{what} was not computed: {reason}")
            }
        }
    }
}

impl std::error::Error for MechanicsError {}

/// `M(q) q'' + bias(q, q') = Q0(q, q') + B(q, q') u`.
#[derive(Clone, Debug)]
pub struct Equations {
    /// Coordinate symbols in order.
    pub coords: Vec<CoordinateSymbols>,
    /// Input symbols in order.
    pub inputs: Vec<Symbol>,
    /// Mass matrix `M_ij = d^2 T / dq_i' dq_j'` (symmetric).
    pub mass_matrix: Vec<Vec<Expr>>,
    /// Coriolis, centrifugal and gravity terms:
    /// `bias_i = sum_j d(dL/dq_i')/dq_j q_j' - dL/dq_i`.
    pub bias: Vec<Expr>,
    /// Generalised forces with the inputs set to zero, `Q0_i`.
    pub forces: Vec<Expr>,
    /// Input matrix `B_ij = dQ_i / du_j`.
    pub input_matrix: Vec<Vec<Expr>>,
    /// The equations in the angles `theta = S q` of the sines and cosines
    /// they were derived in (models of [`ANGLE_FRAME_MIN_COORDINATES`] or
    /// more coordinates whose trigonometric arguments are not the
    /// coordinates themselves): `M = S^T M_theta S`, `bias = S^T bias_theta`.
    pub angles: Option<Arc<AngleCoordinates>>,
}

impl Equations {
    /// The same equations with every entry in simplified canonical form.
    pub fn simplified(&self) -> Equations {
        let t = |v: &[Expr]| v.iter().map(|e| tidy(*e)).collect::<Vec<_>>();
        Equations {
            coords: self.coords.clone(),
            inputs: self.inputs.clone(),
            mass_matrix: self.mass_matrix.iter().map(|r| t(r)).collect(),
            bias: t(&self.bias),
            forces: t(&self.forces),
            input_matrix: self.input_matrix.iter().map(|r| t(r)).collect(),
            angles: self.angles.clone(),
        }
    }

    /// Right-hand side `r = Q0 - bias + B u` (so that `M q'' = r`).
    pub fn rhs(&self) -> Vec<Expr> {
        (0..self.coords.len())
            .map(|i| {
                let bu: Expr = self
                    .inputs
                    .iter()
                    .enumerate()
                    .map(|(j, u)| self.input_matrix[i][j] * Expr::symbol(*u))
                    .sum();
                self.forces[i] - self.bias[i] + bu
            })
            .collect()
    }

    /// The residual `M q'' + bias - Q0 - B u` of each equation (zero on motion).
    pub fn residuals(&self) -> Vec<Expr> {
        let rhs = self.rhs();
        (0..self.coords.len())
            .map(|i| {
                let mq: Expr = self
                    .coords
                    .iter()
                    .enumerate()
                    .map(|(j, c)| self.mass_matrix[i][j] * Expr::symbol(c.qdd))
                    .sum();
                mq - rhs[i]
            })
            .collect()
    }
}

/// Fewest coordinates for which the equations are derived in the angle
/// coordinates `theta = S q` when they differ from the model's (see
/// [`super::angle_coordinates`]). Deriving in `q` directly differentiates
/// every energy term once per coordinate pair: the n-link chain's `M` and
/// `bias` in relative angles have `O(n^3)` terms each row built from
/// `O(n^2)`-term derivatives (33 s at n = 20 with their printing), against
/// `O(n^3)` terms in all in `theta` (0.1 s at n = 20, 3 s at n = 50). For up
/// to three coordinates the direct derivation costs nothing, and its entries
/// are the ones the closed forms (`derive`'s expanded `f`, `g`, the
/// explicit analysis, generated code) have always been built from.
pub const ANGLE_FRAME_MIN_COORDINATES: usize = 4;

/// Derive the Euler-Lagrange equations of `model`. Parameters and derived
/// quantities stay symbolic. The entries are exact but not simplified (fast);
/// call [`Equations::simplified`] before presenting them.
pub fn derive_equations(model: &Model) -> Result<Equations, MechanicsError> {
    let coords = model.coordinate_symbols();
    let inputs = model.input_symbols();
    for u in &inputs {
        if model.kinetic.contains(*u) {
            return Err(MechanicsError::KineticDependsOn {
                symbol: u.name().to_string(),
            });
        }
    }
    for c in &coords {
        if model.kinetic.contains(c.qdd) || model.potential.contains(c.qdd) {
            return Err(MechanicsError::KineticDependsOn {
                symbol: c.qdd.name().to_string(),
            });
        }
    }
    if coords.len() >= ANGLE_FRAME_MIN_COORDINATES {
        if let Some(ac) = angle_coordinates(model)? {
            let (forces, input_matrix) = applied_forces(&coords, &inputs, &model.forces)?;
            return Ok(from_angle_frame(&coords, &inputs, forces, input_matrix, ac));
        }
    }
    derive_equations_from(
        &coords,
        &inputs,
        model.kinetic,
        model.potential,
        &model.forces,
    )
}

/// The equations in `q` from those in `theta = S q`: `M = S^T M_theta S`
/// (through `M_theta S`, so each entry is a sum over one index),
/// `bias = S^T bias_theta`, with `theta`, `theta'` replaced by `S q`, `S q'`.
fn from_angle_frame(
    coords: &[CoordinateSymbols],
    inputs: &[Symbol],
    forces: Vec<Expr>,
    input_matrix: Vec<Vec<Expr>>,
    ac: AngleCoordinates,
) -> Equations {
    let n = coords.len();
    let mut map = HashMap::new();
    for (k, t) in ac.coords.iter().enumerate() {
        let pos = |sym: &dyn Fn(&CoordinateSymbols) -> Symbol| {
            Expr::add_all(
                (0..n)
                    .filter(|j| !ac.s[k][*j].is_zero())
                    .map(|j| Expr::rational(ac.s[k][j]) * Expr::symbol(sym(&coords[j]))),
            )
        };
        map.insert(t.q, pos(&|c| c.q));
        map.insert(t.qd, pos(&|c| c.qd));
    }
    let mut flat: Vec<Expr> = Vec::with_capacity(n * n + n);
    for row in &ac.equations.mass_matrix {
        flat.extend(row.iter().copied());
    }
    flat.extend(ac.equations.bias.iter().copied());
    let flat = crate::sym::substitute_symbols_all(&flat, &map);
    // named, so that the sums below stay sums of names (see `Node::Named`)
    let m_theta = |a: usize, b: usize| {
        let (a, b) = (a.max(b), a.min(b));
        Expr::named(&format!("M_theta[{a}][{b}]"), flat[a * n + b])
    };
    let times = |c: crate::sym::Rational, e: Expr| {
        if c.is_one() {
            e
        } else {
            Expr::rational(c) * e
        }
    };
    // (M_theta S)[a][j]
    let ms: Vec<Vec<Expr>> = (0..n)
        .map(|a| {
            (0..n)
                .map(|j| {
                    Expr::named(
                        &format!("(M_theta S)[{a}][{j}]"),
                        Expr::add_all(
                            (0..n)
                                .filter(|b| !ac.s[*b][j].is_zero())
                                .map(|b| times(ac.s[b][j], m_theta(a, b))),
                        ),
                    )
                })
                .collect()
        })
        .collect();
    let mut mass_matrix = vec![vec![Expr::zero(); n]; n];
    #[allow(clippy::needless_range_loop)] // the symmetric entry is written too
    for i in 0..n {
        for j in 0..=i {
            let e = Expr::add_all(
                (0..n)
                    .filter(|a| !ac.s[*a][i].is_zero())
                    .map(|a| times(ac.s[a][i], ms[a][j])),
            );
            mass_matrix[i][j] = e;
            mass_matrix[j][i] = e;
        }
    }
    let bias = (0..n)
        .map(|i| {
            Expr::add_all((0..n).filter(|a| !ac.s[*a][i].is_zero()).map(|a| {
                let b = Expr::named(&format!("bias_theta[{a}]"), flat[n * n + a]);
                times(ac.s[a][i], b)
            }))
        })
        .collect();
    Equations {
        coords: coords.to_vec(),
        inputs: inputs.to_vec(),
        mass_matrix,
        bias,
        forces,
        input_matrix,
        angles: Some(Arc::new(ac)),
    }
}

/// `Q0` (the forces with the inputs set to zero) and `B = dQ/du`, checking
/// that the forces are affine in the inputs.
#[allow(clippy::type_complexity)]
fn applied_forces(
    coords: &[CoordinateSymbols],
    inputs: &[Symbol],
    model_forces: &[Expr],
) -> Result<(Vec<Expr>, Vec<Vec<Expr>>), MechanicsError> {
    let n = coords.len();
    let zero_inputs: HashMap<Symbol, Expr> = inputs.iter().map(|u| (*u, Expr::zero())).collect();
    let mut forces = Vec::with_capacity(n);
    let mut input_matrix = vec![vec![Expr::zero(); inputs.len()]; n];
    for (i, q) in model_forces.iter().enumerate() {
        for (j, u) in inputs.iter().enumerate() {
            let b = diff(*q, *u);
            for v in inputs {
                let second = diff(b, *v);
                if !second.is_zero() && !crate::sym::is_zero(second) {
                    return Err(MechanicsError::NotControlAffine {
                        coordinate: coords[i].q.name().to_string(),
                        input: u.name().to_string(),
                    });
                }
            }
            input_matrix[i][j] = b;
        }
        forces.push(crate::sym::substitute_symbols(*q, &zero_inputs));
    }
    Ok((forces, input_matrix))
}

/// [`derive_equations`] for given coordinates, inputs, energies and
/// generalised forces (one per coordinate).
pub fn derive_equations_from(
    coords: &[CoordinateSymbols],
    inputs: &[Symbol],
    kinetic: Expr,
    potential: Expr,
    model_forces: &[Expr],
) -> Result<Equations, MechanicsError> {
    let lagrangian = kinetic - potential;
    let n = coords.len();
    let mut mass_matrix = vec![vec![Expr::zero(); n]; n];
    let mut bias = vec![Expr::zero(); n];
    for i in 0..n {
        let p = diff(lagrangian, coords[i].qd);
        let mut terms = Vec::with_capacity(n + 1);
        for j in 0..n {
            mass_matrix[i][j] = diff(p, coords[j].qd);
            terms.push(diff(p, coords[j].q) * Expr::symbol(coords[j].qd));
        }
        terms.push(-diff(lagrangian, coords[i].q));
        bias[i] = Expr::add_all(terms);
    }
    let (forces, input_matrix) = applied_forces(coords, inputs, model_forces)?;
    Ok(Equations {
        coords: coords.to_vec(),
        inputs: inputs.to_vec(),
        mass_matrix,
        bias,
        forces,
        input_matrix,
        angles: None,
    })
}

/// Present an expression in simplified canonical form.
fn tidy(e: Expr) -> Expr {
    crate::sym::simplify(e)
}

/// `x' = f(x) + g(x) u` with `x = (q, q')`, `M^-1 = adj(M) / det(M)`.
#[derive(Clone, Debug)]
pub struct ControlAffine {
    /// State symbols `q, q'`.
    pub state: Vec<Symbol>,
    /// Input symbols.
    pub inputs: Vec<Symbol>,
    /// Drift `f(x)` (2n entries).
    pub f: Vec<Expr>,
    /// Input vector fields, `g[i][j]` = component `i` of the field of input `j`.
    pub g: Vec<Vec<Expr>>,
    /// `det M(q)`.
    pub det_mass: Expr,
}

/// Form the control-affine system. Uses the adjugate over the determinant and
/// the canonical form, so `f` and `g` are exact rational functions; the size
/// grows quickly with the number of coordinates (see
/// [`control_affine_within`] for a budget).
pub fn control_affine(eqs: &Equations) -> Result<ControlAffine, MechanicsError> {
    control_affine_within(eqs, crate::sym::poly::MAX_TERMS)
}

/// [`control_affine`] with a term budget: an intermediate polynomial with more
/// than `max_terms` terms stops it with [`MechanicsError::Budget`].
pub fn control_affine_within(
    eqs: &Equations,
    max_terms: usize,
) -> Result<ControlAffine, MechanicsError> {
    let tidy = |e: Expr, what: &str| {
        crate::sym::try_simplify_within(e, max_terms).map_err(|x| MechanicsError::Budget {
            what: what.to_string(),
            reason: format!("{x} (budget {max_terms} terms)"),
        })
    };
    let n = eqs.coords.len();
    let det = tidy(determinant(&eqs.mass_matrix), "det M")?;
    if det.is_zero() {
        return Err(MechanicsError::SingularMassMatrix);
    }
    let adj = adjugate(&eqs.mass_matrix);
    let drift: Vec<Expr> = (0..n).map(|i| eqs.forces[i] - eqs.bias[i]).collect();
    let mut state: Vec<Symbol> = eqs.coords.iter().map(|c| c.q).collect();
    state.extend(eqs.coords.iter().map(|c| c.qd));
    let mut f: Vec<Expr> = eqs.coords.iter().map(|c| Expr::symbol(c.qd)).collect();
    let mut g = vec![vec![Expr::zero(); eqs.inputs.len()]; 2 * n];
    for i in 0..n {
        let num: Expr = (0..n).map(|k| adj[i][k] * drift[k]).sum();
        f.push(tidy(num / det, "the control-affine f")?);
        for (j, gij) in g[n + i].iter_mut().enumerate() {
            let num: Expr = (0..n).map(|k| adj[i][k] * eqs.input_matrix[k][j]).sum();
            *gij = tidy(num / det, "the control-affine g")?;
        }
    }
    Ok(ControlAffine {
        state,
        inputs: eqs.inputs.clone(),
        f,
        g,
        det_mass: det,
    })
}
