//! Command-line arguments.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

/// plantc: a symbolic control-design compiler for mechanical plants.
#[derive(Debug, Parser)]
#[command(name = "plantc", version, about, long_about = None)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Parameter selection shared by the commands that evaluate a model.
#[derive(Debug, Args, Clone, Default)]
pub struct ParamArgs {
    /// Use the named parameter set of the model file.
    #[arg(long = "set", value_name = "NAME")]
    pub set: Option<String>,
    /// Override one parameter, in SI units (repeatable): `--param l2=0.1685`.
    #[arg(long = "param", value_name = "NAME=VALUE")]
    pub params: Vec<String>,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Check a model file: syntax, names, units; print its diagnostics.
    Check {
        /// The model file (`*.plant`).
        model: PathBuf,
        /// Print a JSON summary.
        #[arg(long)]
        json: bool,
    },
    /// Derive the Euler-Lagrange equations and the control-affine form.
    Derive {
        /// The model file.
        model: PathBuf,
        /// Print JSON (expressions as strings).
        #[arg(long)]
        json: bool,
        /// Print LaTeX instead of plain text.
        #[arg(long, conflicts_with = "json")]
        latex: bool,
    },
    /// Linearize about an operating point (default: every state and input 0).
    Linearize {
        /// The model file.
        model: PathBuf,
        #[command(flatten)]
        params: ParamArgs,
        /// Operating point, e.g. `--at alpha=0,theta=0` (unnamed states are 0;
        /// angles in rad, or with a `deg` suffix).
        #[arg(long, value_name = "NAME=VALUE,...")]
        at: Option<String>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Pole placement `u = -K x` for a single-input system.
    Place {
        #[command(flatten)]
        source: LinearSource,
        /// Desired closed-loop poles, e.g. `"-2+3.464i,-2-3.464i,-40,-45"`.
        #[arg(long, allow_hyphen_values = true)]
        poles: String,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Linear-quadratic regulator `u = -K x` (solves the CARE).
    Lqr {
        #[command(flatten)]
        source: LinearSource,
        /// Diagonal of the state weight Q, e.g. `1,1,1,1`.
        #[arg(long)]
        q: String,
        /// Diagonal of the input weight R, e.g. `1`.
        #[arg(long)]
        r: String,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Generate a standalone, allocation-free Rust crate (plant + controllers).
    Gen {
        /// The model file.
        model: PathBuf,
        /// Emit this controller of the model (repeatable).
        #[arg(long = "controller", value_name = "NAME")]
        controllers: Vec<String>,
        #[command(flatten)]
        params: ParamArgs,
        /// Output directory of the crate.
        #[arg(short = 'o', long = "out", value_name = "DIR")]
        out: PathBuf,
        /// Overwrite a non-empty directory that plantc did not generate.
        #[arg(long)]
        force: bool,
    },
}

/// Where a linear model comes from: a model file (linearized about 0) or a
/// JSON file `{"A": [[..]], "B": [[..]]}`.
#[derive(Debug, Args, Clone)]
pub struct LinearSource {
    /// The model file.
    #[arg(required_unless_present = "linear", conflicts_with = "linear")]
    pub model: Option<PathBuf>,
    /// A JSON file holding `{"A": [[...]], "B": [[...]]}` (as printed by
    /// `plantc linearize --json`).
    #[arg(long, value_name = "FILE.json")]
    pub linear: Option<PathBuf>,
    #[command(flatten)]
    pub params: ParamArgs,
}
