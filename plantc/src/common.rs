//! Helpers shared by the commands: errors, model loading with parameter
//! selection, number formatting.

use std::io::Write;
use std::path::Path;

use plantc_derive::model::{load_model, LoadedModel, ParameterValues};

use crate::cli::ParamArgs;
use crate::{EXIT_BAD_INPUT, EXIT_FAILURE};

/// A command's failure: the message for stderr and the exit code.
#[derive(Debug)]
pub struct CliError {
    /// What to print (already rendered, may span several lines).
    pub message: String,
    /// Process exit code.
    pub code: i32,
}

impl CliError {
    /// Bad input from the user (exit code 2).
    pub fn input(message: impl Into<String>) -> CliError {
        CliError {
            message: message.into(),
            code: EXIT_BAD_INPUT,
        }
    }

    /// The computation failed (exit code 1).
    pub fn failure(message: impl Into<String>) -> CliError {
        CliError {
            message: message.into(),
            code: EXIT_FAILURE,
        }
    }
}

/// Load a model, printing its warnings to `err`; errors become a [`CliError`]
/// with the rendered diagnostics.
pub fn load(path: &Path, err: &mut dyn Write) -> Result<LoadedModel, CliError> {
    let loaded = load_model(path).map_err(|e| CliError::input(e.render()))?;
    if !loaded.diagnostics.is_empty() {
        let _ = write!(
            err,
            "{}",
            plantc_derive::lang::diagnostic::render(&loaded.source, &loaded.diagnostics)
        );
    }
    Ok(loaded)
}

/// Print a warning for each sensor offset or input delay of the model, which
/// `consumer` (a command working on the plant equations) ignores.
pub fn warn_ignored_effects(loaded: &LoadedModel, consumer: &str, err: &mut dyn Write) {
    let w = loaded.ignored_signal_effects(consumer);
    if !w.is_empty() {
        let _ = write!(
            err,
            "{}",
            plantc_derive::lang::diagnostic::render(&loaded.source, &w)
        );
    }
}

/// Parse `--param NAME=VALUE` overrides.
pub fn parse_overrides(params: &[String]) -> Result<Vec<(String, f64)>, CliError> {
    params
        .iter()
        .map(|p| {
            let (name, value) = p.split_once('=').ok_or_else(|| {
                CliError::input(format!(
                    "error: `--param {p}`: expected NAME=VALUE, e.g. `--param l2=0.1685`"
                ))
            })?;
            let v: f64 = value
                .trim()
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite())
                .ok_or_else(|| {
                    CliError::input(format!(
                        "error: `--param {p}`: `{value}` is not a finite number (values are in SI units)"
                    ))
                })?;
            Ok((name.trim().to_string(), v))
        })
        .collect()
}

/// Parameter values from `--set` and `--param`.
pub fn values(loaded: &LoadedModel, args: &ParamArgs) -> Result<ParameterValues, CliError> {
    let overrides = parse_overrides(&args.params)?;
    ParameterValues::new(&loaded.model, args.set.as_deref(), &overrides)
        .map_err(|e| CliError::input(format!("error: {e}")))
}

/// Parse `name=value,...` with optional `deg` suffix on values; names must be
/// in `names`. Returns values in `names` order (unnamed are 0).
pub fn parse_assignments(text: &str, names: &[String], what: &str) -> Result<Vec<f64>, CliError> {
    let mut out = vec![0.0; names.len()];
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (name, value) = item
            .split_once('=')
            .ok_or_else(|| CliError::input(format!("error: `{item}`: expected NAME=VALUE")))?;
        let name = name.trim();
        let idx = names.iter().position(|n| n == name).ok_or_else(|| {
            CliError::input(format!(
                "error: `{name}` is not a {what} of the model (known: {})",
                names.join(", ")
            ))
        })?;
        out[idx] = parse_quantity(value)
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                CliError::input(format!(
                    "error: `{name}={value}`: `{value}` is not a finite number (e.g. 0.1, 10deg)"
                ))
            })?;
    }
    Ok(out)
}

/// A number with an optional `deg` or `rad` suffix, in SI.
pub fn parse_quantity(text: &str) -> Option<f64> {
    let t = text.trim();
    if let Some(d) = t.strip_suffix("deg") {
        return d.trim().parse::<f64>().ok().map(f64::to_radians);
    }
    let t = t.strip_suffix("rad").unwrap_or(t);
    t.trim().parse().ok()
}

