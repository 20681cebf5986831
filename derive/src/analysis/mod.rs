//! Analysis of derived equations: linearization about an equilibrium (and, in
//! later layers, Lie derivatives, normal forms and zero dynamics).

mod lie;
mod linearize;

pub use lie::{lie_chain, lie_derivative, AnalysisError, LieChain};
pub use linearize::{linearize, Linearization, LinearizeError, OperatingPoint};
