//! Model files: loading with diagnostics, equations, linearization, simulation.

use std::collections::BTreeMap;
use std::path::PathBuf;

use plantc_derive::analysis::{linearize as lin, OperatingPoint};
use plantc_derive::control::{resolve, Derivation};
use plantc_derive::linear::{controllability, matrix_to_rows, poles};
use plantc_derive::mechanics::{derive_equations, present_equations, Expand};
use plantc_derive::model::{load_model_text, read_source, LoadError, LoadedModel, ParameterValues};
use plantc_derive::simulate::{
    set_gains, simulate as run_sim, Control, ControllerEval, SimOptions, SimProblem,
};
use plantc_derive::sym::{diff, Expr};
use pyo3::prelude::*;

use crate::blocking;
use crate::errors::{compute, input, Failure, Located};

/// Loads model text named `name`, or the model error.
fn load(name: &str, text: &str) -> Result<LoadedModel, Failure> {
    load_model_text(name, text).map_err(|e| match e {
        LoadError::Io { path, message } => Failure::Io(format!("cannot read `{path}`: {message}")),
        LoadError::Invalid {
            source,
            diagnostics,
        } => Failure::model(name, &source, &diagnostics),
    })
}

/// The warnings of a loaded model as (severity, code, message, line, column, help).
type Warning = (String, String, String, usize, usize, Option<String>);

fn warnings(loaded: &LoadedModel) -> Vec<Warning> {
    loaded
        .diagnostics
        .iter()
        .map(|d| {
            let l = Located::new(&loaded.source, d);
            (
                l.severity.to_string(),
                l.code.to_string(),
                l.message,
                l.line,
                l.column,
                l.help,
            )
        })
        .collect()
}

/// Reads and checks the model file `path`: `(text, warnings)`. Raises
/// `FileNotFoundError` when it does not exist, `ModelError` when it has
/// errors.
#[pyfunction]
pub fn load_file(py: Python<'_>, path: PathBuf) -> PyResult<(String, Vec<Warning>)> {
    blocking::run(py, move || {
        if let Err(e) = std::fs::metadata(&path) {
            if e.kind() == std::io::ErrorKind::NotFound {
                return Err(Failure::NotFound(path.display().to_string()));
            }
        }
        let name = path.display().to_string();
        let text = read_source(&path).map_err(|e| match e {
            LoadError::Io { path, message } => {
                Failure::Io(format!("cannot read `{path}`: {message}"))
            }
            // a file that is not UTF-8: the line and column of its first bad byte
            LoadError::Invalid {
                source,
                diagnostics,
            } => Failure::model(&name, &source, &diagnostics),
        })?;
        let loaded = load(&name, &text)?;
        Ok((text, warnings(&loaded)))
    })
}

/// Checks model text: its warnings, or `ModelError`.
#[pyfunction]
pub fn check_text(py: Python<'_>, name: String, text: String) -> PyResult<Vec<Warning>> {
    blocking::run(py, move || Ok(warnings(&load(&name, &text)?)))
}

fn strings(v: &[Expr], latex: bool) -> Vec<String> {
    v.iter()
        .map(|e| if latex { e.to_latex() } else { e.to_string() })
        .collect()
}

