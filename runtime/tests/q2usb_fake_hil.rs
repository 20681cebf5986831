//! The Q2-USB backend against the fake HIL library (virtual time): balancing
//! and every injected fault ends in Fault with 0 V last and the fault logged.

mod common;

use common::{fake_hil_lib, parse_log, read_trace, tmp_path, Row, Trace, K_THESIS};
use plantc_runtime::{
    run_with_events, BackendError, FaultKind, LogWriter, Q2Usb, Q2UsbConfig, RunConfig, RunReport,
    RuntimeError, StateFeedback, SupervisorState,
};
use std::sync::Mutex;

/// The fake card is a process-wide singleton configured through the
/// environment: fake-HIL tests run one at a time.
static SERIAL: Mutex<()> = Mutex::new(());

struct Outcome {
    result: Result<RunReport, RuntimeError>,
    rows: Vec<Row>,
    trace: Trace,
}

fn run_fake(name: &str, spec: &str, seconds: f64, allow_no_watchdog: bool) -> Outcome {
    let lib = fake_hil_lib();
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let trace_path = tmp_path(&format!("{name}.trace"));
    let log_path = tmp_path(&format!("{name}.csv"));
    std::env::set_var("PLANTC_FAKE_HIL", spec);
    std::env::set_var("PLANTC_FAKE_HIL_TRACE", &trace_path);
    let cfg = Q2UsbConfig {
        library_path: Some(lib),
        allow_no_watchdog,
        ..Q2UsbConfig::default()
    };
    let run_cfg = RunConfig {
        duration_s: Some(seconds),
        // The fake board runs in virtual time: no real-time priority.
        os_realtime: false,
        ..RunConfig::default()
    };
    let result = match Q2Usb::open(cfg) {
        Ok(mut board) => {
            let mut log = LogWriter::create(&log_path).expect("log");
            let mut ctl = StateFeedback::new(K_THESIS.to_vec());
            let r = run_with_events(&run_cfg, &mut board, &mut ctl, Some(&mut log), &mut |t| {
                println!("[{name}] {t}")
            });
            for n in board.notes() {
                println!("[{name}] note: {n}");
            }
            drop(board);
            r
        }
        Err(e) => Err(RuntimeError::Backend(e)),
    };
    let rows = match std::fs::read_to_string(&log_path) {
        Ok(text) => parse_log(&text, false).expect("log parses"),
        Err(_) => Vec::new(),
    };
    let trace = read_trace(&trace_path);
    if let Ok(r) = &result {
        println!("[{name}] {r}");
    }
    Outcome {
        result,
        rows,
        trace,
    }
}

fn assert_zero_volts_last(o: &Outcome) {
    let last = o.trace.ok_writes.last().copied();
    assert_eq!(
        last,
        Some(0.0),
        "last successful write must be 0 V: {:?}",
        &o.trace.lines[o.trace.lines.len().saturating_sub(8)..]
    );
    assert_eq!(
        o.trace.close_output,
        Some(0.0),
        "output at close must be 0 V"
    );
}

fn assert_fault(o: &Outcome, kind: FaultKind) {
    let r = o.result.as_ref().expect("run");
    assert_eq!(r.final_state, SupervisorState::Fault(kind), "{r}");
    let last = o.rows.last().expect("rows");
    assert_eq!(last.state, format!("fault:{}", kind.name()));
    assert_eq!(last.vm, 0.0);
    assert_zero_volts_last(o);
}

#[test]
fn balances_through_the_fake_board() {
    let o = run_fake("balance", "alpha0=5deg", 30.0, false);
    let r = o.result.as_ref().expect("run");
    assert_eq!(r.final_state, SupervisorState::Engaged, "{r}");
    assert_eq!(o.rows.len(), 30_001);
    let max_alpha = o
        .rows
        .iter()
        .filter(|r| r.t >= 20.0)
        .map(|r| r.alpha.abs())
        .fold(0.0, f64::max);
    assert!(max_alpha < 0.5f64.to_radians(), "{max_alpha}");
    // The controller was really driving the board.
    assert!(o.trace.ok_writes.iter().any(|v| v.abs() > 0.5));
    assert_zero_volts_last(&o);
}

