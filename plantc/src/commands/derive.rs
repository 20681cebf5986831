//! `plantc derive`: Euler-Lagrange equations and the control-affine form.

use std::io::Write;
use std::path::Path;

use plantc_derive::mechanics::{derive_equations, det_name, present_equations, Expand};
use plantc_derive::sym::Expr;

use crate::common::{load, write_json, CliError};

fn strings(v: &[Expr]) -> Vec<String> {
    v.iter().map(|e| e.to_string()).collect()
}

pub fn run(
    path: &Path,
    json: bool,
    latex: bool,
    expand: Expand,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    let loaded = load(path, err)?;
    let model = &loaded.model;
    let eqs = derive_equations(model).map_err(|e| CliError::failure(format!("error: {e}")))?;
    let p = present_equations(&eqs, expand);
    if p.det_mass.is_some_and(|d| d.is_zero()) {
        // (a coordinate without any inertia is a check error already; this
        // is M of lower rank, e.g. T = 1/2*m*(x' + y')^2)
        return Err(CliError::input(format!(
            "error: {}: the mass matrix is singular for every state (det M = 0): the kinetic \
             energy does not determine every acceleration; give each coordinate its own inertia",
            path.display()
        )));
    }
    let n = eqs.coords.len();
    let names = model.state_names();
    if json {
        let mut f: Vec<Option<String>> = eqs
            .coords
            .iter()
            .map(|c| Some(c.qd.name().to_string()))
            .collect();
        let mut g: Vec<Vec<Option<String>>> = vec![vec![Some("0".into()); model.inputs.len()]; n];
        match (&p.f, &p.g) {
            (Some(pf), Some(pg)) => {
                f.extend(pf.iter().map(|e| Some(e.to_string())));
                g.extend(
                    pg.iter()
                        .map(|r| r.iter().map(|e| Some(e.to_string())).collect()),
                );
            }
            _ => {
                f.extend((0..n).map(|_| None));
                g.extend((0..n).map(|_| vec![None; model.inputs.len()]));
            }
        }
        let v = serde_json::json!({
            "coordinates": model.coordinates.iter().map(|c| &c.name).collect::<Vec<_>>(),
            "state": names,
            "inputs": model.inputs.iter().map(|c| &c.name).collect::<Vec<_>>(),
            "mass_matrix": p.mass_matrix.iter().map(|r| strings(r)).collect::<Vec<_>>(),
            "bias": strings(&p.bias),
            "forces": strings(&p.forces),
            "input_matrix": p.input_matrix.iter().map(|r| strings(r)).collect::<Vec<_>>(),
            "det_mass": p.det_mass.map(|d| d.to_string()),
            "f": f,
            "g": g,
            "notes": p.notes,
            "angle_frame": p.angles.as_ref().map(|a| a.lines(&|e| e.to_string())),
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
    if let Some(a) = &p.angles {
        for line in a.lines(&show) {
            let _ = writeln!(out, "{line}");
        }
        let _ = writeln!(out);
    }
    for i in 0..n {
        let _ = writeln!(out, "equation of {}:", model.coordinates[i].name);
        if p.angles.is_none() {
            for j in 0..n {
                let _ = writeln!(out, "  M[{i}][{j}] = {}", show(p.mass_matrix[i][j]));
            }
            let _ = writeln!(out, "  bias   = {}", show(p.bias[i]));
        }
        let _ = writeln!(out, "  Q0     = {}", show(p.forces[i]));
        for (j, u) in model.inputs.iter().enumerate() {
            let _ = writeln!(out, "  B[{}]  = {}", u.name, show(p.input_matrix[i][j]));
        }
        let _ = writeln!(out);
    }
    if let Some(d) = p.det_mass {
        let _ = writeln!(out, "{} = det M = {}", show(det_name()), show(d));
        let _ = writeln!(out);
    }
    let _ = writeln!(
        out,
        "x' = f(x) + g(x) u, x = ({}): f = (q', M^-1 (Q0 - bias)), g = (0, M^-1 B)",
        names.join(", ")
    );
    if let (Some(f), Some(g)) = (&p.f, &p.g) {
        for i in 0..n {
            let _ = writeln!(out, "  f[{}] = {}", names[n + i], show(f[i]));
        }
        for (j, u) in model.inputs.iter().enumerate() {
            for i in 0..n {
                if !g[i][j].is_zero() {
                    let _ = writeln!(out, "  g[{}, {}] = {}", names[n + i], u.name, show(g[i][j]));
                }
            }
        }
    }
    for note in &p.notes {
        let _ = writeln!(out, "note: {note}");
    }
    Ok(())
}
