//! `plantc`: the command line of the plantc control-design compiler.
//!
//! [`run`] takes the arguments and output streams so that end-to-end tests can
//! drive the CLI in process.

mod cli;
mod commands;
mod common;
pub mod host;

pub use cli::Cli;
pub use common::CliError;

use std::ffi::OsString;
use std::io::Write;

use clap::Parser;

/// Exit code for bad input (model errors, bad data, bad arguments).
pub const EXIT_BAD_INPUT: i32 = 2;
/// Exit code for a failure of the requested computation.
pub const EXIT_FAILURE: i32 = 1;

/// Run the command line with `args` (including the program name) and return
/// the process exit code. Results go to `out`, diagnostics and notes to `err`.
pub fn run<I, T>(args: I, out: &mut dyn Write, err: &mut dyn Write) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() { EXIT_BAD_INPUT } else { 0 };
            let text = e.render().to_string();
            if e.use_stderr() {
                let _ = write!(err, "{text}");
            } else {
                let _ = write!(out, "{text}");
            }
            return code;
        }
    };
    match commands::dispatch(&cli, out, err) {
        Ok(()) => 0,
        Err(e) => {
            let _ = write!(err, "{}", e.message);
            if !e.message.ends_with('\n') {
                let _ = writeln!(err);
            }
            e.code
        }
    }
}
