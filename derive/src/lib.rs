//! plantc-derive: the model language, the symbolic core, Euler-Lagrange mechanics
//! and linear analysis/design.
//!
//! Layers (each depends only on the ones above it):
//! - [`sym`]: hash-consed expression DAG, exact rationals, differentiation,
//!   substitution, canonical form, printing, compiled numeric tapes.
//! - [`lang`]: the `.plant` model language: lexer, parser, AST with spans,
//!   name resolution, dimensional analysis, diagnostics, lossless editing.
//! - [`model`]: lowering of a checked AST into a symbolic [`model::Model`].
//! - [`mechanics`]: Euler-Lagrange equations, mass matrix, control-affine form.
//! - [`linear`]: numeric linear analysis and design (controllability, poles,
//!   pole placement, LQR, sliding surfaces).
//! - [`robustness`]: controllers against plants with mismatched parameters.

pub mod analysis;
pub mod control;
pub mod lang;
pub mod linear;
pub mod mechanics;
pub mod model;
pub mod robustness;
pub mod simulate;
pub mod sym;
