//! Balances the reference pendulum in the simulator in real time and logs to CSV.
//!
//! Usage: `sim_realtime [LOG.csv] [SECONDS] [RATE_HZ]` (defaults: sim.csv, 10, 1000).
//! Used by the kill -9 test; also a minimal example of the runtime API.

use plantc_runtime::{
    run_with_events, LogWriter, RotaryPendulumReference, RunConfig, SimBackend, SimConfig,
    StateFeedback,
};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let log_path = args.get(1).map_or("sim.csv", String::as_str);
    let seconds: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(10.0);
    let rate: f64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(1000.0);

    let plant = RotaryPendulumReference::default();
    let mut cfg = RunConfig::for_plant(&plant);
    cfg.duration_s = Some(seconds);
    cfg.rate_hz = rate;
    let sim = SimConfig {
        real_time: true,
        ..SimConfig::default()
    };
    let x0 = vec![0.0, 5f64.to_radians(), 0.0, 0.0];
    let mut backend = match SimBackend::new(Box::new(plant), x0, sim) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2);
        }
    };
    // Thesis pole-placement gain (u = -K x).
    let mut controller = StateFeedback::new(vec![-7.8914, 37.8313, -2.9850, 3.6222]);
    let mut log = match LogWriter::create(log_path) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2);
        }
    };
    let result = run_with_events(
        &cfg,
        &mut backend,
        &mut controller,
        Some(&mut log),
        &mut |t| println!("{t}"),
    );
    match result {
        Ok(report) => print!("{report}"),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
}
