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
    /// Format model files in the canonical layout (aligned parameter tables,
    /// spacing; comments kept). Directories are searched for `*.plant`; `-`
    /// reads standard input and writes the result to standard output.
    Fmt {
        /// Files or directories.
        #[arg(required = true)]
        paths: Vec<PathBuf>,
        /// Do not write: list the files that are not formatted and exit with
        /// code 1 if there is any (for CI).
        #[arg(long)]
        check: bool,
    },
    /// Run the language server (LSP over standard input and output) for
    /// editors: diagnostics, hover, completion, rename, formatting...
    Lsp,
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
        /// Expand f = (q', M^-1 (Q0 - bias)) and g = (0, M^-1 B) whatever the
        /// size (by default only up to 3 coordinates; larger systems are
        /// printed by their structure).
        #[arg(long, conflicts_with = "no_expand")]
        expand: bool,
        /// Never expand f and g (print M, bias, Q0, B only).
        #[arg(long)]
        no_expand: bool,
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
    /// Lie derivatives, relative degree, linearizing law, normal form and zero
    /// dynamics of an output; or, with --controller, a sliding-mode
    /// controller's equivalent control and reduced dynamics on its surface.
    Analyze {
        /// The model file.
        model: PathBuf,
        /// The output to analyse (default: the model's first output); for a
        /// model with several inputs as many outputs, `a,b` (default: the
        /// declared outputs when they are that many).
        #[arg(long, value_name = "NAME[,NAME...]")]
        output: Option<String>,
        /// Analyse this controller: a `surface` (sliding-mode) controller, or
        /// a `linearize output` controller (its output).
        #[arg(long, conflicts_with = "output")]
        controller: Option<String>,
        #[command(flatten)]
        params: ParamArgs,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Exact interval of gains (varied together, `a = b = k`) for which a
    /// feedback-linearizing controller stabilises the origin.
    Stability {
        /// The model file.
        model: PathBuf,
        /// The controller (a `linearize output` controller of the model).
        #[arg(long)]
        controller: String,
        /// Gains varied together, e.g. `a,b`.
        #[arg(long, value_name = "GAIN,...")]
        vary: String,
        #[command(flatten)]
        params: ParamArgs,
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
    /// Generate a standalone, allocation-free Rust crate (plant + controllers);
    /// with --rig, a binary that runs them on the simulator or the board.
    Gen(GenArgs),
    /// Simulate the model with one of its controllers; write a CSV trajectory.
    Sim(SimArgs),
    /// Run a controller in the real-time loop on the simulator or a Quanser
    /// Q2-USB board, with the safety supervisor and a CSV log.
    Run(RunArgs),
    /// Robustness study: controllers designed on the model's values (or
    /// --set) against plants whose parameters differ; which hold, and the
    /// chattering (total variation of the input). Cases run in parallel.
    Robustness(RobustnessArgs),
    /// Make measurement-like CSV data from the model with hidden effects
    /// (true parameter values, encoder quantisation, optional noise).
    Synth(SynthArgs),
    /// Compare the model with measured experiments: fit %, RMSE, where it fails.
    Compare(CompareArgs),
    /// Fit the parameters marked `estimate` (or `--free`) to measured experiments.
    Fit(FitArgs),
    /// Name the physical effect the model is missing, from measured experiments.
    Diagnose(DiagnoseArgs),
    /// The whole story: compare the nominal model with the data, diagnose the
    /// missing effect, add it to a copy of the model, fit, compare again;
    /// before/after table, fitted model and figures under `-o DIR`.
    Identify(IdentifyArgs),
}

/// Arguments of `plantc gen`.
#[derive(Debug, Args, Clone)]
pub struct GenArgs {
    /// The model file.
    pub model: PathBuf,
    /// Emit this controller of the model (repeatable).
    #[arg(long = "controller", value_name = "NAME")]
    pub controllers: Vec<String>,
    #[command(flatten)]
    pub params: ParamArgs,
    /// Output directory of the crate.
    #[arg(short = 'o', long = "out", value_name = "DIR")]
    pub out: PathBuf,
    /// Overwrite a non-empty directory that plantc did not generate.
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub rig: RigGenArgs,
}

/// How `plantc gen --rig` (and `plantc run --compiled`) make a rig crate.
#[derive(Debug, Args, Clone)]
pub struct RigGenArgs {
    /// Generate a rig binary: the generated plant, controllers and velocity
    /// observer linked into plantc-runtime (simulator and Q2-USB backends,
    /// supervisor, log), with `plantc run`'s options.
    #[arg(long)]
    pub rig: bool,
    /// Loop rate the rig's velocity observer is designed for (Hz); the rig
    /// binary's default rate.
    #[arg(
        long = "rate",
        value_name = "HZ",
        default_value_t = 1000.0,
        requires = "rig"
    )]
    pub observer_rate: f64,
    /// Process noise of the rig's observer design: unmodelled angular
    /// acceleration (rad/s^2), as `plantc run --observer-accel`.
    #[arg(
        long = "observer-accel",
        value_name = "RAD_PER_S2",
        default_value_t = 30.0,
        requires = "rig"
    )]
    pub observer_accel: f64,
    /// The plantc-runtime the rig crate builds against: a path to its
    /// directory, or `version:REQ` for a released one (default: the runtime/
    /// of the plantc checkout this binary was built from).
    #[arg(long = "runtime", value_name = "PATH|version:REQ", requires = "rig")]
    pub runtime: Option<String>,
}