/// Format a number compactly for tables.
pub fn num(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else if x.abs() >= 1e-3 && x.abs() < 1e5 {
        let s = format!("{x:.6}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_string()
    } else {
        format!("{x:.6e}")
    }
}

/// Print a matrix with row labels.
pub fn write_matrix(out: &mut dyn Write, name: &str, rows: &[Vec<f64>], labels: &[String]) {
    let _ = writeln!(out, "{name} =");
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|r| r.iter().map(|x| num(*x)).collect())
        .collect();
    let width = cells.iter().flatten().map(String::len).max().unwrap_or(1);
    let lw = labels.iter().map(String::len).max().unwrap_or(0);
    for (i, r) in cells.iter().enumerate() {
        let label = labels.get(i).map_or("", String::as_str);
        let _ = write!(out, "  {label:<lw$} [");
        for (j, c) in r.iter().enumerate() {
            if j > 0 {
                let _ = write!(out, " ");
            }
            let _ = write!(out, "{c:>width$}");
        }
        let _ = writeln!(out, "]");
    }
}

/// A complex number as `re` or `re+imi`, compactly.
pub fn complex_text(re: f64, im: f64) -> String {
    if im == 0.0 {
        num(re)
    } else {
        format!("{}{:+}i", num(re), im)
    }
}

/// Pretty JSON of a command's result, on its own line.
pub fn write_json(out: &mut dyn Write, v: &serde_json::Value) {
    let _ = writeln!(
        out,
        "{}",
        serde_json::to_string_pretty(v).unwrap_or_default()
    );
}

/// The channels a model needs from a measurement file: its coordinates
/// (angle or length) and its inputs (kind from the declared unit).
pub fn channel_spec(model: &plantc_derive::model::Model) -> plantc_identify::ChannelSpec {
    use plantc_derive::model::CoordinateKind;
    use plantc_identify::Kind;
    let mut spec = plantc_identify::ChannelSpec::new();
    for c in &model.coordinates {
        spec = match c.kind {
            CoordinateKind::Angle => spec.angle(&c.name),
            CoordinateKind::Length => spec.length(&c.name),
        };
    }
    for i in &model.inputs {
        let kind = match i.unit.replace(' ', "").as_str() {
            "V" => Kind::Voltage,
            "A" => Kind::Current,
            "N" => Kind::Force,
            "N*m" | "Nm" | "N.m" => Kind::Torque,
            _ => Kind::Other,
        };
        // an input a recorded controller drives may be absent: the
        // controller in the loop computes it
        let driven = model
            .recorded
            .iter()
            .any(|r| r.laws.iter().any(|l| model.inputs[l.0].name == i.name));
        spec = if driven {
            spec.optional(&i.name, kind)
        } else {
            spec.input(&i.name, kind)
        };
    }
    spec
}

/// Reads the measured experiments of `data` for `model`; warnings go to
/// `err`, a bad file is bad input (exit 2) with its file:line:col message.
pub fn read_data(
    model: &plantc_derive::model::Model,
    data: &crate::cli::DataArgs,
    err: &mut dyn Write,
) -> Result<Vec<plantc_identify::Experiment>, CliError> {
    let spec = channel_spec(model);
    let mut options = plantc_identify::ReadOptions {
        rename: plantc_identify::parse_rename(&data.map)
            .map_err(|e| CliError::input(format!("error: --map: {e}")))?,
        ..plantc_identify::ReadOptions::default()
    };
    if let Some(c) = &data.channels {
        options.mat_channels = Some(
            plantc_identify::parse_channel_map(c)
                .map_err(|e| CliError::input(format!("error: {e}")))?,
        );
    }
    let continuous = inputs_settled(data)?;
    let (exps, warnings) = plantc_identify::read_experiments(&data.data, &spec, &options)
        .map_err(|e| CliError::input(format!("error: {e}")))?;
    for w in warnings {
        let _ = writeln!(err, "{w}");
    }
    if continuous == Some(true) {
        return Ok(plantc_identify::continuous_records(model, &exps));
    }
    Ok(exps)
}

/// `--inputs`: `Some(true)` continuous, `Some(false)` held, `None` auto
/// (the diagnosis decides).
pub fn inputs_settled(data: &crate::cli::DataArgs) -> Result<Option<bool>, CliError> {
    match data.inputs.trim() {
        "auto" => Ok(None),
        "held" => Ok(Some(false)),
        "continuous" => Ok(Some(true)),
        other => Err(CliError::input(format!(
            "error: --inputs: expected `held`, `continuous` or `auto`, got `{other}`"
        ))),
    }
}

