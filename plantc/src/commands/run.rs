//! `plantc run`: the real-time loop on the simulator or a Q2-USB board.

use std::io::Write;

use plantc_derive::analysis::{linearize, OperatingPoint};
use plantc_derive::control::{resolve, Derivation, ResolvedController};
use plantc_derive::linear::{observer_plant, ObserverPlantError};
use plantc_derive::mechanics::NumericDynamics;
use plantc_derive::model::{Model, ParameterValues};
use plantc_runtime::{
    run_with_notes, stop_on_signals, Backend, FaultKind, LogWriter, ModelController, ModelPlant,
    ObserverSpec, Q2Usb, Q2UsbConfig, RunConfig, SimBackend, SimConfig, SupervisorState,
    SwingUpLimits,
};

use super::sim::{parse_gains, refuse_overwrite};
use crate::cli::{BackendKind, LogPrecision, RunArgs, VelocityKind};
use crate::common::{load, parse_assignments, parse_quantity, values, CliError};

pub fn run(args: &RunArgs, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), CliError> {
    if args.compiled.is_some() {
        return super::run_compiled::run(args, out, err);
    }
    let loaded = load(&args.model, err)?;
    let model = &loaded.model;
    let vals = values(&loaded, &args.params)?;
    let fail = |e: &dyn std::fmt::Display| CliError::failure(format!("error: {e}"));
    let derivation = Derivation::new(model).map_err(|e| fail(&e))?;
    let resolved = resolve(model, &derivation, &args.controller, &vals).map_err(|e| fail(&e))?;
    let mut controller = ModelController::new(model, &resolved, &vals).map_err(|e| fail(&e))?;
    for (name, value) in parse_gains(&args.gain)? {
        controller
            .set_gain(&name, value)
            .map_err(|e| CliError::input(format!("error: {e}")))?;
    }
    let dynamics = NumericDynamics::new(model, &derivation.equations).map_err(|e| fail(&e))?;
    let plant = ModelPlant::new(model, dynamics, &vals);
    let mut config = RunConfig::for_plant(&plant);
    config.rate_hz = args.rate;
    config.duration_s = Some(args.duration);
    let swing_up = matches!(&resolved, ResolvedController::Hybrid { modes, .. }
        if modes.iter().any(|m| m.swing_up));
    let (velocity, bandwidth) = velocity_choice(args, swing_up)?;
    config.velocity_bandwidth = bandwidth;
    if swing_up {
        config.supervisor.swing_up = Some(SwingUpLimits {
            hanging_window_rad: positive_angle(&args.hanging_window, "hanging-window")?,
            max_arm_speed: positive_speed(args.max_arm_speed, "max-arm-speed")?,
            max_pendulum_speed: positive_speed(args.max_pendulum_speed, "max-pendulum-speed")?,
        });
        let _ = writeln!(
            err,
            "note: `{}` has a swing-up mode: swing-up allowed from hanging (within {}), arm limit {}, speeds up to {} rad/s (arm) and {} rad/s (pendulum)",
            args.controller, args.hanging_window, args.arm_limit, args.max_arm_speed, args.max_pendulum_speed
        );
    }
    if velocity == VelocityKind::Observer {
        let mut spec = observer_spec(model, &derivation, &vals)?;
        if !(args.observer_accel.is_finite() && args.observer_accel > 0.0) {
            return Err(CliError::input(format!(
                "error: --observer-accel {}: expected a positive acceleration in rad/s^2",
                args.observer_accel
            )));
        }
        spec.accel_std = args.observer_accel;
        config.observer = Some(spec);
    }
    config.supervisor.arm_limit_rad = positive_angle(&args.arm_limit, "arm-limit")?;
    config.supervisor.fall_angle_rad = positive_angle(&args.fall_angle, "fall-angle")?;
    config.supervisor.catch_window_rad = positive_angle(&args.catch_window, "catch-window")?;
    catch_window_inside_fall_angle(
        args,
        config.supervisor.catch_window_rad,
        config.supervisor.fall_angle_rad,
    )?;
    let mut backend: Box<dyn Backend> = match args.backend {
        BackendKind::Sim => {
            let x0 = match &args.x0 {
                Some(text) => parse_assignments(text, &model.state_names(), "state")?,
                None => vec![0.0; model.state_names().len()],
            };
            let sim = SimConfig {
                real_time: args.realtime,
                noise: sim_noise(args)?,
                ..SimConfig::default()
            };
            Box::new(SimBackend::new(Box::new(plant), x0, sim).map_err(|e| fail(&e))?)
        }
        BackendKind::Q2usb => {
            if args.x0.is_some() {
                let _ = writeln!(
                    err,
                    "note: --x0 is ignored on hardware (the state comes from the encoders)"
                );
            }
            let cfg = Q2UsbConfig {
                library_path: args.hil_lib.clone(),
                card_identifier: args.board.clone(),
                allow_no_watchdog: args.allow_no_watchdog,
                ..Q2UsbConfig::default()
            };
            let board = Q2Usb::open(cfg).map_err(|e| fail(&e))?;
            for note in board.notes() {
                let _ = writeln!(err, "note: {note}");
            }
            Box::new(board)
        }
    };
    let mut log = match &args.log {
        Some(path) => {
            refuse_overwrite(path, args.force, "log")?;
            // O_EXCL without --force: a run started meanwhile with the same
            // log is refused, not interleaved (the check above is only the
            // early, friendly refusal)
            let mut log = LogWriter::open(path, args.force).map_err(|e| match e {
                plantc_runtime::LogError::Io {
                    kind: std::io::ErrorKind::AlreadyExists,
                    ..
                } => CliError::input(format!(
                    "error: log `{}` already exists; pass --force to overwrite it",
                    path.display()
                )),
                e => fail(&e),
            })?;
            log.set_full_precision(args.log_precision == LogPrecision::Full);
            Some(log)
        }
        None => None,
    };
    let _ = writeln!(
        out,
        "running `{}` on {:?} at {} Hz for {} s",
        args.controller, args.backend, args.rate, args.duration
    );
    if let Err(e) = stop_on_signals(config.stop.clone()) {
        let _ = writeln!(
            err,
            "note: signal handlers not installed ({e}); Ctrl-C or kill will end the process without the 0 V stop"
        );
    }
    let err_cell = std::cell::RefCell::new(&mut *err);
    let report = run_with_notes(
        &config,
        backend.as_mut(),
        &mut controller,
        None,
        log.as_mut(),
        &mut |t| {
            let _ = writeln!(err_cell.borrow_mut(), "supervisor: {t}");
        },
        &mut |n| {
            let _ = writeln!(err_cell.borrow_mut(), "supervisor: {n}");
        },
    );
    // the safe stop is complete once the board is closed and the log flushed
    drop(backend);
    drop(log);
    plantc_runtime::stop_completed();
    let report = report.map_err(|e| fail(&e))?;
    let _ = writeln!(out, "{report}");
    if !report.stop_errors.is_empty() {
        // The safe stop was not clean (a failed 0 V write or close): a
        // failure whatever the final state, each failure said on stderr.
        for e in &report.stop_errors {
            let _ = writeln!(err, "error: safe stop: {e}");
        }
        return Err(CliError::failure(format!(
            "run ended in {} and the safe stop failed ({} error{}; see above)",
            report.final_state,
            report.stop_errors.len(),
            if report.stop_errors.len() == 1 {
                ""
            } else {
                "s"
            }
        )));
    }
    if report.final_state == SupervisorState::Fault(FaultKind::Stopped) {
        // Exit code of a process ended by the signal, by convention
        // (128 + signal number: 130 SIGINT, 143 SIGTERM, 129 SIGHUP, 131 SIGQUIT).
        let (name, code) = plantc_runtime::stop_signal()
            .map_or(("a stop request", 130), |s| (s.name, s.exit_code));
        return Err(CliError {
            message: format!("stopped by {name} (0 V written, board closed, log flushed)"),
            code,
        });
    }
    if !report.engaged() && !matches!(report.final_state, SupervisorState::Fault(_)) {
        let why = match &report.not_engaged {
            Some(n) => n.to_string(),
            None => format!(
                "the run ({} s) ended before the pendulum entered the catch window ({})",
                args.duration, args.catch_window
            ),
        };
        return Err(CliError::failure(format!(
            "error: the controller never engaged: {why}"
        )));
    }
    if report.fault_detail.is_some() || matches!(report.final_state, SupervisorState::Fault(_)) {
        // A fault that ends the run (other than the planned end) is a failure.
        if !report.final_state.to_string().contains("duration") {
            return Err(CliError::failure(format!(
                "run ended in {}",
                report.final_state
            )));
        }
    }
    Ok(())
}

