//! Rotary-pendulum plant and controllers generated at build time by
//! `plantc-codegen` from `models/rotary_pendulum.plant` (parameter set
//! `thesis`, controllers `feedback_linearization`, `pole_placement`, the
//! hybrid `swing_up` (with its modes `energy_pump` and `pole_placement`) and
//! `sliding_mode`).
#![cfg_attr(not(feature = "std"), no_std)]

/// The generated module (see `build.rs`).
pub mod rotary_pendulum {
    include!(concat!(env!("OUT_DIR"), "/rotary_pendulum.rs"));
}
