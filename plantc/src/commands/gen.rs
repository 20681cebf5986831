//! `plantc gen`: write a standalone generated crate (plant + controllers), or
//! with `--rig` a binary crate linking them into plantc-runtime.

use std::io::Write;
use std::path::PathBuf;

use plantc_codegen::{
    write_crate, CrateOptions, Error, ObserverOptions, RigOptions, RuntimeSource,
};

use crate::cli::{GenArgs, RigGenArgs};
use crate::common::{load, parse_overrides, warn_ignored_effects, CliError};

/// Generate the crate `args` describe.
pub fn run(args: &GenArgs, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), CliError> {
    // Load once here for the warnings and a rendered error with file positions.
    let loaded = load(&args.model, err)?;
    warn_ignored_effects(&loaded, "`plantc gen`", err);
    let opts = CrateOptions {
        model: args.model.clone(),
        controllers: args.controllers.clone(),
        set: args.params.set.clone(),
        overrides: parse_overrides(&args.params.params)?,
        dir: args.out.clone(),
        force: args.force,
        rig: if args.rig.rig {
            Some(rig_options(&args.rig)?)
        } else {
            None
        },
    };
    let files = write_crate(&opts).map_err(codegen_error)?;
    for f in files {
        let _ = writeln!(out, "wrote {}", f.display());
    }
    if opts.rig.is_some() {
        let _ = writeln!(
            out,
            "build and run: cd {} && cargo build --release && ./target/release/{} --help",
            args.out.display(),
            plantc_codegen::rig_package_name(&loaded.model.name)
        );
    }
    Ok(())
}

/// A codegen error as a CLI error (bad input: exit 2; else 1).
pub fn codegen_error(e: Error) -> CliError {
    match e {
        Error::NotGenerated { .. } | Error::Load(_) | Error::Values(_) | Error::Control(_) => {
            CliError::input(e.to_string())
        }
        _ => CliError::failure(e.to_string()),
    }
}

/// The rig settings from the command line.
pub fn rig_options(args: &RigGenArgs) -> Result<RigOptions, CliError> {
    if !(args.observer_rate.is_finite()
        && args.observer_rate > 0.0
        && args.observer_rate <= plantc_runtime::MAX_RATE_HZ)
    {
        return Err(CliError::input(format!(
            "error: --rate {}: expected a loop rate in (0, {}] Hz",
            args.observer_rate,
            plantc_runtime::MAX_RATE_HZ
        )));
    }
    if !(args.observer_accel.is_finite() && args.observer_accel > 0.0) {
        return Err(CliError::input(format!(
            "error: --observer-accel {}: expected a positive acceleration in rad/s^2",
            args.observer_accel
        )));
    }
    let runtime = match &args.runtime {
        Some(text) => match text.strip_prefix("version:") {
            Some(v) if !v.trim().is_empty() => RuntimeSource::Version(v.trim().to_string()),
            Some(_) => {
                return Err(CliError::input(
                    "error: --runtime version: needs a requirement, e.g. version:0.1",
                ))
            }
            None => {
                let p = PathBuf::from(text);
                if !p.join("Cargo.toml").is_file() {
                    return Err(CliError::input(format!(
                        "error: --runtime {text}: no Cargo.toml there (expected plantc's runtime/ directory)"
                    )));
                }
                // An absolute path, so the crate builds from wherever it is moved to.
                RuntimeSource::Path(std::path::absolute(&p).unwrap_or(p))
            }
        },
        None => RuntimeSource::Path(RuntimeSource::this_checkout().ok_or_else(|| {
            CliError::input(
                "error: this plantc was built outside its checkout (no runtime/ next to codegen/); \
                 pass --runtime PATH (plantc's runtime/ directory) or --runtime version:REQ",
            )
        })?),
    };
    Ok(RigOptions {
        observer: ObserverOptions {
            rate_hz: args.observer_rate,
            accel_std: args.observer_accel,
            counts_per_rev: 4096.0,
        },
        runtime,
    })
}