/// `--WHAT TEXT`: a positive angle (`180deg`, `0.5rad` or `0.5`), in rad.
pub(crate) fn positive_angle(text: &str, what: &str) -> Result<f64, CliError> {
    parse_quantity(text)
        .filter(|x| x.is_finite() && *x > 0.0)
        .ok_or_else(|| {
            CliError::input(format!(
                "error: --{what} `{text}`: expected a positive angle, e.g. 180deg"
            ))
        })
}

/// `--WHAT X`: a positive speed in rad/s.
pub(crate) fn positive_speed(x: f64, what: &str) -> Result<f64, CliError> {
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(CliError::input(format!(
            "error: --{what} {x}: expected a positive speed in rad/s"
        )))
    }
}

/// Refuses a catch window (rad) that is not inside the fall angle (rad).
pub(crate) fn catch_window_inside_fall_angle(
    args: &RunArgs,
    catch_window: f64,
    fall_angle: f64,
) -> Result<(), CliError> {
    if catch_window >= fall_angle {
        return Err(CliError::input(format!(
            "error: --catch-window {} must be smaller than --fall-angle {}",
            args.catch_window, args.fall_angle
        )));
    }
    Ok(())
}

/// `--velocity` and `--velocity-bandwidth` (rad/s) for a controller with or
/// without a swing-up mode: a swing-up mode needs the filtered derivative
/// (the observer's model is linearized about upright), by default faster.
pub(crate) fn velocity_choice(
    args: &RunArgs,
    swing_up: bool,
) -> Result<(VelocityKind, f64), CliError> {
    let velocity = match (args.velocity, swing_up) {
        (Some(VelocityKind::Observer), true) => {
            return Err(CliError::input(format!(
                "error: `{}` has a swing-up mode; the velocity observer's model is linearized \
                 about upright and does not hold while the pendulum swings: use --velocity derivative",
                args.controller
            )))
        }
        (Some(v), _) => v,
        (None, true) => VelocityKind::Derivative,
        (None, false) => VelocityKind::Observer,
    };
    let bandwidth = args
        .velocity_bandwidth
        .unwrap_or(if swing_up { 200.0 } else { 50.0 });
    if !(bandwidth.is_finite() && bandwidth > 0.0) {
        return Err(CliError::input(format!(
            "error: --velocity-bandwidth {bandwidth}: expected a positive rate in rad/s"
        )));
    }
    Ok((velocity, bandwidth))
}