/// Reads the held-out files of `--validate` (none given: no experiments)
/// with the measured data's `--map` and `--channels`.
pub fn read_held_out(
    model: &plantc_derive::model::Model,
    data: &crate::cli::DataArgs,
    validate: &[std::path::PathBuf],
    err: &mut dyn Write,
) -> Result<Vec<plantc_identify::Experiment>, CliError> {
    if validate.is_empty() {
        return Ok(Vec::new());
    }
    let held_out = crate::cli::DataArgs {
        data: validate.to_vec(),
        ..data.clone()
    };
    read_data(model, &held_out, err)
}

/// A validation's per-channel fit % (simulation or prediction), e.g.
/// `theta 93.1 %, alpha -` (`-`: no fit % for the channel).
pub fn channel_fits(scores: &[plantc_identify::ChannelScore]) -> String {
    scores
        .iter()
        .map(|c| {
            format!(
                "{} {}",
                c.channel,
                c.fit_percent
                    .map_or("-".to_string(), |f| format!("{f:.1} %"))
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The names of a comma-separated list (`a, b,,c` -> `a`, `b`, `c`).
pub fn name_list(text: &str) -> Vec<String> {
    text.split(',')
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

/// A value in SI as a number literal in the parameter's declared unit, for
/// the lossless editor.
/// `text` with the given parameter values (SI) written in, each in its
/// declared unit, through the lossless editor; names the model lacks are
/// skipped.
pub fn write_parameter_values<'a>(
    text: &str,
    model: &plantc_derive::model::Model,
    values: impl IntoIterator<Item = (&'a str, f64)>,
) -> Result<String, CliError> {
    let mut t = text.to_string();
    for (name, v) in values {
        if let Some(p) = model.parameter(name) {
            t = plantc_derive::lang::edit::set_parameter_value(
                &t,
                name,
                &declared_value_text(p, v),
            )
            .map_err(|e| CliError::failure(format!("error: writing `{name}`: {e}")))?;
        }
    }
    Ok(t)
}

/// A parameter's SI value as literal text in its declared unit.
pub fn declared_value_text(p: &plantc_derive::model::Parameter, si: f64) -> String {
    let scale = plantc_derive::lang::units::parse_unit(&p.unit)
        .map(|u| u.scale.to_f64())
        .unwrap_or(1.0);
    plantc_derive::lang::edit::number_text(si / scale)
}

/// Whether `a` and `b` are the same existing file (also through links).
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return x.dev() == y.dev() && x.ino() == y.ino();
        }
    }
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// A model text in the canonical layout of `plantc fmt`: every model file
/// plantc writes goes through it. The formatter refuses only texts with
/// syntax errors, which a model that loaded cannot have, and texts whose
/// meaning it would change (its own bug, caught by its check); such a text is
/// returned as it is rather than lost.
pub fn canonical(text: &str) -> String {
    plantc_derive::lang::format::format(text).unwrap_or_else(|_| text.to_string())
}

/// Writes a model file (crash-safe) in the canonical layout.
pub fn write_model(path: &Path, text: &str) -> Result<(), CliError> {
    write_output(path, canonical(text))
}

/// Writes `bytes` to `path` crash-safely (temporary file, fsync, rename):
/// a kill at any moment leaves the old complete file or the new one.
pub fn write_output(path: &Path, bytes: impl AsRef<[u8]>) -> Result<(), CliError> {
    plantc_fsio::write_atomic(path, bytes).map_err(|e| CliError::failure(format!("error: {e}")))
}

/// Checks before any work that a file can be written at `path` (its
/// directory exists and accepts files): a long fit must not end in
/// "cannot write".
pub fn check_writable(path: &Path) -> Result<(), CliError> {
    plantc_fsio::probe_writable(path).map_err(|e| CliError::input(format!("error: {e}")))
}

/// Refuses to write `out` when it exists (the input model included) unless
/// `force`; never writes over the input model without `force` either. Also
/// checks up front that `out` can be written.
pub fn refuse_to_clobber(out: &Path, input: &Path, force: bool) -> Result<(), CliError> {
    let same = same_file(out, input);
    if same && !force {
        return Err(CliError::input(format!(
            "error: `{}` is the input model; write the result to another file, or pass --force to replace it",
            out.display()
        )));
    }
    if out.exists() && !force {
        return Err(CliError::input(format!(
            "error: `{}` already exists; pass --force to overwrite it",
            out.display()
        )));
    }
    check_writable(out)
}

/// The fit options of `--weight`, `--estimate-initial`, `--offsets`,
/// `--closed-loop` and (for commands that fit) `--horizon`.
pub fn fit_options(
    model: &plantc_derive::model::Model,
    c: &crate::cli::FitControlArgs,
    fit_horizon: Option<&str>,
) -> Result<plantc_identify::FitOptions, CliError> {
    use plantc_identify::{ClosedLoop, FitOptions, Horizon, InitialVelocity, Offsets};
    let bad = |m: String| CliError::input(format!("error: {m}"));
    // every command that fits takes its control arguments here
    if let Some(n) = c.threads {
        plantc_identify::parallel::set_threads(usize::from(n));
    }
    let horizon = match fit_horizon.unwrap_or("auto").trim() {
        "auto" => Horizon::Auto,
        "whole" | "all" => Horizon::Whole,
        s => match s.trim_end_matches('s').trim().parse::<f64>() {
            Ok(h) if h > 0.0 && h.is_finite() => Horizon::Segments(h),
            _ => {
                return Err(bad(format!(
                    "--horizon `{s}`: expected `auto`, `whole` or a positive number of seconds"
                )))
            }
        },
    };
    let mut weights = Vec::new();
    for w in c.weights.iter().flat_map(|s| s.split(',')) {
        let w = w.trim();
        if w.is_empty() {
            continue;
        }
        let Some((name, v)) = w.split_once('=') else {
            return Err(bad(format!(
                "--weight `{w}`: expected COORD=W, e.g. `alpha=20`"
            )));
        };
        let name = name.trim();
        if !model.coordinates.iter().any(|c| c.name == name) {
            let known: Vec<&str> = model.coordinates.iter().map(|c| c.name.as_str()).collect();
            return Err(bad(format!(
                "--weight `{w}`: the model has no coordinate `{name}`; coordinates: {}",
                known.join(", ")
            )));
        }
        match v.trim().parse::<f64>() {
            Ok(x) if x > 0.0 && x.is_finite() => weights.push((name.to_string(), x)),
            _ => {
                return Err(bad(format!(
                    "--weight `{w}`: the weight must be a positive number"
                )))
            }
        }
    }
    let (estimate_positions, estimate_velocities) = {
        let mut p = false;
        let mut v = false;
        for part in c.estimate_initial.split(',').map(str::trim) {
            match part {
                "positions" => p = true,
                "velocities" => v = true,
                "all" => {
                    p = true;
                    v = true
                }
                "none" => {}
                other => {
                    return Err(bad(format!(
                        "--estimate-initial `{other}`: expected `velocities`, `positions`, `all` or `none`"
                    )))
                }
            }
        }
        (p, v)
    };
    let offsets = match c.offsets.trim() {
        "auto" => Offsets::Auto,
        "none" => Offsets::None,
        list => {
            let names = name_list(list);
            for n in &names {
                if !model.coordinates.iter().any(|c| &c.name == n) {
                    return Err(bad(format!("--offsets: the model has no coordinate `{n}`")));
                }
            }
            Offsets::On(names)
        }
    };
    let closed_loop = match c.closed_loop.trim() {
        "auto" => ClosedLoop::Auto,
        "off" | "none" => ClosedLoop::Off,
        name => {
            if model.recorded_controller(name).is_none() {
                let known: Vec<&str> = model.recorded.iter().map(|r| r.name.as_str()).collect();
                return Err(bad(format!(
                    "--closed-loop `{name}`: the model has no recorded controller of that name{}",
                    if known.is_empty() {
                        " (it has none)".to_string()
                    } else {
                        format!("; it has: {}", known.join(", "))
                    }
                )));
            }
            ClosedLoop::Named(name.to_string())
        }
    };
    let friction = plantc_identify::synth::parse_friction(&c.friction)
        .map_err(|e| bad(format!("--friction: {e}")))?;
    let mut opts = FitOptions {
        horizon,
        weights,
        estimate_positions,
        estimate_velocities,
        offsets,
        closed_loop,
        ..FitOptions::default()
    };
    opts.sim.dry_friction = friction;
    if !estimate_velocities {
        opts.sim.initial_velocity = InitialVelocity::Zero;
    }
    Ok(opts)
}
