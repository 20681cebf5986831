//! Real-time timing of the sim backend; prints the run report's numbers.

use plantc_runtime::{
    run, RotaryPendulumReference, RunConfig, SimBackend, SimConfig, StateFeedback, SupervisorState,
};

fn timed(rate: f64, seconds: f64) {
    let plant = RotaryPendulumReference::default();
    let mut cfg = RunConfig::for_plant(&plant);
    cfg.duration_s = Some(seconds);
    cfg.rate_hz = rate;
    let sim = SimConfig {
        real_time: true,
        ..SimConfig::default()
    };
    let mut be = SimBackend::new(Box::new(plant), vec![0.0, 0.05, 0.0, 0.0], sim).unwrap();
    let mut ctl = StateFeedback::new(vec![-7.8914, 37.8313, -2.9850, 3.6222]);
    let report = run(&cfg, &mut be, &mut ctl, None).unwrap();
    println!("--- {rate} Hz, {seconds} s real time ---\n{report}");
    assert!(!report.virtual_time);
    // Timing on a shared 2-core machine is noisy: assert only what must hold.
    assert!(matches!(
        report.final_state,
        SupervisorState::Engaged | SupervisorState::Fault(plantc_runtime::FaultKind::Overrun)
    ));
    assert_eq!(report.jitter_ns.count + 1, report.samples);
    assert!(report.jitter_ns.p50 < (1e9 / rate) as u64, "{report}");
    assert!(report.controller_ns.count > 0 && report.controller_ns.p50 > 0);
}

#[test]
fn timing_report_1khz_and_2khz() {
    timed(1000.0, 2.0);
    timed(2000.0, 1.0);
}
