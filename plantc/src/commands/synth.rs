//! `plantc synth`: measurement-like CSV data from a model with hidden effects
//! (the library does the work: `plantc_identify::synth`).

use std::io::Write;

use plantc_identify::synth::{
    file_names, parse_effect_spec, parse_experiment_spec, synthesize, SynthError, SynthOptions,
    SynthSpec,
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

/// Most samples of one synthesised experiment: 1e7, the size `compare` is
/// measured on for a recording (issue 31: under 1 GB and a few minutes).
const MAX_SYNTH_SAMPLES: usize = 10_000_000;

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
    // the sample count is checked before anything is allocated (a duration
    // of 1e9 s asked for 12 TB at once)
    for e in &experiments {
        let samples = e.duration * args.rate;
        if samples > MAX_SYNTH_SAMPLES as f64 {
            return Err(CliError::input(format!(
                "error: `{}`: {} s at {} Hz is {samples:.3e} samples; synth writes at most \
                 {:.0e} per experiment (the largest recording the identification commands are \
                 measured on): shorten the duration or lower --rate",
                e.token, e.duration, args.rate, MAX_SYNTH_SAMPLES as f64
            )));
        }
    }
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
        },
    };
    // Refuse before simulating: nothing the user had is lost.
    let mut names: Vec<String> = file_names(&spec.experiments)
        .map_err(synth_error)?
        .into_iter()
        .map(|n| format!("{n}.csv"))
        .collect();
    names.push("truth.json".into());
    // a commit a killed run left half done is finished before the files
    // are looked for
    plantc_fsio::finish_interrupted(&args.out);
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
    // All files are written aside and moved in at the end; only synth's own
    // files (its manifest) are replaced, the user's stay where they are, and
    // synth's earlier files of other names are kept.
    let fresh = plantc_fsio::FreshDir::create(&args.out, "synth")
        .map_err(|e| CliError::failure(format!("error: {e}")))?
        .replace_unlisted(args.force)
        .keep_earlier_files();
    // long experiments take seconds: a progress line on a terminal
    let data = with_progress("synthesizing", |_| synthesize(&text, &spec)).map_err(synth_error)?;
    let staging = fresh.path();
    let write = |name: &str, content: &str| write_output(&staging.join(name), content);
    for f in &data.files {
        write(&f.file_name, &f.text)?;
    }
    write("truth.json", &data.truth)?;
    fresh
        .commit()
        .map_err(|e| CliError::failure(format!("error: {e}")))?;
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
        "{}: hidden effect(s): {}; {} Hz, {}, noise {}",
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
        num(spec.options.noise)
    );
    Ok(())
}
