//! `plantc linearize`: Jacobians about an operating point, poles, controllability.

use std::io::Write;
use std::path::Path;

use plantc_derive::analysis::{linearize, Linearization, OperatingPoint};
use plantc_derive::linear::{controllability, matrix_to_rows, poles, LinearModel};
use plantc_derive::mechanics::derive_equations;

use crate::cli::ParamArgs;
use crate::common::{
    complex_text, load, parse_assignments, values, write_json, write_matrix, CliError,
};

/// Linearize a model file about `at` (all zeros when `None`).
pub fn linearize_file(
    path: &Path,
    params: &ParamArgs,
    at: Option<&str>,
    err: &mut dyn Write,
) -> Result<Linearization, CliError> {
    let loaded = load(path, err)?;
    let model = &loaded.model;
    let vals = values(&loaded, params)?;
    let mut op = OperatingPoint::zero(model);
    if let Some(text) = at {
        let mut names = model.state_names();
        names.extend(model.inputs.iter().map(|u| u.name.clone()));
        let v = parse_assignments(text, &names, "state or input")?;
        let n = op.x.len();
        op.x.copy_from_slice(&v[..n]);
        op.u.copy_from_slice(&v[n..]);
    }
    let eqs = derive_equations(model).map_err(|e| CliError::failure(format!("error: {e}")))?;
    let lin =
        linearize(model, &eqs, &vals, &op).map_err(|e| CliError::failure(format!("error: {e}")))?;
    for note in &lin.notes {
        let _ = writeln!(err, "note: {note}");
    }
    Ok(lin)
}

/// The linear model of a linearization.
pub fn to_linear_model(lin: &Linearization) -> Result<LinearModel, CliError> {
    LinearModel::with_names(
        lin.state.clone(),
        lin.inputs.clone(),
        lin.a.clone(),
        lin.b.clone(),
    )
    .map_err(|e| CliError::failure(format!("error: {e}")))
}

pub fn run(
    path: &Path,
    params: &ParamArgs,
    at: Option<&str>,
    json: bool,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    let lin = linearize_file(path, params, at, err)?;
    let p = poles(&lin.a).map_err(|e| CliError::failure(format!("error: {e}")))?;
    let ctrb =
        controllability(&lin.a, &lin.b).map_err(|e| CliError::failure(format!("error: {e}")))?;
    if json {
        let v = serde_json::json!({
            "state": lin.state,
            "inputs": lin.inputs,
            "A": matrix_to_rows(&lin.a),
            "B": matrix_to_rows(&lin.b),
            "poles": p,
            "controllable": ctrb.controllable,
            "controllability_rank": ctrb.rank,
            "pbh_margin": ctrb.pbh_margin,
            "pbh_tolerance": ctrb.pbh_tolerance,
            "rank_tolerance": ctrb.tolerance,
            "singular_values": ctrb.singular_values,
            "notes": lin.notes,
        });
        write_json(out, &v);
        return Ok(());
    }
    let _ = writeln!(
        out,
        "state x = ({}), input u = ({})",
        lin.state.join(", "),
        lin.inputs.join(", ")
    );
    write_matrix(out, "A", &matrix_to_rows(&lin.a), &lin.state);
    write_matrix(out, "B", &matrix_to_rows(&lin.b), &lin.state);
    let ps: Vec<String> = p.iter().map(|x| complex_text(x.re, x.im)).collect();
    let _ = writeln!(out, "open-loop poles: {}", ps.join(", "));
    let sv: Vec<String> = ctrb
        .singular_values
        .iter()
        .map(|s| format!("{s:.3e}"))
        .collect();
    let _ = writeln!(
        out,
        "controllability: {} (PBH margin {:.3e} at eigenvalue {} on the balanced realisation; tolerance {:.1e})",
        if ctrb.controllable {
            "controllable"
        } else {
            "NOT controllable"
        },
        ctrb.pbh_margin,
        complex_text(ctrb.pbh_eigenvalue.0, ctrb.pbh_eigenvalue.1),
        ctrb.pbh_tolerance
    );
    let _ = writeln!(
        out,
        "controllability matrix: rank {} of {} (singular values {}; tolerance {:.3e}; informative only, it spans many orders of magnitude)",
        ctrb.rank,
        lin.state.len(),
        sv.join(", "),
        ctrb.tolerance
    );
    Ok(())
}
