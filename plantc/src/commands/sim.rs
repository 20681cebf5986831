//! `plantc sim`: closed-loop simulation of a model with one of its controllers;
//! CSV trajectory, optional SVG figure, short summary.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use plantc_derive::control::{resolve, Derivation};
use plantc_derive::mechanics::smooth_signs;
use plantc_derive::simulate::{
    set_gains, simulate, Control, ControllerEval, Integrator, SimError, SimOptions, SimProblem,
    Trajectory,
};

use crate::cli::{IntegratorKind, SimArgs};
use crate::common::{
    check_writable, load, num, parse_assignments, parse_quantity, same_file, values,
    warn_ignored_effects, write_output, CliError,
};

/// Refuses an existing `path` unless `force`, and checks that it can be
/// written (before any work).
pub(crate) fn refuse_overwrite(path: &Path, force: bool, what: &str) -> Result<(), CliError> {
    if path.exists() && !force {
        return Err(CliError::input(format!(
            "error: {what} `{}` already exists; pass --force to overwrite it",
            path.display()
        )));
    }
    check_writable(path)
}

/// Two outputs of one command must be different files (`-o x.csv --plot
/// x.csv` would replace the trajectory by the figure).
pub(crate) fn distinct_outputs(a: &Path, b: &Path) -> Result<(), CliError> {
    let lexical = |p: &Path| {
        let abs = std::env::current_dir().map_or(p.to_path_buf(), |d| d.join(p));
        let mut n = std::path::PathBuf::new();
        for c in abs.components() {
            match c {
                std::path::Component::CurDir => {}
                std::path::Component::ParentDir => {
                    n.pop();
                }
                c => n.push(c),
            }
        }
        n
    };
    if lexical(a) == lexical(b) || same_file(a, b) {
        return Err(CliError::input(format!(
            "error: the trajectory (-o) and the figure (--plot) would both go to `{}`; give the figure its own file, e.g. `--plot {}`",
            b.display(),
            b.with_extension("svg").display()
        )));
    }
    Ok(())
}

/// `--gain a=1.5,b=1.5` (repeatable).
pub(crate) fn parse_gains(items: &[String]) -> Result<Vec<(String, f64)>, CliError> {
    let mut v = Vec::new();
    for text in items {
        for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (name, value) = item.split_once('=').ok_or_else(|| {
                CliError::input(format!("error: `--gain {item}`: expected NAME=VALUE"))
            })?;
            let x = parse_quantity(value)
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    CliError::input(format!("error: `--gain {item}`: `{value}` is not a number"))
                })?;
            v.push((name.trim().to_string(), x));
        }
    }
    Ok(v)
}

fn sim_error(e: SimError) -> CliError {
    match e {
        SimError::UnknownGain { .. } | SimError::Setup(_) => CliError::input(format!("error: {e}")),
        _ => CliError::failure(format!("error: simulation failed: {e}")),
    }
}

/// Column headers: `t`, states, inputs, outputs (`y_<name>` when the name is a state).
fn headers(traj: &Trajectory) -> Vec<String> {
    let mut h = vec!["t".to_string()];
    h.extend(traj.state_names.iter().cloned());
    h.extend(traj.input_names.iter().cloned());
    for o in &traj.output_names {
        if traj.state_names.contains(o) || traj.input_names.contains(o) || o == "t" {
            h.push(format!("y_{o}"));
        } else {
            h.push(o.clone());
        }
    }
    if !traj.modes.is_empty() {
        h.push("mode".to_string());
    }
    h
}

