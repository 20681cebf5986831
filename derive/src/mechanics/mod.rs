//! Euler-Lagrange mechanics: from `T`, `V` and the generalised forces to
//! `M(q) q'' + bias(q, q') = Q0(q, q') + B(q, q') u` and the control-affine form
//! `x' = f(x) + g(x) u` with `x = (q, q')`.

mod angle_coordinates;
pub mod dry_friction;
mod euler_lagrange;
mod matrix;
mod numeric;
mod present;
mod quadratic;
mod screen;
mod separable;
pub mod small_lu;
mod solve;
pub mod stick_slip;

pub use angle_coordinates::{angle_coordinates, AngleCoordinates};
pub use dry_friction::{decompose as decompose_dry_friction, DryFriction};
pub use euler_lagrange::{
    control_affine, control_affine_within, derive_equations, derive_equations_from, ControlAffine,
    Equations, MechanicsError,
};
pub use matrix::{adjugate, determinant};
pub use numeric::{
    flat_outputs, has_sign, smooth_signs, smooth_signs_with, NumericDynamics, NumericError,
    Workspace, FALLBACK_SIGN_WIDTH,
};
pub use present::{
    det_name, present_equations, Expand, PresentedAngles, PresentedEquations, PresentedSeparable,
    EXPAND_MAX_COORDINATES, EXPAND_MAX_TERMS, PRESENT_MAX_TERMS,
};
pub use screen::{mass_matrix_conditioning, screening_points};
pub use separable::{separable_mass, AngleFactor, SeparableMass};
pub use solve::{ldl_solve, lu_solve_at, SolveError};
