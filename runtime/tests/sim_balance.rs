//! The simulator backend balances the reference pendulum with the thesis gain.

mod common;

use common::{parse_log, tmp_path, K_THESIS};
use plantc_runtime::{
    run_with_events, FaultKind, LogWriter, RotaryPendulumReference, RunConfig, SimBackend,
    SimConfig, SimNoise, StateFeedback, SupervisorState,
};

fn balance(
    sim: SimConfig,
    seconds: f64,
    name: &str,
) -> (plantc_runtime::RunReport, Vec<common::Row>) {
    let plant = RotaryPendulumReference::default();
    let mut cfg = RunConfig::for_plant(&plant);
    cfg.duration_s = Some(seconds);
    let x0 = vec![0.0, 5f64.to_radians(), 0.0, 0.0];
    let mut be = SimBackend::new(Box::new(plant), x0, sim).expect("sim");
    let mut ctl = StateFeedback::new(K_THESIS.to_vec());
    let path = tmp_path(name);
    let mut log = LogWriter::create(&path).expect("log");
    let mut events = Vec::new();
    let report = run_with_events(&cfg, &mut be, &mut ctl, Some(&mut log), &mut |t| {
        events.push(*t)
    })
    .expect("run");
    drop(log);
    assert_eq!(events, report.transitions);
    assert_eq!(be.last_written(), 0.0, "last voltage must be 0 V");
    let text = std::fs::read_to_string(&path).expect("read log");
    let rows = parse_log(&text, false).expect("log parses");
    println!("{report}");
    (report, rows)
}

#[test]
fn thesis_gain_catches_and_balances_for_30_s() {
    let (report, rows) = balance(SimConfig::default(), 30.0, "sim_balance.csv");
    assert_eq!(report.final_state, SupervisorState::Engaged, "{report}");
    assert_eq!(report.transitions.len(), 2);
    assert_eq!(report.transitions[1].to, SupervisorState::Engaged);
    assert_eq!(rows.len() as u64, report.samples);
    assert_eq!(rows.len(), 30_001);
    assert!((rows.last().unwrap().t - 30.0).abs() < 1e-9);
    // Settled: the last 10 s stay within a few encoder counts of upright and the arm near 0.
    let tail = rows.iter().filter(|r| r.t >= 20.0);
    let mut max_alpha: f64 = 0.0;
    let mut max_theta: f64 = 0.0;
    let mut max_v: f64 = 0.0;
    for r in tail {
        max_alpha = max_alpha.max(r.alpha.abs());
        max_theta = max_theta.max(r.theta.abs());
        max_v = max_v.max(r.vm.abs());
        assert_eq!(r.state, "engaged");
    }
    println!("tail: max |alpha| {max_alpha:.5} rad, max |theta| {max_theta:.5} rad, max |Vm| {max_v:.3} V");
    assert!(max_alpha < 0.5f64.to_radians(), "{max_alpha}");
    assert!(max_theta < 5f64.to_radians(), "{max_theta}");
    // Catching from 5 deg needs a visible voltage at the start.
    assert!(rows.iter().take(100).any(|r| r.vm.abs() > 0.5));
}

#[test]
fn balances_with_noise_and_one_sample_delay() {
    let sim = SimConfig {
        noise: Some(SimNoise {
            seed: 7,
            counts_std: 0.5,
            volts_std: 0.05,
        }),
        input_delay_samples: 1,
        ..SimConfig::default()
    };
    let (report, rows) = balance(sim, 10.0, "sim_noise.csv");
    assert_eq!(report.final_state, SupervisorState::Engaged, "{report}");
    let max_alpha = rows
        .iter()
        .filter(|r| r.t >= 5.0)
        .map(|r| r.alpha.abs())
        .fold(0.0, f64::max);
    assert!(max_alpha < 2f64.to_radians(), "{max_alpha}");
}

#[test]
fn zero_gain_lets_it_fall_and_faults_with_zero_volts() {
    let plant = RotaryPendulumReference::default();
    let mut cfg = RunConfig::for_plant(&plant);
    cfg.duration_s = Some(10.0);
    let mut be = SimBackend::new(
        Box::new(plant),
        vec![0.0, 5f64.to_radians(), 0.0, 0.0],
        SimConfig::default(),
    )
    .unwrap();
    let mut ctl = StateFeedback::new(vec![0.0; 4]);
    let report = plantc_runtime::run(&cfg, &mut be, &mut ctl, None).unwrap();
    assert_eq!(
        report.final_state,
        SupervisorState::Fault(FaultKind::PendulumFell)
    );
    assert_eq!(be.last_written(), 0.0);
}