/// Arguments of `plantc identify`.
#[derive(Debug, Args, Clone)]
pub struct IdentifyArgs {
    /// The model file (never modified).
    pub model: PathBuf,
    #[command(flatten)]
    pub data: DataArgs,
    #[command(flatten)]
    pub control: FitControlArgs,
    /// The model's parameters to fit (default: those marked `estimate`),
    /// e.g. `J1,l2`: each needs its `estimate [lo, hi]` box; the others
    /// are held at their values. Added effects' parameters are always
    /// fitted.
    #[arg(long, value_name = "NAME,...")]
    pub free: Option<String>,
    /// Fit horizon: `auto` (whole records; segments when the replay
    /// diverges), `whole`, or a segment length in s (multiple shooting: each
    /// segment starts from its own estimated state).
    #[arg(long, value_name = "auto|whole|SECONDS", default_value = "auto")]
    pub horizon: String,
    /// Most effects added in turn (diagnose -> add -> refit rounds; the
    /// rounds stop earlier when the residual reaches the noise floor or no
    /// candidate helps).
    #[arg(long = "max-effects", value_name = "N", default_value_t = 3)]
    pub max_effects: usize,
    /// Held-out experiments the model is judged on at each stage.
    #[arg(long, value_name = "FILE", num_args = 1..)]
    pub validate: Vec<PathBuf>,
    /// Prediction horizon in s for the validation (k-step-ahead fit %).
    #[arg(long, value_name = "S")]
    pub predict: Option<f64>,
    /// Output directory: `with_effect.plant`, `fitted.plant`, `report.json`,
    /// `report.html` and the figures of each stage. Built aside and swapped in when the run
    /// completes: an interrupted run leaves the previous DIR as it was, and
    /// files of an earlier run never survive into the new one.
    #[arg(short = 'o', long = "out", value_name = "DIR")]
    pub out: PathBuf,
    /// Write into a non-empty DIR that identify did not write, or that holds
    /// the input model (identify's files are replaced, other entries kept);
    /// replace a `--report` FILE that identify did not write.
    #[arg(long)]
    pub force: bool,
    /// Print the summary as JSON instead of the story.
    #[arg(long)]
    pub json: bool,
    /// Also write the HTML report to FILE (`report.html` in DIR is always
    /// written): one self-contained file, no network needed.
    #[arg(long, value_name = "FILE.html")]
    pub report: Option<PathBuf>,
}

