//! `plantc synth`: measurement-like CSV data from a model with hidden effects
//! (the library does the work: `plantc_identify::synth`).

use std::io::Write;

use plantc_identify::synth::{
    file_names, friction_name, parse_effect_spec, parse_experiment_spec, parse_friction,
    synthesize, SynthError, SynthOptions, SynthSpec,
};

use crate::cli::SynthArgs;
use crate::commands::fit::with_progress;
use crate::common::{num, parse_quantity, write_output, CliError};

fn synth_error(e: SynthError) -> CliError {
    match e {
        SynthError::Sim(_) => CliError::failure(format!("error: {e}")),
        _ => CliError::input(format!("error: {e}")),
    }
}

pub fn run(args: &SynthArgs, out: &mut dyn Write, _err: &mut dyn Write) -> Result<(), CliError> {
    let effects = args
        .effects
        .iter()
        .map(|t| parse_effect_spec(t))
        .collect::<Result<Vec<_>, _>>()
        .map_err(synth_error)?;
    let experiments = args
        .experiments
        .iter()
        .map(|t| parse_experiment_spec(t))
        .collect::<Result<Vec<_>, _>>()
        .map_err(synth_error)?;
    let friction = parse_friction(&args.friction).map_err(synth_error)?;
    let mut parameter_set = None;
    let mut values = Vec::new();
    for item in &args.set {
        match item.split_once('=') {
            Some((name, value)) => {
                let v = parse_quantity(value).filter(|v| v.is_finite()).ok_or_else(|| {
                    CliError::input(format!(
                        "error: `--set {item}`: `{value}` is not a number (SI, or with `deg`)"
                    ))
                })?;
                values.push((name.trim().to_string(), v));
            }
            None if parameter_set.is_none() => parameter_set = Some(item.trim().to_string()),
            None => {
                return Err(CliError::input(format!(
                    "error: `--set {item}`: only one named parameter set can be used; give single values as NAME=VALUE"
                )))
            }
        }
    }
    let text =
        plantc_derive::model::read_source(&args.model).map_err(|e| CliError::input(e.render()))?;
    let case = args.case.clone().unwrap_or_else(|| {
        args.out
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "synthetic".into())
    });
    let spec = SynthSpec {
        case,
        model_name: args
            .model
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        effects,
        parameter_set,
        values,
        experiments,
        options: SynthOptions {
            rate: args.rate,
            counts: (args.counts > 0).then_some(args.counts),
            noise: args.noise,
            seed: args.seed,
            substep: args.substep,
            friction,
        },
    };
    // Refuse before simulating: nothing the user had is lost.
    let mut names: Vec<String> = file_names(&spec.experiments)
        .map_err(synth_error)?
        .into_iter()
        .map(|n| format!("{n}.csv"))
        .collect();
    names.push("truth.json".into());
    if !args.force {
        for n in &names {
            let p = args.out.join(n);
            if p.exists() {
                return Err(CliError::input(format!(
                    "error: `{}` already exists; pass --force to overwrite it",
                    p.display()
                )));
            }
        }
    }
    // All files appear together: written into a copy of DIR swapped in at
    // the end (other entries of DIR are kept). In the current directory,
    // which cannot be swapped, each file is still replaced crash-safely.
    let fresh = match plantc_fsio::FreshDir::create(&args.out) {
        Ok(f) => Some(f),
        Err(plantc_fsio::Error::CurrentDirectory { .. }) => None,
        Err(e) => return Err(CliError::failure(format!("error: {e}"))),
    };
    // long experiments take seconds: a progress line on a terminal
    let data = with_progress("synthesizing", |_| synthesize(&text, &spec)).map_err(synth_error)?;
    let staging = fresh.as_ref().map_or(args.out.as_path(), |f| f.path());
    let write = |name: &str, content: &str| write_output(&staging.join(name), content);
    for f in &data.files {
        write(&f.file_name, &f.text)?;
    }
    write("truth.json", &data.truth)?;
    if let Some(f) = fresh {
        f.commit_keeping(|n| !names.iter().any(|w| n == std::path::Path::new(w)))
            .map_err(|e| CliError::failure(format!("error: {e}")))?;
    }
    for f in &data.files {
        let _ = writeln!(
            out,
            "{}: {} samples",
            args.out.join(&f.file_name).display(),
            f.text.lines().count().saturating_sub(1)
        );
    }
    let effects: Vec<String> = spec
        .effects
        .iter()
        .map(|e| format!("{} on {}", e.effect, e.target))
        .collect();
    let _ = writeln!(
        out,
        "{}: hidden effect(s): {}; {} Hz, {}, noise {}, dry friction {}",
        args.out.join("truth.json").display(),
        if effects.is_empty() {
            "none".to_string()
        } else {
            effects.join(", ")
        },
        num(spec.options.rate),
        match spec.options.counts {
            Some(c) => format!("{c} counts/rev"),
            None => "no quantisation".into(),
        },
        num(spec.options.noise),
        friction_name(spec.options.friction)
    );
    Ok(())
}
