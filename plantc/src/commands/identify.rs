//! `plantc identify`: the whole identification story in one command.
//!
//! nominal model -> compare (where it fails) -> diagnose (which effect is
//! missing) -> apply it to a copy of the model -> fit -> compare again, with
//! a before/after table, the fitted model file and overlay/residual figures
//! for each stage, and `report.html` (the same story for a person to read:
//! [`plantc_identify::Report`]). The input model is never modified;
//! everything is written under `-o DIR` (and the report to `--report FILE`).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use plantc_derive::model::Model;
use plantc_identify::diagnose::model_from_text;
use plantc_identify::{
    identify, render_html, Experiment, FigureChannels, FitReport, FitResult, Report, StoryOptions,
    StoryProgress, Validation,
};

use crate::cli::IdentifyArgs;
use crate::commands::compare::{write_failures, write_figures};
use crate::commands::fit::{progress_text, with_progress};
use crate::common::{
    channel_fits, fit_options, load, read_data, read_held_out, write_json, write_parameter_values,
    CliError,
};

/// One stage of the story: its label and its comparison with the data.
struct Stage {
    label: String,
    report: FitReport,
}

/// One table cell: fit % and RMSE, or `diverged`.
fn cell(f: &plantc_identify::ChannelFit) -> String {
    if f.diverged {
        return "diverged".to_string();
    }
    let fit = f
        .fit_percent
        .map_or("-".to_string(), |v| format!("{v:.1} %"));
    format!("{fit}  {:.2e}", f.rmse)
}

fn fail(e: impl std::fmt::Display) -> CliError {
    CliError::failure(format!("error: {e}"))
}

fn write_file(path: &Path, text: &str) -> Result<(), CliError> {
    // crash-safe (temporary file, fsync, rename); models in the canonical layout
    let text = if path.extension().is_some_and(|e| e == "plant") {
        crate::common::canonical(text)
    } else {
        text.to_string()
    };
    plantc_fsio::write_atomic(path, text).map_err(fail)
}

/// The model text with every fitted parameter written in (lossless).
/// `--free`: the `estimate` boxes of the model's other parameters are
/// taken out of the text the story runs on (they are held), and put back
/// into every model file identify writes.
struct FreeSelection {
    /// (parameter, lo, hi) as written.
    held: Vec<(String, String, String)>,
}

impl FreeSelection {
    /// The selection `list` on model `text`: the text with the others'
    /// boxes cleared, or an error naming a parameter that is unknown or has
    /// no box.
    fn new(text: &str, model: &Model, list: &str) -> Result<(FreeSelection, String), CliError> {
        let names = crate::common::name_list(list);
        let known: Vec<&str> = model.parameters.iter().map(|p| p.name.as_str()).collect();
        for n in &names {
            match model.parameter(n) {
                None => {
                    return Err(CliError::input(format!(
                        "error: `--free {list}`: the model has no parameter `{n}`; parameters: {}",
                        known.join(", ")
                    )))
                }
                Some(p) if p.estimate.is_none() => {
                    return Err(CliError::input(format!(
                        "error: `--free {list}`: `{n}` has no `estimate [lo, hi]` box in the model file; add one to its `parameter` line (identify searches within it)"
                    )))
                }
                Some(_) => {}
            }
        }
        let checked = plantc_derive::lang::parse_and_check("model", text);
        let file = checked
            .model
            .ok_or_else(|| CliError::input("error: the model does not parse".to_string()))?;
        let mut held = Vec::new();
        let mut out = text.to_string();
        for p in &file.parameters {
            if let (Some(b), false) = (&p.estimate, names.contains(&p.name.name)) {
                held.push((
                    p.name.name.clone(),
                    text[b.lo.span.start..b.lo.span.end].to_string(),
                    text[b.hi.span.start..b.hi.span.end].to_string(),
                ));
            }
        }
        for (n, _, _) in &held {
            out = plantc_derive::lang::edit::clear_estimate(&out, n).map_err(fail)?;
        }
        Ok((FreeSelection { held }, out))
    }

