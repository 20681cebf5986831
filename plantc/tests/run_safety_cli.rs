//! `plantc run` safety outside the loop. Stopped by a signal (reliability
//! reproducer 03): SIGINT,
//! SIGTERM, SIGHUP and SIGQUIT each end the run like Ctrl-C: `fault:stopped`,
//! 0 V the last value written, the board closed, the log flushed, and the exit
//! code 128 + signal. Against the fake HIL board (which refuses the watchdog,
//! so nothing but plantc can bring the output back to 0 V) and against the
//! simulator in real time. `--hil-lib NAME` (reproducer 14): a bare name is
//! a file of the current directory first, and what was loaded is said.
//! Unix only (signals, `.so` names).
#![cfg(unix)]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{model, repo, tmp};

extern "C" {
    fn kill(pid: i32, sig: i32) -> i32;
    fn signal(sig: i32, handler: usize) -> usize;
}

/// Every signal of [`SIGNALS`] at its default disposition in the child, as
/// when a run is started from a terminal, whatever this test inherited (a
/// background job of a non-interactive shell starts with SIGINT and SIGQUIT
/// ignored, and plantc keeps a signal ignored at its start ignored, as
/// `nohup` asks: `nohup_keeps_sighup_ignored`).
fn default_signals(cmd: &mut Command) -> &mut Command {
    use std::os::unix::process::CommandExt;
    const SIG_DFL: usize = 0;
    // SAFETY: between fork and exec, only the async-signal-safe `signal`.
    unsafe {
        cmd.pre_exec(|| {
            for (_, sig) in SIGNALS {
                signal(sig, SIG_DFL);
            }
            Ok(())
        })
    }
}

/// Builds (once) and locates the fake HIL cdylib.
fn fake_hil() -> PathBuf {
    use std::sync::OnceLock;
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        let status = Command::new(env!("CARGO"))
            .args(["build", "-p", "plantc-fake-hil"])
            .current_dir(repo())
            .status()
            .expect("cargo runs");
        assert!(status.success(), "cargo build -p plantc-fake-hil");
        let name = format!(
            "{}plantc_fake_hil{}",
            std::env::consts::DLL_PREFIX,
            std::env::consts::DLL_SUFFIX
        );
        let exe = std::env::current_exe().unwrap();
        let profile = exe.parent().and_then(Path::parent).unwrap().to_path_buf();
        [profile.join(&name), repo().join("target/debug").join(&name)]
            .into_iter()
            .find(|p| p.is_file())
            .unwrap_or_else(|| panic!("{name} not found"))
    })
    .clone()
}

