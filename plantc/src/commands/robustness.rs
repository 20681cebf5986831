//! `plantc robustness`: controllers against mismatched plants (the study is
//! `plantc_derive::robustness`); prints which hold and the chattering.

use std::io::Write;
use std::time::Instant;

use plantc_derive::control::Derivation;
use plantc_derive::model::ControllerSpec;
use plantc_derive::robustness::{study, CaseResult, Mismatch, StudyOptions};

use crate::cli::RobustnessArgs;
use crate::common::{
    load, name_list, parse_assignments, parse_quantity, values, write_json, CliError,
};

fn positive_angle(text: &str, what: &str) -> Result<f64, CliError> {
    parse_quantity(text)
        .filter(|x| x.is_finite() && *x > 0.0)
        .ok_or_else(|| {
            CliError::input(format!(
                "error: --{what} `{text}`: expected a positive angle, e.g. 30deg"
            ))
        })
}

fn coordinate(
    model: &plantc_derive::model::Model,
    name: &str,
    what: &str,
) -> Result<usize, CliError> {
    model
        .coordinates
        .iter()
        .position(|c| c.name == name)
        .ok_or_else(|| {
            CliError::input(format!(
                "error: --{what} `{name}` is not a coordinate (coordinates: {})",
                model
                    .coordinates
                    .iter()
                    .map(|c| c.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })
}

pub fn run(
    args: &RobustnessArgs,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    let loaded = load(&args.model, err)?;
    let model = &loaded.model;
    let design = values(&loaded, &args.params)?;
    let controllers: Vec<String> = if args.controllers.is_empty() {
        model
            .controllers
            .iter()
            .filter(|c| {
                !matches!(
                    c,
                    ControllerSpec::Hybrid { .. } | ControllerSpec::Direct { .. }
                )
            })
            .map(|c| c.name().to_string())
            .collect()
    } else {
        args.controllers.clone()
    };
    if controllers.is_empty() {
        return Err(CliError::input(
            "error: the model declares no balancing controller",
        ));
    }
    let by = {
        let t = args.by.trim();
        let v = match t.strip_suffix('%') {
            Some(p) => p.trim().parse::<f64>().ok().map(|x| x / 100.0),
            None => t.parse::<f64>().ok(),
        };
        v.filter(|x| x.is_finite() && *x > 0.0 && *x < 1.0)
            .ok_or_else(|| {
                CliError::input(format!(
                    "error: --by `{}`: expected a fraction in (0, 1) or a percentage, e.g. 20%",
                    args.by
                ))
            })?
    };
    let vary = name_list(args.vary.as_deref().unwrap_or(""));
    let mut add = Vec::new();
    for item in &args.add {
        let (name, value) = item.split_once('=').ok_or_else(|| {
            CliError::input(format!("error: `--add {item}`: expected NAME=VALUE"))
        })?;
        let v = parse_quantity(value)
            .filter(|x| x.is_finite())
            .ok_or_else(|| {
                CliError::input(format!("error: `--add {item}`: `{value}` is not a number"))
            })?;
        add.push((name.trim().to_string(), v));
    }
    for p in vary.iter().chain(add.iter().map(|(p, _)| p)) {
        if model.parameter(p).is_none() {
            return Err(CliError::input(format!(
                "error: `{p}` is not a parameter of the model"
            )));
        }
    }
    let mismatches = Mismatch::standard(&vary, by, &add);
    let x0 = match &args.x0 {
        Some(text) => parse_assignments(text, &model.state_names(), "state")?,
        None => vec![0.0; model.state_names().len()],
    };
    let mut options = StudyOptions::new(model, x0);
    if !(args.duration.is_finite() && args.duration > 2.0) {
        return Err(CliError::input(format!(
            "error: --duration {}: expected more than the 2 s settling window",
            args.duration
        )));
    }
    if !(args.rate.is_finite() && args.rate > 0.0) {
        return Err(CliError::input(format!(
            "error: --rate {}: expected a positive rate",
            args.rate
        )));
    }
    options.duration = args.duration;
    options.sample_rate = args.rate;
    if let Some(p) = &args.pendulum {
        options.pendulum = coordinate(model, p, "pendulum")?;
    }
    if let Some(a) = &args.arm {
        options.arm = coordinate(model, a, "arm")?;
    }
    options.fall_angle = positive_angle(&args.fall_angle, "fall-angle")?;
    options.arm_limit = positive_angle(&args.arm_limit, "arm-limit")?;
    options.settle_angle = positive_angle(&args.settle, "settle")?;
    if let Some(t) = args.threads {
        if t == 0 {
            return Err(CliError::input("error: --threads must be at least 1"));
        }
        options.threads = t;
    }
    let derivation =
        Derivation::new(model).map_err(|e| CliError::failure(format!("error: {e}")))?;
    let started = Instant::now();
    let results = study(
        model,
        &derivation,
        &design,
        &controllers,
        &mismatches,
        &options,
    )
    .map_err(|e| CliError::input(format!("error: {e}")))?;
    let elapsed = started.elapsed().as_secs_f64();
    let pendulum = &model.coordinates[options.pendulum].name;
    let input = model.inputs.first().map_or("u", |i| i.name.as_str());
    if args.json {
        let v = serde_json::json!({
            "design": args.params.set.clone().unwrap_or_else(|| "nominal".into()),
            "duration": options.duration,
            "rate": options.sample_rate,
            "threads": options.threads,
            "seconds": elapsed,
            "cases": results.iter().map(|r| serde_json::json!({
                "controller": r.controller,
                "plant": r.mismatch,
                "holds": r.outcome.holds(),
                "outcome": r.outcome.to_string(),
                "detail": match &r.outcome {
                    plantc_derive::robustness::Outcome::Failed { message } => Some(message.clone()),
                    _ => None,
                },
                "tail_angle_deg": r.tail_angle.to_degrees(),
                "max_arm_deg": r.max_arm.to_degrees(),
                "total_variation": r.total_variation,
                "tail_variation_per_s": r.tail_variation_rate,
            })).collect::<Vec<_>>(),
        });
        write_json(out, &v);
        return Ok(());
    }
    let _ = writeln!(
        out,
        "{} controller(s) x {} plant(s), designed with {}; {} s per case at {} Hz (zero-order hold, exact states, dry friction as tanh(v/{:e})); {} threads, {:.1} s",
        controllers.len(),
        mismatches.len(),
        args.params.set.as_deref().map_or("the nominal values".to_string(), |s| format!("set `{s}`")),
        options.duration,
        options.sample_rate,
        options.smooth_sign,
        options.threads,
        elapsed
    );
    let table = |title: &str, cell: &dyn Fn(&CaseResult) -> String| {
        let width = controllers
            .iter()
            .map(String::len)
            .max()
            .unwrap_or(10)
            .max(10);
        let mut t = format!("{title}\n{:<width$}", "controller");
        for m in &mismatches {
            t.push_str(&format!(" | {:>14}", m.label));
        }
        t.push('\n');
        for c in &controllers {
            t.push_str(&format!("{c:<width$}"));
            for m in &mismatches {
                let r = results
                    .iter()
                    .find(|r| &r.controller == c && r.mismatch == m.label);
                t.push_str(&format!(" | {:>14}", r.map_or("-".into(), cell)));
            }
            t.push('\n');
        }
        t
    };
    let _ = writeln!(
        out,
        "{}",
        table(
            &format!(
                "outcome (holds: |{pendulum}| < {} and the arm within {} throughout, settled within {} over the last 2 s; in brackets the largest |{pendulum}| over the last 2 s, deg):",
                args.fall_angle, args.arm_limit, args.settle
            ),
            &|r| format!("{} ({:.2})", r.outcome, r.tail_angle.to_degrees())
        )
    );
    let _ = writeln!(
        out,
        "{}",
        table(
            &format!("chattering: total variation of {input} over the run (and per second over the last 2 s):"),
            &|r| format!("{:.1} ({:.2}/s)", r.total_variation, r.tail_variation_rate)
        )
    );
    for r in &results {
        if let plantc_derive::robustness::Outcome::Failed { message } = &r.outcome {
            let _ = writeln!(out, "{} against {}: {message}", r.controller, r.mismatch);
        }
    }
    let holds = results.iter().filter(|r| r.outcome.holds()).count();
    let _ = writeln!(out, "{holds} of {} cases hold", results.len());
    Ok(())
}
