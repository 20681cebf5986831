//! `plantc run --compiled DIR`: the same run with the generated code.
//!
//! Design: plantc generates (or updates, writing only changed files) the rig
//! crate of `plantc gen --rig` in DIR for this model, parameters and
//! controller, builds it with `cargo build --release` (incremental: a no-op
//! when nothing changed) and runs the rig binary with the run's options,
//! forwarding its output. The binary that runs is the one that goes to the
//! board, so this tests that artifact; no unsafe ABI is needed between
//! plantc and separately compiled Rust code (a cdylib would need a
//! hand-written C interface and could run code the binary does not).
//! `--compare` then replays the interpreted observer and controller over the
//! compiled run's full-precision log (same measured counts, same applied
//! voltages) and reports the largest voltage difference and both timings.

use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Command, Stdio};
use std::sync::atomic::AtomicBool;
use std::sync::{mpsc, Arc};

use plantc_codegen::{build_rig, write_crate, CrateOptions};
use plantc_derive::control::{resolve, Derivation};
use plantc_runtime::{
    replay_log, stop_on_ctrl_c, DerivativeEstimator, EncoderMap, ModelController, Q2UsbConfig,
    SimConfig, VelocityEstimator, VelocityObserver,
};

use super::gen::{codegen_error, rig_options};
use super::run::{observer_spec, sim_noise};
use super::sim::{parse_gains, refuse_overwrite};
use crate::cli::{BackendKind, LogPrecision, RigGenArgs, RunArgs, VelocityKind};
use crate::common::{
    load, parse_assignments, parse_overrides, parse_quantity, values, warn_ignored_effects,
    CliError,
};

