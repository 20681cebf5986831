//! `plantc fit`: bounded simulation-error fit of the parameters marked
//! `estimate` (or `--free`), with standard errors and correlated pairs; the
//! fitted values are written into a copy of the model through the lossless
//! editor.

use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use plantc_identify::{fit_with_progress, FitError, FitOptions, FitProgress, FitResult};

use crate::cli::FitArgs;
use crate::common::{
    load, read_data, refuse_to_clobber, values, write_json, write_output, write_parameter_values,
    CliError,
};

/// Runs `work` while showing elapsed time and the latest status that
/// `work` reports through its argument (a `\r` line on stderr, only when
/// stderr is a terminal: logs stay clean).
pub(crate) fn with_progress<T>(what: &str, work: impl FnOnce(&dyn Fn(String)) -> T) -> T {
    let status = Mutex::new(String::new());
    let set = |s: String| {
        if let Ok(mut g) = status.lock() {
            *g = s;
        }
    };
    if !std::io::stderr().is_terminal() {
        return work(&set);
    }
    let done = AtomicBool::new(false);
    std::thread::scope(|s| {
        s.spawn(|| {
            let start = Instant::now();
            let spin = ['|', '/', '-', '\\'];
            let mut k = 0;
            while !done.load(Ordering::Relaxed) {
                let st = status.lock().map(|g| g.clone()).unwrap_or_default();
                eprint!(
                    "\r\x1b[K{} {what} {:.1} s  {st}",
                    spin[k % 4],
                    start.elapsed().as_secs_f64()
                );
                k += 1;
                std::thread::sleep(Duration::from_millis(200));
            }
            eprint!("\r\x1b[K");
        });
        let r = work(&set);
        done.store(true, Ordering::Relaxed);
        r
    })
}

/// A status line for [`with_progress`] from a fit's progress.
pub(crate) fn progress_text(p: &FitProgress) -> String {
    let h = if p.horizon.is_finite() {
        format!("first {} s", p.horizon)
    } else {
        "whole record".to_string()
    };
    format!(
        "stage {}/{} ({h}), iteration {}, RMSE {:.3e}",
        p.stage + 1,
        p.stages,
        p.iteration,
        p.rmse
    )
}

fn fit_error(e: FitError) -> CliError {
    match e {
        FitError::Sim(plantc_identify::SimError::Diverged { .. }) => {
            CliError::failure(format!("error: {e}"))
        }
        _ => CliError::input(format!("error: {e}")),
    }
}

/// The JSON shape of `plantc fit --json`.
pub(crate) fn fit_json(r: &FitResult) -> serde_json::Value {
    let mut params = serde_json::Map::new();
    for e in &r.parameters {
        params.insert(
            e.name.clone(),
            serde_json::json!({"value": e.value, "std_error": e.std_error, "at_bound": e.at_bound}),
        );
    }
    let corr: Vec<serde_json::Value> = r
        .correlations
        .iter()
        .map(|(a, b, c)| serde_json::json!({"a": a, "b": b, "corr": c}))
        .collect();
    serde_json::json!({
        "parameters": params,
        "before": {"rmse": r.before_rmse},
        "after": {"rmse": r.after_rmse},
        "correlated": corr,
        "iterations": r.iterations,
    })
}

pub fn run(args: &FitArgs, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), CliError> {
    if let Some(o) = &args.out {
        refuse_to_clobber(o, &args.model, args.force)?;
    }
    let loaded = load(&args.model, err)?;
    let model = &loaded.model;
    let vals = values(&loaded, &args.params)?;
    let free = match &args.free {
        Some(list) => {
            let names: Vec<String> = list
                .split(',')
                .map(|s| s.trim().to_string())
                .filter(|s| !s.is_empty())
                .collect();
            for n in &names {
                if model.parameter(n).is_none() {
                    let known: Vec<&str> =
                        model.parameters.iter().map(|p| p.name.as_str()).collect();
                    return Err(CliError::input(format!(
                        "error: `--free {list}`: the model has no parameter `{n}`; parameters: {}",
                        known.join(", ")
                    )));
                }
            }
            Some(names)
        }
        None => None,
    };
    let measured = read_data(model, &args.data, err)?;
    let opts = FitOptions {
        free,
        start: Some(vals.base.clone()),
        ..FitOptions::default()
    };
    let n_free = opts.free.as_ref().map_or_else(
        || plantc_identify::estimated_parameters(model).len(),
        Vec::len,
    );
    let _ = writeln!(
        err,
        "fitting {n_free} parameter(s) to {} experiment(s)...",
        measured.len()
    );
    let started = Instant::now();
    let result = with_progress("fitting", |set| {
        fit_with_progress(model, &measured, &opts, &mut |p| set(progress_text(p)))
    })
    .map_err(fit_error)?;
    let _ = writeln!(
        err,
        "fit done in {:.1} s: {} iterations, {} simulations",
        started.elapsed().as_secs_f64(),
        result.iterations,
        result.simulations
    );
    if let Some(o) = &args.out {
        let text = std::fs::read_to_string(&args.model).map_err(|e| {
            CliError::input(format!(
                "error: cannot read `{}`: {e}",
                args.model.display()
            ))
        })?;
        // the fitted values, and values chosen with --set/--param (part of
        // the fitted model)
        let values = model.parameters.iter().enumerate().filter_map(|(i, p)| {
            match result.parameters.iter().find(|e| e.name == p.name) {
                Some(e) => Some((p.name.as_str(), e.value)),
                None if result.base[i] != p.value => Some((p.name.as_str(), result.base[i])),
                None => None,
            }
        });
        let text = write_parameter_values(&text, model, values)?;
        write_output(o, text)?;
        let _ = writeln!(err, "fitted model -> {}", o.display());
    }
    if args.json {
        write_json(out, &fit_json(&result));
        return Ok(());
    }
    let w = result
        .parameters
        .iter()
        .map(|e| e.name.len())
        .max()
        .unwrap_or(4)
        .max(9);
    let _ = writeln!(
        out,
        "{:<w$}  {:>12}  {:>12}  {:>12}",
        "parameter", "start", "estimate", "std error"
    );
    for e in &result.parameters {
        let _ = writeln!(
            out,
            "{:<w$}  {:>12}  {:>12}  {:>12}{}",
            e.name,
            format!("{:.5e}", e.start),
            format!("{:.5e}", e.value),
            format!("{:.2e}", e.std_error),
            if e.at_bound { "  at its bound" } else { "" }
        );
    }
    let _ = writeln!(
        out,
        "RMSE before {:.3e}, after {:.3e} ({:.2}x lower)",
        result.before_rmse,
        result.after_rmse,
        result.before_rmse / result.after_rmse.max(f64::MIN_POSITIVE)
    );
    for (a, b, c) in &result.correlations {
        let _ = writeln!(
            out,
            "warning: `{a}` and `{b}` are strongly correlated (corr {c:.3}): the data cannot separate them; fix one of them or add an experiment that excites them differently"
        );
    }
    Ok(())
}
