//! Numeric linear analysis and design.
//!
//! - [`LinearModel`]: `x' = A x + B u` with names, JSON load/save.
//! - [`poles`], [`parse_poles`]: eigenvalues in canonical order; pole lists.
//! - [`controllability`]: PBH margin on the balanced realisation (the decision),
//!   controllability matrix and SVD rank.
//! - [`place`]: single-input pole placement (`u = -K x`).
//! - [`lqr`]: continuous-time LQR via the CARE.
//! - [`sliding_surface`], [`reduced_dynamics`]: linear sliding surfaces.
//! - [`design_velocity_observer`]: steady-state Kalman velocity observer for
//!   encoder-only measurements (used by the runtime and by `plantc gen --rig`).
//! - [`AnalysisReport`], [`PlaceReport`], [`LqrReport`]: the CLI's JSON shapes.
//!
//! All functions return [`LinearError`] on bad input instead of panicking.

mod balance;
mod controllability;
mod error;
mod linear_model;
mod lqr;
mod observer;
mod place;
mod poles;
mod report;
mod sliding;

pub use balance::{balance, balancing_scales};
pub use controllability::{
    controllability, controllability_matrix, numerical_rank, pbh_margin, Controllability,
};
pub use error::LinearError;
pub use linear_model::{matrix_from_rows, matrix_to_rows, LinearModel};
pub use lqr::{care_residual, lqr, Lqr};
pub use observer::{
    design_velocity_observer, encoder_variance, observer_plant, ObserverDesign, ObserverError,
    ObserverPlantError,
};
pub use place::{char_poly, check_desired_poles, place, pole_match_error, Placement};
pub use poles::{canonicalize_poles, format_pole, parse_poles, poles, Pole};
pub use report::{analyze, to_json, AnalysisReport, LqrReport, PlaceReport};
pub use sliding::{reduced_dynamics, sliding_surface, ReducedDynamics, SlidingSurface};
