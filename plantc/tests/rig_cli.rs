//! The rig crate end to end (issue 13): `plantc gen --rig` for
//! `pole_placement` and `fl_arm` (`--set thesis`), built with plain
//! `cargo build` (release, offline), run against the fake HIL library for
//! 30 s from 5 deg (engaged throughout, |alpha| < 1 deg over the last 5 s,
//! the log read by identify's reader) and with `fault=read_error@2.0` (ends
//! in the fault, 0 V last, the fault in the log); no allocation over 1e5
//! cycles of the binary's loop; the compiled and interpreted controllers give
//! the same voltage sequence to 1e-9 V over 30 s simulated with the same
//! seed; `plantc run --compiled --compare` agrees too.
//!
//! Building a crate costs CI time, so this is one test function sharing one
//! build: the rig crate's target directory is `target/rig-tests` (kept
//! between runs), and the `--compiled` crate reuses its dependencies there.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use plantc_derive::analysis::{linearize, OperatingPoint};
use plantc_derive::control::{resolve, Derivation};
use plantc_derive::model::{load_model, ParameterValues};
use plantc_identify::{read_experiment, ChannelSpec, Kind};
use plantc_runtime::{
    replay_log, EncoderMap, ModelController, ObserverSpec, ReplayReport, VelocityObserver,
};

mod common;

use common::{fake_hil_lib, model, number_after, plantc, repo, s, tmp};

/// 1 kHz for 30 s, both ends included.
const SAMPLES_30S: usize = 30_001;

fn cargo() -> String {
    std::env::var("CARGO").unwrap_or_else(|_| "cargo".into())
}

fn rig_target() -> PathBuf {
    repo().join("target/rig-tests")
}

/// Runs the rig binary: (exit code, stdout, stderr).
fn rig(bin: &Path, args: &[&str], fake_hil: Option<(&str, &Path)>) -> (i32, String, String) {
    let mut cmd = Command::new(bin);
    cmd.args(args);
    if let Some((spec, trace)) = fake_hil {
        cmd.env("PLANTC_FAKE_HIL", spec)
            .env("PLANTC_FAKE_HIL_TRACE", trace);
    }
    let o = cmd.output().expect("the rig binary runs");
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// What a log says: through identify's reader, plus the text-only state column.
struct Log {
    samples: usize,
    t_end: f64,
    tail_alpha: f64,
    states: Vec<String>,
    last_vm: f64,
}

fn read_log(path: &Path) -> Log {
    let spec = ChannelSpec::new()
        .angle("theta")
        .angle("alpha")
        .input("Vm", Kind::Voltage);
    let (exp, _) = read_experiment(path, &spec).expect("identify's reader accepts the log");
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
    let text = std::fs::read_to_string(path).expect("log");
    let states = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(9).unwrap_or("").to_string())
        .collect();
    Log {
        samples: exp.len(),
        t_end,
        tail_alpha,
        states,
        last_vm: *vm.last().expect("Vm"),
    }
}

/// The applied-voltage column (`Vm`, the 8th) of a log, as written.
fn volts(path: &Path) -> Vec<f64> {
    std::fs::read_to_string(path)
        .expect("log")
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(7).expect("Vm").parse().expect("number"))
        .collect()
}

/// The fake board's output at close (its trace's last `output=`).
fn close_output(trace: &Path) -> Option<f64> {
    std::fs::read_to_string(trace)
        .ok()?
        .lines()
        .rev()
        .find_map(|l| l.split_whitespace().find_map(|w| w.strip_prefix("output=")))
        .and_then(|v| v.parse().ok())
}

/// The interpreted observer (designed at start, as `plantc run` does, with
/// the `--set thesis` values the rig was generated with) and controller
/// (`--set thesis` with `params` changed, `gains` set) replayed over a
/// simulator log of the rig.
fn replay_interpreted(
    log: &Path,
    controller: &str,
    gains: &[(&str, f64)],
    params: &[(&str, f64)],
) -> ReplayReport {
    let model = load_model(Path::new(&model())).expect("model").model;
    let vals = ParameterValues::new(&model, Some("thesis"), &[]).unwrap();
    let changed: Vec<(String, f64)> = params.iter().map(|(n, v)| (n.to_string(), *v)).collect();
    let ctl_vals = ParameterValues::new(&model, Some("thesis"), &changed).unwrap();
    let der = Derivation::new(&model).unwrap();
    let lin = linearize(&model, &der.equations, &vals, &OperatingPoint::zero(&model)).unwrap();
    let spec = ObserverSpec::new(
        (0..16).map(|k| lin.a[(k / 4, k % 4)]).collect(),
        (0..4).map(|i| lin.b[(i, 0)]).collect(),
    );
    let maps = [EncoderMap::plain(4096.0); 2];
    let mut observer = VelocityObserver::design(&spec, &maps, 1e-3).unwrap();
    let resolved = resolve(&model, &der, controller, &vals).unwrap();
    let mut ctl = ModelController::new(&model, &resolved, &ctl_vals).unwrap();
    for (g, v) in gains {
        ctl.set_gain(g, *v).unwrap();
    }
    let text = std::fs::read_to_string(log).unwrap();
    replay_log(&text, &maps, (-10.0, 10.0), &mut observer, &mut ctl).expect("replay")
}