/// Arguments of `plantc synth`.
#[derive(Debug, Args, Clone)]
pub struct SynthArgs {
    /// The model file.
    pub model: PathBuf,
    /// A hidden effect (repeatable): `coulomb_friction:alpha=8e-4` or
    /// `stribeck_friction:alpha:Fc=8e-4,Fs=1.2e-3,vs=0.1` (values in SI).
    #[arg(long = "effect", value_name = "EFFECT:TARGET=VALUE")]
    pub effects: Vec<String>,
    /// A true parameter value (repeatable, SI or `deg`): `--set J1=1.6e-3`;
    /// a name without `=` selects a named parameter set of the model.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    pub set: Vec<String>,
    /// An experiment (repeatable): `free_swing:alpha0=120deg,duration=20`,
    /// `driven:alpha0=180deg,band=0.3-6,rms=1.5,seed=1,duration=20`,
    /// `step:amplitude=1,at=0.5,duration=5`; `name=` names the file.
    #[arg(
        long = "experiment",
        value_name = "KIND:KEY=VALUE,...",
        required = true
    )]
    pub experiments: Vec<String>,
    /// Sample rate (Hz).
    #[arg(long, default_value_t = 500.0)]
    pub rate: f64,
    /// Encoder counts per revolution of angle coordinates (0: no quantisation).
    #[arg(long, default_value_t = 4096)]
    pub counts: u32,
    /// Standard deviation of Gaussian noise on the coordinates (SI, before
    /// quantisation).
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
    /// Seed of the noise and of the multisine phases.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Simulation substep (s).
    #[arg(long, default_value_t = 1e-4)]
    pub substep: f64,
    /// Dry friction of the true model: `sticking` (a joint at rest stays at
    /// rest below its static level, as on a rig) or `smooth:WIDTH` (the
    /// `tanh(v / WIDTH)` law of earlier versions, e.g. `smooth:1e-3`).
    #[arg(long, value_name = "LAW", default_value = "sticking")]
    pub friction: String,
    /// Name of the case in truth.json (default: the directory's name).
    #[arg(long)]
    pub case: Option<String>,
    /// Output directory (created if missing).
    #[arg(short = 'o', long = "out", value_name = "DIR")]
    pub out: PathBuf,
    /// Overwrite existing files in DIR.
    #[arg(long)]
    pub force: bool,
}

/// Measured data files and how to read them.
#[derive(Debug, Args, Clone)]
pub struct DataArgs {
    /// Measured experiments: CSV files with a header (`t` and the model's
    /// coordinates and inputs, unit suffixes like `alpha[deg]` allowed) or
    /// MAT v5 files.
    #[arg(required = true, value_name = "DATA")]
    pub data: Vec<PathBuf>,
    /// For MAT files: the signal rows after time, e.g. `theta,alpha,Vm`.
    #[arg(long, value_name = "NAME,...")]
    pub channels: Option<String>,
    /// Read a channel from a column of another name, e.g. `Vm=plant_input`
    /// (repeatable, or comma-separated).
    #[arg(long = "map", value_name = "NAME=COLUMN")]
    pub map: Vec<String>,
    /// How the recorded inputs act between samples: `held` (each value over
    /// its sample interval, as a rig's converter holds it), `continuous`
    /// (points of a signal that moves in between: records from a simulator
    /// that integrates a continuous input, a sampled sensor such as a
    /// measured torque), or `auto` (`fit` reads them as continuous when
    /// that fits better, `identify` and `diagnose` when that explains the
    /// records better than any effect, and they say so; `compare` holds
    /// them).
    #[arg(long, value_name = "READING", default_value = "auto")]
    pub inputs: String,
}

