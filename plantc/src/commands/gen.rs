//! `plantc gen`: write a standalone generated crate (plant model + controllers).

use std::io::Write;
use std::path::Path;

use plantc_codegen::{write_crate, CrateOptions, Error};

use crate::cli::ParamArgs;
use crate::common::{load, parse_overrides, warn_ignored_effects, CliError};

/// Generate the crate for `model` into `dir`.
pub fn run(
    model: &Path,
    controllers: &[String],
    params: &ParamArgs,
    dir: &Path,
    force: bool,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), CliError> {
    // Load once here for the warnings and a rendered error with file positions.
    let loaded = load(model, err)?;
    warn_ignored_effects(&loaded, "`plantc gen`", err);
    let opts = CrateOptions {
        model: model.to_path_buf(),
        controllers: controllers.to_vec(),
        set: params.set.clone(),
        overrides: parse_overrides(&params.params)?,
        dir: dir.to_path_buf(),
        force,
    };
    let files = write_crate(&opts).map_err(|e| match e {
        Error::NotGenerated { .. } | Error::Load(_) | Error::Values(_) | Error::Control(_) => {
            CliError::input(e.to_string())
        }
        _ => CliError::failure(e.to_string()),
    })?;
    for f in files {
        let _ = writeln!(out, "wrote {}", f.display());
    }
    Ok(())
}
