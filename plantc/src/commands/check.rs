//! `plantc check`: parse and check a model file.

use std::io::Write;
use std::path::Path;

use plantc_derive::lang::diagnostic::to_json;
use plantc_derive::lang::{Diagnostic, Severity, SourceFile};
use plantc_derive::model::{load_model, LoadError};

use crate::common::{write_json, CliError};
use crate::EXIT_BAD_INPUT;

pub fn run(
    path: &Path,
    json: bool,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    if json {
        return run_json(path, out, err);
    }
    let loaded = crate::common::load(path, err)?;
    let m = &loaded.model;
    let _ = writeln!(
        out,
        "{}: ok ({} coordinates, {} inputs, {} parameters, {} sets, {} controllers)",
        path.display(),
        m.coordinates.len(),
        m.inputs.len(),
        m.parameters.len(),
        m.sets.len(),
        m.controllers.len()
    );
    Ok(())
}

/// `--json`: one JSON object on standard output whatever the outcome, with
/// every diagnostic (errors, warnings, notes); the rendered diagnostics go to
/// standard error as without `--json`. Exit code 2 when the model has errors.
fn run_json(path: &Path, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), CliError> {
    let file = path.display().to_string();
    let count = |ds: &[Diagnostic], s: Severity| ds.iter().filter(|d| d.severity == s).count();
    let summary = |source: &SourceFile, ds: &[Diagnostic]| {
        serde_json::json!({
            "file": file,
            "ok": count(ds, Severity::Error) == 0,
            "errors": count(ds, Severity::Error),
            "warnings": count(ds, Severity::Warning),
            "diagnostics": ds.iter().map(|d| to_json(source, d)).collect::<Vec<_>>(),
        })
    };
    match load_model(path) {
        Ok(loaded) => {
            let m = &loaded.model;
            let mut v = summary(&loaded.source, &loaded.diagnostics);
            v["model"] = m.name.clone().into();
            v["coordinates"] = m.coordinates.iter().map(|c| c.name.clone()).collect();
            v["inputs"] = m.inputs.iter().map(|c| c.name.clone()).collect();
            v["outputs"] = m.outputs.iter().map(|c| c.name.clone()).collect();
            v["parameters"] = m.parameters.iter().map(|p| p.name.clone()).collect();
            v["sets"] = m.sets.iter().map(|s| s.name.clone()).collect();
            v["controllers"] = m.controllers.iter().map(|c| c.name().to_string()).collect();
            if !loaded.diagnostics.is_empty() {
                let _ = write!(
                    err,
                    "{}",
                    plantc_derive::lang::render(&loaded.source, &loaded.diagnostics)
                );
            }
            write_json(out, &v);
            Ok(())
        }
        Err(e) => {
            let v = match &e {
                LoadError::Invalid {
                    source,
                    diagnostics,
                } => summary(source, diagnostics),
                LoadError::Io { message, .. } => serde_json::json!({
                    "file": file,
                    "ok": false,
                    "errors": 1,
                    "warnings": 0,
                    "diagnostics": [{
                        "severity": "error",
                        "code": "plantc::io",
                        "message": format!("cannot read `{file}`: {message}"),
                        "file": file,
                    }],
                }),
            };
            write_json(out, &v);
            Err(CliError {
                message: e.render(),
                code: EXIT_BAD_INPUT,
            })
        }
    }
}
