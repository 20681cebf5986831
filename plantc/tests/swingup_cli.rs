//! Issue 14 end to end through `plantc::run`: the energy swing-up with catch
//! (`swing_up`) and the sliding-mode controller on the simulator and on the
//! q2usb backend against the fake HIL library, `plantc sim` with a hybrid
//! controller, `plantc analyze --controller`, and `plantc robustness`.
//!
//! Swing-up acceptance: from alpha0 = pi - 0.05 (hanging) with the model's
//! values and gains (kE = 200, k_theta = 2, 10 V): caught within 0.6 s with
//! the arm within 100 deg, and at 15 s |alpha| < 0.01 rad, |theta| < 3 deg;
//! the log shows each mode switch. Sliding mode: balances from 10 deg for 30 s.

use std::path::Path;
use std::sync::Mutex;

mod common;

use common::{fake_hil_lib, model, number_after, plantc, repo, tmp};

/// The fake HIL card is configured through the environment: q2usb runs in
/// this binary take turns.
static FAKE_HIL: Mutex<()> = Mutex::new(());

fn wrap(a: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    a - tau * ((a + std::f64::consts::PI) / tau).floor()
}

/// Rows of a `plantc run` log as (t, theta, alpha, state, mode).
fn log_rows(path: &Path) -> Vec<(f64, f64, f64, String, String)> {
    let text = std::fs::read_to_string(path).expect("log");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |n: &str| {
        header
            .iter()
            .position(|h| *h == n)
            .unwrap_or_else(|| panic!("no column {n}: {header:?}"))
    };
    let (t, th, al, st, mo) = (
        col("t"),
        col("theta"),
        col("alpha"),
        col("state"),
        col("mode"),
    );
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (
                f[t].parse().unwrap(),
                f[th].parse().unwrap(),
                f[al].parse().unwrap(),
                f[st].to_string(),
                f[mo].to_string(),
            )
        })
        .collect()
}

fn with_fake_hil<T>(spec: &str, dir: &Path, f: impl FnOnce() -> T) -> T {
    let _g = FAKE_HIL.lock().unwrap_or_else(|e| e.into_inner());
    std::env::set_var("PLANTC_FAKE_HIL", spec);
    std::env::set_var("PLANTC_FAKE_HIL_TRACE", dir.join("trace.txt"));
    f()
}

