//! `plantc run --backend q2usb` against a failing HIL library (issue 31,
//! reproducer r01): the fake HIL board (`runtime/fake-hil`) injects write,
//! read, watchdog and close failures and hung calls (`PLANTC_FAKE_HIL`).
//! In every case the process ends with a non-zero exit code, every failed
//! 0 V write is reported on stderr, and the board's trace (flushed line by
//! line, so it tells the board's state however the process ended) shows the
//! output at 0 V or the watchdog still armed with its 0 V expiration state
//! when the process ends. Unix only (`.so` names, process exit codes).
#![cfg(unix)]

mod common;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use common::{fake_hil_lib, model, tmp};

/// The fake board's state at the end of its trace.
#[derive(Debug, Default)]
struct Board {
    /// Voltage on the output (the last accepted write, 0 after an expiry).
    output: f64,
    /// The watchdog was started and not stopped since.
    armed: bool,
    /// The expiration state (0 V) was accepted.
    expiration_set: bool,
    expired: bool,
    closed: bool,
    /// Injected failures and hangs seen.
    injected: usize,
    hung: Option<String>,
}

impl Board {
    fn from_trace(path: &Path) -> (Board, String) {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        let mut b = Board::default();
        for line in text.lines() {
            let mut it = line.split_whitespace().skip(1);
            let what = it.next().unwrap_or("");
            let rest: Vec<&str> = it.collect();
            let injected = rest.contains(&"err=injected");
            if injected {
                b.injected += 1;
                continue;
            }
            match what {
                "write" if rest.last() == Some(&"ok") => {
                    b.output = rest[1].strip_prefix("v=").unwrap().parse().unwrap()
                }
                "watchdog_start" => b.armed = true,
                "watchdog_stop" => b.armed = false,
                "watchdog_expiration_state" => b.expiration_set = true,
                "watchdog_expired" => {
                    b.expired = true;
                    b.output = 0.0;
                }
                "watchdog_clear" => b.expired = false,
                "close" => b.closed = true,
                "hang" => b.hung = Some(rest[0].to_string()),
                _ => {}
            }
        }
        (b, text)
    }

    /// The output is at 0 V, or it is held by an armed watchdog (or its
    /// expiry) whose expiration state is 0 V.
    fn safe(&self) -> bool {
        self.output == 0.0 || (self.armed && self.expiration_set) || self.expired
    }
}

struct Outcome {
    code: i32,
    stderr: String,
    board: Board,
    trace: String,
    elapsed: Duration,
}

/// `plantc run` on the fake board with `faults` (a `PLANTC_FAKE_HIL` list).
fn run_with(name: &str, faults: &str, extra: &[&str]) -> Outcome {
    let lib = fake_hil_lib();
    let dir = tmp(name);
    let trace = dir.join("board.trace");
    let start = Instant::now();
    let o = Command::new(env!("CARGO_BIN_EXE_plantc"))
        .args(["run", &model(), "--controller", "pole_placement"])
        .args(["--backend", "q2usb", "--hil-lib", lib.to_str().unwrap()])
        .args(["--duration", "2"])
        .args(extra)
        .env("PLANTC_FAKE_HIL", format!("alpha0=5deg,{faults}"))
        .env("PLANTC_FAKE_HIL_TRACE", &trace)
        .current_dir(&dir)
        .output()
        .expect("plantc runs");
    let elapsed = start.elapsed();
    let (board, trace) = Board::from_trace(&trace);
    Outcome {
        code: o.status.code().unwrap_or(-1),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
        board,
        trace,
        elapsed,
    }
}

fn assert_safe_and_failed(name: &str, o: &Outcome) {
    let tail: Vec<&str> = o.trace.lines().rev().take(8).collect();
    assert!(
        o.board.safe(),
        "{name}: the board is not safe at the end: {:?}\ntrace tail: {tail:?}\nstderr: {}",
        o.board,
        o.stderr
    );
    assert_ne!(
        o.code, 0,
        "{name}: exit 0 after a HIL failure: {}",
        o.stderr
    );
    assert!(
        o.board.injected > 0 || o.board.hung.is_some(),
        "{name}: no fault was injected: {tail:?}"
    );
}