#[test]
fn rig_crate_on_the_fake_board_and_against_the_interpreter() {
    if Command::new(cargo()).arg("--version").output().is_err() {
        eprintln!("skipped: cargo not available");
        return;
    }
    let started = Instant::now();
    let root = tmp("rig");
    let dir = root.join("rig");
    let model = model();
    let (code, out, err) = plantc(&[
        "gen",
        &model,
        "--set",
        "thesis",
        "--controller",
        "pole_placement",
        "--controller",
        "fl_arm",
        "--rig",
        "-o",
        &s(&dir),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let toml = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
    assert!(toml.starts_with("# @generated by plantc"), "{toml}");
    assert!(
        toml.contains("To point elsewhere, change this line"),
        "{toml}"
    );
    let deps: Vec<&str> = toml
        .lines()
        .skip_while(|l| l.trim() != "[dependencies]")
        .skip(1)
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .filter_map(|l| l.split_once('=').map(|(n, _)| n.trim()))
        .collect();
    assert_eq!(deps, ["plantc-runtime"], "{toml}");
    assert!(toml.contains("default-features = false"), "{toml}");
    for f in ["src/main.rs", "src/model.rs"] {
        let text = std::fs::read_to_string(dir.join(f)).unwrap();
        assert!(text.starts_with("// @generated by plantc from "), "{f}");
    }
    let readme = std::fs::read_to_string(dir.join("README.md")).unwrap();
    assert!(
        readme.contains("Where plantc-runtime comes from"),
        "{readme}"
    );

    // The fake HIL is built in the workspace's own target directory.
    let hil = fake_hil_lib();

    // ---- plain `cargo build` from the generated directory (release, offline) ----
    let t0 = Instant::now();
    let build = Command::new(cargo())
        .args(["build", "--release", "--offline"])
        .current_dir(&dir)
        .env("CARGO_TARGET_DIR", rig_target())
        .output()
        .unwrap();
    assert!(
        build.status.success(),
        "cargo build of the rig crate failed:\n{}",
        String::from_utf8_lossy(&build.stderr)
    );
    let bin = rig_target().join(format!(
        "release/rotary-pendulum-rig{}",
        std::env::consts::EXE_SUFFIX
    ));
    println!(
        "rig crate release build: {:.1} s (incremental over target/rig-tests), binary {} bytes",
        t0.elapsed().as_secs_f64(),
        std::fs::metadata(&bin).map(|m| m.len()).unwrap_or(0)
    );
    // Its dependencies: nothing of plantc but the runtime, no model interpreter.
    let lock = std::fs::read_to_string(dir.join("Cargo.lock")).unwrap();
    let packages: Vec<&str> = lock
        .lines()
        .filter_map(|l| l.strip_prefix("name = \""))
        .map(|l| l.trim_end_matches('"'))
        .collect();
    println!("rig binary's dependency graph (Cargo.lock): {packages:?}");
    for banned in ["plantc-derive", "nalgebra", "plantc-codegen", "clap"] {
        assert!(!packages.contains(&banned), "{banned} in {packages:?}");
    }
    assert!(packages.contains(&"libloading"), "{packages:?}");

    // ---- 30 s from 5 deg against the fake HIL: engaged throughout, balanced ----
    for controller in ["pole_placement", "fl_arm"] {
        let log = root.join(format!("{controller}_q2.csv"));
        let trace = root.join(format!("{controller}_q2.trace"));
        let (code, out, err) = rig(
            &bin,
            &[
                "--controller",
                controller,
                "--backend",
                "q2usb",
                "--hil-lib",
                &s(&hil),
                "--duration",
                "30",
                "--log",
                &s(&log),
            ],
            Some(("alpha0=5deg", &trace)),
        );
        println!("[{controller} on the fake board]\n{out}{err}");
        assert_eq!(code, 0, "{out}{err}");
        assert!(out.contains("final state engaged"), "{out}");
        assert!(
            out.contains("generated steady-state Kalman observer"),
            "{out}"
        );
        let l = read_log(&log);
        assert_eq!(l.samples, SAMPLES_30S);
        assert!((l.t_end - 30.0).abs() < 1e-6, "{}", l.t_end);
        assert!(
            l.states.iter().all(|s| s == "engaged"),
            "not engaged throughout: {:?}",
            l.states.iter().find(|s| *s != "engaged")
        );
        assert!(
            l.tail_alpha < 1f64.to_radians(),
            "{controller}: max |alpha| over the last 5 s {} deg",
            l.tail_alpha.to_degrees()
        );
        assert_eq!(close_output(&trace), Some(0.0), "output at close");
    }

    // ---- an injected read error: Fault, 0 V last, the fault in the log ----
    let log = root.join("fault.csv");
    let trace = root.join("fault.trace");
    let (code, out, err) = rig(
        &bin,
        &[
            "--controller",
            "fl_arm",
            "--backend",
            "q2usb",
            "--hil-lib",
            &s(&hil),
            "--duration",
            "30",
            "--log",
            &s(&log),
        ],
        Some(("alpha0=5deg,fault=read_error@2.0", &trace)),
    );
    assert_eq!(code, 1, "{out}{err}");
    assert!(err.contains("run ended in fault:read_error"), "{err}");
    let l = read_log(&log);
    assert_eq!(
        l.states.last().map(String::as_str),
        Some("fault:read_error")
    );
    assert_eq!(l.last_vm, 0.0);
    assert!(
        (l.t_end - 2.0).abs() < 0.01,
        "fault injected at 2.0 s: {}",
        l.t_end
    );
    let trace_text = std::fs::read_to_string(&trace).unwrap();
    let last_write = trace_text
        .lines()
        .rev()
        .find(|l| l.contains(" write ") && l.ends_with(" ok"))
        .unwrap_or("");
    assert!(
        last_write.contains("v=0.000000"),
        "last write: {last_write}"
    );
    assert_eq!(close_output(&trace), Some(0.0), "output at close");

    // ---- no allocation over 1e5 cycles of the binary's loop ----
    let (code, out, err) = rig(
        &bin,
        &[
            "--controller",
            "fl_arm",
            "--x0",
            "alpha=5deg",
            "--duration",
            "101",
            "--sim-noise",
            "counts=0.5,volts=0.05,seed=2",
            "--log",
            &s(&root.join("alloc.csv")),
        ],
        None,
    );
    assert_eq!(code, 0, "{out}{err}");
    let allocs = number_after(&out, "loop allocations: ").expect("allocation line");
    let cycles = number_after(&out, &format!("loop allocations: {allocs} in ")).unwrap_or(0.0);
    println!("rig binary loop: {allocs} allocations in {cycles} cycles");
    assert_eq!(allocs, 0.0, "{out}");
    assert!(cycles >= 1e5, "{out}");

    // ---- interpreted vs compiled: the same voltage sequence (same seed) ----
    // The rig binary runs 30 s on its simulator with seeded noise; the
    // interpreted observer and controller (derive's tapes, the observer
    // designed at start as `plantc run` does) are replayed over exactly the
    // counts it measured and the voltages it applied.
    let mut timing = Vec::new();
    for controller in ["pole_placement", "fl_arm"] {
        let common_args = [
            "--controller",
            controller,
            "--x0",
            "alpha=5deg",
            "--duration",
            "30",
            "--sim-noise",
            "counts=0.5,volts=0.05,seed=7",
            "--log-precision",
            "full",
        ];
        let comp_log = root.join(format!("{controller}_compiled.csv"));
        let mut rargs = common_args.to_vec();
        let comp_log_s = s(&comp_log);
        rargs.extend_from_slice(&["--log", &comp_log_s]);
        let (code, cout, cerr) = rig(&bin, &rargs, None);
        assert_eq!(code, 0, "{cout}{cerr}");
        let r = replay_interpreted(&comp_log, controller, &[], &[]);
        println!("{controller}: {r}");
        assert_eq!(r.rows as usize, SAMPLES_30S);
        assert_eq!(r.compared as usize, SAMPLES_30S, "engaged throughout");
        assert!(r.max_volts_diff < 1e-9, "{controller}: {r}");

        // The interpreted path in its own closed loop (`plantc run`, its own
        // simulated plant: derive's tape instead of the generated plant).
        let interp_log = root.join(format!("{controller}_interp.csv"));
        let mut args = vec!["run", model.as_str(), "--set", "thesis"];
        args.extend_from_slice(&common_args);
        let interp_log_s = s(&interp_log);
        args.extend_from_slice(&["--log", &interp_log_s]);
        let (code, iout, ierr) = plantc(&args);
        assert_eq!(code, 0, "{iout}{ierr}");
        let (a, b) = (volts(&interp_log), volts(&comp_log));
        assert_eq!(a.len(), b.len());
        let first = a.iter().zip(&b).position(|(x, y)| (x - y).abs() > 1e-9);
        let max = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        // The two simulated plants agree to ~5e-15 relative, but the
        // pendulum is open-loop unstable and the encoders hide differences
        // below a count from both controllers, so the two closed loops run
        // the same voltages until a count flips (then both keep balancing).
        println!(
            "{controller}: independent closed loops (plantc run vs rig binary, same seed): \
             identical voltages to 1e-9 V for the first {:.3} s, max |difference| {max:.3e} V over 30 s",
            first.map_or(30.0, |k| k as f64 * 1e-3)
        );
        assert!(
            !matches!(first, Some(k) if k < 100),
            "diverged at sample {first:?}"
        );
        let key = "estimator + controller: p50 ";
        timing.push((
            controller,
            number_after(&cout, key).expect("compiled timing"),
            number_after(&iout, key).expect("interpreted timing"),
        ));
    }
    for (c, compiled, interpreted) in &timing {
        println!(
            "{c}: estimator + controller p50 {compiled} ns generated (release rig binary), \
             {interpreted} ns interpreted (plantc run, test profile)"
        );
    }

    // ---- gains and parameters changed at start-up (values file, command line) ----
    let values = root.join("values.txt");
    std::fs::write(
        &values,
        "# outer-law gains\na = 0.3\nb = 0.3   # arm\nRm = 2.7\n",
    )
    .unwrap();
    let log = root.join("values.csv");
    let (code, out, err) = rig(
        &bin,
        &[
            "--controller",
            "fl_arm",
            "--values",
            &s(&values),
            "--gain",
            "wn=5",
            "--x0",
            "alpha=5deg",
            "--duration",
            "10",
            "--log-precision",
            "full",
            "--log",
            &s(&log),
        ],
        None,
    );
    assert_eq!(code, 0, "{out}{err}");
    assert!(
        err.contains("note: --param changes the simulated plant"),
        "{err}"
    );
    let changed = [("a", 0.3), ("b", 0.3), ("wn", 5.0)];
    let r = replay_interpreted(&log, "fl_arm", &changed, &[("Rm", 2.7)]);
    println!("fl_arm with a = b = 0.3, wn = 5, Rm = 2.7: {r}");
    assert!(r.max_volts_diff < 1e-9, "{r}");
    // ... and they did change the law: the defaults do not replay it.
    let r = replay_interpreted(&log, "fl_arm", &[], &[]);
    assert!(r.max_volts_diff > 1e-3, "{r}");
    let r = replay_interpreted(&log, "fl_arm", &changed, &[]);
    assert!(r.max_volts_diff > 1e-6, "Rm changed nothing: {r}");

    // ---- bad input: exit 2 with the cause ----
    std::fs::write(&values, "a = 0.3\n  zz = 1\n").unwrap();
    for (args, expected) in [
        (
            vec!["--controller", "fl_arm", "--values", &s(&values)],
            format!("{}:2:3: unknown name `zz`", values.display()),
        ),
        (
            vec!["--rate", "500"],
            "the observer was designed for 1000 Hz".to_string(),
        ),
        (
            vec!["--controller", "lqr_unit"],
            "unknown controller `lqr_unit` (this binary has: pole_placement, fl_arm)".into(),
        ),
        (
            vec!["--gain", "k_beta=1"],
            "unknown gain `k_beta` of pole_placement (gains: k_theta, k_alpha, k_theta_dot, k_alpha_dot)".into(),
        ),
        (
            vec!["--x0", "beta=1"],
            "unknown state `beta`".into(),
        ),
    ] {
        let (code, out, err) = rig(&bin, &args, None);
        assert_eq!(code, 2, "{args:?}: {out}{err}");
        assert!(err.contains(&expected), "{args:?}: {err}");
    }

    // ---- plantc run --compiled --compare: the same generated code from the CLI ----
    let log = root.join("compiled_compare.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_plantc"))
        .args([
            "run",
            model.as_str(),
            "--set",
            "thesis",
            "--controller",
            "fl_arm",
            "--x0",
            "alpha=5deg",
            "--duration",
            "30",
            "--sim-noise",
            "counts=0.5,volts=0.05,seed=7",
            "--log",
            &s(&log),
            "--compiled",
            &s(&root.join("compiled")),
            "--compare",
        ])
        .env("CARGO_TARGET_DIR", rig_target())
        .env("CARGO_NET_OFFLINE", "true")
        .output()
        .unwrap();
    let (cout, cerr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    println!("[plantc run --compiled --compare]\n{cout}");
    assert!(out.status.success(), "{cout}{cerr}");
    assert!(cout.contains("(generated code)"), "{cout}");
    let diff = number_after(&cout, "max |Vm difference| ").expect("compare line");
    assert!(diff < 1e-9, "{cout}");
    // Same seed, same generated code: the compiled log equals the rig binary's.
    assert_eq!(volts(&log), volts(&root.join("fl_arm_compiled.csv")));

    #[cfg(unix)]
    signals_stop_the_rig_safely(&bin, &hil, &model, &root);

    println!(
        "rig test total: {:.1} s wall clock",
        started.elapsed().as_secs_f64()
    );
    let _ = std::fs::remove_dir_all(&root);
}

#[cfg(unix)]
extern "C" {
    fn kill(pid: i32, sig: i32) -> i32;
}

/// Starts `cmd`, waits until `log` has rows, sends SIGTERM to that process
/// only and returns (exit code, stderr, last log row's Vm and state).
#[cfg(unix)]
fn sigterm_after_rows(mut cmd: Command, log: &Path) -> (i32, String, f64, String) {
    use std::io::Read;
    use std::process::Stdio;
    use std::time::Duration;
    let mut child = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while std::fs::read_to_string(log).map_or(0, |t| t.lines().count()) < 300 {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("run ended before the signal: {status}");
        }
        assert!(start.elapsed() < Duration::from_secs(300), "no log rows");
        std::thread::sleep(Duration::from_millis(20));
    }
    // SAFETY: plain kill(2) on our own child.
    assert_eq!(unsafe { kill(child.id() as i32, 15) }, 0);
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > Duration::from_secs(30) {
            let _ = child.kill();
            panic!("SIGTERM did not stop the run within 30 s");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    let text = std::fs::read_to_string(log).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let last: Vec<&str> = text.lines().last().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| h.starts_with(name)).unwrap();
    (
        status.code().unwrap_or(-1),
        err,
        last[col("Vm")].parse().unwrap(),
        last[col("state")].to_string(),
    )
}

/// Reliability (issue 12): SIGTERM stops the rig binary like Ctrl-C (0 V,
/// board closed, log flushed, exit 143), and a SIGTERM sent to
/// `plantc run --compiled` alone is passed on to the binary it runs.
#[cfg(unix)]
fn signals_stop_the_rig_safely(bin: &Path, hil: &Path, model: &str, root: &Path) {
    let log = root.join("sigterm_rig.csv");
    let trace = root.join("sigterm_rig.trace");
    let mut cmd = Command::new(bin);
    cmd.args(["--controller", "fl_arm", "--backend", "q2usb", "--hil-lib"])
        .arg(hil)
        .args(["--duration", "100000", "--log"])
        .arg(&log)
        .env("PLANTC_FAKE_HIL", "alpha0=5deg")
        .env("PLANTC_FAKE_HIL_TRACE", &trace);
    let (code, err, vm, state) = sigterm_after_rows(cmd, &log);
    println!("[SIGTERM to the rig binary] exit {code}, last Vm {vm}, {state}\n{err}");
    assert_eq!(code, 143, "{err}");
    assert!(err.contains("stopped by SIGTERM"), "{err}");
    assert_eq!((vm, state.as_str()), (0.0, "fault:stopped"));
    assert_eq!(close_output(&trace), Some(0.0), "output at close");

    let log = root.join("sigterm_compiled.csv");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_plantc"));
    cmd.args(["run", model, "--set", "thesis", "--controller", "fl_arm"])
        .args(["--x0", "alpha=5deg", "--realtime", "--duration", "100000"])
        .arg("--log")
        .arg(&log)
        .arg("--compiled")
        .arg(root.join("compiled"))
        .env("CARGO_TARGET_DIR", rig_target())
        .env("CARGO_NET_OFFLINE", "true");
    let (code, err, vm, state) = sigterm_after_rows(cmd, &log);
    println!("[SIGTERM to plantc run --compiled] exit {code}, last Vm {vm}, {state}\n{err}");
    assert_eq!(code, 143, "{err}");
    assert!(err.contains("stopped by SIGTERM"), "{err}");
    assert_eq!((vm, state.as_str()), (0.0, "fault:stopped"));
}