#[test]
fn read_error_faults() {
    let o = run_fake(
        "read_error",
        "alpha0=5deg,fault=read_error@2.0",
        10.0,
        false,
    );
    assert_fault(&o, FaultKind::ReadError);
    let r = o.result.as_ref().unwrap();
    let detail = r.fault_detail.as_deref().unwrap_or("");
    assert!(
        detail.contains("-101") && detail.contains("injected read_error"),
        "{detail}"
    );
    let t = o.rows.last().unwrap().t;
    assert!((t - 2.0).abs() < 0.01, "{t}");
}

#[test]
fn stuck_encoder_faults() {
    let o = run_fake("stuck", "alpha0=5deg,fault=stuck_encoder@2.0", 10.0, false);
    assert_fault(&o, FaultKind::EncoderStuck);
}

#[test]
fn slow_calls_fault_as_overruns() {
    let o = run_fake("slow", "alpha0=5deg,fault=slow_calls@1.0", 10.0, false);
    assert_fault(&o, FaultKind::Overrun);
    let r = o.result.as_ref().unwrap();
    assert!(r.overruns >= 5, "{r}");
    assert!(o.rows.iter().rev().take(5).all(|r| r.overrun));
}

#[test]
fn watchdog_not_reloaded_expires() {
    let o = run_fake("no_reload", "alpha0=5deg,fault=no_reload@1.0", 10.0, false);
    // The expired board refuses writes: the output is 0 V by its expiration
    // state (not by a write); the refused 0 V writes are reported, the
    // watchdog is not cleared before the card is closed.
    let r = o.result.as_ref().expect("run");
    assert_eq!(
        r.final_state,
        SupervisorState::Fault(FaultKind::WatchdogExpired),
        "{r}"
    );
    assert_eq!(o.rows.last().unwrap().vm, 0.0);
    assert!(o.trace.expired);
    assert_eq!(o.trace.close_output, Some(0.0));
    assert!(!o.trace.lines.iter().any(|l| l.contains("watchdog_clear")));
    assert!(
        r.stop_errors.len() >= 2
            && r.stop_errors
                .last()
                .unwrap()
                .contains("0 V expiration state"),
        "{:?}",
        r.stop_errors
    );
    let t = o.rows.last().unwrap().t;
    assert!(
        (1.09..1.2).contains(&t),
        "expiry 0.1 s after 1.0 s, got {t}"
    );
}

#[test]
fn watchdog_refused_blocks_start_without_override() {
    let o = run_fake(
        "wd_refused",
        "alpha0=5deg,fault=watchdog_refused",
        5.0,
        false,
    );
    match &o.result {
        Err(RuntimeError::Backend(BackendError::WatchdogRefused { code, message })) => {
            assert_eq!(*code, -102);
            assert!(message.contains("watchdog_refused"), "{message}");
        }
        other => panic!("expected a refusal, got {other:?}"),
    }
    assert!(o.rows.is_empty());
    assert!(o.trace.ok_writes.iter().all(|&v| v == 0.0));
    assert_zero_volts_last(&o);
}

#[test]
fn watchdog_refused_runs_with_override() {
    let o = run_fake(
        "wd_override",
        "alpha0=5deg,fault=watchdog_refused",
        5.0,
        true,
    );
    let r = o.result.as_ref().expect("run");
    assert_eq!(r.final_state, SupervisorState::Engaged, "{r}");
    assert_zero_volts_last(&o);
}

#[test]
fn falls_back_to_os_timing_without_tasks() {
    // Real time: hil_read_encoder paced by the OS clock at 1 kHz for 1 s.
    let o = run_fake("no_tasks", "alpha0=5deg,no_tasks", 1.0, false);
    let r = o.result.as_ref().expect("run");
    assert!(
        !r.final_state.is_fault() || r.final_state == SupervisorState::Fault(FaultKind::Overrun),
        "{r}"
    );
    assert_zero_volts_last(&o);
}
