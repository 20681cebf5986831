//! End-to-end tests of `plantc run` through `plantc::run`: the acceptance runs
//! of issue 5 (catch from 5 deg and balance 30 s with `pole_placement` and
//! `fl_arm`, on the simulator and on the q2usb backend against the fake HIL
//! library), the log read by the identification data reader, and a fault.
//!
//! The simulator and the fake board run in virtual time, so a 30 s run takes
//! well under real time (printed by each test).

use std::path::Path;
use std::sync::Mutex;
use std::time::Instant;

use plantc_identify::{read_experiment, ChannelSpec, Kind};

mod common;

use common::{fake_hil_lib, model, plantc, tmp};

/// The fake HIL card is a process-wide singleton configured through the
/// environment, so q2usb runs in this binary take turns.
static FAKE_HIL: Mutex<()> = Mutex::new(());

/// What a log says, read through the identification data reader.
struct LogSummary {
    samples: usize,
    t_end: f64,
    /// Largest |alpha| (rad) over the last 5 s.
    tail_alpha: f64,
    /// Largest |Vm| (V) over the first 0.2 s (the catch).
    catch_volts: f64,
    last_vm: f64,
    last_state: String,
}

fn read_log(path: &Path) -> LogSummary {
    let spec = ChannelSpec::new()
        .angle("theta")
        .angle("alpha")
        .input("Vm", Kind::Voltage);
    let (exp, warnings) =
        read_experiment(path, &spec).expect("the identification reader accepts the log");
    for w in &warnings {
        println!("reader warning: {w}");
    }
    for name in ["theta", "alpha", "Vm", "Vm_cmd", "theta_dot", "alpha_dot"] {
        assert!(
            exp.values(name).is_some(),
            "column {name} missing: {:?}",
            exp.channel_names()
        );
    }
    let t = &exp.t;
    let alpha = exp.values("alpha").expect("alpha");
    let vm = exp.values("Vm").expect("Vm");
    let t_end = *t.last().expect("samples");
    let tail_alpha = t
        .iter()
        .zip(alpha)
        .filter(|(t, _)| **t >= t_end - 5.0)
        .map(|(_, a)| a.abs())
        .fold(0.0, f64::max);
    let catch_volts = t
        .iter()
        .zip(vm)
        .filter(|(t, _)| **t <= 0.2)
        .map(|(_, v)| v.abs())
        .fold(0.0, f64::max);
    // The state column is text; the reader drops it, so read the last line directly.
    let text = std::fs::read_to_string(path).expect("log");
    let last_line = text.lines().last().expect("rows");
    let fields: Vec<&str> = last_line.split(',').collect();
    LogSummary {
        samples: exp.len(),
        t_end,
        tail_alpha,
        catch_volts,
        last_vm: *vm.last().expect("Vm"),
        last_state: fields.get(9).map(|s| s.to_string()).unwrap_or_default(),
    }
}

/// Runs `plantc run` for 30 s from alpha = 5 deg and checks the acceptance:
/// exit 0, still engaged at 30 s, every sample logged, a visible catch, and
/// |alpha| below 1 deg over the last 5 s. The 1 deg bound is the criterion of
/// runtime/README.md ("Measured margin"), whose tables measured 0.18 deg for
/// pole_placement and 0.35 deg for fl_arm a = b = 0.5 with the thesis set.
fn balance_30s(name: &str, extra: &[&str], env: Option<&str>) {
    let dir = tmp(name);
    let log = dir.join("out.csv");
    let model = model();
    let mut args = vec!["run", model.as_str()];
    args.extend_from_slice(extra);
    let log_s = log.to_str().expect("utf8 path");
    args.extend_from_slice(&["--duration", "30", "--log", log_s]);
    let _guard = env.map(|spec| {
        let g = FAKE_HIL.lock().unwrap_or_else(|e| e.into_inner());
        std::env::set_var("PLANTC_FAKE_HIL", spec);
        std::env::set_var("PLANTC_FAKE_HIL_TRACE", dir.join("trace.txt"));
        g
    });
    let start = Instant::now();
    let (code, out, err) = plantc(&args);
    println!(
        "{name}: {:.2} s wall clock\n{out}{err}",
        start.elapsed().as_secs_f64()
    );
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("final state engaged"), "{out}");
    assert!(out.contains("steady-state Kalman observer"), "{out}");
    let s = read_log(&log);
    assert_eq!(s.samples, 30_001, "1 kHz for 30 s, both ends included");
    assert!((s.t_end - 30.0).abs() < 1e-6, "{}", s.t_end);
    assert_eq!(s.last_state, "engaged");
    assert!(s.catch_volts > 0.1, "no visible catch: {} V", s.catch_volts);
    assert!(
        s.tail_alpha < 1f64.to_radians(),
        "max |alpha| over the last 5 s: {} deg",
        s.tail_alpha.to_degrees()
    );
    if env.is_some() {
        // The board's output at close is 0 V.
        let trace = std::fs::read_to_string(dir.join("trace.txt")).expect("trace");
        let close = trace
            .lines()
            .rev()
            .find_map(|l| l.split_whitespace().find_map(|w| w.strip_prefix("output=")))
            .and_then(|v| v.parse::<f64>().ok());
        assert_eq!(close, Some(0.0), "output at close");
    }
}