pub fn run(args: &RunArgs, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), CliError> {
    let Some(dir) = &args.compiled else {
        return Err(CliError::failure(
            "internal: --compiled without a directory",
        ));
    };
    let loaded = load(&args.model, err)?;
    warn_ignored_effects(&loaded, "`plantc run --compiled`", err);
    let model = &loaded.model;
    let vals = values(&loaded, &args.params)?;

    // Check what plantc can check, and hand the binary normalised values.
    let gains = parse_gains(&args.gain)?;
    let names = model.state_names();
    let x0 = match &args.x0 {
        Some(text) => Some(parse_assignments(text, &names, "state")?),
        None => None,
    };
    let angle = |text: &str, what: &str| {
        parse_quantity(text)
            .filter(|x| x.is_finite() && *x > 0.0)
            .ok_or_else(|| {
                CliError::input(format!(
                    "error: --{what} `{text}`: expected a positive angle, e.g. 180deg"
                ))
            })
    };
    let arm_limit = angle(&args.arm_limit, "arm-limit")?;
    let fall_angle = angle(&args.fall_angle, "fall-angle")?;
    let noise = sim_noise(args)?;
    let catch_window = angle(&args.catch_window, "catch-window")?;
    if catch_window >= fall_angle {
        return Err(CliError::input(format!(
            "error: --catch-window {} must be smaller than --fall-angle {}",
            args.catch_window, args.fall_angle
        )));
    }
    // as in the interpreted `run`: a swing-up mode needs the derivative
    // (the observer's model is linearized about upright), faster
    let swing_up = matches!(model.controller(&args.controller),
        Some(plantc_derive::model::ControllerSpec::Hybrid { modes, .. }) if modes.iter().any(|m| m.swing_up));
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
    let speed = |x: f64, what: &str| {
        if x.is_finite() && x > 0.0 {
            Ok(x)
        } else {
            Err(CliError::input(format!(
                "error: --{what} {x}: expected a positive speed in rad/s"
            )))
        }
    };
    let hanging_window = angle(&args.hanging_window, "hanging-window")?;
    let max_arm_speed = speed(args.max_arm_speed, "max-arm-speed")?;
    let max_pendulum_speed = speed(args.max_pendulum_speed, "max-pendulum-speed")?;
    if let Some(path) = &args.log {
        refuse_overwrite(path, args.force, "log")?;
    }

    let opts = CrateOptions {
        model: args.model.clone(),
        controllers: vec![args.controller.clone()],
        set: args.params.set.clone(),
        overrides: parse_overrides(&args.params.params)?,
        dir: dir.clone(),
        force: false,
        rig: Some(rig_options(&RigGenArgs {
            rig: true,
            observer_rate: args.rate,
            observer_accel: args.observer_accel,
            runtime: args.runtime.clone(),
        })?),
    };
    write_crate(&opts).map_err(|e| match e {
        plantc_codegen::Error::NotGenerated { dir } => CliError::input(format!(
            "error: --compiled {}: the directory is not empty and was not generated by plantc; \
             give an empty or new directory, or one made by `plantc gen --rig`",
            dir.display()
        )),
        e => codegen_error(e),
    })?;
    let _ = writeln!(
        err,
        "rig crate: {} (building with cargo build --release)",
        dir.display()
    );
    let _ = err.flush();
    let binary = build_rig(dir, true, false).map_err(codegen_error)?;

    let mut child_args: Vec<String> = vec!["--controller".into(), args.controller.clone()];
    for (name, value) in &gains {
        child_args.extend(["--gain".into(), format!("{name}={value:?}")]);
    }
    let backend = match args.backend {
        BackendKind::Sim => "sim",
        BackendKind::Q2usb => "q2usb",
    };
    child_args.extend(["--backend".into(), backend.into()]);
    if let Some(x0) = &x0 {
        let text = names
            .iter()
            .zip(x0)
            .map(|(n, v)| format!("{n}={v:?}"))
            .collect::<Vec<_>>()
            .join(",");
        child_args.extend(["--x0".into(), text]);
    }
    if let Some(lib) = &args.hil_lib {
        child_args.extend(["--hil-lib".into(), lib.display().to_string()]);
    }
    child_args.extend(["--board".into(), args.board.clone()]);
    if args.allow_no_watchdog {
        child_args.push("--allow-no-watchdog".into());
    }
    child_args.extend([
        "--rate".into(),
        format!("{:?}", args.rate),
        "--duration".into(),
        format!("{:?}", args.duration),
        "--arm-limit".into(),
        format!("{arm_limit:?}"),
        "--fall-angle".into(),
        format!("{fall_angle:?}"),
        "--catch-window".into(),
        format!("{catch_window:?}rad"),
        "--hanging-window".into(),
        format!("{hanging_window:?}rad"),
        "--max-arm-speed".into(),
        format!("{max_arm_speed:?}"),
        "--max-pendulum-speed".into(),
        format!("{max_pendulum_speed:?}"),
    ]);
    match velocity {
        VelocityKind::Observer => child_args.extend(["--velocity".into(), "observer".into()]),
        VelocityKind::Derivative => child_args.extend([
            "--velocity".into(),
            "derivative".into(),
            "--velocity-bandwidth".into(),
            format!("{bandwidth:?}"),
        ]),
    }
    if args.realtime {
        child_args.push("--realtime".into());
    }
    if let Some(text) = &args.sim_noise {
        child_args.extend(["--sim-noise".into(), text.clone()]);
    }
    let full = args.compare || args.log_precision == LogPrecision::Full;
    if let Some(log) = &args.log {
        child_args.extend(["--log".into(), log.display().to_string()]);
        if full {
            child_args.extend(["--log-precision".into(), "full".into()]);
        }
        if args.force {
            child_args.push("--force".into());
        }
    }

    // The first Ctrl-C reaches the binary too (same process group), which
    // stops at 0 V and exits 130; a SIGTERM/SIGHUP/SIGQUIT sent to plantc
    // alone is passed on to the binary. plantc stays to report it.
    let stop = Arc::new(AtomicBool::new(false));
    let _ = stop_on_ctrl_c(stop.clone());
    let _ = writeln!(err, "running {}", binary.display());
    let code = run_forwarding(&binary, &child_args, &stop, out, err)?;

    if args.compare {
        if let Some(log) = &args.log {
            compare(
                args,
                model,
                &vals,
                log,
                noise.is_some(),
                (velocity, bandwidth),
                out,
            )?;
        }
    }
    match code {
        0 => Ok(()),
        129..=131 | 143 => Err(CliError {
            message: format!(
                "stopped by {} (0 V written, board closed, log flushed)",
                plantc_runtime::stop_signal().map_or("Ctrl-C", |s| s.name)
            ),
            code,
        }),
        2 => Err(CliError::input(
            "error: the rig binary refused its options (see above)",
        )),
        c => Err(CliError::failure(format!(
            "the rig binary exited with code {c}"
        ))),
    }
}

