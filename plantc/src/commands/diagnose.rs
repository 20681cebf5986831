//! `plantc diagnose`: which physical effect is the model missing? Ranks the
//! candidates of `plantc_identify::diagnose`, prints the verdict, the evidence
//! and the text to add; `--apply -o OUT` writes the model with the top effect
//! added (its parameters marked `estimate`), the effect's and the model's
//! estimated parameters at the values of the refit with the effect, so that
//! `plantc fit OUT` starts where the diagnosis ended.

use std::io::Write;

use plantc_identify::{fitted_instance, Diagnosis, Ranked};

use crate::cli::DiagnoseArgs;
use crate::commands::fit::with_progress;

use crate::common::{
    fit_options, load, read_data, refuse_to_clobber, write_json, write_model,
    write_parameter_values, CliError,
};

/// One finding in the JSON shape of `plantc diagnose --json`.
fn finding_json(r: &Ranked) -> serde_json::Value {
    let inst = fitted_instance(r);
    let mut params = serde_json::Map::new();
    for p in &inst.parameters {
        let se = r
            .parameters
            .iter()
            .find(|e| e.name == p.name)
            .map(|e| e.std_error)
            .filter(|s| s.is_finite());
        params.insert(
            p.base.clone(),
            serde_json::json!({"name": p.name, "value": p.value, "unit": p.unit, "std_error": se}),
        );
    }
    let ev = &r.evidence;
    let shares = |v: &[plantc_identify::Share]| {
        v.iter()
            .map(|s| serde_json::json!({"where": s.label, "share": s.share}))
            .collect::<Vec<_>>()
    };
    serde_json::json!({
        "effect": inst.effect,
        "target": inst.target,
        "parameters": params,
        "evidence": {
            "rmse_before": ev.rmse_before,
            "rmse_after": ev.rmse_after,
            "weighted_rms_ratio": r.gain,
            "test": r.test,
            "residual_share": ev.residual_share,
            "bic_gain": ev.bic_gain,
            "equation_error_rank": ev.equation_error_rank,
            "acts_where": ev.acts_where,
            "by_experiment": shares(&ev.by_experiment),
            "by_speed": shares(&ev.by_speed),
        },
        "snippet": inst.snippet(),
    })
}

/// The findings, best first: the accepted candidate, then any other refitted
/// candidate that passes the same decision rule (an alternative
/// explanation).
fn findings(d: &Diagnosis) -> Vec<&Ranked> {
    let Some(v) = &d.verdict else {
        return Vec::new();
    };
    let mut f: Vec<&Ranked> = d
        .ranking
        .iter()
        .filter(|r| r.candidate.label() == v.label())
        .take(1)
        .collect();
    f.extend(
        d.ranking
            .iter()
            .filter(|r| r.candidate.label() != v.label() && r.passes()),
    );
    f
}