fn write_csv(path: &Path, traj: &Trajectory) -> Result<(), CliError> {
    let fail = |e: &dyn std::fmt::Display| CliError::failure(format!("error: {e}"));
    let mut f = plantc_fsio::AtomicFile::create(path).map_err(|e| fail(&e))?;
    let io = |e: std::io::Error| {
        CliError::failure(format!("error: cannot write `{}`: {e}", path.display()))
    };
    writeln!(f, "{}", headers(traj).join(",")).map_err(io)?;
    for k in 0..traj.len() {
        let row = std::iter::once(traj.t[k])
            .chain(traj.states[k].iter().copied())
            .chain(traj.inputs[k].iter().copied())
            .chain(traj.outputs[k].iter().copied());
        for (i, x) in row.enumerate() {
            if i > 0 {
                f.write_all(b",").map_err(io)?;
            }
            write!(f, "{x}").map_err(io)?;
        }
        if let Some(m) = traj.modes.get(k) {
            write!(f, ",{}", traj.mode_names[*m]).map_err(io)?;
        }
        f.write_all(b"\n").map_err(io)?;
    }
    f.commit().map_err(|e| fail(&e))
}

/// The figure as SVG text.
fn plot(traj: &Trajectory, units: &[String], title: &str) -> Result<String, String> {
    let mut svg = String::new();
    draw(&mut svg, traj, units, title)?;
    Ok(svg)
}

fn draw(svg: &mut String, traj: &Trajectory, units: &[String], title: &str) -> Result<(), String> {
    use plotters::prelude::*;
    // Panels: angles in degrees (arm, pendulum, ...), then each input.
    let n = traj.state_names.len() / 2;
    let mut panels: Vec<(String, Vec<f64>)> = Vec::new();
    for i in 0..n {
        let name = &traj.state_names[i];
        panels.push((
            format!("{name} [deg]"),
            traj.states.iter().map(|x| x[i].to_degrees()).collect(),
        ));
    }
    for (j, name) in traj.input_names.iter().enumerate() {
        let label = match units.get(j).map(String::as_str) {
            Some("") | None => name.clone(),
            Some(u) => format!("{name} [{u}]"),
        };
        panels.push((label, traj.inputs.iter().map(|u| u[j]).collect()));
    }
    let t_end = traj.t.last().copied().unwrap_or(1.0).max(1e-9);
    let height = 240 * panels.len() as u32 + 40;
    let root = SVGBackend::with_string(svg, (900, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let root = root
        .titled(title, ("sans-serif", 20))
        .map_err(|e| e.to_string())?;
    let areas = root.split_evenly((panels.len(), 1));
    for (area, (label, data)) in areas.iter().zip(&panels) {
        let (mut lo, mut hi) = data
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                (l.min(*v), h.max(*v))
            });
        if !(lo.is_finite() && hi.is_finite()) {
            lo = -1.0;
            hi = 1.0;
        }
        let pad = ((hi - lo) * 0.05).max(1e-6 * hi.abs().max(1.0));
        let mut chart = ChartBuilder::on(area)
            .margin(8)
            .x_label_area_size(35)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..t_end, (lo - pad)..(hi + pad))
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("t [s]")
            .y_desc(label.as_str())
            .draw()
            .map_err(|e| e.to_string())?;
        chart
            .draw_series(LineSeries::new(
                traj.t.iter().copied().zip(data.iter().copied()),
                &BLUE,
            ))
            .map_err(|e| e.to_string())?;
    }
    root.present().map_err(|e| e.to_string())?;
    Ok(())
}