#[test]
fn sim_pole_placement_balances_30s() {
    balance_30s(
        "sim_pp",
        &[
            "--controller",
            "pole_placement",
            "--backend",
            "sim",
            "--x0",
            "alpha=5deg",
        ],
        None,
    );
}

#[test]
fn sim_fl_arm_balances_30s() {
    // a = b = 0.5 (the model's default gains) lies inside the stable interval
    // 0 < a = b < 1.002 (`plantc stability ... --set thesis`).
    balance_30s(
        "sim_fl",
        &[
            "--set",
            "thesis",
            "--controller",
            "fl_arm",
            "--backend",
            "sim",
            "--x0",
            "alpha=5deg",
        ],
        None,
    );
}

#[test]
fn q2usb_fake_hil_pole_placement_balances_30s() {
    let lib = fake_hil_lib();
    let lib = lib.to_str().expect("utf8 path");
    balance_30s(
        "q2_pp",
        &[
            "--controller",
            "pole_placement",
            "--backend",
            "q2usb",
            "--hil-lib",
            lib,
        ],
        Some("alpha0=5deg"),
    );
}

#[test]
fn q2usb_fake_hil_fl_arm_balances_30s() {
    // The fake board simulates the reference pendulum (Table 3 values, no dry
    // friction), i.e. the thesis parameter set.
    let lib = fake_hil_lib();
    let lib = lib.to_str().expect("utf8 path");
    balance_30s(
        "q2_fl",
        &[
            "--set",
            "thesis",
            "--controller",
            "fl_arm",
            "--backend",
            "q2usb",
            "--hil-lib",
            lib,
        ],
        Some("alpha0=5deg"),
    );
}

#[test]
fn q2usb_read_error_ends_in_fault_with_zero_volts() {
    let lib = fake_hil_lib();
    let dir = tmp("q2_read_error");
    let log = dir.join("out.csv");
    let _g = FAKE_HIL.lock().unwrap_or_else(|e| e.into_inner());
    std::env::set_var("PLANTC_FAKE_HIL", "alpha0=5deg,fault=read_error@1.0");
    std::env::set_var("PLANTC_FAKE_HIL_TRACE", dir.join("trace.txt"));
    let model = model();
    let (code, out, err) = plantc(&[
        "run",
        &model,
        "--controller",
        "pole_placement",
        "--backend",
        "q2usb",
        "--hil-lib",
        lib.to_str().expect("utf8 path"),
        "--duration",
        "5",
        "--log",
        log.to_str().expect("utf8 path"),
    ]);
    assert_ne!(code, 0, "{out}{err}");
    assert!(err.contains("fault:read_error"), "{err}");
    let s = read_log(&log);
    assert_eq!(s.last_state, "fault:read_error");
    assert_eq!(s.last_vm, 0.0);
    assert!(
        (s.t_end - 1.0).abs() < 0.01,
        "fault injected at 1.0 s: {}",
        s.t_end
    );
}