pub fn run(args: &DiagnoseArgs, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), CliError> {
    if args.json {
        crate::commands::fit::quiet();
    }
    if let (true, Some(o)) = (args.apply, &args.out) {
        refuse_to_clobber(o, &args.model, args.force)?;
    }
    let loaded = load(&args.model, err)?;
    let model = &loaded.model;
    let measured = read_data(model, &args.data, err)?;
    let fit_opts = fit_options(model, &args.control, Some(&args.horizon))?;
    let text = std::fs::read_to_string(&args.model).map_err(|e| {
        CliError::input(format!(
            "error: cannot read `{}`: {e}",
            args.model.display()
        ))
    })?;
    let _ = writeln!(
        err,
        "refitting the model with each candidate effect on {} experiment(s)...",
        measured.len()
    );
    let dopts = plantc_identify::DiagnoseOptions {
        fit: fit_opts,
        inputs_read: crate::common::inputs_settled(&args.data)?.is_some(),
        ..plantc_identify::DiagnoseOptions::default()
    };
    let d = with_progress("diagnosing", |_| {
        plantc_identify::diagnose_with(&text, &measured, &dopts)
    })
    .map_err(|e| CliError::failure(format!("error: {e}")))?;
    let findings = findings(&d);
    if args.apply {
        if let (Some(o), Some(top)) = (&args.out, findings.first()) {
            let mut edited = fitted_instance(top)
                .apply(&text)
                .map_err(|e| CliError::failure(format!("error: {e}")))?;
            // The model's own estimated parameters at the values refitted
            // with the effect: `plantc fit OUT` starts where diagnose ended.
            if let Some(f) = &top.fit {
                let values = f.parameters.iter().map(|e| (e.name.as_str(), e.value));
                edited = write_parameter_values(&edited, model, values)?;
            }
            write_model(o, &edited)?;
            let _ = writeln!(
                err,
                "model with {} added -> {}",
                top.candidate.label(),
                o.display()
            );
        } else {
            let _ = writeln!(
                err,
                "note: the model is adequate: nothing to apply, no file written"
            );
        }
    }
    if args.json {
        let v = serde_json::json!({
            "verdict": if !findings.is_empty() {
                "missing_effect"
            } else if d.unexplained() {
                "unexplained_residual"
            } else {
                "adequate"
            },
            "verdict_line": d.verdict_line(),
            "dry_friction": match &d.creeping {
                Some(law) => serde_json::json!({"law": "creeping", "width": law.width, "test": law.test}),
                None => serde_json::json!({"law": "sticking"}),
            },
            "noise_floor_cost": d.floor,
            "baseline_cost": d.baseline.after_cost,
            "at_floor": d.at_floor,
            "effective_samples": d.effective_samples,
            "nuisance_flags": d.nuisance_flags(),
            "notes": d.notes,
            "findings": findings.iter().map(|r| finding_json(r)).collect::<Vec<_>>(),
            "baseline": {"rmse": d.baseline.after_rmse},
            "candidates": d.ranking.iter().map(|r| serde_json::json!({
                "effect": r.candidate.effect,
                "target": r.candidate.target,
                "rmse": r.fit.as_ref().map(|f| f.after_rmse),
                "weighted_rms_ratio": r.gain,
                "test": r.test,
                "passes": r.passes(),
                "bic_gain": r.evidence.bic_gain,
                "equation_error_rank": r.evidence.equation_error_rank,
                "refitted": r.fit.is_some(),
                "stopped_short": r.stopped_short(),
                "error": r.error,
            })).collect::<Vec<_>>(),
        });
        write_json(out, &v);
        return Ok(());
    }
    let _ = writeln!(
        out,
        "baseline (nominal model refitted): RMSE {:.3e}",
        d.baseline.after_rmse
    );
    let _ = writeln!(
        out,
        "{:<20} {:<8} {:>10} {:>12} {:>10} {:>6}  where",
        "effect", "target", "eq.err BIC", "refit RMSE", "wRMS ratio", "rule"
    );
    for r in &d.ranking {
        let (rmse, gain) = match (&r.fit, &r.error) {
            (Some(f), _) => (format!("{:.3e}", f.after_rmse), format!("{:.3}", r.gain)),
            (None, Some(_)) => ("failed".to_string(), "-".to_string()),
            (None, None) => ("not refit".to_string(), "-".to_string()),
        };
        let rule = match &r.test {
            Some(_) if r.passes() => "passes",
            Some(t) if t.likely() => "small",
            Some(_) if r.stopped_short() => "short",
            Some(_) => "fails",
            None => "-",
        };
        let _ = writeln!(
            out,
            "{:<20} {:<8} {:>10.1} {:>12} {:>10} {:>6}  {}",
            r.candidate.effect,
            r.candidate.target,
            r.evidence.bic_gain,
            rmse,
            gain,
            rule,
            r.evidence.acts_where
        );
    }
    let _ = writeln!(
        out,
        "(wRMS ratio: the baseline's weighted RMS over the refit's, in noise units; rule: the decision rule against the baseline, `small` = likely but its contribution stays below the noise, `short` = fails, its refit stopped where it could no longer change the verdict)"
    );
    for n in &d.notes {
        let _ = writeln!(out, "note: {n}");
    }
    match findings.first() {
        Some(top) => {
            let inst = fitted_instance(top);
            let _ = writeln!(
                out,
                "\nverdict: {}. Add to the model:\n{}",
                d.verdict_line(),
                inst.snippet()
            );
        }
        None => {
            let _ = writeln!(out, "\nverdict: {}", d.verdict_line());
        }
    }
    Ok(())
}
