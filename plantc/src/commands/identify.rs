//! `plantc identify`: the whole identification story in one command.
//!
//! nominal model -> compare (where it fails) -> diagnose (which effect is
//! missing) -> apply it to a copy of the model -> fit -> compare again, with
//! a before/after table, the fitted model file and overlay/residual figures
//! for each stage. The input model is never modified; everything is written
//! under `-o DIR`.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use plantc_derive::model::{Model, ParameterValues};
use plantc_identify::diagnose::model_from_text;
use plantc_identify::{diagnose, fit_with_progress, Experiment, FitOptions, FitReport, FitResult};

use crate::cli::IdentifyArgs;
use crate::commands::compare::{report, simulate_experiments, write_failures, write_figures};
use crate::commands::diagnose::fitted_instance;
use crate::commands::fit::{progress_text, with_progress};
use crate::common::{load, read_data, write_json, write_output, write_parameter_values, CliError};

/// One stage of the story: its label and its comparison with the data.
struct Stage {
    label: String,
    report: FitReport,
}

fn fail(e: impl std::fmt::Display) -> CliError {
    CliError::failure(format!("error: {e}"))
}

/// The output directory being written: built aside (`fresh`), named `dir`
/// in messages, swapped in when the story is complete.
struct OutDir<'a> {
    dir: &'a Path,
    fresh: plantc_fsio::FreshDir,
}

impl OutDir<'_> {
    /// Writes `name` (crash-safe) and returns the path shown to the user.
    fn write(&self, name: &str, text: &str) -> Result<PathBuf, CliError> {
        write_output(&self.fresh.path().join(name), text)?;
        Ok(self.dir.join(name))
    }
}

/// Simulate, compare and draw one stage into `out`'s `figures` folder.
fn stage(
    label: &str,
    model: &Model,
    full: &[f64],
    measured: &[Experiment],
    (out, figures): (&OutDir, &str),
    err: &mut dyn Write,
) -> Result<(Stage, Vec<Experiment>), CliError> {
    let simulated = simulate_experiments(model, full, measured)?;
    let rep = report(model, measured, &simulated)?;
    write_figures(
        &out.fresh.path().join(figures),
        &out.dir.join(figures),
        model,
        measured,
        &simulated,
        err,
    )?;
    Ok((
        Stage {
            label: label.to_string(),
            report: rep,
        },
        simulated,
    ))
}

/// The model text with every fitted parameter written in (lossless).
fn with_values(text: &str, model: &Model, r: &FitResult) -> Result<String, CliError> {
    let values = r.parameters.iter().map(|e| (e.name.as_str(), e.value));
    write_parameter_values(text, model, values)
}

/// Before/after table: one column per stage, one row per experiment and
/// channel (fit % and RMSE), and the RMSE over everything.
fn table(out: &mut dyn Write, stages: &[Stage], measured: &[Experiment], channels: &[&str]) {
    let rows: Vec<(String, usize, &str)> = measured
        .iter()
        .enumerate()
        .flat_map(|(i, m)| {
            channels
                .iter()
                .map(move |c| (format!("{} / {c}", m.name), i, *c))
        })
        .collect();
    let lw = rows.iter().map(|r| r.0.len()).max().unwrap_or(10).max(18);
    let cw = stages
        .iter()
        .map(|s| s.label.len())
        .max()
        .unwrap_or(8)
        .max(18);
    let mut head = format!("{:<lw$}", "");
    for s in stages {
        head.push_str(&format!("  {:>cw$}", s.label));
    }
    let _ = writeln!(out, "{head}");
    let mut line = format!("{:<lw$}", "RMSE, all channels");
    for s in stages {
        line.push_str(&format!("  {:>cw$}", format!("{:.3e}", s.report.rmse)));
    }
    let _ = writeln!(out, "{line}");
    for (label, i, c) in &rows {
        let mut line = format!("{label:<lw$}");
        for s in stages {
            let cell = s
                .report
                .experiments
                .get(*i)
                .and_then(|e| e.channels.get(*c))
                .map_or("-".to_string(), |f| {
                    let fit = f
                        .fit_percent
                        .map_or("-".to_string(), |v| format!("{v:.1} %"));
                    format!("{fit}  {:.2e}", f.rmse)
                });
            line.push_str(&format!("  {cell:>cw$}"));
        }
        let _ = writeln!(out, "{line}");
    }
    let _ = writeln!(
        out,
        "(cells: fit % as MATLAB's compare, then RMSE in SI units; fit % of a channel that barely moves is capped by encoder quantisation: judge it by RMSE)"
    );
}

pub fn run(args: &IdentifyArgs, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), CliError> {
    // the story goes to a buffer: printed as text, or replaced by JSON
    let mut text_out = Vec::new();
    let summary = story(args, &mut text_out, err)?;
    if args.json {
        write_json(out, &summary);
    } else {
        let _ = out.write_all(&text_out);
    }
    Ok(())
}