/// Waits until the log has at least `rows` data rows (the loop is running).
fn wait_for_rows(child: &mut Child, log: &Path, rows: usize) {
    let start = Instant::now();
    loop {
        let n = std::fs::read_to_string(log).map_or(0, |t| t.lines().count());
        if n > rows + 1 {
            return;
        }
        if let Ok(Some(status)) = child.try_wait() {
            panic!("run ended before the signal: {status}");
        }
        assert!(start.elapsed() < Duration::from_secs(60), "no log rows");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Sends `sig`, waits (bounded) and returns the exit code and stderr.
fn signal_and_wait(mut child: Child, sig: i32) -> (i32, String) {
    // SAFETY: plain kill(2) on our own child.
    assert_eq!(unsafe { kill(child.id() as i32, sig) }, 0);
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            use std::io::Read;
            child
                .stderr
                .take()
                .unwrap()
                .read_to_string(&mut err)
                .unwrap();
            return (status.code().unwrap_or(-1), err);
        }
        if start.elapsed() > Duration::from_secs(20) {
            let _ = child.kill();
            panic!("signal {sig} did not stop the run within 20 s");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The log's last row: (vm, state); and whether the file ends with a newline.
fn last_row(log: &Path) -> (f64, String, bool) {
    let text = std::fs::read_to_string(log).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let last: Vec<&str> = text.lines().last().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| h.starts_with(name)).unwrap();
    (
        last[col("Vm")].parse().unwrap(),
        last[col("state")].to_string(),
        text.ends_with('\n'),
    )
}

const SIGNALS: [(&str, i32); 4] = [
    ("SIGINT", 2),
    ("SIGTERM", 15),
    ("SIGHUP", 1),
    ("SIGQUIT", 3),
];

#[test]
fn every_terminating_signal_stops_the_board_at_zero_volts() {
    let lib = fake_hil();
    let dir = tmp("signals_q2usb");
    for (name, sig) in SIGNALS {
        let log = dir.join(format!("{name}.csv"));
        let trace = dir.join(format!("{name}.trace"));
        let mut child = default_signals(&mut Command::new(env!("CARGO_BIN_EXE_plantc")))
            .args(["run", &model(), "--controller", "pole_placement"])
            .args(["--backend", "q2usb", "--hil-lib", lib.to_str().unwrap()])
            .args(["--allow-no-watchdog", "--duration", "100000"])
            .args(["--log", log.to_str().unwrap()])
            .env("PLANTC_FAKE_HIL", "alpha0=5deg,watchdog_refused")
            .env("PLANTC_FAKE_HIL_TRACE", &trace)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        wait_for_rows(&mut child, &log, 500);
        let (code, err) = signal_and_wait(child, sig);
        assert_eq!(code, 128 + sig, "{name}: {err}");
        assert!(err.contains(&format!("stopped by {name}")), "{name}: {err}");
        let t = std::fs::read_to_string(&trace).unwrap();
        let last_write = t.lines().rfind(|l| l.contains("write ch=0")).unwrap();
        assert!(last_write.contains("v=0.000000 ok"), "{name}: {last_write}");
        assert!(
            t.lines().last().unwrap().contains("close output=0.000000"),
            "{name}: board not closed at 0 V: {:?}",
            t.lines().last()
        );
        let (vm, state, complete) = last_row(&log);
        assert_eq!(
            (vm, state.as_str(), complete),
            (0.0, "fault:stopped", true),
            "{name}"
        );
    }
}

#[test]
fn sigterm_stops_a_real_time_simulated_run() {
    let dir = tmp("signals_sim");
    let log = dir.join("run.csv");
    let child = Command::new(env!("CARGO_BIN_EXE_plantc"))
        .args([
            "run",
            &model(),
            "--controller",
            "pole_placement",
            "--x0",
            "alpha=5deg",
        ])
        .args([
            "--realtime",
            "--duration",
            "60",
            "--log",
            log.to_str().unwrap(),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut child = child;
    wait_for_rows(&mut child, &log, 200);
    // twice, as from a process-group kill plus the one a parent forwards:
    // the duplicate must not cut the safe stop short
    // SAFETY: plain kill(2) on our own child.
    assert_eq!(unsafe { kill(child.id() as i32, 15) }, 0);
    let (code, err) = signal_and_wait(child, 15);
    assert_eq!(code, 143, "{err}");
    let (vm, state, complete) = last_row(&log);
    assert_eq!((vm, state.as_str(), complete), (0.0, "fault:stopped", true));
}

/// Runs the built binary in `dir` with the fake HIL configured.
fn run_in(dir: &Path, hil_lib: &str) -> (i32, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_plantc"))
        .args(["run", &model(), "--controller", "pole_placement"])
        .args([
            "--backend",
            "q2usb",
            "--hil-lib",
            hil_lib,
            "--duration",
            "0.2",
        ])
        .env("PLANTC_FAKE_HIL", "alpha0=5deg")
        .current_dir(dir)
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn a_bare_hil_lib_name_is_a_file_of_the_current_directory() {
    let dir = tmp("hil_lib_bare");
    std::fs::copy(fake_hil(), dir.join("libhil_local.so")).unwrap();
    let (code, err) = run_in(&dir, "libhil_local.so");
    assert_eq!(code, 0, "{err}");
    let here = std::fs::canonicalize(&dir).unwrap();
    assert!(
        err.contains(&format!(
            "note: HIL library: `{}/libhil_local.so`",
            here.display()
        )),
        "{err}"
    );
    // a local file named like a system library wins over the system one
    std::fs::copy(fake_hil(), dir.join("libm.so.6")).unwrap();
    let (code, err) = run_in(&dir, "libm.so.6");
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains(&format!("{}/libm.so.6`", here.display())),
        "{err}"
    );
    // without the local file the system's libm loads, and is named as no HIL library
    std::fs::remove_file(dir.join("libm.so.6")).unwrap();
    let (code, err) = run_in(&dir, "libm.so.6");
    assert_ne!(code, 0, "{err}");
    assert!(
        err.contains("libm.so.6: it loaded, but is not a HIL library (no `hil_open`)"),
        "{err}"
    );
}

#[test]
fn run_help_names_the_default_hil_libraries() {
    let o = Command::new(env!("CARGO_BIN_EXE_plantc"))
        .args(["help", "run"])
        .output()
        .unwrap();
    let help = String::from_utf8_lossy(&o.stdout)
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    for c in plantc_runtime::hil_ffi::default_library_candidates() {
        assert!(
            help.contains(&c.display().to_string()),
            "help lacks {}: {help}",
            c.display()
        );
    }
}

/// Issue 31 (r16): started under `nohup` (SIGHUP ignored), `plantc run` keeps
/// SIGHUP ignored: a hang-up does not stop the run.
#[test]
fn nohup_keeps_sighup_ignored() {
    let dir = tmp("nohup");
    let log = dir.join("run.csv");
    let mut child = Command::new("nohup")
        .arg(env!("CARGO_BIN_EXE_plantc"))
        .args(["run", &model(), "--controller", "pole_placement"])
        .args(["--x0", "alpha=5deg", "--realtime", "--duration", "1.5"])
        .args(["--log", log.to_str().unwrap()])
        .current_dir(&dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_for_rows(&mut child, &log, 200);
    // SAFETY: plain kill(2) on our own child.
    assert_eq!(unsafe { kill(child.id() as i32, 1) }, 0);
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(0), "stopped by the ignored SIGHUP");
    let (_, state, complete) = last_row(&log);
    assert_eq!((state.as_str(), complete), ("engaged", true));
}