pub fn run(args: &SimArgs, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), CliError> {
    refuse_overwrite(&args.output, args.force, "output file")?;
    if let Some(p) = &args.plot {
        distinct_outputs(&args.output, p)?;
        refuse_overwrite(p, args.force, "plot file")?;
    }
    if !(args.duration.is_finite() && args.duration > 0.0) {
        return Err(CliError::input(format!(
            "error: --duration {} must be positive",
            args.duration
        )));
    }
    let loaded = load(&args.model, err)?;
    warn_ignored_effects(&loaded, "`plantc sim`", err);
    let model = &loaded.model;
    let vals = values(&loaded, &args.params)?;
    let x0 = match &args.x0 {
        Some(text) => parse_assignments(text, &model.state_names(), "state")?,
        None => vec![0.0; model.state_symbols().len()],
    };
    let gains = parse_gains(&args.gain)?;
    let derivation =
        Derivation::new(model).map_err(|e| CliError::failure(format!("error: {e}")))?;
    let mut ctrl = resolve(model, &derivation, &args.controller, &vals).map_err(|e| match e {
        plantc_derive::control::ControlError::UnknownController { .. } => {
            CliError::input(format!("error: {e}"))
        }
        _ => CliError::failure(format!("error: {e}")),
    })?;
    set_gains(&mut ctrl, &gains).map_err(sim_error)?;
    let control = Control::Feedback(ControllerEval::new(model, &ctrl).map_err(sim_error)?);
    let equations = match args.smooth_sign {
        Some(w) if w.is_finite() && w > 0.0 => smooth_signs(&derivation.equations, w),
        Some(w) => {
            return Err(CliError::input(format!(
                "error: --smooth-sign {w} must be a positive width"
            )))
        }
        None => derivation.equations.clone(),
    };
    let problem =
        SimProblem::new(model, &equations, &vals, control, x0, args.duration).map_err(sim_error)?;
    for note in problem.dynamics.notes() {
        let _ = writeln!(err, "note: {note}");
    }
    let mut options = SimOptions {
        output_rate: args.output_rate,
        sample_rate: args.sample_rate,
        integrator: match args.integrator {
            IntegratorKind::Auto => Integrator::Auto,
            IntegratorKind::Explicit => Integrator::Explicit,
            IntegratorKind::Implicit => Integrator::Implicit,
        },
        ..SimOptions::default()
    };
    if let Some(r) = args.rtol {
        options.rtol = r;
        options.atol = r * 1e-2;
    }
    let started = Instant::now();
    let traj = simulate(&problem, &options).map_err(sim_error)?;
    let elapsed = started.elapsed();
    if let Some(s) = traj.stiffness.filter(|s| s.is_stiff()) {
        let _ = writeln!(
            err,
            "note: the model is stiff at the initial state (fastest mode {:.2e} 1/s: an explicit integrator needs about {:.1e} steps for {} s), so it was integrated with the implicit Rosenbrock method; check the parameter values if that is not expected (`--integrator explicit` forces Dormand-Prince)",
            s.fastest_mode,
            s.explicit_steps,
            num(args.duration)
        );
    }
    write_csv(&args.output, &traj)?;
    let mode = match args.sample_rate {
        Some(r) => format!("sampled at {} Hz, zero-order hold", num(r)),
        None => "continuous time".to_string(),
    };
    let _ = writeln!(
        out,
        "simulated {} s of `{}` ({mode}) in {:.1} ms: {} samples -> {}",
        num(args.duration),
        args.controller,
        elapsed.as_secs_f64() * 1e3,
        traj.len(),
        args.output.display()
    );
    let last = traj.states.last().cloned().unwrap_or_default();
    let fin: Vec<String> = traj
        .state_names
        .iter()
        .zip(&last)
        .map(|(n, v)| format!("{n} = {}", num(*v)))
        .collect();
    let _ = writeln!(out, "final state: {}", fin.join(", "));
    for (j, name) in traj.input_names.iter().enumerate() {
        let max = traj.inputs.iter().fold(0.0f64, |m, u| m.max(u[j].abs()));
        let _ = writeln!(out, "max |{name}| = {}", num(max));
    }
    let _ = writeln!(
        out,
        "input saturated {:.1} % of the time",
        100.0 * traj.saturation_share()
    );
    if let Some(first) = traj.mode_names.first() {
        let _ = writeln!(out, "mode at t = 0: {first}");
        for (t, from, to) in &traj.switches {
            let _ = writeln!(
                out,
                "mode switch at t = {t:.3} s: {} -> {}",
                traj.mode_names[*from], traj.mode_names[*to]
            );
        }
    }
    if let Some(p) = &args.plot {
        let title = format!("{}: {} ({mode})", model.name, args.controller);
        let units: Vec<String> = model.inputs.iter().map(|i| i.unit.clone()).collect();
        let svg = plot(&traj, &units, &title)
            .map_err(|e| CliError::failure(format!("error: cannot draw `{}`: {e}", p.display())))?;
        write_output(p, svg)?;
        let _ = writeln!(out, "figure -> {}", p.display());
    }
    Ok(())
}