/// How a model is fitted to or judged on measurements (shared by compare,
/// fit, diagnose and identify).
#[derive(Debug, Args, Clone)]
pub struct FitControlArgs {
    /// Weight of a channel's residual per SI unit, e.g. `alpha=20`
    /// (repeatable; default: 1 / the channel's noise floor: encoder quantum or measured high-frequency noise).
    #[arg(long = "weight", value_name = "COORD=W")]
    pub weights: Vec<String>,
    /// Initial state estimated per experiment: `positions,velocities`
    /// (default; the positions within their noise), `velocities` (the first
    /// samples taken as the positions), or `none` (measured positions, zero
    /// velocities).
    #[arg(
        long = "estimate-initial",
        value_name = "WHAT",
        default_value = "positions,velocities"
    )]
    pub estimate_initial: String,
    /// Per-experiment sensor zero offsets: `auto` (coordinates whose value
    /// matters, kept when significant), `none`, or coordinates `alpha,...`.
    #[arg(long, value_name = "auto|none|COORD,...", default_value = "auto")]
    pub offsets: String,
    /// Recorded controller simulated in the loop: `auto` (the model's, when
    /// the data hold its columns; `identify` with none in the model and
    /// records whose open-loop replay falls: the logged input with a
    /// stabilising feedback of its own), `off`, or its name.
    #[arg(
        long = "closed-loop",
        value_name = "auto|off|NAME",
        default_value = "auto"
    )]
    pub closed_loop: String,
    /// Worker threads for the fits and the candidate refits (default: the
    /// `PLANTC_THREADS` environment variable, else one per core); the
    /// results are the same on any number.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
    pub threads: Option<u16>,
    /// How the model's dry friction is simulated: `sticking` (a joint at
    /// rest stays at rest below its static level, as on a rig) or
    /// `smooth:WIDTH` (`sign(v)` replaced by `tanh(v / WIDTH)`: a held joint
    /// creeps, as in simulators that integrate that law, e.g. `smooth:1e-3`).
    #[arg(long, value_name = "LAW", default_value = "sticking")]
    pub friction: String,
}

/// Arguments of `plantc compare`.
#[derive(Debug, Args, Clone)]
pub struct CompareArgs {
    /// The model file.
    pub model: PathBuf,
    #[command(flatten)]
    pub data: DataArgs,
    #[command(flatten)]
    pub params: ParamArgs,
    #[command(flatten)]
    pub control: FitControlArgs,
    /// Also predict `S` seconds ahead (k-step-ahead prediction from the
    /// measured state, for unstable plants): fit % of the predictions.
    #[arg(long, value_name = "S")]
    pub horizon: Option<f64>,
    /// Lags of the residual tests (whiteness, input cross-correlation).
    #[arg(long, value_name = "L", default_value_t = 25)]
    pub lags: usize,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
    /// Write an overlay + residual SVG and a residual-test SVG per experiment
    /// into this directory (existing figures are kept unless --force).
    #[arg(long, value_name = "DIR")]
    pub plots: Option<PathBuf>,
    /// Overwrite existing figures in the --plots directory.
    #[arg(long, requires = "plots")]
    pub force: bool,
}

/// Arguments of `plantc fit`.
#[derive(Debug, Args, Clone)]
pub struct FitArgs {
    /// The model file.
    pub model: PathBuf,
    #[command(flatten)]
    pub data: DataArgs,
    #[command(flatten)]
    pub params: ParamArgs,
    /// Parameters to fit (default: those marked `estimate`), e.g. `J1,l2`.
    #[arg(long, value_name = "NAME,...")]
    pub free: Option<String>,
    #[command(flatten)]
    pub control: FitControlArgs,
    /// Fit horizon: `auto` (whole records; segments when the replay
    /// diverges), `whole`, or a segment length in s (multiple shooting: each
    /// segment starts from its own estimated state).
    #[arg(long, value_name = "auto|whole|SECONDS", default_value = "auto")]
    pub horizon: String,
    /// Held-out experiments: after the fit, the model is judged on them
    /// (fit %, prediction fit with --predict, residual tests).
    #[arg(long, value_name = "FILE", num_args = 1..)]
    pub validate: Vec<PathBuf>,
    /// Prediction horizon in s for the validation (k-step-ahead fit %).
    #[arg(long, value_name = "S")]
    pub predict: Option<f64>,
    /// Write the model with the fitted values here (never the input file or
    /// an existing file unless --force).
    #[arg(short = 'o', long = "out", value_name = "OUT.plant")]
    pub out: Option<PathBuf>,
    /// Overwrite OUT.
    #[arg(long)]
    pub force: bool,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `plantc diagnose`.
#[derive(Debug, Args, Clone)]
pub struct DiagnoseArgs {
    /// The model file.
    pub model: PathBuf,
    #[command(flatten)]
    pub data: DataArgs,
    #[command(flatten)]
    pub control: FitControlArgs,
    /// Fit horizon: `auto` (whole records; segments when the replay
    /// diverges), `whole`, or a segment length in s (multiple shooting: each
    /// segment starts from its own estimated state).
    #[arg(long, value_name = "auto|whole|SECONDS", default_value = "auto")]
    pub horizon: String,

