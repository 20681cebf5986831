//! `plantc fit`: bounded simulation-error fit of the parameters marked
//! `estimate` (or `--free`), with standard errors and correlated pairs; the
//! fitted values are written into a copy of the model through the lossless
//! editor.

use std::io::{IsTerminal, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use plantc_identify::{
    fit_with_progress, validate, FitError, FitOptions, FitProgress, FitResult, ValidateOptions,
};

use crate::cli::FitArgs;
use crate::common::{
    channel_fits, fit_options, load, name_list, read_data, read_held_out, refuse_to_clobber,
    values, write_json, write_model, write_parameter_values, CliError,
};

/// No progress line from now on (`--json`: the output is for a program).
static QUIET: AtomicBool = AtomicBool::new(false);

/// Silence [`with_progress`] for the rest of the run.
pub(crate) fn quiet() {
    QUIET.store(true, Ordering::Relaxed);
}

/// Runs `work` while showing elapsed time and the latest status that
/// `work` reports through its argument, and the diagnosis' candidate
/// refits (`plantc_identify::progress`) (a `\r` line on stderr, only when
/// stderr is a terminal and not after [`quiet`]: logs stay clean).
pub(crate) fn with_progress<T>(what: &str, work: impl FnOnce(&dyn Fn(String)) -> T) -> T {
    let status = Mutex::new(String::new());
    let set = |s: String| {
        crate::host::progress();
        if let Ok(mut g) = status.lock() {
            *g = s;
        }
    };
    if !std::io::stderr().is_terminal() || QUIET.load(Ordering::Relaxed) {
        return work(&set);
    }
    let done = AtomicBool::new(false);
    std::thread::scope(|s| {
        s.spawn(|| {
            let start = Instant::now();
            let spin = ['|', '/', '-', '\\'];
            let mut k = 0;
            while !done.load(Ordering::Relaxed) {
                let mut st = status.lock().map(|g| g.clone()).unwrap_or_default();
                if let Some(c) = plantc_identify::progress::current() {
                    st = format!("{st}  {c}");
                }
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
        // the spinner stops also when `work` unwinds (a host's progress
        // hook stopping it): the scope waits for the spinner thread
        let _stop_spinner = SetOnDrop(&done);
        work(&set)
    })
}

/// Sets its flag when dropped.
struct SetOnDrop<'a>(&'a AtomicBool);

impl Drop for SetOnDrop<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// A status line for [`with_progress`] from a fit's progress.
pub(crate) fn progress_text(p: &FitProgress) -> String {
    let h = if p.horizon.is_finite() {
        format!("first {} s", p.horizon)
    } else {
        "whole record".to_string()
    };
    format!(
        "stage {}/{} ({h}), iteration {}, cost {:.3e}",
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

/// The JSON shape of `plantc fit --json` (see [`FitResult::to_json`]).
pub(crate) fn fit_json(r: &FitResult) -> serde_json::Value {
    r.to_json()
}

/// A cost for printing: `diverged` when infinite.
pub(crate) fn cost_text(c: f64) -> String {
    if c.is_finite() {
        format!("{c:.4e}")
    } else {
        "diverged".to_string()
    }
}

/// The fit's result as text: parameters, cost before and after, per
/// experiment nuisance, identifiability and what the fit did.
pub(crate) fn write_fit(out: &mut dyn Write, r: &FitResult) {
    let w = r
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
    for e in &r.parameters {
        let flag = if e.fixed {
            "  fixed (not identifiable)"
        } else if e.at_bound {
            "  at its bound"
        } else {
            ""
        };
        let _ = writeln!(
            out,
            "{:<w$}  {:>12}  {:>12}  {:>12}{flag}",
            e.name,
            format!("{:.5e}", e.start),
            format!("{:.5e}", e.value),
            if e.std_error.is_finite() {
                format!("{:.2e}", e.std_error)
            } else {
                "-".to_string()
            },
        );
    }
    let ratio = if r.before_cost.is_finite() {
        format!(
            " (cost ratio before/after {:.2})",
            r.before_cost / r.after_cost.max(f64::MIN_POSITIVE)
        )
    } else {
        String::new()
    };
    let _ = writeln!(
        out,
        "cost (weighted RMS over {}) before {}, after {}{ratio}; RMSE before {}, after {:.3e}",
        match r.segments {
            Some(h) => format!("{h} s segments"),
            None => "whole records".to_string(),
        },
        cost_text(r.before_cost),
        cost_text(r.after_cost),
        cost_text(r.before_rmse),
        r.after_rmse
    );
    let _ = writeln!(
        out,
        "weights: {}",
        r.weights
            .iter()
            .map(|c| format!(
                "{} {:.3} per SI unit{} (noise floor {:.2e})",
                c.name,
                c.weight,
                if c.overridden { " (set)" } else { "" },
                c.noise
            ))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let coords: Vec<String> = r.weights.iter().map(|w| w.name.clone()).collect();
    let pct = |v: &Option<f64>| v.map_or("-".to_string(), |f| format!("{f:.1} %"));
    for e in &r.experiments {
        let _ = writeln!(
            out,
            "  {}: fit {}",
            e.name,
            coords
                .iter()
                .enumerate()
                .map(|(i, c)| format!(
                    "{c} {} -> {}",
                    pct(e.fit_before.get(i).unwrap_or(&None)),
                    pct(e.fit_after.get(i).unwrap_or(&None))
                ))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    for e in &r.experiments {
        if let Some(l) = e.release_line() {
            let _ = writeln!(out, "  {l}");
        }
    }
    for e in &r.experiments {
        let mut parts: Vec<String> = e
            .initial_state
            .iter()
            .filter(|v| v.estimated)
            .map(|v| format!("{} = {:.4}", v.name, v.value))
            .collect();
        parts.extend(e.offsets.iter().map(|v| {
            format!(
                "{} = {:.4e}{}",
                v.name,
                v.value,
                if v.std_error.is_finite() {
                    format!(" +- {:.1e}", v.std_error)
                } else {
                    String::new()
                }
            )
        }));
        if !parts.is_empty() {
            let _ = writeln!(out, "  {}: {}", e.name, parts.join(", "));
        }
    }
    if !r.identifiability.is_identifiable() || !r.identifiability.fixed.is_empty() {
        let _ = writeln!(
            out,
            "warning: not every parameter is identifiable from these data:"
        );
    }
    for m in r.identifiability.messages() {
        let _ = writeln!(out, "  {m}");
    }
    for n in &r.notes {
        let _ = writeln!(out, "note: {n}");
    }
}

/// A validation as text: per experiment, simulation and prediction fit %,
/// and the residual tests.
pub(crate) fn write_validation(out: &mut dyn Write, v: &plantc_identify::Validation) {
    for e in &v.experiments {
        let sim = if e.simulation.is_empty() {
            e.simulation_error
                .clone()
                .unwrap_or_else(|| "no simulation".to_string())
        } else {
            channel_fits(&e.simulation)
        };
        let _ = writeln!(out, "  {}: simulation fit {sim}", e.name);
        if let Some(l) = e.nuisance.release_line() {
            let _ = writeln!(out, "    {l}");
        }
        if let Some(h) = v.horizon {
            let _ = writeln!(
                out,
                "  {}: {h} s-ahead prediction fit {}",
                e.name,
                channel_fits(&e.prediction)
            );
        }
        for t in &e.residual_tests {
            let _ = writeln!(out, "    residuals {}", t.summary());
        }
    }
}

pub fn run(args: &FitArgs, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), CliError> {
    if args.json {
        quiet();
    }
    if let Some(o) = &args.out {
        refuse_to_clobber(o, &args.model, args.force)?;
    }
    let loaded = load(&args.model, err)?;
    let model = &loaded.model;
    let vals = values(&loaded, &args.params)?;
    let free = match &args.free {
        Some(list) => {
            let names = name_list(list);
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
    let mut held_out = read_held_out(model, &args.data, &args.validate, err)?;
    let auto_inputs = crate::common::inputs_settled(&args.data)?.is_none();
    let opts = FitOptions {
        free,
        start: Some(vals.base.clone()),
        ..fit_options(model, &args.control, Some(&args.horizon))?
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
    let (result, continuous) = with_progress("fitting", |set| {
        let mut progress = |p: &plantc_identify::FitProgress| set(progress_text(p));
        if auto_inputs {
            plantc_identify::fit_reading_inputs(model, &measured, &opts, &mut progress)
        } else {
            fit_with_progress(model, &measured, &opts, &mut progress).map(|r| (r, None))
        }
    })
    .map_err(fit_error)?;
    if let Some((held, cont)) = continuous {
        let _ = writeln!(
            err,
            "inputs read as continuous signals, not held over each sample interval: weighted RMS {held:.4e} held, {cont:.4e} continuous (records made by integrating a continuous input, or sampling one; --inputs held keeps them held)"
        );
        held_out = plantc_identify::continuous_records(model, &held_out);
    }
    let _ = writeln!(
        err,
        "fit done in {:.1} s: {} iterations, {} simulations",
        started.elapsed().as_secs_f64(),
        result.iterations,
        result.simulations
    );
    let validation = if held_out.is_empty() {
        None
    } else {
        Some(
            validate(
                model,
                &result.base,
                &held_out,
                &ValidateOptions {
                    fit: opts.clone(),
                    horizon: args.predict,
                    ..ValidateOptions::default()
                },
            )
            .map_err(fit_error)?,
        )
    };
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
        write_model(o, &text)?;
        let _ = writeln!(err, "fitted model -> {}", o.display());
    }
    if args.json {
        let mut j = fit_json(&result);
        j["inputs"] = match continuous {
            Some((held, cont)) => {
                serde_json::json!({"read": "continuous", "weighted_rms_held": held, "weighted_rms_continuous": cont})
            }
            None => serde_json::json!({"read": "held"}),
        };
        if let Some(v) = &validation {
            j["validation"] =
                serde_json::to_value(v).map_err(|e| CliError::failure(e.to_string()))?;
        }
        write_json(out, &j);
        return Ok(());
    }
    write_fit(out, &result);
    if let Some(v) = &validation {
        let _ = writeln!(
            out,
            "validation on {} held-out experiment(s):",
            held_out.len()
        );
        write_validation(out, v);
    }
    Ok(())
}
