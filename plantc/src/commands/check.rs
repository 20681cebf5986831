//! `plantc check`: parse and check a model file.

use std::io::Write;
use std::path::Path;

use crate::common::{load, write_json, CliError};

pub fn run(
    path: &Path,
    json: bool,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    let loaded = load(path, err)?;
    let m = &loaded.model;
    if json {
        let v = serde_json::json!({
            "model": m.name,
            "coordinates": m.coordinates.iter().map(|c| &c.name).collect::<Vec<_>>(),
            "inputs": m.inputs.iter().map(|c| &c.name).collect::<Vec<_>>(),
            "outputs": m.outputs.iter().map(|c| &c.name).collect::<Vec<_>>(),
            "parameters": m.parameters.iter().map(|p| &p.name).collect::<Vec<_>>(),
            "sets": m.sets.iter().map(|s| &s.name).collect::<Vec<_>>(),
            "controllers": m.controllers.iter().map(|c| c.name()).collect::<Vec<_>>(),
            "warnings": loaded.diagnostics.len(),
        });
        write_json(out, &v);
    } else {
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
    }
    Ok(())
}
