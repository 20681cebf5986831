//! `plantc compare`: simulate the model over measured experiments (from each
//! measured initial state, with the measured input) and report fit %, RMSE and
//! where the model fails; optional SVG figures.

use std::io::Write;
use std::path::Path;

use plantc_derive::model::Model;
use plantc_identify::{
    compare, plot_comparison, where_it_fails, Channel, Experiment, FailOptions, FitReport, Signals,
    SimOptions, Simulator,
};

use crate::cli::CompareArgs;
use crate::commands::fit::with_progress;
use crate::common::{channel_spec, load, num, read_data, values, write_json, CliError};

/// The model simulated over each measured experiment, as experiments with the
/// same names, files and sample instants (coordinates only).
pub(crate) fn simulate_experiments(
    model: &Model,
    full: &[f64],
    measured: &[Experiment],
) -> Result<Vec<Experiment>, CliError> {
    let sim = Simulator::new(model, SimOptions::default())
        .map_err(|e| CliError::failure(format!("error: {e}")))?;
    measured
        .iter()
        .map(|m| {
            let sig = Signals::from_experiment(model, m)
                .map_err(|e| CliError::input(format!("error: {e}")))?;
            let tr = sim
                .simulate(&sig, full, m.len())
                .map_err(|e| CliError::failure(format!("error: {e}")))?;
            Ok(Experiment {
                name: m.name.clone(),
                file: m.file.clone(),
                t: m.t.clone(),
                channels: model
                    .coordinates
                    .iter()
                    .zip(tr.q)
                    .map(|(c, q)| Channel {
                        name: c.name.clone(),
                        unit_note: None,
                        values: q,
                    })
                    .collect(),
            })
        })
        .collect()
}

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
    for p in figure_paths(dir, measured) {
        if p.exists() && !force {
            return Err(CliError::input(format!(
                "error: figure `{}` already exists; pass --force to overwrite it, or choose another --plots directory",
                p.display()
            )));
        }
    }
    Ok(())
}

/// An overlay + residual SVG per experiment, `<dir>/<experiment>.svg`;
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
    let names: Vec<&str> = model.coordinates.iter().map(|c| c.name.as_str()).collect();
    for ((m, s), p) in measured
        .iter()
        .zip(simulated)
        .zip(figure_paths(dir, measured))
    {
        plot_comparison(&p, m, s, &names).map_err(|e| CliError::failure(format!("error: {e}")))?;
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
    let (simulated, rep) = with_progress("simulating", |_| {
        let simulated = simulate_experiments(model, &vals.full, &measured)?;
        let rep = report(model, &measured, &simulated)?;
        Ok::<_, CliError>((simulated, rep))
    })?;
    if let Some(dir) = &args.plots {
        write_figures(dir, dir, model, &measured, &simulated, err)?;
    }
    if args.json {
        write_json(
            out,
            &serde_json::to_value(&rep).map_err(|e| CliError::failure(e.to_string()))?,
        );
        return Ok(());
    }
    let _ = writeln!(
        out,
        "`{}` against {} experiment(s):",
        model.name,
        measured.len()
    );
    write_table(out, &rep, &measured);
    // Where it fails, in plain words.
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
    Ok(())
}
