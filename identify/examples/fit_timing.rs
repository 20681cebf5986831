//! Timing of the identification steps on one recorded case (a folder with
//! `free_swing_large.csv`, `free_swing_small.csv`, `driven.csv`, as
//! `data/demo_coulomb` or what `plantc synth` writes): the nominal fit (the model's `estimate` parameters),
//! the equation-error ranking and a full diagnosis, each timed by the wall
//! clock. Run through `bench/fit_timing.sh`, or directly:
//!
//! ```text
//! cargo run --release -p plantc-identify --example fit_timing -- models/rotary_pendulum.plant data/demo_coulomb [repeats] [fit-only]
//! ```
//!
//! With `fit-only` the equation-error ranking and the diagnosis are skipped.
//!
//! Prints one JSON object.

use std::path::PathBuf;
use std::time::Instant;

use plantc_identify::diagnose::{model_from_text, regressor_for};
use plantc_identify::{
    candidates, diagnose, estimated_parameters, fit, read_experiments, ChannelSpec, EquationError,
    EquationErrorOptions, FitOptions, Kind, ReadOptions,
};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        eprintln!("usage: fit_timing MODEL CASE_DIR [repeats]");
        std::process::exit(2);
    }
    let repeats: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(3);
    let text = match std::fs::read_to_string(&args[0]) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("{}: {e}", args[0]);
            std::process::exit(2);
        }
    };
    let dir = PathBuf::from(&args[1]);
    let files: Vec<PathBuf> = ["free_swing_large", "free_swing_small", "driven"]
        .iter()
        .map(|n| dir.join(format!("{n}.csv")))
        .collect();
    let spec = ChannelSpec::new()
        .angle("theta")
        .angle("alpha")
        .input("Vm", Kind::Voltage);
    let exps = match read_experiments(&files, &spec, &ReadOptions::default()) {
        Ok((e, _)) => e,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let model = match model_from_text("model", &text) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let samples: usize = exps.iter().map(|e| e.t.len()).sum();
    let mut fit_times = Vec::new();
    let mut last = None;
    for _ in 0..repeats {
        let t = Instant::now();
        let r = fit(&model, &exps, &FitOptions::default());
        fit_times.push(t.elapsed().as_secs_f64());
        last = Some(r);
    }
    let (iterations, simulations, rmse) = match last {
        Some(Ok(r)) => (r.iterations, r.simulations, r.after_rmse),
        Some(Err(e)) => {
            eprintln!("fit: {e}");
            std::process::exit(1);
        }
        None => (0, 0, f64::NAN),
    };
    if args.get(3).map(String::as_str) == Some("fit-only") {
        let out = serde_json::json!({
            "case": dir.display().to_string(),
            "fit_seconds": fit_times,
            "fit_iterations": iterations,
            "fit_simulations": simulations,
            "fit_rmse": rmse,
        });
        println!("{out}");
        return;
    }
    let base: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let t = Instant::now();
    let ranked = EquationError::new(
        &model,
        &base,
        &estimated_parameters(&model),
        &exps,
        &EquationErrorOptions::default(),
    )
    .and_then(|ee| {
        candidates(&model)
            .into_iter()
            .map(|c| {
                let m = c
                    .apply(&text)
                    .ok()
                    .and_then(|t| model_from_text(&c.label(), &t).ok());
                match m {
                    Some(m) => ee.score(&regressor_for(&c, m)).map(|s| (c.label(), s)),
                    None => Err(plantc_identify::equation_error::EquationErrorError::NoSamples),
                }
            })
            .collect::<Result<Vec<_>, _>>()
    });
    let ee_time = t.elapsed().as_secs_f64();
    let mut ee_top = match ranked {
        Ok(v) => v,
        Err(e) => {
            eprintln!("equation error: {e}");
            std::process::exit(1);
        }
    };
    ee_top.sort_by(|a, b| b.1.bic_gain.total_cmp(&a.1.bic_gain));
    let t = Instant::now();
    let d = match diagnose(&text, &exps, &FitOptions::default()) {
        Ok(d) => d,
        Err(e) => {
            eprintln!("diagnose: {e}");
            std::process::exit(1);
        }
    };
    let diagnose_time = t.elapsed().as_secs_f64();
    let mut sorted = fit_times.clone();
    sorted.sort_by(f64::total_cmp);
    let out = serde_json::json!({
        "case": dir.display().to_string(),
        "samples": samples,
        "free_parameters": estimated_parameters(&model),
        "fit_seconds": fit_times,
        "fit_median_seconds": sorted[sorted.len() / 2],
        "fit_iterations": iterations,
        "fit_simulations": simulations,
        "fit_rmse": rmse,
        "equation_error_seconds": ee_time,
        "equation_error_top": ee_top.first().map(|(l, _)| l.clone()),
        "diagnose_seconds": diagnose_time,
        "diagnose_verdict": d.verdict.as_ref().map(|c| c.label()),
        "diagnose_refits": d.ranking.iter().filter(|r| r.fit.is_some()).count(),
    });
    println!("{out}");
}
