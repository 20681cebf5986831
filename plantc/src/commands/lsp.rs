//! `plantc lsp`: the language server over standard input and output.

use crate::common::CliError;

pub fn run() -> Result<(), CliError> {
    plantc_lsp::run_stdio().map_err(|e| CliError::failure(format!("error: language server: {e}")))
}