    /// `text` with the held parameters' boxes put back.
    fn restore(&self, text: &str) -> Result<String, CliError> {
        let mut out = text.to_string();
        for (n, lo, hi) in &self.held {
            out = plantc_derive::lang::edit::set_estimate(&out, n, lo, hi).map_err(fail)?;
        }
        Ok(out)
    }
}

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
                .map_or("-".to_string(), cell);
            line.push_str(&format!("  {cell:>cw$}"));
        }
        let _ = writeln!(out, "{line}");
    }
    let _ = writeln!(
        out,
        "(cells: each stage's model simulated over the whole records from its estimated initial state, fit % as MATLAB's compare, then RMSE in SI units; `diverged`: the simulation could not be finished or left the data, fit % below -100; fit % of a channel that barely moves is capped by encoder quantisation: judge it by RMSE)"
    );
}

pub fn run(args: &IdentifyArgs, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), CliError> {
    if args.json {
        crate::commands::fit::quiet();
    }
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

/// A validation's fit % per experiment and channel, one line per experiment.
fn write_validation_lines(out: &mut dyn Write, v: &Validation) {
    for e in &v.experiments {
        let sim = if e.simulation.is_empty() {
            "simulation diverged".to_string()
        } else {
            channel_fits(&e.simulation)
        };
        let pred = match v.horizon {
            Some(h) => format!("; {h} s ahead {}", channel_fits(&e.prediction)),
            None => String::new(),
        };
        let _ = writeln!(out, "   held out {}: {sim}{pred}", e.name);
    }
}

fn story(
    args: &IdentifyArgs,
    out: &mut Vec<u8>,
    err: &mut dyn Write,
) -> Result<serde_json::Value, CliError> {
    let dir: &PathBuf = &args.out;
    // a commit a killed run left half done is finished before the directory
    // is judged (its manifest is written last)
    plantc_fsio::finish_interrupted(dir);
    if let Some(file) = &args.report {
        refuse_report_file(file, args.force)?;
    }
    if dir.exists()
        && !args.force
        && std::fs::read_dir(dir).map_or(true, |mut d| d.next().is_some())
        && !made_by_identify(dir)
    {
        return Err(CliError::input(format!(
            "error: `{}` exists, is not empty and was not written by `plantc identify`; choose a new directory or pass --force (identify then writes its files beside yours: a file of yours at one of its paths is replaced, no other is touched)",
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
    let (selection, text) = match &args.free {
        Some(list) => {
            let (sel, t) = FreeSelection::new(&text, model, list)?;
            (Some(sel), t)
        }
        None => (None, text),
    };
    let restore = |t: String| -> Result<String, CliError> {
        match &selection {
            Some(sel) => sel.restore(&t),
            None => Ok(t),
        }
    };
    let measured = read_data(model, &args.data, err)?;
    let held_out = read_held_out(model, &args.data, &args.validate, err)?;
    let opts = StoryOptions {
        fit: fit_options(model, &args.control, Some(&args.horizon))?,
        max_effects: args.max_effects,
        validate: held_out.clone(),
        predict: args.predict,
        diagnose: plantc_identify::DiagnoseOptions {
            inputs_read: crate::common::inputs_settled(&args.data)?.is_some(),
            ..plantc_identify::DiagnoseOptions::default()
        },
    };
    // inputs are checked before anything is written; the new directory is
    // built aside and swapped in at the end: a killed run leaves the old one
    let fresh = plantc_fsio::FreshDir::create(dir, "identify")
        .map_err(fail)?
        .replace_unlisted(args.force || made_by_identify_before_manifests(dir));
    let staging = fresh.path().to_path_buf();
    let channels: Vec<&str> = model.coordinates.iter().map(|c| c.name.as_str()).collect();
    let s = with_progress("identifying", |set| {
        identify(&text, &measured, &opts, &mut |p| match p {
            StoryProgress::Step(s) => set(s.clone()),
            StoryProgress::Fit(f) => set(progress_text(f)),
        })
    })
    .map_err(fail)?;

    // 1. the nominal model
    let nominal = &s.stages[0];
    let mut estimated: Vec<&str> = Vec::new();
    if opts.fit.estimate_positions {
        estimated.push("initial positions");
    }
    if opts.fit.estimate_velocities {
        estimated.push("initial velocities");
    }
    if !matches!(opts.fit.offsets, plantc_identify::Offsets::None) {
        estimated.push("sensor zeros");
    }
    let estimated = match estimated.split_last() {
        None => "nothing".to_string(),
        Some((last, [])) => last.to_string(),
        Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
    };
    let _ = writeln!(
        out,
        "1. nominal model `{}` against {} experiment(s) ({estimated} estimated per experiment)",
        args.model.display(),
        measured.len()
    );
    if let Some(replay) = &s.stabilised {
        let _ = writeln!(out, "   note: {}", replay.note());
    }
    for e in &s.fit.experiments {
        if let Some(l) = e.release_line() {
            let _ = writeln!(out, "   {l}");
        }
    }
    write_stage_figures((&staging, dir), "1-nominal", model, &measured, nominal, err)?;
    let _ = writeln!(out, "   RMSE {:.3e}; where it fails:", nominal.report.rmse);
    if write_failures(out, model, &measured, &nominal.simulated)? == 0 {
        let _ = writeln!(out, "  no pattern in the residuals");
    }
    if let Some(v) = &nominal.validation {
        write_validation_lines(out, v);
    }
    // 2. the nominal model refitted (round 1's baseline)
    let refitted = &s.stages[1];
    let _ = writeln!(
        out,
        "\n2. diagnose: refit the nominal model, rank candidate effects by equation error, refit the leaders"
    );
    write_stage_figures(
        (&staging, dir),
        "2-refitted",
        model,
        &measured,
        refitted,
        err,
    )?;
    // (", dry friction creeping" when the records' law was adopted there)
    let law = refitted
        .label
        .strip_prefix("nominal, refitted")
        .unwrap_or_default();
    if let Some((round, r)) = &s.continuous_inputs {
        let _ = writeln!(
            out,
            "   inputs read as continuous signals, not held over each sample interval, from round {round} on: weighted RMS {:.4e} held, {:.4e} continuous ({})",
            r.held, r.continuous, r.why
        );
    }
    if let Some((round, _, words)) = &s.unpredictable {
        let _ = writeln!(out, "   from round {round} on, {words}");
    }
    let _ = writeln!(
        out,
        "   nominal model refitted{law}: RMSE {:.3e}; where it still fails:",
        refitted.report.rmse
    );
    if write_failures(out, model, &measured, &refitted.simulated)? == 0 {
        let _ = writeln!(out, "  no pattern in the residuals");
    }
    if let Some(v) = &refitted.validation {
        write_validation_lines(out, v);
    }
    // 3. the rounds
    let mut summary_rounds = Vec::new();
    let mut files = vec!["fitted.plant".to_string()];
    for (k, round) in s.rounds.iter().enumerate() {
        let _ = writeln!(out, "\n{}. round {}:", 3 + k, k + 1);
        for r in round.ranking.iter().filter(|r| r.fit.is_some()) {
            let rule = r.rule_line();
            let _ = writeln!(
                out,
                "   candidate {:<28} refit RMSE {:.3e}, equation-error rank {}; {rule}",
                r.candidate.label(),
                r.fit.as_ref().map_or(f64::NAN, |f| f.after_rmse),
                r.evidence.equation_error_rank,
            );
        }
        match (&round.effect, &round.fit) {
            (Some(inst), Some(f)) => {
                let what = "missing effect";
                let _ = writeln!(
                    out,
                    "   {what}: `{}` on `{}`; added to a copy of the model:\n{}",
                    inst.effect,
                    inst.target,
                    indent(&inst.snippet())
                );
                let stage = &s.stages[2 + k];
                let m2 = model_from_text("stage", &stage.text).map_err(fail)?;
                let file = if k == 0 {
                    "with_effect.plant".to_string()
                } else {
                    format!("with_effect_{}.plant", k + 1)
                };
                let edited = restore(with_values(&stage.text, &m2, f)?)?;
                write_file(&staging.join(&file), &edited)?;
                files.push(file.clone());
                let _ = writeln!(
                    err,
                    "model with the effect -> {}",
                    dir.join(&file).display()
                );
                write_estimates(out, &f.parameters);
                for m in f.identifiability.messages() {
                    let _ = writeln!(out, "   warning: {m}");
                }
                show_stage(
                    (out, err),
                    (&staging, dir),
                    &format!("{}-fitted", 3 + k),
                    &m2,
                    &measured,
                    stage,
                )?;
                summary_rounds.push(serde_json::json!({
                    "effect": inst.effect,
                    "target": inst.target,
                    "snippet": inst.snippet(),
                    "cost_before": round.cost_before,
                    "cost_after": round.cost_after,
                    "test": round.test,
                    "fit": crate::commands::fit::fit_json(f),
                    "model": file,
                }));
            }
            _ => {
                let _ = writeln!(out, "   verdict: {}", s.stop);
                if let Some(stage) = s.better_start.and_then(|i| s.stages.get(i)) {
                    let _ = writeln!(
                        out,
                        "   the model as it stands, refitted from a candidate's values, reached a lower cost ({:.3e}): that fit is the result",
                        stage.cost.unwrap_or(f64::NAN)
                    );
                }
            }
        }
    }
    // the end steps in the order the story ran them (its stages): earlier
    // effects the model no longer needs removed, effects replaced by their
    // simpler form
    enum EndStep<'s> {
        Removed(&'s plantc_identify::story::Removal),
        Simplified(&'s plantc_identify::story::Simplification),
    }
    let mut end_steps: Vec<(usize, EndStep)> = s
        .removals
        .iter()
        .map(|r| (r.stage, EndStep::Removed(r)))
        .chain(
            s.simplifications
                .iter()
                .map(|x| (x.stage, EndStep::Simplified(x))),
        )
        .collect();
    end_steps.sort_by_key(|(stage, _)| *stage);
    let mut summary_removed = Vec::new();
    let mut summary_simplified = Vec::new();
    for (i, (_, step)) in end_steps.iter().enumerate() {
        let n = 3 + s.rounds.len() + i;
        match step {
            EndStep::Removed(removal) => {
                let ratio = removal.cost_without / removal.cost_with.max(f64::MIN_POSITIVE);
                let _ = writeln!(
                    out,
                    "\n{n}. removed: `{}` (round {}) no longer passes the decision rule against the model as it now stands without it (weighted RMS {:.3e} with it, {:.3e} without: ratio {ratio:.3}; {})",
                    removal.effect.label(),
                    removal.round,
                    removal.cost_with,
                    removal.cost_without,
                    removal.test.describe(),
                );
                summary_removed.push(serde_json::json!({
                    "round": removal.round,
                    "effect": removal.effect.label(),
                    "cost_with": removal.cost_with,
                    "cost_without": removal.cost_without,
                }));
            }
            EndStep::Simplified(simple) => {
                let ratio = simple.cost_simpler / simple.cost_with.max(f64::MIN_POSITIVE);
                match &simple.then {
                    None => {
                        let _ = writeln!(
                            out,
                            "\n{n}. simplification: with the later effects in, `{}` (round {}) no longer passes the decision rule against the simpler `{}` it contains (weighted RMS {:.3e} with it, {:.3e} with the simpler one: ratio {ratio:.3}; {}); replaced:\n{}",
                            simple.from.label(),
                            simple.round,
                            simple.to.label(),
                            simple.cost_with,
                            simple.cost_simpler,
                            simple.test.as_ref().map_or_else(String::new, |t| t.describe()),
                            indent(&simple.to.snippet())
                        );
                    }
                    Some(then) => {
                        let _ = writeln!(
                            out,
                            "\n{n}. simplification: `{}` (round {}) was fitted to no shape of its own (no hump, or its velocity at a bound of its box); with `{}` in its place the diagnosis names `{}`, and the model with both (weighted RMS {:.3e} against {:.3e}, ratio {ratio:.3}) has the lower information criterion; replaced and added:\n{}\n{}",
                            simple.from.label(),
                            simple.round,
                            simple.to.label(),
                            then.label(),
                            simple.cost_simpler,
                            simple.cost_with,
                            indent(&simple.to.snippet()),
                            indent(&then.snippet())
                        );
                    }
                }
                summary_simplified.push(serde_json::json!({
                    "round": simple.round,
                    "from": simple.from.label(),
                    "to": simple.to.label(),
                    "snippet": simple.to.snippet(),
                    "then": simple.then.as_ref().map(|t| t.label()),
                    "cost_with": simple.cost_with,
                    "cost_simpler": simple.cost_simpler,
                }));
            }
        }
        let (stage, what) = match step {
            EndStep::Removed(r) => (r.stage, "removed"),
            EndStep::Simplified(x) => (x.stage, "simplified"),
        };
        if let Some(stage) = s.stages.get(stage) {
            let m2 = model_from_text("stage", &stage.text).map_err(fail)?;
            show_stage(
                (out, err),
                (&staging, dir),
                &format!("{n}-{what}"),
                &m2,
                &measured,
                stage,
            )?;
        }
    }
    if !s.simplifications.is_empty() || !s.removals.is_empty() {
        write_estimates(out, &s.fit.parameters);
    }
    // the result
    let final_model = model_from_text("final", &s.text).map_err(fail)?;
    let mut fitted = restore(with_values(&s.text, &final_model, &s.fit)?)?;
    if let Some(law) = &s.creeping {
        // the values were fitted under the creeping law: said where the
        // model is read
        fitted = format!(
            "# fitted with dry friction creeping: simulate it with `--friction smooth:{:.4e}`\n# (the records' joints creep rather than stick; see `plantc identify`'s verdict)\n{fitted}",
            law.width
        );
    }
    write_file(&staging.join("fitted.plant"), &fitted)?;
    let stage_refs: Vec<Stage> = s
        .stages
        .iter()
        .flat_map(|st| {
            let mut v = vec![Stage {
                label: st.label.clone(),
                report: st.report.clone(),
            }];
            if let Some(seg) = &st.segment_report {
                v.push(Stage {
                    label: format!("({}: segments as fitted)", st.label),
                    report: seg.clone(),
                });
            }
            v
        })
        .collect();
    let _ = writeln!(out, "\nbefore and after:");
    table(out, &stage_refs, &measured, &channels);
    // whole-record simulations at both ends (a stage's segments are its
    // own column, and said apart)
    let first = s.stages.first().map_or(f64::NAN, |st| st.report.rmse);
    let last = s.stages.last().map_or(f64::NAN, |st| st.report.rmse);
    let shown = |v: f64| {
        if v.is_finite() {
            format!("{v:.3e}")
        } else {
            "diverged".to_string()
        }
    };
    let ratio = if first.is_finite() && last.is_finite() {
        format!(" (RMSE ratio {:.1})", first / last.max(f64::MIN_POSITIVE))
    } else {
        String::new()
    };
    let on_segments = s
        .stages
        .last()
        .and_then(|st| st.segment_report.as_ref())
        .map(|r| format!("; on the segments as fitted {}", shown(r.rmse)))
        .unwrap_or_default();
    let elapsed = started.elapsed().as_secs_f64();
    let _ = writeln!(
        out,
        "RMSE {} -> {}{ratio}{on_segments}; {} ({} effect(s) in the final model); model -> {}, figures -> {}/ ({elapsed:.1} s)",
        shown(first),
        shown(last),
        s.stop,
        s.effects_added(),
        dir.join("fitted.plant").display(),
        dir.display(),
    );
    let _ = writeln!(err, "done in {elapsed:.1} s");
    let mut summary = serde_json::json!({
        "model": args.model.display().to_string(),
        "verdict": if s.rounds.iter().any(|r| r.effect.is_some()) {
            "missing_effect"
        } else if s.unexplained {
            "unexplained_residual"
        } else {
            "adequate"
        },
        "stop": s.stop,
        "inputs": match &s.continuous_inputs {
            Some((round, r)) => serde_json::json!({"read": "continuous", "from_round": round, "weighted_rms_held": r.held, "weighted_rms_continuous": r.continuous, "why": r.why}),
            None => serde_json::json!({"read": "held"}),
        },
        "dry_friction": match &s.creeping {
            Some(law) => serde_json::json!({"law": "creeping", "width": law.width}),
            None => serde_json::json!({"law": "sticking"}),
        },
        "stabilised_replay": s.stabilised.as_ref().map(|r| serde_json::json!({
            "note": r.note(),
            "controller": r.name,
            "gains": r.gains,
            "poles": [r.poles.0, r.poles.1],
            "block": r.block,
        })),
        "unpredictable": s.unpredictable.as_ref().map(|(round, h, words)| serde_json::json!({
            "round": round,
            "segments": h,
            "note": words,
        })),
        "rounds": summary_rounds,
        "simplified": summary_simplified,
        "removed": summary_removed,
        "fit": crate::commands::fit::fit_json(&s.fit),
        "seconds": elapsed,
        "files": files,
    });
    if let Some(first) = s.rounds.first().and_then(|r| r.effect.as_ref()) {
        summary["effect"] = serde_json::json!({
            "effect": first.effect,
            "target": first.target,
            "snippet": first.snippet(),
        });
    }
    summary["stages"] = s
        .stages
        .iter()
        .map(|st| {
            let mut j =
                serde_json::json!({"stage": st.label, "report": st.report, "cost": st.cost});
            if let Some(v) = &st.validation {
                j["validation"] = serde_json::to_value(v).unwrap_or_default();
            }
            j
        })
        .collect::<Vec<_>>()
        .into();
    let mut buf = Vec::new();
    write_json(&mut buf, &summary);
    write_file(&staging.join("report.json"), &String::from_utf8_lossy(&buf))?;
    // the report a person reads: the story as printed, the summary as above
    let report = Report::new(
        &args.model.display().to_string(),
        &s,
        &measured,
        &FigureChannels::of_model(model),
        &String::from_utf8_lossy(out),
        summary.clone(),
    );
    let html = render_html(&report);
    write_file(&staging.join("report.html"), &html)?;
    // move the complete output in: only identify's own files (its manifest)
    // are replaced or deleted, the user's stay where they are
    fresh.commit().map_err(fail)?;
    let _ = writeln!(err, "report -> {}", dir.join("report.html").display());
    if let Some(file) = &args.report {
        write_file(file, &html)?;
        let _ = writeln!(err, "report -> {}", file.display());
    }
    Ok(summary)
}

/// Refuses, before any work, a `--report` file that exists and was not
/// written by identify (unless `force`), or whose directory does not exist.
fn refuse_report_file(file: &Path, force: bool) -> Result<(), CliError> {
    if file.is_dir() {
        return Err(CliError::input(format!(
            "error: --report `{}` is a directory; name the HTML file to write",
            file.display()
        )));
    }
    let parent = file.parent().filter(|p| !p.as_os_str().is_empty());
    if parent.is_some_and(|p| !p.is_dir()) {
        return Err(CliError::input(format!(
            "error: --report `{}`: the directory `{}` does not exist",
            file.display(),
            parent.unwrap_or(Path::new(".")).display()
        )));
    }
    let ours = std::fs::read_to_string(file)
        .is_ok_and(|t| t.contains(plantc_identify::report_html::GENERATOR));
    if file.exists() && !ours && !force {
        return Err(CliError::input(format!(
            "error: --report `{}` exists and was not written by `plantc identify`; choose another file or pass --force to replace it",
            file.display()
        )));
    }
    Ok(())
}

/// A stage's overlay + residual figures under `dir/sub/`.
fn write_stage_figures(
    (dir, shown): (&Path, &Path),
    sub: &str,
    model: &Model,
    measured: &[Experiment],
    stage: &plantc_identify::Stage,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    write_figures(
        &dir.join(sub),
        &shown.join(sub),
        model,
        measured,
        &stage.simulated,
        err,
    )
}

/// A fit's estimates, one line each, with their standard errors and
/// whether fixed or at a bound.
fn write_estimates(out: &mut dyn Write, estimates: &[plantc_identify::Estimate]) {
    for e in estimates {
        let _ = writeln!(
            out,
            "   {:<10} = {:.5e}  (std error {:.1e}){}",
            e.name,
            e.value,
            e.std_error,
            if e.fixed {
                "  fixed (not identifiable)"
            } else if e.at_bound {
                "  at its bound"
            } else {
                ""
            }
        );
    }
}

/// A stage's figures ([`write_stage_figures`]) and its validation lines.
fn show_stage(
    (out, err): (&mut dyn Write, &mut dyn Write),
    dirs: (&Path, &Path),
    sub: &str,
    model: &Model,
    measured: &[Experiment],
    stage: &plantc_identify::Stage,
) -> Result<(), CliError> {
    write_stage_figures(dirs, sub, model, measured, stage, err)?;
    if let Some(v) = &stage.validation {
        write_validation_lines(out, v);
    }
    Ok(())
}

/// Whether `dir` holds the output of an earlier `plantc identify`: its
/// manifest, or (written before manifests) a `report.json` with the story's
/// keys. It may be written into without asking: only identify's own files
/// are replaced or deleted.
fn made_by_identify(dir: &Path) -> bool {
    plantc_fsio::manifest(dir, "identify").is_some() || made_by_identify_before_manifests(dir)
}

/// An identify output from before manifests (its `report.json` has the
/// story's keys): identify's files there are replaced, none deleted.
fn made_by_identify_before_manifests(dir: &Path) -> bool {
    plantc_fsio::manifest(dir, "identify").is_none()
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