fn story(
    args: &IdentifyArgs,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<serde_json::Value, CliError> {
    let dir: &PathBuf = &args.out;
    if dir.exists()
        && !args.force
        && std::fs::read_dir(dir).map_or(true, |mut d| d.next().is_some())
        && !made_by_identify(dir)
    {
        return Err(CliError::input(format!(
            "error: `{}` exists, is not empty and was not written by `plantc identify`; choose a new directory or pass --force (identify's files are replaced, others kept)",
            dir.display()
        )));
    }
    // the output directory is replaced as a whole: never the input model
    if let (Ok(m), Ok(d)) = (args.model.canonicalize(), dir.canonicalize()) {
        if m.starts_with(&d) && !args.force {
            return Err(CliError::input(format!(
                "error: the input model `{}` lies inside the output directory `{}`, which identify replaces; copy the model elsewhere (e.g. `cp {} model.plant`) or choose another -o, or pass --force to replace it",
                args.model.display(),
                dir.display(),
                args.model.display()
            )));
        }
    }
    let started = Instant::now();
    let loaded = load(&args.model, err)?;
    let model = &loaded.model;
    let text = std::fs::read_to_string(&args.model).map_err(|e| {
        CliError::input(format!(
            "error: cannot read `{}`: {e}",
            args.model.display()
        ))
    })?;
    let measured = read_data(model, &args.data, err)?;
    // inputs are checked before anything is written; the new directory is
    // built aside and swapped in at the end: a killed run leaves the old one
    let out_dir = OutDir {
        dir,
        fresh: plantc_fsio::FreshDir::create(dir).map_err(fail)?,
    };
    let channels: Vec<&str> = model.coordinates.iter().map(|c| c.name.as_str()).collect();
    let nominal = ParameterValues::new(model, None, &[]).map_err(fail)?;

    // 1. the nominal model against the data
    let _ = writeln!(
        out,
        "1. nominal model `{}` against {} experiment(s)",
        args.model.display(),
        measured.len()
    );
    let (s1, sim1) = stage(
        "nominal",
        model,
        &nominal.full,
        &measured,
        (&out_dir, "1-nominal"),
        err,
    )?;
    let _ = writeln!(out, "   RMSE {:.3e}; where it fails:", s1.report.rmse);
    if write_failures(out, model, &measured, &sim1)? == 0 {
        let _ = writeln!(out, "  no pattern in the residuals");
    }

    // 2. diagnose (includes the refit of the nominal model)
    let _ = writeln!(
        out,
        "\n2. diagnose: refit the nominal model, rank candidate effects by equation error, refit the leaders"
    );
    let d = with_progress("diagnosing", |_| {
        diagnose(&text, &measured, &FitOptions::default())
    })
    .map_err(fail)?;
    let refit_vals = ParameterValues::from_base(model, d.baseline.base.clone());
    let (s2, sim2) = stage(
        "nominal, refitted",
        model,
        &refit_vals.full,
        &measured,
        (&out_dir, "2-refitted"),
        err,
    )?;
    let _ = writeln!(
        out,
        "   nominal model refitted: RMSE {:.3e}; where it still fails:",
        s2.report.rmse
    );
    if write_failures(out, model, &measured, &sim2)? == 0 {
        let _ = writeln!(out, "  no pattern in the residuals");
    }
    for r in d.ranking.iter().filter(|r| r.fit.is_some()) {
        let _ = writeln!(
            out,
            "   candidate {:<28} refit RMSE {:.3e} ({:.2}x), equation-error rank {}, acts: {}",
            r.candidate.label(),
            r.fit.as_ref().map_or(f64::NAN, |f| f.after_rmse),
            r.gain,
            r.evidence.equation_error_rank,
            r.evidence.acts_where
        );
    }
    let mut stages = vec![s1, s2];
    let mut summary = serde_json::json!({
        "model": args.model.display().to_string(),
        "verdict": "adequate",
    });
    let final_text;
    match (&d.verdict, d.ranking.first()) {
        (Some(_), Some(top)) => {
            // 3. apply the top effect to a copy, at the values of its refit
            let inst = fitted_instance(top);
            let _ = writeln!(
                out,
                "\n3. missing effect: `{}` on `{}`; added to a copy of the model:\n{}",
                inst.effect,
                inst.target,
                indent(&inst.snippet())
            );
            let edited = inst.apply(&text).map_err(fail)?;
            let with_effect = model_from_text("with_effect", &edited).map_err(fail)?;
            let edited = match &top.fit {
                Some(f) => with_values(&edited, &with_effect, f)?,
                None => edited,
            };
            let path = out_dir.write("with_effect.plant", &edited)?;
            let _ = writeln!(err, "model with the effect -> {}", path.display());
            // 4. fit it
            let m2 = model_from_text("with_effect", &edited).map_err(fail)?;
            let start: Vec<f64> = m2.parameters.iter().map(|p| p.value).collect();
            let f = with_progress("fitting", |set| {
                fit_with_progress(
                    &m2,
                    &measured,
                    &FitOptions {
                        start: Some(start),
                        ..FitOptions::default()
                    },
                    &mut |p| set(progress_text(p)),
                )
            })
            .map_err(fail)?;
            let fitted = with_values(&edited, &m2, &f)?;
            let path = out_dir.write("fitted.plant", &fitted)?;
            let _ = writeln!(
                out,
                "\n4. fit of the model with the effect -> {}",
                path.display()
            );
            for e in &f.parameters {
                let _ = writeln!(
                    out,
                    "   {:<10} = {:.5e}  (std error {:.1e}){}",
                    e.name,
                    e.value,
                    e.std_error,
                    if e.at_bound { "  at its bound" } else { "" }
                );
            }
            for (a, b, c) in &f.correlations {
                let _ = writeln!(
                    out,
                    "   warning: `{a}` and `{b}` are strongly correlated ({c:.3})"
                );
            }
            // 5. compare again
            let vals = ParameterValues::from_base(&m2, f.base.clone());
            let (s3, _) = stage(
                &format!("+ {}, fitted", inst.label()),
                &m2,
                &vals.full,
                &measured,
                (&out_dir, "3-fitted"),
                err,
            )?;
            stages.push(s3);
            summary["verdict"] = "missing_effect".into();
            summary["effect"] = serde_json::json!({
                "effect": inst.effect,
                "target": inst.target,
                "snippet": inst.snippet(),
            });
            summary["fit"] = crate::commands::fit::fit_json(&f);
            final_text = "fitted.plant";
        }
        _ => {
            let _ = writeln!(
                out,
                "\n3. verdict: adequate: no candidate effect lowers the RMSE clearly; the refitted nominal model is the result"
            );
            let fitted = with_values(&text, model, &d.baseline)?;
            out_dir.write("fitted.plant", &fitted)?;
            summary["fit"] = crate::commands::fit::fit_json(&d.baseline);
            final_text = "fitted.plant";
        }
    }
    let _ = writeln!(out, "\n5. before and after:");
    table(out, &stages, &measured, &channels);
    let first = stages.first().map_or(f64::NAN, |s| s.report.rmse);
    let last = stages.last().map_or(f64::NAN, |s| s.report.rmse);
    let _ = writeln!(
        out,
        "RMSE {first:.3e} -> {last:.3e}: {:.1}x lower; model -> {}, figures -> {}/{{1-nominal,2-refitted{}}}/",
        first / last.max(f64::MIN_POSITIVE),
        dir.join(final_text).display(),
        dir.display(),
        if stages.len() > 2 { ",3-fitted" } else { "" }
    );
    summary["stages"] = stages
        .iter()
        .map(|s| serde_json::json!({"stage": s.label, "report": s.report}))
        .collect::<Vec<_>>()
        .into();
    let mut buf = Vec::new();
    write_json(&mut buf, &summary);
    out_dir.write("report.json", &String::from_utf8_lossy(&buf))?;
    // swap the complete directory in; entries identify never writes (the
    // user's, with --force) are kept
    out_dir
        .fresh
        .commit_keeping(|n| !IDENTIFY_ENTRIES.iter().any(|k| n == Path::new(k)))
        .map_err(fail)?;
    let _ = writeln!(err, "done in {:.1} s", started.elapsed().as_secs_f64());
    Ok(summary)
}

/// Everything identify writes at the top of its output directory.
const IDENTIFY_ENTRIES: [&str; 6] = [
    "report.json",
    "fitted.plant",
    "with_effect.plant",
    "1-nominal",
    "2-refitted",
    "3-fitted",
];

/// Whether `dir` holds the output of an earlier `plantc identify` (its
/// `report.json` has the story's keys, and nothing else is in it): it may be
/// replaced without asking.
fn made_by_identify(dir: &Path) -> bool {
    let only_ours = std::fs::read_dir(dir).is_ok_and(|entries| {
        entries.flatten().all(|e| {
            let n = e.file_name();
            IDENTIFY_ENTRIES
                .iter()
                .any(|k| n == std::ffi::OsStr::new(k))
        })
    });
    only_ours
        && std::fs::read_to_string(dir.join("report.json"))
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .is_some_and(|v| v.get("stages").is_some() && v.get("verdict").is_some())
}

fn indent(s: &str) -> String {
    s.lines()
        .map(|l| format!("   {l}"))
        .collect::<Vec<_>>()
        .join("\n")
}