/// Runs `plantc <args> --compiled <rig> --compare` as a process: the rig
/// crate is built into `target/rig-tests` (shared with `rig_cli.rs`), the
/// fake HIL configured through the child's environment.
fn plantc_compiled(
    args: &[&str],
    rig: &Path,
    fake: Option<(&str, &Path)>,
) -> (i32, String, String) {
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_plantc"));
    cmd.args(args)
        .args(["--compiled", rig.to_str().expect("utf8"), "--compare"])
        .env("CARGO_TARGET_DIR", repo().join("target/rig-tests"))
        .env("CARGO_NET_OFFLINE", "true");
    if let Some((spec, dir)) = fake {
        cmd.env("PLANTC_FAKE_HIL", spec)
            .env("PLANTC_FAKE_HIL_TRACE", dir.join("trace.txt"));
    }
    let o = cmd.output().expect("plantc runs");
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Runs `plantc <args>`: with `compiled`, through that rig crate (a
/// process); else in this process; the fake HIL configured by `fake`, its
/// trace in `dir`.
fn run_case(
    args: &[&str],
    dir: &Path,
    fake: Option<&str>,
    compiled: Option<&Path>,
) -> (i32, String, String) {
    match (fake, compiled) {
        (_, Some(rig)) => plantc_compiled(args, rig, fake.map(|f| (f, dir))),
        (Some(spec), None) => with_fake_hil(spec, dir, || plantc(args)),
        (None, None) => plantc(args),
    }
}

/// The swing-up acceptance run; with `compiled`, the generated controller in
/// a rig crate (`run --compiled`), the interpreted path replayed over its log.
fn swing_up(name: &str, backend: &[&str], fake: Option<&str>, compiled: Option<&Path>) {
    let dir = tmp(name);
    let log = dir.join("out.csv");
    let model = model();
    let mut args = vec!["run", model.as_str(), "--controller", "swing_up"];
    args.extend_from_slice(backend);
    let log_s = log.to_str().expect("utf8");
    args.extend_from_slice(&["--duration", "15", "--log", log_s]);
    let (code, out, err) = run_case(&args, &dir, fake, compiled);
    println!("{name}:\n{out}{err}");
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("final state engaged"), "{out}");
    assert!(
        err.contains("armed -> swing_up") && err.contains("swing_up -> engaged"),
        "{err}"
    );
    assert!(
        out.contains("filtered derivative, bandwidth 200 rad/s"),
        "{out}"
    );
    let rows = log_rows(&log);
    assert_eq!(rows.len(), 15_001);
    // every mode switch is in the log; here exactly one, pump -> catch
    let switches: Vec<(f64, &str, &str)> = rows
        .windows(2)
        .filter(|w| w[0].4 != w[1].4)
        .map(|w| (w[1].0, w[0].4.as_str(), w[1].4.as_str()))
        .collect();
    assert_eq!(rows[0].4, "pump");
    assert_eq!(switches.len(), 1, "{switches:?}");
    let (t_catch, from, to) = switches[0];
    assert_eq!((from, to), ("pump", "catch"));
    assert!(
        out.contains(&format!("t={t_catch:.3}s mode pump -> catch")),
        "{out}"
    );
    let arm = rows
        .iter()
        .filter(|r| r.0 <= t_catch)
        .fold(0.0f64, |m, r| m.max(r.1.abs()));
    let last = rows.last().unwrap();
    let (alpha, theta) = (wrap(last.2), last.1);
    println!(
        "{name}: caught at {t_catch:.3} s, arm within {:.1} deg; at 15 s alpha = {alpha:.2e} rad, theta = {:.3} deg",
        arm.to_degrees(),
        theta.to_degrees()
    );
    assert!(t_catch <= 0.6, "caught at {t_catch} s");
    assert!(arm.to_degrees() <= 100.0, "arm {} deg", arm.to_degrees());
    assert!(alpha.abs() < 0.01, "alpha {alpha}");
    assert!(
        theta.to_degrees().abs() < 3.0,
        "theta {}",
        theta.to_degrees()
    );
    assert_eq!(last.3, "engaged");
    if compiled.is_some() {
        assert!(out.contains("`swing_up` (generated code)"), "{out}");
        assert!(out.contains("loop allocations: 0 in 15000 cycles"), "{out}");
        // the interpreted hybrid controller replayed over what the generated
        // one measured: the same inputs up to rounding
        let diff = number_after(&out, "max |Vm difference| ").expect("compare line");
        println!("{name}: max |Vm difference| to the interpreted path {diff:e} V");
        assert!(diff < 1e-9, "{out}");
    }
}

#[test]
fn sim_swing_up_catches_and_balances() {
    swing_up(
        "sim_swing_up",
        &["--backend", "sim", "--x0", "alpha=3.0915926535897933"],
        None,
        None,
    );
}

#[test]
fn q2usb_fake_hil_swing_up_catches_and_balances() {
    let lib = fake_hil_lib();
    let lib = lib.to_str().expect("utf8");
    swing_up(
        "q2_swing_up",
        &["--backend", "q2usb", "--hil-lib", lib],
        Some("alpha0=3.0915926535897933rad"),
        None,
    );
}

#[test]
fn compiled_swing_up_and_sliding_mode_on_the_rig() {
    if std::process::Command::new(env!("CARGO"))
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("skipped: cargo not available");
        return;
    }
    // one rig crate for both runs (the second reuses the build)
    let rig = tmp("compiled_rig").join("rig");
    swing_up(
        "compiled_sim_swing_up",
        &["--backend", "sim", "--x0", "alpha=3.0915926535897933"],
        None,
        Some(&rig),
    );
    let lib = fake_hil_lib();
    let lib = lib.to_str().expect("utf8");
    swing_up(
        "compiled_q2_swing_up",
        &["--backend", "q2usb", "--hil-lib", lib],
        Some("alpha0=3.0915926535897933rad"),
        Some(&rig),
    );
    // the sliding-mode controller's rig (generated observer) on the simulator
    let rig = tmp("compiled_smc_rig").join("rig");
    sliding_30s(
        "compiled_sim_smc",
        &["--backend", "sim", "--x0", "alpha=10deg"],
        None,
        Some(&rig),
    );
}

fn sliding_30s(name: &str, backend: &[&str], fake: Option<&str>, compiled: Option<&Path>) {
    let dir = tmp(name);
    let log = dir.join("out.csv");
    let model = model();
    let mut args = vec!["run", model.as_str(), "--controller", "sliding_mode"];
    args.extend_from_slice(backend);
    let log_s = log.to_str().expect("utf8");
    // the encoder reads 10 deg as 114 counts (10.02 deg): catch within 12 deg
    args.extend_from_slice(&[
        "--catch-window",
        "12deg",
        "--duration",
        "30",
        "--log",
        log_s,
    ]);
    let (code, out, err) = run_case(&args, &dir, fake, compiled);
    println!("{name}:\n{out}{err}");
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("final state engaged"), "{out}");
    let text = std::fs::read_to_string(&log).expect("log");
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    assert!(!header.contains(&"mode"), "no modes: {header:?}");
    let a = header.iter().position(|h| *h == "alpha").unwrap();
    let rows: Vec<(f64, f64)> = text
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[0].parse().unwrap(), f[a].parse().unwrap())
        })
        .collect();
    assert_eq!(rows.len(), 30_001);
    let tail = rows
        .iter()
        .filter(|r| r.0 >= 25.0)
        .fold(0.0f64, |m, r| m.max(wrap(r.1).abs()));
    println!(
        "{name}: max |alpha| over the last 5 s {:.3} deg",
        tail.to_degrees()
    );
    assert!(tail.to_degrees() < 1.0, "{}", tail.to_degrees());
    if compiled.is_some() {
        assert!(out.contains("loop allocations: 0 in 30000 cycles"), "{out}");
        let diff = number_after(&out, "max |Vm difference| ").expect("compare line");
        println!("{name}: max |Vm difference| to the interpreted path {diff:e} V");
        assert!(diff < 1e-9, "{out}");
    }
}

