//! One module per subcommand.

mod check;
mod derive;
mod design;
mod gen;
mod linearize;

use std::io::Write;

use crate::cli::{Cli, Command};
use crate::common::CliError;

/// Run the parsed command.
pub fn dispatch(cli: &Cli, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), CliError> {
    match &cli.command {
        Command::Check { model, json } => check::run(model, *json, out, err),
        Command::Derive { model, json, latex } => derive::run(model, *json, *latex, out, err),
        Command::Linearize { model, params, at, json } => {
            linearize::run(model, params, at.as_deref(), *json, out, err)
        }
        Command::Place { source, poles, json } => design::place(source, poles, *json, out, err),
        Command::Lqr { source, q, r, json } => design::lqr(source, q, r, *json, out, err),
        Command::Gen { model, controllers, params, out: dir, force } => {
            gen::run(model, controllers, params, dir, *force, out, err)
        }
    }
}
