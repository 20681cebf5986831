//! `plantc derive`: Euler-Lagrange equations and the control-affine form.

use std::io::Write;
use std::path::Path;

use plantc_derive::mechanics::{control_affine, derive_equations};
use plantc_derive::sym::Expr;

use crate::common::{load, write_json, CliError};

fn strings(v: &[Expr]) -> Vec<String> {
    v.iter().map(|e| e.to_string()).collect()
}

pub fn run(
    path: &Path,
    json: bool,
    latex: bool,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    let loaded = load(path, err)?;
    let model = &loaded.model;
    let eqs = derive_equations(model)
        .map_err(|e| CliError::failure(format!("error: {e}")))?
        .simplified();
    let ca = control_affine(&eqs).map_err(|e| CliError::failure(format!("error: {e}")))?;
    if json {
        let v = serde_json::json!({
            "coordinates": model.coordinates.iter().map(|c| &c.name).collect::<Vec<_>>(),
            "state": model.state_names(),
            "inputs": model.inputs.iter().map(|c| &c.name).collect::<Vec<_>>(),
            "mass_matrix": eqs.mass_matrix.iter().map(|r| strings(r)).collect::<Vec<_>>(),
            "bias": strings(&eqs.bias),
            "forces": strings(&eqs.forces),
            "input_matrix": eqs.input_matrix.iter().map(|r| strings(r)).collect::<Vec<_>>(),
            "f": strings(&ca.f),
            "g": ca.g.iter().map(|r| strings(r)).collect::<Vec<_>>(),
            "derived": model.derived.iter().map(|d| (d.name.clone(), d.expr.to_string())).collect::<std::collections::BTreeMap<_, _>>(),
        });
        write_json(out, &v);
        return Ok(());
    }
    let show = |e: Expr| if latex { e.to_latex() } else { e.to_string() };
    let _ = writeln!(
        out,
        "model {}: M(q) q'' + bias(q, q') = Q0(q, q') + B(q, q') u",
        model.name
    );
    let _ = writeln!(out);
    for d in &model.derived {
        let _ = writeln!(out, "  {} = {}", d.name, show(d.expr));
    }
    if !model.derived.is_empty() {
        let _ = writeln!(out);
    }
    let n = eqs.coords.len();
    for i in 0..n {
        let _ = writeln!(out, "equation of {}:", model.coordinates[i].name);
        for j in 0..n {
            let _ = writeln!(out, "  M[{i}][{j}] = {}", show(eqs.mass_matrix[i][j]));
        }
        let _ = writeln!(out, "  bias   = {}", show(eqs.bias[i]));
        let _ = writeln!(out, "  Q0     = {}", show(eqs.forces[i]));
        for (j, u) in model.inputs.iter().enumerate() {
            let _ = writeln!(out, "  B[{}]  = {}", u.name, show(eqs.input_matrix[i][j]));
        }
        let _ = writeln!(out);
    }
    let _ = writeln!(out, "det M = {}", show(ca.det_mass));
    let _ = writeln!(out);
    let names = model.state_names();
    let _ = writeln!(out, "x' = f(x) + g(x) u, x = ({})", names.join(", "));
    for (i, name) in names.iter().enumerate() {
        let _ = writeln!(out, "  f[{name}] = {}", show(ca.f[i]));
    }
    for (j, u) in model.inputs.iter().enumerate() {
        for (i, name) in names.iter().enumerate() {
            if !ca.g[i][j].is_zero() {
                let _ = writeln!(out, "  g[{name}, {}] = {}", u.name, show(ca.g[i][j]));
            }
        }
    }
    Ok(())
}