#[test]
fn sim_sliding_mode_balances_from_10_degrees_for_30_s() {
    sliding_30s(
        "sim_smc",
        &["--backend", "sim", "--x0", "alpha=10deg"],
        None,
        None,
    );
}

#[test]
fn q2usb_fake_hil_sliding_mode_balances_from_10_degrees_for_30_s() {
    let lib = fake_hil_lib();
    let lib = lib.to_str().expect("utf8");
    sliding_30s(
        "q2_smc",
        &["--backend", "q2usb", "--hil-lib", lib],
        Some("alpha0=10deg"),
        None,
    );
}

#[test]
fn swing_up_refuses_the_observer_and_a_balancing_controller_never_engages_hanging() {
    let model = model();
    let (code, out, err) = plantc(&[
        "run",
        &model,
        "--controller",
        "swing_up",
        "--velocity",
        "observer",
        "--duration",
        "1",
    ]);
    assert_ne!(code, 0, "{out}{err}");
    assert!(err.contains("use --velocity derivative"), "{err}");
    // the same through the rig crate, refused before anything is generated
    let rig = tmp("refused_rig").join("rig");
    let (code, out, err) = plantc(&[
        "run",
        &model,
        "--controller",
        "swing_up",
        "--velocity",
        "observer",
        "--compiled",
        rig.to_str().unwrap(),
    ]);
    assert_ne!(code, 0, "{out}{err}");
    assert!(err.contains("use --velocity derivative"), "{err}");
    assert!(!rig.exists());
    // pole placement alone from hanging: the supervisor stays armed (0 V),
    // the run says why and fails (issue 28)
    let (code, out, err) = plantc(&[
        "run",
        &model,
        "--controller",
        "pole_placement",
        "--x0",
        "alpha=3.0915926535897933",
        "--duration",
        "1",
    ]);
    assert_eq!(code, 1, "{out}{err}");
    assert!(out.contains("final state armed"), "{out}");
    assert!(err.contains("the controller never engaged"), "{err}");
    assert!(err.contains("swing-up mode"), "{err}");
    let (code, _, err) = plantc(&[
        "run",
        &model,
        "--controller",
        "sliding_mode",
        "--catch-window",
        "40deg",
        "--duration",
        "1",
    ]);
    assert_ne!(code, 0);
    assert!(err.contains("--catch-window"), "{err}");
}

#[test]
fn sim_writes_the_mode_and_reports_switches() {
    let dir = tmp("sim_modes");
    let csv = dir.join("out.csv");
    let (code, out, err) = plantc(&[
        "sim",
        &model(),
        "--controller",
        "swing_up",
        "--x0",
        "alpha=3.0915926535897933",
        "--duration",
        "2",
        "--sample-rate",
        "1000",
        "--smooth-sign",
        "1e-3",
        "-o",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("mode at t = 0: pump"), "{out}");
    assert!(
        out.contains("mode switch at t = 0.431 s: pump -> catch"),
        "{out}"
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.lines().next().unwrap().ends_with(",mode"));
    assert!(text.lines().nth(1).unwrap().ends_with(",pump"));
    assert!(text.lines().last().unwrap().ends_with(",catch"));
}

#[test]
fn analyze_reports_the_sliding_dynamics() {
    let (code, out, err) = plantc(&["analyze", &model(), "--controller", "sliding_mode"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("c B = 1.000000"), "{out}");
    assert!(out.contains("sliding poles: -6, -3-2i, -3+2i"), "{out}");
    assert!(out.contains("asymptotically stable"), "{out}");
    let (code, out, err) = plantc(&["analyze", &model(), "--controller", "pole_placement"]);
    assert_ne!(code, 0, "{out}");
    assert!(err.contains("neither a sliding-mode"), "{err}");
    // a feedback-linearizing controller: its output's analysis
    let (code, out, _) = plantc(&["analyze", &model(), "--controller", "fl_arm"]);
    assert_eq!(code, 0);
    assert!(out.contains("output y = alpha, relative degree 2"), "{out}");
}

#[test]
fn robustness_prints_the_table() {
    let (code, out, err) = plantc(&[
        "robustness",
        &model(),
        "--set",
        "thesis",
        "--controller",
        "pole_placement",
        "--controller",
        "feedback_linearization",
        "--vary",
        "J1",
        "--add",
        "Fg1=0.01",
        "--x0",
        "alpha=10deg",
        "--duration",
        "4",
        "--threads",
        "2",
    ]);
    assert_eq!(code, 0, "{out}{err}");
    println!("{out}");
    for label in ["nominal", "J1 -20%", "J1 +20%", "Fg1 = 0.01"] {
        assert!(out.contains(label), "{label}: {out}");
    }
    assert!(out.contains("4 of 8 cases hold"), "{out}");
    let (code, _, err) = plantc(&["robustness", &model(), "--vary", "J9"]);
    assert_ne!(code, 0);
    assert!(err.contains("`J9` is not a parameter"), "{err}");
}