#[test]
fn quanser_filtered_derivative_stays_available_and_fl_arm_falls_with_it() {
    // runtime/README.md: with the 50 rad/s filtered derivative fl_arm
    // (a = b = 0.5, thesis set) falls within ~2 s in the sampled loop; the
    // run must end in a fault, exit non-zero and leave 0 V in the log.
    let dir = tmp("derivative");
    let log = dir.join("out.csv");
    let model = model();
    let (code, out, err) = plantc(&[
        "run",
        &model,
        "--set",
        "thesis",
        "--controller",
        "fl_arm",
        "--velocity",
        "derivative",
        "--x0",
        "alpha=5deg",
        "--duration",
        "30",
        "--log",
        log.to_str().expect("utf8 path"),
    ]);
    assert_ne!(code, 0, "{out}{err}");
    assert!(
        out.contains("filtered derivative, bandwidth 50 rad/s"),
        "{out}"
    );
    let s = read_log(&log);
    assert!(s.last_state.starts_with("fault:"), "{}", s.last_state);
    assert_eq!(s.last_vm, 0.0);
    assert!(s.t_end < 10.0, "{}", s.t_end);
}

#[test]
fn bad_estimator_settings_are_input_errors() {
    let model = model();
    for (flag, value) in [("--velocity-bandwidth", "0"), ("--observer-accel", "0")] {
        let (code, out, err) = plantc(&[
            "run",
            &model,
            "--controller",
            "pole_placement",
            "--duration",
            "0.01",
            flag,
            value,
        ]);
        assert_ne!(code, 0, "{flag} {value}: {out}{err}");
        assert!(err.contains(flag), "{err}");
    }
}

