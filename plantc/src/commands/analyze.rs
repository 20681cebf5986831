//! `plantc analyze`: Lie derivatives, relative degree, linearizing law, normal
//! form and zero dynamics of an output.

use std::io::Write;
use std::path::Path;

use plantc_derive::analysis::{analyze_output, OutputAnalysisError};
use plantc_derive::control::Derivation;

use crate::cli::ParamArgs;
use crate::common::{complex_text, load, values, write_json, CliError};

pub fn run(
    path: &Path,
    output: Option<&str>,
    params: &ParamArgs,
    json: bool,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    let loaded = load(path, err)?;
    let model = &loaded.model;
    let vals = values(&loaded, params)?;
    let name = match output {
        Some(o) => o.to_string(),
        None => model
            .outputs
            .first()
            .map(|o| o.name.clone())
            .ok_or_else(|| {
                CliError::input("error: the model declares no output; pass --output NAME")
            })?,
    };
    if !model.outputs.iter().any(|o| o.name == name) {
        let known: Vec<&str> = model.outputs.iter().map(|o| o.name.as_str()).collect();
        return Err(CliError::input(format!(
            "error: unknown output `{name}` (the model declares: {})",
            known.join(", ")
        )));
    }
    let d = Derivation::new(model).map_err(|e| CliError::failure(format!("error: {e}")))?;
    let rep = analyze_output(model, &d, &name, &vals).map_err(|e| match e {
        OutputAnalysisError::Lie(e) => CliError::failure(format!("error: {e}")),
        e => CliError::failure(format!("error: {e}")),
    })?;
    let nf = &rep.normal_form;
    let zd = &rep.zero_dynamics;
    if json {
        let lie_map: serde_json::Map<String, serde_json::Value> = rep
            .lie_derivatives
            .iter()
            .map(|(k, v)| (k.clone(), serde_json::Value::String(v.clone())))
            .collect();
        let defs: serde_json::Map<String, serde_json::Value> = rep
            .definitions
            .iter()
            .map(|(k, v)| (k.clone(), serde_json::Value::String(v.clone())))
            .collect();
        let v = serde_json::json!({
            "output": name,
            "relative_degree": rep.relative_degree,
            "definitions": defs,
            "lie_derivatives": lie_map,
            "control_law": rep.law,
            "control_law_expanded": rep.law_expanded,
            "singular_set": rep.singular_set,
            "notes": rep.notes,
            "normal_form": {
                "xi": nf.xi.iter().map(|e| e.to_string()).collect::<Vec<_>>(),
                "eta": nf.eta.iter().map(|e| e.to_string()).collect::<Vec<_>>(),
                "eta_origin": nf.eta_origin,
            },
            "zero_dynamics": {
                "equations": zd.equations(),
                "explicit": zd.explicit,
                "eigenvalues": zd.eigenvalues.iter().map(|p| serde_json::json!({"re": p.re, "im": p.im})).collect::<Vec<_>>(),
                "asymptotically_stable": zd.asymptotically_stable(),
                "minimum_phase": zd.minimum_phase(),
                "classification": zd.class.describe(),
                "equilibrium_residual": zd.equilibrium_residual,
            },
        });
        write_json(out, &v);
        return Ok(());
    }
    let _ = writeln!(
        out,
        "output y = {name}, relative degree {}",
        rep.relative_degree
    );
    let width = rep
        .lie_derivatives
        .iter()
        .chain(&rep.definitions)
        .map(|(k, _)| k.len())
        .max()
        .unwrap_or(0);
    for (k, v) in &rep.definitions {
        let _ = writeln!(out, "  {k:<width$} = {v}");
    }
    for (k, v) in &rep.lie_derivatives {
        let _ = writeln!(out, "  {k:<width$} = {v}");
    }
    let _ = writeln!(out, "linearizing law: {}", rep.law);
    let _ = writeln!(out, "singular set: {}", rep.singular_set);
    let _ = writeln!(out, "normal form:");
    for (i, x) in nf.xi.iter().enumerate() {
        let _ = writeln!(out, "  xi{} = {x}", i + 1);
    }
    for (i, (e, o)) in nf.eta.iter().zip(&nf.eta_origin).enumerate() {
        let shown = if zd.explicit || e.dag_size() < 200 {
            e.to_string()
        } else {
            "(see origin)".to_string()
        };
        let _ = writeln!(out, "  eta{} = {shown}    ({o})", i + 1);
    }
    let _ = writeln!(out, "zero dynamics (xi = 0):");
    for e in zd.equations() {
        let _ = writeln!(out, "  {e}");
    }
    let eig: Vec<String> = zd
        .eigenvalues
        .iter()
        .map(|p| complex_text(p.re, p.im))
        .collect();
    let _ = writeln!(out, "  eigenvalues at eta = 0: {}", eig.join(", "));
    let _ = writeln!(out, "  {}", zd.class.describe());
    if zd.equilibrium_residual > 1e-9 {
        let _ = writeln!(
            out,
            "  note: eta = 0 is not an equilibrium (residual {:.3e})",
            zd.equilibrium_residual
        );
    }
    for n in &rep.notes {
        let _ = writeln!(out, "note: {n}");
    }
    Ok(())
}
