//! `plantc compare`: simulate the model over measured experiments (from each
//! measured initial state, with the measured input) and report fit %, RMSE and
//! where the model fails; optional SVG figures.

use std::io::Write;
use std::path::Path;

use plantc_derive::model::Model;
use plantc_identify::{
    as_experiments, compare, into_experiments, plot_comparison, plot_residual_tests, validate,
    where_it_fails, Experiment, FailOptions, FigureChannels, FitReport, ValidateOptions,
};

use crate::cli::CompareArgs;
use crate::commands::fit::with_progress;
use crate::common::{
    channel_fits, channel_spec, fit_options, load, num, read_data, values, write_json, CliError,
};

/// Fit % and RMSE of the model's coordinates over the experiments.
pub(crate) fn report(
    model: &Model,
    measured: &[Experiment],
    simulated: &[Experiment],
) -> Result<FitReport, CliError> {
    let names: Vec<&str> = model.coordinates.iter().map(|c| c.name.as_str()).collect();
    compare(measured, simulated, &names).map_err(|e| CliError::failure(format!("error: {e}")))
}

/// The figure file of each experiment: `<dir>/<experiment>.svg` (experiment
/// names are unique: see `plantc_identify::read_experiments`).
pub(crate) fn figure_paths(dir: &Path, measured: &[Experiment]) -> Vec<std::path::PathBuf> {
    measured
        .iter()
        .map(|m| dir.join(format!("{}.svg", m.name)))
        .collect()
}

/// Refuses, before any work, figures that would replace existing files
/// (unless `force`), and a `dir` that is not a directory.
pub(crate) fn refuse_existing_figures(
    dir: &Path,
    measured: &[Experiment],
    force: bool,
) -> Result<(), CliError> {
    if dir.exists() && !dir.is_dir() {
        return Err(CliError::input(format!(
            "error: --plots `{}` is a file, not a directory",
            dir.display()
        )));
    }
    // the overlay, and the prediction and residual-test figures compare may add
    let extra = measured.iter().flat_map(|m| {
        ["predicted", "residual-tests"].map(|k| dir.join(format!("{}-{k}.svg", m.name)))
    });
    for p in figure_paths(dir, measured).into_iter().chain(extra) {
        if p.exists() && !force {
            return Err(CliError::input(format!(
                "error: figure `{}` already exists; pass --force to overwrite it, or choose another --plots directory",
                p.display()
            )));
        }
    }
    Ok(())
}

/// An overlay + residual (+ input) SVG per experiment, `<dir>/<experiment>.svg`;
/// `shown` is the directory named in the messages (the final place when
/// `dir` is a staging directory).
pub(crate) fn write_figures(
    dir: &Path,
    shown: &Path,
    model: &Model,
    measured: &[Experiment],
    simulated: &[Experiment],
    err: &mut dyn Write,
) -> Result<(), CliError> {
    std::fs::create_dir_all(dir)
        .map_err(|e| CliError::failure(format!("error: cannot create `{}`: {e}", dir.display())))?;
    let figure = FigureChannels::of_model(model);
    for ((m, s), p) in measured
        .iter()
        .zip(simulated)
        .zip(figure_paths(dir, measured))
    {
        plot_comparison(&p, m, s, &figure).map_err(|e| CliError::failure(format!("error: {e}")))?;
        let _ = writeln!(
            err,
            "figure -> {}",
            shown.join(p.file_name().unwrap_or_default()).display()
        );
    }
    Ok(())
}

/// The where-it-fails findings of every experiment and channel, one
/// indented line each; returns how many.
pub(crate) fn write_failures(
    out: &mut dyn Write,
    model: &Model,
    measured: &[Experiment],
    simulated: &[Experiment],
) -> Result<usize, CliError> {
    let spec = channel_spec(model);
    let opts = FailOptions::for_spec(&spec);
    let names: Vec<&str> = model.coordinates.iter().map(|c| c.name.as_str()).collect();
    let mut n = 0;
    for (m, s) in measured.iter().zip(simulated) {
        let diags = where_it_fails(m, s, &names, &opts)
            .map_err(|e| CliError::failure(format!("error: {e}")))?;
        for f in diags.iter().flat_map(|d| &d.findings) {
            let _ = writeln!(out, "  {f}");
            n += 1;
        }
    }
    Ok(n)
}

/// The report as a text table.
pub(crate) fn write_table(out: &mut dyn Write, rep: &FitReport, measured: &[Experiment]) {
    let wn = measured
        .iter()
        .map(|e| e.name.len())
        .max()
        .unwrap_or(10)
        .max(10);
    let _ = writeln!(
        out,
        "{:<wn$}  {:<8}  {:>8}  {:>12}",
        "experiment", "channel", "fit %", "RMSE"
    );
    for (e, m) in rep.experiments.iter().zip(measured) {
        for (ch, f) in &e.channels {
            let fit = f.fit_percent.map_or("-".to_string(), |v| format!("{v:.1}"));
            let _ = writeln!(
                out,
                "{:<wn$}  {:<8}  {:>8}  {:>12}",
                m.name,
                ch,
                fit,
                format!("{:.3e}", f.rmse)
            );
        }
    }
    let _ = writeln!(
        out,
        "RMSE over all experiments and channels: {:.3e}",
        rep.rmse
    );
}