    /// Print JSON.
    #[arg(long)]
    pub json: bool,
    /// Write the model with the top effect added (needs -o).
    #[arg(long, requires = "out")]
    pub apply: bool,
    /// Where --apply writes (never the input file or an existing file unless
    /// --force).
    #[arg(
        short = 'o',
        long = "out",
        value_name = "OUT.plant",
        requires = "apply"
    )]
    pub out: Option<PathBuf>,
    /// Overwrite OUT.
    #[arg(long)]
    pub force: bool,
}

/// The integration method of `plantc sim`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum IntegratorKind {
    /// Explicit unless stiff at the initial state.
    Auto,
    /// Dormand-Prince 5(4).
    Explicit,
    /// Rosenbrock ROS2 (stiff models).
    Implicit,
}

/// Which hardware the loop drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendKind {
    /// The model simulated (encoder quantisation, zero-order hold, saturation).
    Sim,
    /// A Quanser Q2-USB through the HIL C API (hil.dll / libhil.so).
    Q2usb,
}

/// How `plantc run` estimates velocities.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum VelocityKind {
    /// Steady-state Kalman observer on the model linearized about upright.
    Observer,
    /// Filtered derivative `wc s / (s + wc)` of each angle (Quanser's examples).
    Derivative,
}

/// Arguments of `plantc run`.
#[derive(Debug, Args, Clone)]
pub struct RunArgs {
    /// The model file.
    pub model: PathBuf,
    #[command(flatten)]
    pub params: ParamArgs,
    /// The controller declared in the model file.
    #[arg(long)]
    pub controller: String,
    /// Override controller gains, e.g. `--gain a=0.5,b=0.5`.
    #[arg(long, value_name = "NAME=VALUE,...", allow_hyphen_values = true)]
    pub gain: Vec<String>,
    /// Backend.
    #[arg(long, value_enum, default_value_t = BackendKind::Sim)]
    pub backend: BackendKind,
    /// Initial state of the simulator, e.g. `--x0 alpha=5deg`.
    #[arg(long, value_name = "NAME=VALUE,...", allow_hyphen_values = true)]
    pub x0: Option<String>,
    /// Path of the HIL library. A bare file name is looked for in the
    /// current directory first, then on the system library path. Default:
    /// `hil.dll` (Windows), `libhil.dylib` (macOS), `libhil.so` then
    /// `/opt/quanser/lib/libhil.so` (Linux).
    #[arg(long, value_name = "PATH")]
    pub hil_lib: Option<PathBuf>,
    /// Board identifier for hil_open.
    #[arg(long, value_name = "ID", default_value = "0")]
    pub board: String,
    /// Drive the motor even if the board refuses the hardware watchdog.
    #[arg(long)]
    pub allow_no_watchdog: bool,
    /// Loop rate (Hz, at most 2000).
    #[arg(long, value_name = "HZ", default_value_t = 1000.0)]
    pub rate: f64,
    /// Run length (s).
    #[arg(long, value_name = "S", default_value_t = 10.0)]
    pub duration: f64,
    /// Fault once |theta| (the first coordinate) exceeds this, e.g. `180deg`
    /// (the SRV02 arm has no hard stop; cables limit it).
    #[arg(long, value_name = "ANGLE", default_value = "180deg")]
    pub arm_limit: String,
    /// Engage a balancing controller once the pendulum is within this of upright.
    #[arg(long, value_name = "ANGLE", default_value = "10deg")]
    pub catch_window: String,
    /// Fault once the pendulum is this far from upright after engaging.
    #[arg(long, value_name = "ANGLE", default_value = "30deg")]
    pub fall_angle: String,
    /// How velocities are estimated from the encoder angles: a Kalman
    /// observer on the model linearized about upright, or Quanser's filtered
    /// derivative (see --velocity-bandwidth). Default: the observer, or the
    /// derivative for a controller with a swing-up mode (the observer's
    /// model only holds near upright).
    #[arg(long, value_enum)]
    pub velocity: Option<VelocityKind>,
    /// Swing-up (a hybrid controller's `swing_up` mode) starts only with the
    /// pendulum within this of hanging.
    #[arg(long, value_name = "ANGLE", default_value = "20deg")]
    pub hanging_window: String,
    /// Fault during swing-up once |arm speed| exceeds this (rad/s).
    #[arg(long, value_name = "RAD_PER_S", default_value_t = 30.0)]
    pub max_arm_speed: f64,
    /// Fault during swing-up once |pendulum speed| exceeds this (rad/s).
    #[arg(long, value_name = "RAD_PER_S", default_value_t = 25.0)]
    pub max_pendulum_speed: f64,
    /// Bandwidth of the filtered derivative (rad/s; with --velocity
    /// derivative). Default 50 (Quanser's examples), 200 for a controller
    /// with a swing-up mode (at 50 the energy pump's lag loses the catch).
    #[arg(long, value_name = "RAD_PER_S")]
    pub velocity_bandwidth: Option<f64>,
    /// Observer process noise: unmodelled angular acceleration (rad/s^2;
    /// larger = faster, noisier observer).
    #[arg(long, value_name = "RAD_PER_S2", default_value_t = 30.0)]
    pub observer_accel: f64,
    /// Run the simulator in real time (default: as fast as possible).
    #[arg(long)]
    pub realtime: bool,
    /// Seeded simulator noise: encoder noise in counts and a disturbance
    /// voltage (standard deviations), e.g. `counts=0.5,volts=0.05,seed=1`.
    #[arg(long, value_name = "counts=STD,volts=STD,seed=N")]
    pub sim_noise: Option<String>,
    /// CSV log of every sample (never overwritten unless --force).
    #[arg(long, value_name = "FILE.csv")]
    pub log: Option<PathBuf>,
    /// Numbers in the log: fixed decimals, or the shortest text that reads
    /// back to the same number (for comparing runs bit for bit).
    #[arg(long, value_enum, default_value_t = LogPrecision::Fixed)]
    pub log_precision: LogPrecision,
    /// Overwrite an existing log.
    #[arg(long)]
    pub force: bool,
    /// Run the generated code instead of the interpreter: generate (or
    /// update) the rig crate in DIR for this model, parameters and controller
    /// (as `plantc gen --rig`, the observer designed for --rate and
    /// --observer-accel), build it with cargo (release) and run its binary
    /// with these options.
    #[arg(long, value_name = "DIR")]
    pub compiled: Option<PathBuf>,
    /// With --compiled: replay the interpreted observer and controller over
    /// the compiled run's log (written at full precision) and report the
    /// largest voltage and velocity differences and the replay's timing.
    #[arg(long, requires_all = ["compiled", "log"])]
    pub compare: bool,
    /// With --compiled: the plantc-runtime the rig crate builds against, as
    /// `plantc gen --runtime`.
    #[arg(long, value_name = "PATH|version:REQ", requires = "compiled")]
    pub runtime: Option<String>,
}

