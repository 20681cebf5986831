//! Supervisor and loop behaviour on the simulator: every exit path writes 0 V
//! last, outputs are clamped, the controller only drives when engaged.

mod common;

use common::{parse_log, tmp_path, K_THESIS};
use plantc_runtime::{
    run, Controller, FaultKind, LogWriter, RotaryPendulumReference, RunConfig, RuntimeError,
    SimBackend, SimConfig, StateFeedback, SupervisorState,
};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

fn sim(alpha0_deg: f64) -> SimBackend {
    SimBackend::new(
        Box::new(RotaryPendulumReference::default()),
        vec![0.0, alpha0_deg.to_radians(), 0.0, 0.0],
        SimConfig::default(),
    )
    .unwrap()
}

fn cfg(seconds: f64) -> RunConfig {
    RunConfig {
        duration_s: Some(seconds),
        ..RunConfig::default()
    }
}

/// Balances, then misbehaves from `t_bad` on.
struct Misbehaving {
    inner: StateFeedback,
    t_bad: f64,
    mode: u8,
    stop: Option<Arc<AtomicBool>>,
}

impl Controller for Misbehaving {
    fn control(&mut self, t: f64, x: &[f64], u: &mut [f64]) {
        self.inner.control(t, x, u);
        if t >= self.t_bad {
            match self.mode {
                0 => panic!("controller bug at t={t}"),
                1 => u[0] = f64::NAN,
                2 => {
                    if let Some(s) = &self.stop {
                        s.store(true, Ordering::Relaxed);
                    }
                }
                _ => u[0] = 1e6,
            }
        }
    }
}

fn misbehave(mode: u8, name: &str) -> (plantc_runtime::RunReport, Vec<common::Row>, f64) {
    let mut c = cfg(5.0);
    let stop = Arc::new(AtomicBool::new(false));
    c.stop = stop.clone();
    let mut be = sim(5.0);
    let mut ctl = Misbehaving {
        inner: StateFeedback::new(K_THESIS.to_vec()),
        t_bad: 1.0,
        mode,
        stop: Some(stop),
    };
    let path = tmp_path(name);
    let mut log = LogWriter::create(&path).unwrap();
    let report = run(&c, &mut be, &mut ctl, Some(&mut log)).unwrap();
    drop(log);
    let rows = parse_log(&std::fs::read_to_string(&path).unwrap(), false).unwrap();
    (report, rows, be.last_written())
}

#[test]
fn controller_panic_faults_with_zero_volts() {
    let (r, rows, last) = misbehave(0, "panic.csv");
    assert_eq!(
        r.final_state,
        SupervisorState::Fault(FaultKind::ControllerPanic)
    );
    assert_eq!(last, 0.0);
    let l = rows.last().unwrap();
    assert_eq!(l.state, "fault:controller_panic");
    assert_eq!(l.vm, 0.0);
    assert!((l.t - 1.0).abs() < 1e-9);
}

#[test]
fn non_finite_output_faults_with_zero_volts() {
    let (r, rows, last) = misbehave(1, "nan.csv");
    assert_eq!(
        r.final_state,
        SupervisorState::Fault(FaultKind::NonFiniteOutput)
    );
    assert_eq!(last, 0.0);
    assert_eq!(rows.last().unwrap().state, "fault:non_finite_output");
    assert!(rows.last().unwrap().vm_cmd.is_nan());
}

#[test]
fn stop_flag_faults_as_stopped() {
    let (r, rows, last) = misbehave(2, "stop.csv");
    assert_eq!(r.final_state, SupervisorState::Fault(FaultKind::Stopped));
    assert_eq!(last, 0.0);
    assert_eq!(rows.last().unwrap().state, "fault:stopped");
    // Set during the t = 1.0 call, seen at the next sample.
    assert!((rows.last().unwrap().t - 1.001).abs() < 1e-9);
}

#[test]
fn output_is_clamped_to_the_input_limits() {
    let (r, rows, last) = misbehave(3, "clamp.csv");
    assert_eq!(last, 0.0);
    let big: Vec<_> = rows.iter().filter(|r| r.vm_cmd > 1e5).collect();
    assert!(!big.is_empty(), "{r}");
    assert!(rows.iter().all(|r| r.vm.abs() <= 10.0));
    assert!(big.iter().any(|r| r.vm == 10.0));
}

#[test]
fn arm_limit_faults() {
    let mut c = cfg(5.0);
    c.supervisor.arm_limit_rad = 0.02;
    let mut be = sim(5.0);
    let mut ctl = StateFeedback::new(K_THESIS.to_vec());
    let r = run(&c, &mut be, &mut ctl, None).unwrap();
    assert_eq!(
        r.final_state,
        SupervisorState::Fault(FaultKind::ArmLimit),
        "{r}"
    );
    assert_eq!(be.last_written(), 0.0);
}

