//! Analysis of derived equations: linearization about an equilibrium, Lie
//! derivatives and relative degree (vector relative degree and decoupling
//! matrix for several inputs), normal form, zero dynamics and exact
//! stability intervals of feedback-linearizing controllers, and the sliding
//! dynamics of sliding-mode controllers.

mod decoupling;
mod lie;
mod linearize;
mod mechanical;
mod normal_form;
mod report;
mod sliding;
mod stability_interval;
mod zero_dynamics;

pub use decoupling::{decoupling, hadamard_ratio, Decoupling, OutputLie, SCREEN_ZERO};
pub use lie::{lie_chain, lie_derivative, AnalysisError, LieChain};
pub use linearize::{linearize, Linearization, LinearizeError, OperatingPoint};
pub use mechanical::{
    mechanical_chain, MechanicalParts, ANALYSIS_MAX_TERMS, EXPLICIT_MAX_COORDINATES,
};
pub use normal_form::{candidates, normal_form, normal_form_for, NormalForm, NormalFormError};
pub use report::{
    analyze_output, analyze_outputs, DecouplingReport, OutputAnalysisError, OutputReport,
};
pub use sliding::{sliding_analysis, SlidingAnalysis, SlidingError};
pub use stability_interval::{
    stability_interval, KPoly, StabilityError, StabilityInterval, METHOD as STABILITY_METHOD,
};
pub use zero_dynamics::{
    classify, zero_dynamics, ZeroDynamics, ZeroDynamicsClass, ZeroDynamicsError,
};
