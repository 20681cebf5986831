//! plantc-runtime: runs a controller against a plant, simulated or real.
//!
//! - [`Plant`] and [`Controller`] are the interfaces generated code is adapted to.
//! - [`Backend`] abstracts the hardware: [`SimBackend`] integrates a plant in
//!   (virtual or real) time; [`Q2Usb`] drives a Quanser Q2-USB through the HIL C
//!   library loaded at run time.
//! - [`run`] executes the fixed-rate loop under the safety [`Supervisor`]
//!   (Idle -> Armed -> Engaged / SwingUp -> Fault; SwingUp only for hybrid
//!   controllers' swing-up modes), logs every sample as CSV through a
//!   [`LogWriter`] and returns a [`RunReport`]. On every exit path the last
//!   voltage written is 0 V.
//!
//! [`RotaryPendulumReference`] is the hand-written physics of the test doubles.
//!
//! Velocities come from a [`VelocityEstimator`]: the filtered derivative, the
//! steady-state Kalman observer designed at start (`model` feature, default),
//! or a generated observer. [`rig`] is the command line and run flow of the
//! rig binaries `plantc gen --rig` generates: they implement [`RigModel`]
//! over the generated code and call [`rig_main`]; with
//! `default-features = false` they depend on nothing of plantc but this
//! crate and on nothing else but libloading.
//!
//! ```
//! use plantc_runtime::*;
//!
//! let plant = RotaryPendulumReference::default();
//! let mut config = RunConfig::for_plant(&plant);
//! config.duration_s = Some(1.0);
//! let x0 = vec![0.0, 5f64.to_radians(), 0.0, 0.0];
//! let mut backend = SimBackend::new(Box::new(plant), x0, SimConfig::default())?;
//! let mut controller = StateFeedback::new(vec![-7.8914, 37.8313, -2.9850, 3.6222]);
//! let report = run(&config, &mut backend, &mut controller, None)?;
//! assert_eq!(report.final_state, SupervisorState::Engaged);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod alloc_count;
pub mod backend;
pub mod control_loop;
pub mod controller;
pub mod error;
pub mod estimator;
pub mod hil_deadline;
pub mod hil_ffi;
pub mod histogram;
pub mod integrate;
pub mod interrupt;
pub mod log;
#[cfg(feature = "model")]
pub mod model_plant;
pub mod pacer;
pub mod plant;
pub mod prng;
pub mod q2usb;
pub mod reference_pendulum;
pub mod replay;
pub mod report;
pub mod rig;
pub mod rt_os;
pub mod sim;
pub mod supervisor;
pub mod velocity_filter;
pub mod velocity_observer;

pub use alloc_count::CountingAllocator;
pub use backend::{Backend, BackendError, EncoderMap, OutputHold, Tick};
pub use control_loop::{
    run, run_with_estimator, run_with_events, run_with_notes, RunConfig, MAX_RATE_HZ,
};
pub use controller::{Controller, Mode, StateFeedback};
pub use error::RuntimeError;
pub use estimator::{DerivativeEstimator, VelocityEstimator};
pub use interrupt::{
    forward_stop, stop_completed, stop_on_ctrl_c, stop_on_signals, stop_signal, StopSignal,
};
pub use log::{LogError, LogWriter};
#[cfg(feature = "model")]
pub use model_plant::{ModelController, ModelPlant};
pub use plant::Plant;
pub use q2usb::{EncoderChannel, Q2Usb, Q2UsbConfig};
pub use reference_pendulum::{PendulumParams, RotaryPendulumReference};
pub use replay::{replay_log, ReplayError, ReplayReport};
pub use report::{ModeSwitch, Percentiles, RunReport};
pub use rig::{rig_main, ObserverInfo, RigInfo, RigModel};
pub use sim::{SimBackend, SimConfig, SimNoise};
pub use supervisor::{
    FaultKind, NotEngaged, Supervisor, SupervisorConfig, SupervisorState, SwingUpLimits,
    Transition, NOT_ENGAGED_AFTER_S,
};
pub use velocity_observer::{ObserverSpec, VelocityObserver};