/// Runs `binary` with `args`, writing its stdout and stderr lines to `out`
/// and `err` as they come; returns its exit code (1 if killed by a signal).
fn run_forwarding(
    binary: &std::path::Path,
    args: &[String],
    stop: &AtomicBool,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<i32, CliError> {
    let mut child = Command::new(binary)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| CliError::failure(format!("error: cannot run {}: {e}", binary.display())))?;
    let (tx, rx) = mpsc::channel::<(bool, String)>();
    let pipe = |r: Box<dyn Read + Send>, is_err: bool, tx: mpsc::Sender<(bool, String)>| {
        std::thread::spawn(move || {
            for line in BufReader::new(r).lines() {
                let Ok(line) = line else { break };
                if tx.send((is_err, line)).is_err() {
                    break;
                }
            }
        })
    };
    let mut threads = Vec::new();
    if let Some(o) = child.stdout.take() {
        threads.push(pipe(Box::new(o), false, tx.clone()));
    }
    if let Some(e) = child.stderr.take() {
        threads.push(pipe(Box::new(e), true, tx.clone()));
    }
    drop(tx);
    let mut forwarded = false;
    loop {
        match rx.recv_timeout(std::time::Duration::from_millis(50)) {
            Ok((is_err, line)) => {
                let w: &mut dyn Write = if is_err { &mut *err } else { &mut *out };
                let _ = writeln!(w, "{line}");
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
        }
        if !forwarded && stop.load(std::sync::atomic::Ordering::SeqCst) {
            // a second signal to the same child is ignored by its handler
            forwarded = plantc_runtime::forward_stop(child.id());
        }
    }
    for t in threads {
        let _ = t.join();
    }
    let status = child
        .wait()
        .map_err(|e| CliError::failure(format!("error: waiting for the rig binary: {e}")))?;
    Ok(status.code().unwrap_or(1))
}

/// `--compare`: the interpreted observer and controller replayed over the
/// compiled run's log.
fn compare(
    args: &RunArgs,
    model: &plantc_derive::model::Model,
    vals: &plantc_derive::model::ParameterValues,
    log: &std::path::Path,
    noisy: bool,
    (velocity, bandwidth): (VelocityKind, f64),
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let fail = |e: &dyn std::fmt::Display| CliError::failure(format!("error: --compare: {e}"));
    let text = std::fs::read_to_string(log).map_err(|e| fail(&e))?;
    let nq = model.coordinates.len();
    let maps: Vec<EncoderMap> = match args.backend {
        BackendKind::Sim => vec![EncoderMap::plain(SimConfig::default().counts_per_rev); nq],
        BackendKind::Q2usb => Q2UsbConfig::default()
            .encoders
            .iter()
            .map(|e| e.map)
            .collect(),
    };
    let period = 1.0 / args.rate;
    let mut estimator: Box<dyn VelocityEstimator> = match velocity {
        VelocityKind::Observer => {
            let derivation = Derivation::new(model).map_err(|e| fail(&e))?;
            let mut spec = observer_spec(model, &derivation, vals)?;
            spec.accel_std = args.observer_accel;
            Box::new(VelocityObserver::design(&spec, &maps, period).map_err(|e| fail(&e))?)
        }
        VelocityKind::Derivative => Box::new(DerivativeEstimator::new(nq, bandwidth, period)),
    };
    let derivation = Derivation::new(model).map_err(|e| fail(&e))?;
    let resolved = resolve(model, &derivation, &args.controller, vals).map_err(|e| fail(&e))?;
    let mut controller = ModelController::new(model, &resolved, vals).map_err(|e| fail(&e))?;
    for (name, value) in parse_gains(&args.gain)? {
        controller.set_gain(&name, value).map_err(|e| fail(&e))?;
    }
    let limits = model
        .inputs
        .first()
        .and_then(|u| u.limits)
        .unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
    let report = replay_log(&text, &maps, limits, estimator.as_mut(), &mut controller)
        .map_err(|e| fail(&e))?;
    let _ = writeln!(
        out,
        "compare (interpreted path replayed over the compiled run's measurements{}): {report}",
        if noisy {
            ", simulator noise included"
        } else {
            ""
        }
    );
    Ok(())
}
