//! One module per subcommand.

mod analyze;
mod check;
mod compare;
mod derive;
mod design;
mod diagnose;
mod fit;
mod fmt;
mod gen;
mod identify;
mod linearize;
mod lsp;
mod robustness;
mod run;
mod run_compiled;
mod sim;
mod stability;
mod synth;

use std::io::Write;

use crate::cli::{Cli, Command};
use crate::common::CliError;
use plantc_derive::mechanics::Expand;

/// Run the parsed command.
pub fn dispatch(cli: &Cli, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), CliError> {
    match &cli.command {
        Command::Check { model, json } => check::run(model, *json, out, err),
        Command::Fmt { paths, check } => fmt::run(paths, *check, out, err),
        Command::Lsp => lsp::run(),
        Command::Derive {
            model,
            json,
            latex,
            expand,
            no_expand,
        } => {
            let e = if *expand {
                Expand::Always
            } else if *no_expand {
                Expand::Never
            } else {
                Expand::Auto
            };
            derive::run(model, *json, *latex, e, out, err)
        }
        Command::Linearize {
            model,
            params,
            at,
            json,
        } => linearize::run(model, params, at.as_deref(), *json, out, err),
        Command::Analyze {
            model,
            controller: Some(c),
            params,
            json,
            ..
        } => analyze::controller(model, c, params, *json, out, err),
        Command::Analyze {
            model,
            output,
            controller: None,
            params,
            json,
        } => analyze::run(model, output.as_deref(), params, *json, out, err),
        Command::Stability {
            model,
            controller,
            vary,
            params,
            json,
        } => stability::run(model, controller, vary, params, *json, out, err),
        Command::Place {
            source,
            poles,
            json,
        } => design::place(source, poles, *json, out, err),
        Command::Lqr { source, q, r, json } => design::lqr(source, q, r, *json, out, err),
        Command::Run(args) => run::run(args, out, err),
        Command::Robustness(args) => robustness::run(args, out, err),
        Command::Sim(args) => sim::run(args, out, err),
        Command::Synth(args) => synth::run(args, out, err),
        Command::Compare(args) => compare::run(args, out, err),
        Command::Fit(args) => fit::run(args, out, err),
        Command::Diagnose(args) => diagnose::run(args, out, err),
        Command::Identify(args) => identify::run(args, out, err),
        Command::Gen(args) => gen::run(args, out, err),
    }
}