/// The equations of motion as JSON: the fields of `plantc derive --json`
/// (printed forms), and the same under `"latex"` in LaTeX.
#[pyfunction]
#[pyo3(signature = (name, text, expand = None))]
pub fn derive(
    py: Python<'_>,
    name: String,
    text: String,
    expand: Option<bool>,
) -> PyResult<String> {
    blocking::run(py, move || {
        let loaded = load(&name, &text)?;
        let model = &loaded.model;
        let eqs = derive_equations(model).map_err(compute)?;
        let p = present_equations(
            &eqs,
            match expand {
                None => Expand::Auto,
                Some(true) => Expand::Always,
                Some(false) => Expand::Never,
            },
        );
        let n = eqs.coords.len();
        let m = model.inputs.len();
        let forms = |latex: bool| {
            let show = |e: &Expr| if latex { e.to_latex() } else { e.to_string() };
            let mut f: Vec<Option<String>> = eqs
                .coords
                .iter()
                .map(|c| Some(show(&Expr::symbol(c.qd))))
                .collect();
            let mut g: Vec<Vec<Option<String>>> = vec![vec![Some("0".into()); m]; n];
            match (&p.f, &p.g) {
                (Some(pf), Some(pg)) => {
                    f.extend(pf.iter().map(|e| Some(show(e))));
                    g.extend(pg.iter().map(|r| r.iter().map(|e| Some(show(e))).collect()));
                }
                _ => {
                    f.extend((0..n).map(|_| None));
                    g.extend((0..n).map(|_| vec![None; m]));
                }
            }
            serde_json::json!({
                "mass_matrix": p.mass_matrix.iter().map(|r| strings(r, latex)).collect::<Vec<_>>(),
                "bias": strings(&p.bias, latex),
                "forces": strings(&p.forces, latex),
                "input_matrix": p.input_matrix.iter().map(|r| strings(r, latex)).collect::<Vec<_>>(),
                "det_mass": p.det_mass.map(|d| show(&d)),
                "f": f,
                "g": g,
                "derived": model.derived.iter().map(|d| (d.name.clone(), show(&d.expr))).collect::<BTreeMap<_, _>>(),
            })
        };
        let mut v = forms(false);
        v["coordinates"] = serde_json::json!(model
            .coordinates
            .iter()
            .map(|c| &c.name)
            .collect::<Vec<_>>());
        v["state"] = serde_json::json!(model.state_names());
        v["inputs"] = serde_json::json!(model.inputs.iter().map(|c| &c.name).collect::<Vec<_>>());
        v["notes"] = serde_json::json!(p.notes);
        v["latex"] = forms(true);
        Ok(v.to_string())
    })
}

/// Parameter values from a set and overrides.
fn values(
    loaded: &LoadedModel,
    set: Option<&str>,
    params: &[(String, f64)],
) -> Result<ParameterValues, Failure> {
    ParameterValues::new(&loaded.model, set, params).map_err(input)
}

/// Values by name into `names` order (unnamed: 0); an unknown name is an error.
fn by_name(given: &[(String, f64)], names: &[String], what: &str) -> Result<Vec<f64>, Failure> {
    let mut out = vec![0.0; names.len()];
    for (n, v) in given {
        let i = names.iter().position(|x| x == n).ok_or_else(|| {
            Failure::Input(format!(
                "`{n}` is not a {what} of the model (known: {})",
                names.join(", ")
            ))
        })?;
        if !v.is_finite() {
            return Err(Failure::Input(format!("{what} `{n}` = {v} is not finite")));
        }
        out[i] = *v;
    }
    Ok(out)
}

