//! Analysis of derived equations: linearization about an equilibrium (and, in
//! later layers, Lie derivatives, normal forms and zero dynamics).

mod linearize;

pub use linearize::{linearize, Linearization, LinearizeError, OperatingPoint};
