//! `plantc analyze`: Lie derivatives, relative degree, linearizing law, normal
//! form and zero dynamics of an output; for a model with several inputs, of
//! as many outputs (vector relative degree, decoupling matrix and law).

use std::io::Write;
use std::path::Path;

use plantc_derive::analysis::{
    analyze_output, analyze_outputs, sliding_analysis, NormalForm, ZeroDynamics,
};
use plantc_derive::control::{resolve, Derivation, ResolvedController};
use plantc_derive::model::Model;
use plantc_derive::model::{ControllerSpec, ParameterValues};

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
    let several = output.is_some_and(|o| o.contains(','));
    if model.inputs.len() > 1 || several {
        return outputs(model, output, &vals, json, out);
    }
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
    let rep = analyze_output(model, &d, &name, &vals)
        .map_err(|e| CliError::failure(format!("error: {e}")))?;
    let nf = &rep.normal_form;
    let zd = &rep.zero_dynamics;
    if json {
        let v = serde_json::json!({
            "output": name,
            "relative_degree": rep.relative_degree,
            "definitions": pairs_json(&rep.definitions),
            "lie_derivatives": pairs_json(&rep.lie_derivatives),
            "control_law": rep.law,
            "control_law_expanded": rep.law_expanded,
            "singular_set": rep.singular_set,
            "notes": rep.notes,
            "normal_form": normal_form_json(nf),
            "zero_dynamics": zero_dynamics_json(zd),
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
    print_normal_form(out, nf, zd, &rep.notes);
    Ok(())
}

/// `(name, text)` pairs as a JSON object.
fn pairs_json(pairs: &[(String, String)]) -> serde_json::Value {
    serde_json::Value::Object(
        pairs
            .iter()
            .map(|(k, v)| (k.clone(), serde_json::Value::String(v.clone())))
            .collect(),
    )
}

/// The normal form as JSON.
fn normal_form_json(nf: &NormalForm) -> serde_json::Value {
    serde_json::json!({
        "xi": nf.xi.iter().map(|e| e.to_string()).collect::<Vec<_>>(),
        "eta": nf.eta.iter().map(|e| e.to_string()).collect::<Vec<_>>(),
        "eta_origin": nf.eta_origin,
    })
}

/// The zero dynamics as JSON.
fn zero_dynamics_json(zd: &ZeroDynamics) -> serde_json::Value {
    serde_json::json!({
        "equations": zd.equations(),
        "explicit": zd.explicit,
        "eigenvalues": zd.eigenvalues.iter().map(|p| serde_json::json!({"re": p.re, "im": p.im})).collect::<Vec<_>>(),
        "asymptotically_stable": zd.asymptotically_stable(),
        "minimum_phase": zd.minimum_phase(),
        "classification": zd.class.describe(),
        "equilibrium_residual": zd.equilibrium_residual,
    })
}

/// The normal form, the zero dynamics and the notes, as text.
fn print_normal_form(out: &mut dyn Write, nf: &NormalForm, zd: &ZeroDynamics, notes: &[String]) {
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
    if zd.eigenvalues.is_empty() {
        let _ = writeln!(
            out,
            "  none: the relative degrees add up to the state dimension"
        );
    } else {
        let eig: Vec<String> = zd
            .eigenvalues
            .iter()
            .map(|p| complex_text(p.re, p.im))
            .collect();
        let _ = writeln!(out, "  eigenvalues at eta = 0: {}", eig.join(", "));
    }
    let _ = writeln!(out, "  {}", zd.class.describe());
    if zd.equilibrium_residual > 1e-9 {
        let _ = writeln!(
            out,
            "  note: eta = 0 is not an equilibrium (residual {:.3e})",
            zd.equilibrium_residual
        );
    }
    for n in notes {
        let _ = writeln!(out, "note: {n}");
    }
}

/// The outputs of a square analysis: `--output a,b` (as many as the model
/// has inputs), or the model's declared outputs when they are that many.
fn output_names(model: &Model, output: Option<&str>) -> Result<Vec<String>, CliError> {
    let m = model.inputs.len();
    let declared: Vec<&str> = model.outputs.iter().map(|o| o.name.as_str()).collect();
    let inputs: Vec<&str> = model.inputs.iter().map(|u| u.name.as_str()).collect();
    let names: Vec<String> = match output {
        Some(list) => list.split(',').map(|s| s.trim().to_string()).collect(),
        None if declared.len() == m => declared.iter().map(|s| s.to_string()).collect(),
        None => {
            return Err(CliError::input(format!(
                "error: the model has {m} inputs ({}) and declares {} output{} ({}); a decoupling \
                 analysis needs {m}: pass --output NAME,NAME",
                inputs.join(", "),
                declared.len(),
                if declared.len() == 1 { "" } else { "s" },
                declared.join(", ")
            )))
        }
    };
    if let Some(empty) = names.iter().position(|s| s.is_empty()) {
        return Err(CliError::input(format!(
            "error: --output: name {} of `{}` is empty",
            empty + 1,
            output.unwrap_or_default()
        )));
    }
    for name in &names {
        if !declared.contains(&name.as_str()) {
            return Err(CliError::input(format!(
                "error: unknown output `{name}` (the model declares: {})",
                declared.join(", ")
            )));
        }
    }
    for (i, name) in names.iter().enumerate() {
        if names[..i].contains(name) {
            return Err(CliError::input(format!(
                "error: --output names `{name}` twice (a decoupling analysis needs distinct outputs)"
            )));
        }
    }
    if names.len() != m {
        return Err(CliError::input(format!(
            "error: --output names {} output{} and the model has {m} input{} ({}); a decoupling \
             analysis needs as many outputs as inputs",
            names.len(),
            if names.len() == 1 { "" } else { "s" },
            if m == 1 { "" } else { "s" },
            inputs.join(", ")
        )));
    }
    Ok(names)
}

/// `plantc analyze` of a model with several inputs: vector relative degree,
/// decoupling matrix, its law, normal form and zero dynamics.
fn outputs(
    model: &Model,
    output: Option<&str>,
    vals: &ParameterValues,
    json: bool,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let names = output_names(model, output)?;
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let d = Derivation::new(model).map_err(|e| CliError::failure(format!("error: {e}")))?;
    let rep = analyze_outputs(model, &d, &refs, vals)
        .map_err(|e| CliError::failure(format!("error: {e}")))?;
    let nf = &rep.normal_form;
    let zd = &rep.zero_dynamics;
    let degrees = rep.decoupling.vector_relative_degree();
    if json {
        let lie: serde_json::Map<String, serde_json::Value> = rep
            .outputs
            .iter()
            .zip(&rep.lie_derivatives)
            .map(|(o, rows)| (o.clone(), pairs_json(rows)))
            .collect();
        let v = serde_json::json!({
            "outputs": rep.outputs,
            "inputs": rep.inputs,
            "vector_relative_degree": degrees,
            "definitions": pairs_json(&rep.definitions),
            "lie_derivatives": lie,
            "decoupling_matrix": rep.matrix_text,
            "decoupling_matrix_at_operating_point": rep.matrix_at_operating_point,
            "b": rep.drift_text,
            "det_decoupling_matrix": rep.det_text,
            "control_law": rep.law,
            "singular_set": rep.singular_set,
            "notes": rep.notes,
            "normal_form": normal_form_json(nf),
            "zero_dynamics": zero_dynamics_json(zd),
        });
        write_json(out, &v);
        return Ok(());
    }
    let _ = writeln!(
        out,
        "outputs y = ({}), inputs u = ({}): vector relative degree ({})",
        rep.outputs.join(", "),
        rep.inputs.join(", "),
        degrees
            .iter()
            .map(|r| r.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    for (k, v) in &rep.definitions {
        let _ = writeln!(out, "  {k} = {v}");
    }
    for (i, (o, rows)) in rep.outputs.iter().zip(&rep.lie_derivatives).enumerate() {
        let _ = writeln!(out, "  y{} = {o}:", i + 1);
        let width = rows.iter().map(|(k, _)| k.len()).max().unwrap_or(0);
        for (k, v) in rows {
            let _ = writeln!(out, "    {k:<width$} = {v}");
        }
    }
    let _ = writeln!(
        out,
        "decoupling matrix A(x) (row i = L_g L_f^(r_i-1) h_i, column j = input u_j):"
    );
    for (o, row) in rep.outputs.iter().zip(&rep.matrix_text) {
        let _ = writeln!(out, "  A[{o}] = [{}]", row.join(", "));
    }
    if let Some(det) = &rep.det_text {
        let _ = writeln!(out, "  det A = {det}");
    }
    let a0: Vec<String> = rep
        .matrix_at_operating_point
        .iter()
        .map(|row| {
            format!(
                "[{}]",
                row.iter()
                    .map(|v| format!("{v:.6}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
        .collect();
    let _ = writeln!(out, "  at the operating point (x = 0): [{}]", a0.join(", "));
    let _ = writeln!(out, "linearizing law (decoupling): {}", rep.law);
    let _ = writeln!(out, "singular set (det A = 0): {}", rep.singular_set);
    print_normal_form(out, nf, zd, &rep.notes);
    Ok(())
}

/// `plantc analyze --controller NAME`: a sliding-mode controller's surface,
/// equivalent control and reduced dynamics; a feedback-linearizing one's output.
pub fn controller(
    path: &Path,
    name: &str,
    params: &ParamArgs,
    json: bool,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    let loaded = load(path, err)?;
    let model = &loaded.model;
    match model.controller(name) {
        Some(ControllerSpec::FeedbackLinearization { output, .. }) => {
            let output = output.clone();
            return run(path, Some(&output), params, json, out, err);
        }
        Some(ControllerSpec::SlidingMode { .. }) => {}
        Some(_) => {
            return Err(CliError::input(format!(
                "error: `{name}` is neither a sliding-mode (`surface`) nor a `linearize output` controller; \
                 analyze reports those (state feedback: `plantc linearize`, `place`, `lqr`)"
            )))
        }
        None => {
            return Err(CliError::input(format!(
                "error: unknown controller `{name}` (known: {})",
                model
                    .controllers
                    .iter()
                    .map(|c| c.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            )))
        }
    }
    let vals = values(&loaded, params)?;
    let d = Derivation::new(model).map_err(|e| CliError::failure(format!("error: {e}")))?;
    let rc =
        resolve(model, &d, name, &vals).map_err(|e| CliError::failure(format!("error: {e}")))?;
    let ResolvedController::SlidingMode { law, .. } = &rc else {
        return Err(CliError::failure(
            "error: internal: not a sliding-mode controller",
        ));
    };
    let a = sliding_analysis(model, &d, &rc, &vals)
        .map_err(|e| CliError::failure(format!("error: {e}")))?;
    let poles: Vec<String> = a
        .reduced
        .poles
        .iter()
        .map(|p| {
            // eigenvalues to 9 significant digits (the rest is rounding)
            let r = |x: f64| {
                if x == 0.0 {
                    0.0
                } else {
                    let scale = 10f64.powi(8 - p.abs().log10().floor() as i32);
                    (x * scale).round() / scale
                }
            };
            complex_text(r(p.re), r(p.im))
        })
        .collect();
    let stable = a.reduced.asymptotically_stable();
    let verdict = if stable {
        "asymptotically stable (every sliding pole in the left half-plane): on the surface the state returns to 0"
    } else {
        "NOT asymptotically stable: a sliding pole is not in the left half-plane, so on the surface the state does not return to 0"
    };
    if json {
        let v = serde_json::json!({
            "controller": name,
            "surface": a.surface.to_string(),
            "c": a.c,
            "c_b": a.reduced.cb,
            "equivalent_control": format!("u_eq = {}", a.equivalent_control),
            "control_law": format!("u = {law}"),
            "singular_set": a.singular_set,
            "reduced_dynamics": {
                "eliminated": a.eliminated_text(),
                "equations": a.equations(),
                "poles": a.reduced.poles.iter().map(|p| serde_json::json!({"re": p.re, "im": p.im})).collect::<Vec<_>>(),
                "asymptotically_stable": stable,
            },
        });
        write_json(out, &v);
        return Ok(());
    }
    let _ = writeln!(out, "controller {name}: sliding mode");
    let _ = writeln!(out, "surface: s = {}", a.surface);
    let _ = writeln!(
        out,
        "  c = [{}] (c B = {:.6} on the linearization about 0)",
        a.c.iter()
            .zip(&a.states)
            .map(|(c, s)| format!("{s}: {c:.6}"))
            .collect::<Vec<_>>()
            .join(", "),
        a.reduced.cb
    );
    let _ = writeln!(
        out,
        "equivalent control: u_eq = -L_f s / L_g s = {}",
        a.equivalent_control
    );
    let _ = writeln!(out, "law: u = {law}");
    let _ = writeln!(out, "singular set (L_g s = 0): {}", a.singular_set);
    let _ = writeln!(
        out,
        "reduced dynamics on s = 0 under u_eq, linearized about 0 ({}):",
        a.eliminated_text()
    );
    for e in a.equations() {
        let _ = writeln!(out, "  {e}");
    }
    let _ = writeln!(out, "  sliding poles: {}", poles.join(", "));
    let _ = writeln!(out, "  {verdict}");
    Ok(())
}