/// Number format of `plantc run`'s log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LogPrecision {
    /// 6 decimals for time and states, 4 for volts.
    Fixed,
    /// Round-trip numbers.
    Full,
}

/// Arguments of `plantc robustness`.
#[derive(Debug, Args, Clone)]
pub struct RobustnessArgs {
    /// The model file.
    pub model: PathBuf,
    /// Design values of the controllers (the plants differ from them).
    #[command(flatten)]
    pub params: ParamArgs,
    /// A controller of the model (repeatable; default: every controller
    /// without modes or direct laws).
    #[arg(long = "controller", value_name = "NAME")]
    pub controllers: Vec<String>,
    /// Parameters varied one at a time by -/+ --by, e.g. `J1,l2,b1`.
    #[arg(long, value_name = "NAME,...")]
    pub vary: Option<String>,
    /// Relative change of each varied parameter, e.g. `20%` or `0.2`.
    #[arg(long, value_name = "FRACTION", default_value = "20%")]
    pub by: String,
    /// A plant with a parameter set to a value the design lacks, e.g.
    /// `Fg1=0.01` (repeatable).
    #[arg(long = "add", value_name = "NAME=VALUE")]
    pub add: Vec<String>,
    /// Initial state, e.g. `--x0 alpha=10deg`.
    #[arg(long, value_name = "NAME=VALUE,...", allow_hyphen_values = true)]
    pub x0: Option<String>,
    /// Simulated time per case (s).
    #[arg(long, value_name = "S", default_value_t = 10.0)]
    pub duration: f64,
    /// Controller rate (Hz, zero-order hold).
    #[arg(long, value_name = "HZ", default_value_t = 1000.0)]
    pub rate: f64,
    /// The coordinate that must stay up (default: the second coordinate).
    #[arg(long, value_name = "NAME")]
    pub pendulum: Option<String>,
    /// The coordinate with an angle limit (default: the first coordinate).
    #[arg(long, value_name = "NAME")]
    pub arm: Option<String>,
    /// The pendulum must stay within this of upright.
    #[arg(long, value_name = "ANGLE", default_value = "30deg")]
    pub fall_angle: String,
    /// The arm must stay within this of 0.
    #[arg(long, value_name = "ANGLE", default_value = "180deg")]
    pub arm_limit: String,
    /// Settled: largest |pendulum| over the last 2 s below this.
    #[arg(long, value_name = "ANGLE", default_value = "1deg")]
    pub settle: String,
    /// Worker threads (default: the available parallelism).
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `plantc sim`.
#[derive(Debug, Args, Clone)]
pub struct SimArgs {
    /// The model file.
    pub model: PathBuf,
    #[command(flatten)]
    pub params: ParamArgs,
    /// The controller declared in the model file.
    #[arg(long)]
    pub controller: String,
    /// Override controller gains, e.g. `--gain a=1.5,b=1.5`.
    #[arg(long, value_name = "NAME=VALUE,...", allow_hyphen_values = true)]
    pub gain: Vec<String>,
    /// Initial state, e.g. `--x0 alpha=10deg` (unnamed states are 0).
    #[arg(long, value_name = "NAME=VALUE,...", allow_hyphen_values = true)]
    pub x0: Option<String>,
    /// Simulated time (s).
    #[arg(long, default_value_t = 5.0)]
    pub duration: f64,
    /// Output CSV file (never overwritten unless --force).
    #[arg(short = 'o', long = "output", value_name = "FILE.csv")]
    pub output: PathBuf,
    /// Also draw angles and inputs against time as SVG.
    #[arg(long, value_name = "FILE.svg")]
    pub plot: Option<PathBuf>,
    /// Sample the controller at this rate (Hz) and hold its output; default:
    /// continuous time (the law evaluated inside every integrator stage).
    #[arg(long, value_name = "HZ")]
    pub sample_rate: Option<f64>,
    /// Output samples per second.
    #[arg(long, value_name = "HZ", default_value_t = 1000.0)]
    pub output_rate: f64,
    /// Replace every `sign(v)` of the equations (dry friction) by
    /// `tanh(v / WIDTH)`, e.g. `--smooth-sign 1e-3` (rad/s). Without it dry
    /// friction sticks: a joint at rest stays at rest while the force on it
    /// is below its static level (stick-slip switches located by the
    /// integrator).
    #[arg(long, value_name = "WIDTH")]
    pub smooth_sign: Option<f64>,
    /// Relative integrator tolerance (default 1e-8; absolute = rtol/100).
    #[arg(long)]
    pub rtol: Option<f64>,
    /// Integrator: `auto` (explicit Dormand-Prince unless the model is stiff
    /// at the initial state, then implicit), `explicit`, or `implicit`
    /// (Rosenbrock: for stiff models, e.g. a tiny resistance or inertia).
    #[arg(long, value_enum, default_value_t = IntegratorKind::Auto)]
    pub integrator: IntegratorKind,
    /// Overwrite existing output files.
    #[arg(long)]
    pub force: bool,
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