/// Linearization about `at` (states and inputs by name, others 0) as JSON:
/// the fields of `plantc linearize --json` and the output matrices `C`
/// (`dh/dx` at the operating point) and `D` (zero: outputs are functions of
/// the state), with `outputs` naming C's rows.
#[pyfunction]
#[pyo3(signature = (name, text, set = None, params = Vec::new(), at = Vec::new()))]
pub fn linearize(
    py: Python<'_>,
    name: String,
    text: String,
    set: Option<String>,
    params: Vec<(String, f64)>,
    at: Vec<(String, f64)>,
) -> PyResult<String> {
    blocking::run(py, move || {
        let loaded = load(&name, &text)?;
        let model = &loaded.model;
        let vals = values(&loaded, set.as_deref(), &params)?;
        let mut op = OperatingPoint::zero(model);
        let mut names = model.state_names();
        names.extend(model.inputs.iter().map(|u| u.name.clone()));
        let v = by_name(&at, &names, "state or input")?;
        let n = op.x.len();
        op.x.copy_from_slice(&v[..n]);
        op.u.copy_from_slice(&v[n..]);
        let eqs = derive_equations(model).map_err(compute)?;
        let l = lin(model, &eqs, &vals, &op).map_err(compute)?;
        let p = poles(&l.a).map_err(compute)?;
        let ctrb = controllability(&l.a, &l.b).map_err(compute)?;
        // C = dh/dx at the operating point, with the parameter values
        let mut point = vals.symbol_map(model);
        let states = model.state_symbols();
        for (s, x) in states.iter().zip(&op.x) {
            point.insert(*s, *x);
        }
        let c: Vec<Vec<f64>> = model
            .outputs
            .iter()
            .map(|o| {
                states
                    .iter()
                    .map(|s| diff(o.expr, *s).eval_map(&point))
                    .collect()
            })
            .collect();
        let d = vec![vec![0.0; model.inputs.len()]; model.outputs.len()];
        let v = serde_json::json!({
            "state": l.state,
            "inputs": l.inputs,
            "outputs": model.outputs.iter().map(|o| &o.name).collect::<Vec<_>>(),
            "A": matrix_to_rows(&l.a),
            "B": matrix_to_rows(&l.b),
            "C": c,
            "D": d,
            "poles": p,
            "controllable": ctrb.controllable,
            "controllability_rank": ctrb.rank,
            "pbh_margin": ctrb.pbh_margin,
            "pbh_tolerance": ctrb.pbh_tolerance,
            "rank_tolerance": ctrb.tolerance,
            "singular_values": ctrb.singular_values,
            "notes": l.notes,
        });
        Ok(v.to_string())
    })
}

/// Closed-loop simulation with one of the model's controllers (as `plantc
/// sim`): JSON with `t`, `states`, `inputs`, `outputs` (rows per sample),
/// their names, the modes and switches of a hybrid controller, and notes.
#[pyfunction]
#[pyo3(signature = (name, text, controller, x0, duration, set = None, params = Vec::new(), gains = Vec::new(), output_rate = None, sample_rate = None))]
#[allow(clippy::too_many_arguments)]
pub fn simulate(
    py: Python<'_>,
    name: String,
    text: String,
    controller: String,
    x0: Vec<(String, f64)>,
    duration: f64,
    set: Option<String>,
    params: Vec<(String, f64)>,
    gains: Vec<(String, f64)>,
    output_rate: Option<f64>,
    sample_rate: Option<f64>,
) -> PyResult<String> {
    blocking::run(py, move || {
        if !(duration.is_finite() && duration > 0.0) {
            return Err(Failure::Input(format!(
                "duration {duration} must be positive"
            )));
        }
        let loaded = load(&name, &text)?;
        let model = &loaded.model;
        let vals = values(&loaded, set.as_deref(), &params)?;
        let x0 = by_name(&x0, &model.state_names(), "state")?;
        let derivation = Derivation::new(model).map_err(compute)?;
        let mut ctrl = resolve(model, &derivation, &controller, &vals).map_err(input)?;
        set_gains(&mut ctrl, &gains).map_err(input)?;
        let control = Control::Feedback(ControllerEval::new(model, &ctrl).map_err(input)?);
        let problem = SimProblem::new(model, &derivation.equations, &vals, control, x0, duration)
            .map_err(input)?;
        let notes: Vec<String> = problem.dynamics.notes().to_vec();
        let mut options = SimOptions {
            sample_rate,
            ..SimOptions::default()
        };
        if let Some(r) = output_rate {
            options.output_rate = r;
        }
        let traj = run_sim(&problem, &options).map_err(compute)?;
        let v = serde_json::json!({
            "t": traj.t,
            "states": traj.states,
            "inputs": traj.inputs,
            "outputs": traj.outputs,
            "state_names": traj.state_names,
            "input_names": traj.input_names,
            "output_names": traj.output_names,
            "saturated": traj.saturated,
            "mode_names": traj.mode_names,
            "modes": traj.modes,
            "switches": traj.switches,
            "notes": notes,
        });
        Ok(v.to_string())
    })
}