/// Ctrl-C (SIGINT) during a real-time run: the loop stops in `fault:stopped`,
/// the process exits with 130, the log parses and its last Vm is 0 V.
#[cfg(unix)]
#[test]
fn ctrl_c_stops_with_zero_volts_and_a_readable_log() {
    use std::os::unix::process::CommandExt;
    use std::process::{Command, Stdio};
    use std::time::Duration;
    extern "C" {
        fn kill(pid: i32, sig: i32) -> i32;
        fn signal(sig: i32, handler: usize) -> usize;
    }
    const SIGINT: i32 = 2;
    const SIG_DFL: usize = 0;
    let dir = tmp("ctrl_c");
    let log = dir.join("out.csv");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_plantc"));
    // Ctrl-C as from a terminal: SIGINT at its default disposition in the
    // child, whatever this test inherited (a background job of a
    // non-interactive shell starts with SIGINT ignored, and plantc keeps a
    // signal ignored at its start ignored, as `nohup` asks).
    // SAFETY: between fork and exec, only the async-signal-safe `signal`.
    unsafe {
        cmd.pre_exec(|| {
            signal(SIGINT, SIG_DFL);
            Ok(())
        });
    }
    let mut child = cmd
        .args([
            "run",
            &model(),
            "--controller",
            "pole_placement",
            "--x0",
            "alpha=5deg",
        ])
        .args(["--duration", "60", "--realtime", "--log"])
        .arg(&log)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn plantc");
    // Wait until the loop is logging (engaged), then interrupt.
    let start = Instant::now();
    while std::fs::metadata(&log).map_or(0, |m| m.len()) < 20_000 {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no log growth after 60 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // SAFETY: signals our own child process.
    assert_eq!(unsafe { kill(child.id() as i32, SIGINT) }, 0);
    let sent = Instant::now();
    let output = loop {
        if child.try_wait().expect("wait").is_some() {
            break child.wait_with_output().expect("output");
        }
        if sent.elapsed() > Duration::from_secs(10) {
            let _ = child.kill();
            panic!("plantc did not stop within 10 s of SIGINT");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    println!(
        "stopped {:.3} s after SIGINT\n{stdout}{stderr}",
        sent.elapsed().as_secs_f64()
    );
    assert_eq!(output.status.code(), Some(130), "{stdout}{stderr}");
    assert!(stderr.contains("engaged -> fault:stopped"), "{stderr}");
    assert!(stderr.contains("Ctrl-C"), "{stderr}");
    let s = read_log(&log);
    assert_eq!(s.last_state, "fault:stopped");
    assert_eq!(s.last_vm, 0.0);
    assert!(s.t_end < 59.0, "stopped early: {}", s.t_end);
}

/// Largest |alpha| (rad) over the last 5 s of a 30 s library-level run of
/// fl_arm (a = b = 0.5, thesis set) on the simulator with encoder noise and
/// a one-sample input delay (options the CLI does not expose), or the fault.
fn fl_arm_noisy(observer: bool, bandwidth: f64) -> Result<f64, String> {
    use plantc_derive::control::{resolve, Derivation};
    use plantc_derive::mechanics::NumericDynamics;
    use plantc_derive::model::{load_model, ParameterValues};
    use plantc_runtime::{
        run, ModelController, ModelPlant, ObserverSpec, RunConfig, SimBackend, SimConfig, SimNoise,
        SupervisorState,
    };
    let loaded = load_model(Path::new(&model())).expect("model");
    let m = &loaded.model;
    let vals = ParameterValues::new(m, Some("thesis"), &[]).expect("thesis set");
    let derivation = Derivation::new(m).expect("derivation");
    let resolved = resolve(m, &derivation, "fl_arm", &vals).expect("fl_arm");
    let mut ctl = ModelController::new(m, &resolved, &vals).expect("controller");
    let dynamics = NumericDynamics::new(m, &derivation.equations).expect("dynamics");
    let plant = ModelPlant::new(m, dynamics, &vals);
    let mut cfg = RunConfig::for_plant(&plant);
    cfg.duration_s = Some(30.0);
    cfg.velocity_bandwidth = bandwidth;
    if observer {
        // Central differences are exact enough here: with Fg1 = 0 (thesis set)
        // the dry-friction term vanishes.
        cfg.observer = Some(ObserverSpec::from_smooth_plant(&plant).expect("spec"));
    }
    let sim = SimConfig {
        noise: Some(SimNoise {
            seed: 11,
            counts_std: 0.5,
            volts_std: 0.05,
        }),
        input_delay_samples: 1,
        ..SimConfig::default()
    };
    let x0 = vec![0.0, 5f64.to_radians(), 0.0, 0.0];
    let mut be = SimBackend::new(Box::new(plant), x0, sim).expect("sim");
    let dir = tmp(&format!("noisy-{observer}-{bandwidth}"));
    let log = dir.join("out.csv");
    let mut writer = plantc_runtime::LogWriter::create(&log).expect("log");
    let report = run(&cfg, &mut be, &mut ctl, Some(&mut writer)).expect("run");
    drop(writer);
    if report.final_state != SupervisorState::Engaged {
        return Err(report.final_state.to_string());
    }
    Ok(read_log(&log).tail_alpha)
}

#[test]
fn the_observer_tolerates_encoder_noise_and_input_delay() {
    // Noise of 0.5 count and 0.05 V (std), one sample of input delay: the
    // default observer keeps fl_arm within 1 deg (criterion of
    // runtime/README.md), where the 50 rad/s filtered derivative falls.
    let obs = fl_arm_noisy(true, 50.0);
    let der = fl_arm_noisy(false, 50.0);
    // For the record (runtime/README.md), not asserted.
    let der400 = fl_arm_noisy(false, 400.0);
    println!("observer: {obs:?}; derivative 50 rad/s: {der:?}; 400 rad/s: {der400:?}");
    let tail = obs.expect("the observer run stays engaged");
    assert!(tail < 1f64.to_radians(), "{} deg", tail.to_degrees());
    assert!(der.is_err(), "{der:?}");
}

/// Issue 28: the sliding-mode controller released at 10 deg with the default
/// catch window (10 deg; the encoder reads 10.02 deg) never engages: the run
/// says why after a second, how to widen the window, and exits non-zero.
#[test]
fn a_run_that_never_engages_says_why_and_fails() {
    let model = model();
    let run = |extra: &[&str]| {
        let mut args = vec![
            "run",
            model.as_str(),
            "--controller",
            "sliding_mode",
            "--x0",
            "alpha=10deg",
            "--duration",
            "2",
        ];
        args.extend_from_slice(extra);
        plantc(&args)
    };
    let (code, out, err) = run(&[]);
    assert_eq!(code, 1, "{out}{err}");
    assert!(err.contains("supervisor: t=1.00"), "{err}");
    assert!(err.contains("s not engaged: "), "{err}");
    // 114 encoder counts: 10.02 deg
    assert!(err.contains("no closer to upright than 10.02deg"), "{err}");
    assert!(err.contains("--catch-window 12deg"), "{err}");
    assert!(err.contains("the controller never engaged"), "{err}");
    assert!(out.contains("never engaged;"), "{out}");
    // with the window widened as told it engages and exits 0
    let (code, out, err) = run(&["--catch-window", "12deg"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(!err.contains("not engaged"), "{err}");
}
