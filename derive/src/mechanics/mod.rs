//! Euler-Lagrange mechanics: from `T`, `V` and the generalised forces to
//! `M(q) q'' + bias(q, q') = Q0(q, q') + B(q, q') u` and the control-affine form
//! `x' = f(x) + g(x) u` with `x = (q, q')`.

mod angle_coordinates;
mod euler_lagrange;
mod matrix;
mod numeric;
mod present;
mod quadratic;
mod screen;
mod separable;
pub mod small_lu;
mod solve;

pub use angle_coordinates::{angle_coordinates, AngleCoordinates};
pub use euler_lagrange::{
    control_affine, control_affine_within, derive_equations, derive_equations_from, ControlAffine,
    Equations, MechanicsError,
};
pub use matrix::{adjugate, determinant};
pub use numeric::{flat_outputs, has_sign, smooth_signs, NumericDynamics, NumericError, Workspace};
pub use present::{
    det_name, present_equations, Expand, PresentedAngles, PresentedEquations, PresentedSeparable,
    EXPAND_MAX_COORDINATES, EXPAND_MAX_TERMS, PRESENT_MAX_TERMS,
};
pub use screen::{mass_matrix_conditioning, screening_points};
pub use separable::{separable_mass, AngleFactor, SeparableMass};
pub use solve::{ldl_solve, lu_solve_at, SolveError};