#[test]
fn outside_the_catch_window_stays_armed_at_zero_volts() {
    let path = tmp_path("armed.csv");
    let mut log = LogWriter::create(&path).unwrap();
    let mut be = sim(20.0);
    let mut ctl = StateFeedback::new(K_THESIS.to_vec());
    let r = run(&cfg(0.2), &mut be, &mut ctl, Some(&mut log)).unwrap();
    drop(log);
    assert_eq!(r.final_state, SupervisorState::Armed, "{r}");
    assert_eq!(r.controller_ns.count, 0);
    let rows = parse_log(&std::fs::read_to_string(&path).unwrap(), false).unwrap();
    assert!(rows.iter().all(|r| r.vm == 0.0 && r.state == "armed"));
}

#[test]
fn invalid_configuration_is_an_error_not_a_panic() {
    let mut be = sim(5.0);
    let mut ctl = StateFeedback::new(K_THESIS.to_vec());
    let mut c = cfg(1.0);
    c.rate_hz = 5000.0;
    assert!(matches!(
        run(&c, &mut be, &mut ctl, None),
        Err(RuntimeError::InvalidConfig(_))
    ));
    let mut c = cfg(1.0);
    c.state_names.pop();
    assert!(matches!(
        run(&c, &mut be, &mut ctl, None),
        Err(RuntimeError::InvalidConfig(_))
    ));
    // issue 31 (r12): a duration whose sample count leaves f64's exact
    // integers is refused (2e16 s at 1 kHz used to run 0 samples, "ok")
    for d in [1.8e16, 2e16, 1e300] {
        let mut c = cfg(1.0);
        c.duration_s = Some(d);
        match run(&c, &mut be, &mut ctl, None) {
            Err(RuntimeError::InvalidConfig(m)) => assert!(m.contains("2^53"), "{m}"),
            other => panic!("duration {d}: {other:?}"),
        }
    }
    assert_eq!(be.last_written(), 0.0);
}

#[test]
fn q2usb_without_library_is_a_load_error() {
    let cfg = plantc_runtime::Q2UsbConfig {
        library_path: Some("/nonexistent/libhil.so".into()),
        ..Default::default()
    };
    match plantc_runtime::Q2Usb::open(cfg) {
        Err(plantc_runtime::BackendError::Load { path, .. }) => {
            assert!(path.contains("nonexistent"))
        }
        Err(e) => panic!("unexpected {e}"),
        Ok(_) => panic!("opened a nonexistent library"),
    }
}

/// The reference pendulum, until its dynamics blow up at `t_bad` (as a stiff
/// or badly parameterised model does): derivatives become NaN.
struct Diverging {
    inner: RotaryPendulumReference,
    calls: std::sync::atomic::AtomicU64,
    bad_after_calls: u64,
}

impl plantc_runtime::Plant for Diverging {
    fn state_names(&self) -> &[&str] {
        self.inner.state_names()
    }
    fn input_names(&self) -> &[&str] {
        self.inner.input_names()
    }
    fn derivatives(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let calls = self.calls.fetch_add(1, Ordering::Relaxed) + 1;
        self.inner.derivatives(x, u, dx);
        if calls > self.bad_after_calls {
            dx.fill(f64::NAN);
        }
    }
    fn input_limits(&self) -> &[(f64, f64)] {
        self.inner.input_limits()
    }
}

/// Reliability reproducer 04: a diverged simulation read as encoder counts
/// of 0 (a pendulum balanced at rest), ending "engaged" with exit 0, or later
/// as `fault:encoder_stuck`. It is now a fault naming the divergence, at the
/// first sample after it, with 0 V written.
#[test]
fn a_diverged_simulation_is_a_fault_naming_it() {
    let plant = Diverging {
        inner: RotaryPendulumReference::default(),
        calls: std::sync::atomic::AtomicU64::new(0),
        // 4 RK4 stages x 1 substep per 1 ms sample: diverges after 0.5 s
        bad_after_calls: 2_000,
    };
    let mut be = SimBackend::new(
        Box::new(plant),
        vec![0.0, 5f64.to_radians(), 0.0, 0.0],
        SimConfig::default(),
    )
    .unwrap();
    let log_path = tmp_path("diverged.csv");
    let mut log = LogWriter::create(&log_path).unwrap();
    let mut ctl = StateFeedback::new(K_THESIS.to_vec());
    let report = run(&cfg(5.0), &mut be, &mut ctl, Some(&mut log)).unwrap();
    drop(log);
    assert_eq!(
        report.final_state,
        SupervisorState::Fault(FaultKind::PlantDiverged),
        "{report}"
    );
    let detail = report.fault_detail.as_deref().unwrap_or_default();
    assert!(
        detail.contains("diverged") && detail.contains("alpha = NaN"),
        "{detail}"
    );
    let rows = parse_log(&std::fs::read_to_string(&log_path).unwrap(), false).unwrap();
    let last = rows.last().unwrap();
    assert_eq!(last.state, "fault:plant_diverged");
    assert_eq!(last.vm, 0.0);
    assert!(last.t <= 0.6, "{}", last.t);
    assert_eq!(be.last_written(), 0.0);
}