pub fn run(args: &CompareArgs, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), CliError> {
    let loaded = load(&args.model, err)?;
    let model = &loaded.model;
    let vals = values(&loaded, &args.params)?;
    // long records take seconds: a progress line on a terminal
    let measured = with_progress("reading", |_| read_data(model, &args.data, err))?;
    if let Some(dir) = &args.plots {
        refuse_existing_figures(dir, &measured, args.force)?;
    }
    let opts = ValidateOptions {
        fit: fit_options(model, &args.control, None)?,
        horizon: args.horizon,
        lags: args.lags,
    };
    let mut v = with_progress("simulating", |_| {
        validate(model, &vals.base, &measured, &opts)
    })
    .map_err(|e| CliError::failure(format!("error: {e}")))?;
    // the simulations taken over, not copied (a long record's is large)
    let sims: Vec<Option<Vec<Vec<f64>>>> = v
        .experiments
        .iter_mut()
        .map(|e| e.simulated.take())
        .collect();
    let all_simulated = sims.iter().all(Option::is_some);
    let simulated = into_experiments(model, &measured, sims);
    let rep = if all_simulated {
        Some(report(model, &measured, &simulated)?)
    } else {
        None
    };
    if let Some(dir) = &args.plots {
        if all_simulated {
            write_figures(dir, dir, model, &measured, &simulated, err)?;
        }
        if v.horizon.is_some() {
            let preds: Vec<Option<&Vec<Vec<f64>>>> =
                v.experiments.iter().map(|e| e.predicted.as_ref()).collect();
            let predicted = as_experiments(model, &measured, &preds);
            let figure = FigureChannels::of_model(model);
            std::fs::create_dir_all(dir).map_err(|e| {
                CliError::failure(format!("error: cannot create `{}`: {e}", dir.display()))
            })?;
            for (m, p) in measured.iter().zip(&predicted) {
                let path = dir.join(format!("{}-predicted.svg", m.name));
                plot_comparison(&path, m, p, &figure)
                    .map_err(|e| CliError::failure(format!("error: {e}")))?;
                let _ = writeln!(err, "figure -> {}", path.display());
            }
        }
        for e in &v.experiments {
            if e.residual_tests.is_empty() {
                continue;
            }
            let path = dir.join(format!("{}-residual-tests.svg", e.name));
            plot_residual_tests(&path, &e.residual_tests)
                .map_err(|e| CliError::failure(format!("error: {e}")))?;
            let _ = writeln!(err, "figure -> {}", path.display());
        }
    }
    if args.json {
        // the report (fit % and RMSE per file and channel, pooled RMSE) at
        // the top level as always; the validation's details (nuisance,
        // simulation, prediction, residual tests) under `validation`
        let mut j = match &rep {
            Some(r) => serde_json::to_value(r).map_err(|e| CliError::failure(e.to_string()))?,
            None => serde_json::json!({ "experiments": [], "rmse": null }),
        };
        j["validation"] = serde_json::to_value(&v).map_err(|e| CliError::failure(e.to_string()))?;
        write_json(out, &j);
        return Ok(());
    }
    let _ = writeln!(
        out,
        "`{}` against {} experiment(s){}:",
        model.name,
        measured.len(),
        match &v.closed_loop {
            Some(c) => format!(" (closed loop with recorded controller `{c}`)"),
            None => String::new(),
        }
    );
    match &rep {
        Some(rep) => write_table(out, rep, &measured),
        None => {
            for e in &v.experiments {
                if let Some(m) = &e.simulation_error {
                    let _ = writeln!(out, "{}: {m}", e.name);
                }
            }
        }
    }
    // what was estimated per experiment
    for e in &v.experiments {
        if let Some(l) = e.nuisance.release_line() {
            let _ = writeln!(out, "  {l}");
        }
    }
    for e in &v.experiments {
        let est: Vec<String> = e
            .nuisance
            .initial_state
            .iter()
            .filter(|x| x.estimated)
            .chain(e.nuisance.offsets.iter())
            .map(|x| format!("{} = {:.4e}", x.name, x.value))
            .collect();
        if !est.is_empty() {
            let _ = writeln!(out, "  {} (estimated): {}", e.name, est.join(", "));
        }
    }
    if let Some(h) = v.horizon {
        let _ = writeln!(out, "\n{h} s-ahead prediction (from the measured state):");
        for e in &v.experiments {
            let _ = writeln!(out, "  {}: {}", e.name, channel_fits(&e.prediction));
        }
    }
    let _ = writeln!(
        out,
        "\nresidual tests ({} residuals, 99 % band):",
        if v.horizon.is_some() {
            "prediction"
        } else {
            "simulation"
        }
    );
    for e in &v.experiments {
        for t in &e.residual_tests {
            let _ = writeln!(out, "  {}: {}", e.name, t.summary());
        }
    }
    // Where it fails, in plain words.
    if let Some(rep) = &rep {
        let mut findings = Vec::new();
        write_failures(&mut findings, model, &measured, &simulated)?;
        if !findings.is_empty() {
            let _ = writeln!(out, "\nwhere it fails:");
            let _ = out.write_all(&findings);
        } else {
            let _ = writeln!(
                out,
                "\nwhere it fails: no pattern in the residuals (RMSE {})",
                num(rep.rmse)
            );
        }
    }
    Ok(())
}