#[test]
fn write_errors_keep_the_watchdog_armed_and_every_failed_zero_write_is_reported() {
    // every write fails from t = 1 s, the 0 V ones too: the r01 case
    let o = run_with("write_error", "fault=write_error@1.0", &[]);
    assert_safe_and_failed("write_error", &o);
    assert!(o.board.armed && !o.board.closed, "{:?}", o.board);
    assert!(
        o.board.output != 0.0,
        "the controller was driving when writes began to fail: {:?}",
        o.board
    );
    // the loop's 0 V write after the fault and the close's two attempts
    let failed_zero = o.stderr.matches("hil_write_analog failed").count();
    assert!(failed_zero >= 3, "{failed_zero} reported: {}", o.stderr);
    assert_eq!(
        failed_zero,
        o.board.injected - 1,
        "every injected 0 V failure is reported (the first is the fault itself): {}",
        o.stderr
    );
    assert!(o.stderr.contains("watchdog armed"), "{}", o.stderr);
    assert_eq!(o.code, 1, "{}", o.stderr);
}

#[test]
fn a_board_refusing_zero_volts_at_open_is_left_with_its_watchdog_armed() {
    let o = run_with("write_error_zero", "fault=write_error_zero", &[]);
    assert_safe_and_failed("write_error_zero", &o);
    assert!(o.board.armed, "re-armed for the safe stop: {:?}", o.board);
    assert!(o.stderr.contains("hil_write_analog failed"), "{}", o.stderr);
}

#[test]
fn read_reload_and_expiry_faults_end_at_zero_volts_with_the_board_closed() {
    for (name, faults) in [
        ("read_error", "fault=read_error@1.0"),
        ("reload_error", "fault=reload_error@1.0"),
        ("no_reload", "fault=no_reload@1.0"),
    ] {
        let o = run_with(name, faults, &[]);
        if name != "no_reload" {
            assert_safe_and_failed(name, &o);
        } else {
            // no injected call failure: the watchdog expires by itself
            assert!(o.board.expired && o.board.safe(), "{:?}", o.board);
            assert_eq!(o.code, 1, "{}", o.stderr);
            // writes refused after the expiry are reported, with what holds the output
            assert!(o.stderr.contains("0 V expiration state"), "{}", o.stderr);
        }
        assert_eq!(o.board.output, 0.0, "{name}: {:?}", o.board);
        assert!(o.board.closed, "{name}: {:?}", o.board);
    }
}

#[test]
fn watchdog_and_close_failures_are_reported_and_fail_the_run() {
    for (name, faults, expect) in [
        (
            "wd_start",
            "fault=watchdog_start_error",
            "hil_watchdog_start",
        ),
        (
            "wd_stop",
            "fault=watchdog_stop_error",
            "hil_watchdog_stop failed",
        ),
        ("close_error", "fault=close_error", "hil_close failed"),
    ] {
        let o = run_with(name, faults, &[]);
        assert_safe_and_failed(name, &o);
        assert_eq!(o.board.output, 0.0, "{name}: {:?}", o.board);
        assert!(o.stderr.contains(expect), "{name}: {}", o.stderr);
        assert_eq!(o.code, 1, "{name}: {}", o.stderr);
    }
}

#[test]
fn a_hung_call_ends_the_process_after_its_deadline_with_the_watchdog_armed() {
    for (name, faults) in [
        ("hang_write", "fault=hang_write@1.0"),
        ("hang_read", "fault=hang_read@1.0"),
        ("hang_close", "fault=hang_close"),
    ] {
        let o = run_with(name, faults, &[]);
        assert_safe_and_failed(name, &o);
        assert!(o.board.hung.is_some(), "{name}: {:?}", o.board);
        assert!(
            o.stderr.contains("has not returned after"),
            "{name}: {}",
            o.stderr
        );
        if name == "hang_close" {
            // 0 V confirmed and the watchdog stopped before hil_close
            assert_eq!(o.board.output, 0.0, "{name}: {:?}", o.board);
        } else {
            assert!(o.board.armed, "{name}: {:?}", o.board);
            assert!(o.stderr.contains("watchdog is armed"), "{}", o.stderr);
        }
        // the deadline is 1 s at 1 kHz and a 0.1 s watchdog; generous bound
        // for a loaded machine, well short of a hang
        assert!(
            o.elapsed < Duration::from_secs(30),
            "{name}: {:?}",
            o.elapsed
        );
    }
}