/// `--sim-noise`, parsed as the rig binaries parse it.
pub(crate) fn sim_noise(args: &RunArgs) -> Result<Option<plantc_runtime::SimNoise>, CliError> {
    args.sim_noise
        .as_deref()
        .map(plantc_runtime::rig::parse_sim_noise)
        .transpose()
        .map_err(|e| CliError::input(format!("error: --sim-noise: {e}")))
}

/// The observer's linear model: the model linearized about zero state and
/// input (upright), which must be an equilibrium.
pub(crate) fn observer_spec(
    model: &Model,
    derivation: &Derivation,
    vals: &ParameterValues,
) -> Result<ObserverSpec, CliError> {
    let op = OperatingPoint::zero(model);
    let lin = linearize(model, &derivation.equations, vals, &op)
        .map_err(|e| CliError::failure(format!("error: observer: {e}")))?;
    let (a, b) = observer_plant(&lin).map_err(|e| {
        CliError::failure(match e {
            ObserverPlantError::NotEquilibrium { residual } => format!(
                "error: observer: the zero state is not an equilibrium of the model \
                 (largest acceleration {residual:e}); use --velocity derivative"
            ),
            ObserverPlantError::Inputs { count } => format!(
                "error: observer: {count} inputs, exactly one (the motor voltage) supported"
            ),
        })
    })?;
    Ok(ObserverSpec::new(a, b))
}
