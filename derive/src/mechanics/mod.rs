//! Euler-Lagrange mechanics: from `T`, `V` and the generalised forces to
//! `M(q) q'' + bias(q, q') = Q0(q, q') + B(q, q') u` and the control-affine form
//! `x' = f(x) + g(x) u` with `x = (q, q')`.

mod euler_lagrange;
mod matrix;
mod numeric;
pub mod small_lu;

pub use euler_lagrange::{
    control_affine, derive_equations, ControlAffine, Equations, MechanicsError,
};
pub use matrix::{adjugate, determinant};
pub use numeric::{flat_outputs, has_sign, smooth_signs, NumericDynamics, NumericError, Workspace};
