//! The command line and run flow of a generated rig binary
//! (`plantc gen MODEL --controller NAME --rig -o DIR`).
//!
//! The generated crate implements [`RigModel`] in a thin adapter over its
//! generated plant, controllers and observer, and its `main` calls
//! [`rig_main`]. Everything else (argument parsing, backends, supervisor,
//! log, report, exit codes) lives here, so every rig binary behaves like
//! `plantc run`: the same options (`--backend sim|q2usb`, `--hil-lib`,
//! `--board`, `--rate`, `--duration`, `--log`, `--x0`, ...), the same
//! supervisor and watchdog, 0 V on every exit path, the same CSV log.
//!
//! Exit codes: 0 the run ended as planned; 1 it ended in a fault or failed;
//! 2 bad input (options, values file); 130 stopped by Ctrl-C.

use std::f64::consts::PI;
use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::alloc_count;
use crate::backend::Backend;
use crate::control_loop::{run_with_notes, RunConfig};
use crate::controller::{Controller, Mode};
use crate::estimator::{DerivativeEstimator, VelocityEstimator};
use crate::log::{LogError, LogWriter};
use crate::plant::Plant;
use crate::q2usb::{Q2Usb, Q2UsbConfig};
use crate::report::RunReport;
use crate::sim::{SimBackend, SimConfig, SimNoise};
use crate::supervisor::{FaultKind, SupervisorConfig, SupervisorState, SwingUpLimits};

/// How the generated observer was designed (at generation time).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObserverInfo {
    /// The loop rate it is discretised for (Hz).
    pub rate_hz: f64,
    /// Process noise used for the design (rad/s^2).
    pub accel_std: f64,
    /// Encoder counts per revolution assumed for the measurement noise.
    pub counts_per_rev: f64,
    /// Real parts of the slowest and fastest observer poles (rad/s).
    pub poles: (f64, f64),
}

/// What a rig binary was generated from and offers.
#[derive(Debug, Clone, Copy)]
pub struct RigInfo {
    /// Model name.
    pub model: &'static str,
    /// How it was generated, e.g. `models/rotary_pendulum.plant, set thesis`.
    pub generated_from: &'static str,
    /// State names (positions, then velocities).
    pub state_names: &'static [&'static str],
    /// Input names.
    pub input_names: &'static [&'static str],
    /// Input limits, one per input.
    pub input_limits: &'static [(f64, f64)],
    /// Parameter names (`--param NAME=VALUE`).
    pub param_names: &'static [&'static str],
    /// The generated controllers; the first is the default.
    pub controllers: &'static [&'static str],
    /// The generated velocity observer, if any.
    pub observer: Option<ObserverInfo>,
}

/// The generated code behind the runtime's traits: implemented by the
/// adapter module of a generated rig crate.
pub trait RigModel {
    /// The static description.
    fn info(&self) -> &RigInfo;
    /// Gain names of a controller (`--gain NAME=VALUE`), empty if unknown.
    fn gain_names(&self, controller: &str) -> &'static [&'static str];
    /// The generated plant with parameters changed by `params` (name, SI value).
    fn plant(&self, params: &[(String, f64)]) -> Result<Box<dyn Plant + Send>, String>;
    /// The controller `name` with parameters and gains changed.
    fn controller(
        &self,
        name: &str,
        params: &[(String, f64)],
        gains: &[(String, f64)],
    ) -> Result<Box<dyn Controller>, String>;
    /// A fresh generated velocity observer, if any.
    fn observer(&self) -> Option<Box<dyn VelocityEstimator>>;
}

/// Which hardware the rig drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RigBackend {
    /// The generated plant simulated.
    Sim,
    /// A Quanser Q2-USB through the HIL library.
    Q2Usb,
}

/// Velocity estimation of the rig.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RigVelocity {
    /// The generated observer (the default when there is one).
    Observer,
    /// The filtered derivative with this bandwidth (rad/s).
    Derivative(f64),
}

/// Parsed options of a rig binary.
#[derive(Debug, Clone, PartialEq)]
pub struct RigArgs {
    /// Controller to run (default: the first generated one).
    pub controller: Option<String>,
    /// Gain overrides in order (`--gain`, after the values file).
    pub gains: Vec<(String, f64)>,
    /// Parameter overrides in order (`--param`, after the values file).
    pub params: Vec<(String, f64)>,
    /// A file of `NAME = VALUE` lines (gains or parameters).
    pub values: Option<PathBuf>,
    /// Backend.
    pub backend: RigBackend,
    /// Initial state of the simulator, `NAME=VALUE[deg],...`.
    pub x0: Option<String>,
    /// HIL library path.
    pub hil_lib: Option<PathBuf>,
    /// Board identifier.
    pub board: String,
    /// Drive the motor without a hardware watchdog.
    pub allow_no_watchdog: bool,
    /// Loop rate (Hz); default: the observer's design rate, else 1000.
    pub rate: Option<f64>,
    /// Run length (s).
    pub duration: f64,
    /// Arm limit (rad).
    pub arm_limit: f64,
    /// Fall angle (rad).
    pub fall_angle: f64,
    /// Engage a balancing controller within this of upright (rad).
    pub catch_window: f64,
    /// Swing-up limits, used when the controller has a swing-up mode.
    pub swing_up: SwingUpLimits,
    /// Velocity estimation; `None`: the observer if generated, else the derivative at 50 rad/s.
    pub velocity: Option<RigVelocity>,
    /// Simulator in real time.
    pub realtime: bool,
    /// Simulator noise.
    pub sim_noise: Option<SimNoise>,
    /// CSV log.
    pub log: Option<PathBuf>,
    /// Overwrite an existing log.
    pub force: bool,
    /// Full-precision numbers in the log.
    pub log_full_precision: bool,
}

impl Default for RigArgs {
    fn default() -> Self {
        Self {
            controller: None,
            gains: Vec::new(),
            params: Vec::new(),
            values: None,
            backend: RigBackend::Sim,
            x0: None,
            hil_lib: None,
            board: "0".into(),
            allow_no_watchdog: false,
            rate: None,
            duration: 10.0,
            arm_limit: PI,
            fall_angle: 30f64.to_radians(),
            catch_window: SupervisorConfig::default().catch_window_rad,
            swing_up: SwingUpLimits::default(),
            velocity: None,
            realtime: false,
            sim_noise: None,
            log: None,
            force: false,
            log_full_precision: false,
        }
    }
}

/// Why a rig run did not end as planned.
#[derive(Debug, Clone, PartialEq)]
pub enum RigError {
    /// Bad options or values (exit code 2).
    Usage(String),
    /// The run could not start or failed (exit code 1).
    Failure(String),
    /// The run ended in a supervisor fault (exit code 1).
    Fault(SupervisorState),
    /// Stopped by Ctrl-C or a terminating signal (exit code 128 + signal:
    /// 130 SIGINT, 143 SIGTERM, 129 SIGHUP, 131 SIGQUIT).
    Stopped,
}

impl RigError {
    /// The process exit code.
    pub fn exit_code(&self) -> u8 {
        match self {
            RigError::Usage(_) => 2,
            RigError::Failure(_) | RigError::Fault(_) => 1,
            RigError::Stopped => crate::interrupt::stop_signal()
                .and_then(|s| u8::try_from(s.exit_code).ok())
                .unwrap_or(130),
        }
    }
}

impl fmt::Display for RigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RigError::Usage(m) | RigError::Failure(m) => write!(f, "error: {m}"),
            RigError::Fault(s) => write!(f, "run ended in {s}"),
            RigError::Stopped => write!(
                f,
                "stopped by {} (0 V written, board closed, log flushed)",
                crate::interrupt::stop_signal().map_or("Ctrl-C", |s| s.name)
            ),
        }
    }
}

impl std::error::Error for RigError {}

fn usage(m: impl Into<String>) -> RigError {
    RigError::Usage(m.into())
}

/// What the parser found: a run, or a request for help.
#[derive(Debug, Clone, PartialEq)]
pub enum RigCommand {
    /// Run with these options.
    Run(Box<RigArgs>),
    /// Print the help text.
    Help,
}

/// A number with an optional unit suffix: `deg` (to rad), `deg/s` (to rad/s),
/// `rad`, `rad/s`, `s`, `ms`.
fn quantity(text: &str) -> Option<f64> {
    let t = text.trim();
    let (num, scale) = if let Some(n) = t.strip_suffix("deg/s") {
        (n, PI / 180.0)
    } else if let Some(n) = t.strip_suffix("deg") {
        (n, PI / 180.0)
    } else if let Some(n) = t.strip_suffix("rad/s") {
        (n, 1.0)
    } else if let Some(n) = t.strip_suffix("rad") {
        (n, 1.0)
    } else if let Some(n) = t.strip_suffix("ms") {
        (n, 1e-3)
    } else if let Some(n) = t.strip_suffix('s') {
        (n, 1.0)
    } else {
        (t, 1.0)
    };
    num.trim()
        .parse::<f64>()
        .ok()
        .map(|v| v * scale)
        .filter(|v| v.is_finite())
}

/// `NAME=VALUE,...` pairs (values with [`quantity`] units).
fn assignments(option: &str, text: &str) -> Result<Vec<(String, f64)>, RigError> {
    let mut out = Vec::new();
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let Some((name, value)) = item.split_once('=') else {
            return Err(usage(format!(
                "{option} `{item}`: expected NAME=VALUE, e.g. {option} a=0.5"
            )));
        };
        let v = quantity(value).ok_or_else(|| {
            usage(format!(
                "{option} `{item}`: `{}` is not a finite number",
                value.trim()
            ))
        })?;
        out.push((name.trim().to_string(), v));
    }
    Ok(out)
}

/// Parses `--sim-noise counts=STD,volts=STD,seed=N` (counts: encoder noise
/// in counts before quantisation; volts: disturbance voltage; both standard
/// deviations, default 0; seed default 1).
pub fn parse_sim_noise(text: &str) -> Result<SimNoise, String> {
    let mut noise = SimNoise {
        seed: 1,
        counts_std: 0.0,
        volts_std: 0.0,
    };
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (k, v) = item
            .split_once('=')
            .ok_or_else(|| format!("`{item}`: expected KEY=VALUE (counts, volts, seed)"))?;
        let v = v.trim();
        match k.trim() {
            "seed" => {
                noise.seed = v
                    .parse()
                    .map_err(|_| format!("seed `{v}`: expected a whole number"))?
            }
            "counts" | "volts" => {
                let x: f64 = v
                    .parse()
                    .ok()
                    .filter(|x: &f64| x.is_finite() && *x >= 0.0)
                    .ok_or_else(|| format!("{k} `{v}`: expected a standard deviation >= 0"))?;
                if k.trim() == "counts" {
                    noise.counts_std = x;
                } else {
                    noise.volts_std = x;
                }
            }
            other => return Err(format!("unknown key `{other}` (counts, volts, seed)")),
        }
    }
    Ok(noise)
}

fn positive_angle(option: &str, text: &str) -> Result<f64, RigError> {
    quantity(text).filter(|v| *v > 0.0).ok_or_else(|| {
        usage(format!(
            "{option} `{text}`: expected a positive angle, e.g. 180deg"
        ))
    })
}

fn positive(option: &str, text: &str, what: &str) -> Result<f64, RigError> {
    text.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && *v > 0.0)
        .ok_or_else(|| usage(format!("{option} `{text}`: expected {what}")))
}

impl RigArgs {
    /// Parses the options (without the program name). `--opt value` and
    /// `--opt=value` are both accepted.
    pub fn parse<I, S>(args: I) -> Result<RigCommand, RigError>
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        let mut a = RigArgs::default();
        let mut velocity_kind: Option<String> = None;
        let mut bandwidth = 50.0;
        let mut it = args.into_iter().map(Into::into);
        while let Some(arg) = it.next() {
            let (opt, inline) = match arg.split_once('=') {
                Some((o, v)) if o.starts_with("--") => (o.to_string(), Some(v.to_string())),
                _ => (arg.clone(), None),
            };
            let flag = |a: &mut RigArgs, f: fn(&mut RigArgs)| -> Result<(), RigError> {
                if inline.is_some() {
                    return Err(usage(format!("{opt} takes no value")));
                }
                f(a);
                Ok(())
            };
            match opt.as_str() {
                "-h" | "--help" => return Ok(RigCommand::Help),
                "--allow-no-watchdog" => flag(&mut a, |a| a.allow_no_watchdog = true)?,
                "--realtime" => flag(&mut a, |a| a.realtime = true)?,
                "--force" => flag(&mut a, |a| a.force = true)?,
                _ => {
                    if !opt.starts_with("--") {
                        return Err(usage(format!(
                            "unexpected argument `{arg}` (options start with --; see --help)"
                        )));
                    }
                    let value = match inline.clone().or_else(|| it.next()) {
                        Some(v) => v,
                        None => return Err(usage(format!("{opt} needs a value (see --help)"))),
                    };
                    match opt.as_str() {
                        "--controller" => a.controller = Some(value),
                        "--gain" => a.gains.extend(assignments("--gain", &value)?),
                        "--param" => a.params.extend(assignments("--param", &value)?),
                        "--values" => a.values = Some(PathBuf::from(value)),
                        "--backend" => {
                            a.backend = match value.as_str() {
                                "sim" => RigBackend::Sim,
                                "q2usb" => RigBackend::Q2Usb,
                                o => {
                                    return Err(usage(format!(
                                        "--backend `{o}`: expected sim or q2usb"
                                    )))
                                }
                            }
                        }
                        "--x0" => a.x0 = Some(value),
                        "--hil-lib" => a.hil_lib = Some(PathBuf::from(value)),
                        "--board" => a.board = value,
                        "--rate" => {
                            a.rate = Some(positive("--rate", &value, "a rate in Hz, e.g. 1000")?)
                        }
                        "--duration" => {
                            a.duration = value
                                .trim()
                                .parse::<f64>()
                                .ok()
                                .filter(|v| v.is_finite() && *v >= 0.0)
                                .ok_or_else(|| {
                                    usage(format!("--duration `{value}`: expected seconds >= 0"))
                                })?
                        }
                        "--arm-limit" => a.arm_limit = positive_angle("--arm-limit", &value)?,
                        "--fall-angle" => a.fall_angle = positive_angle("--fall-angle", &value)?,
                        "--catch-window" => {
                            a.catch_window = positive_angle("--catch-window", &value)?
                        }
                        "--hanging-window" => {
                            a.swing_up.hanging_window_rad =
                                positive_angle("--hanging-window", &value)?
                        }
                        "--max-arm-speed" => {
                            a.swing_up.max_arm_speed =
                                positive("--max-arm-speed", &value, "a positive speed in rad/s")?
                        }
                        "--max-pendulum-speed" => {
                            a.swing_up.max_pendulum_speed = positive(
                                "--max-pendulum-speed",
                                &value,
                                "a positive speed in rad/s",
                            )?
                        }
                        "--velocity" => match value.as_str() {
                            "observer" | "derivative" => velocity_kind = Some(value),
                            o => {
                                return Err(usage(format!(
                                    "--velocity `{o}`: expected observer or derivative"
                                )))
                            }
                        },
                        "--velocity-bandwidth" => {
                            bandwidth = positive(
                                "--velocity-bandwidth",
                                &value,
                                "a positive rate in rad/s",
                            )?
                        }
                        "--sim-noise" => {
                            a.sim_noise = Some(
                                parse_sim_noise(&value)
                                    .map_err(|e| usage(format!("--sim-noise: {e}")))?,
                            )
                        }
                        "--log" => a.log = Some(PathBuf::from(value)),
                        "--log-precision" => {
                            a.log_full_precision = match value.as_str() {
                                "full" => true,
                                "fixed" => false,
                                o => {
                                    return Err(usage(format!(
                                        "--log-precision `{o}`: expected fixed or full"
                                    )))
                                }
                            }
                        }
                        _ => return Err(usage(format!("unknown option `{opt}` (see --help)"))),
                    }
                }
            }
        }
        a.velocity = match velocity_kind.as_deref() {
            Some("observer") => Some(RigVelocity::Observer),
            Some(_) => Some(RigVelocity::Derivative(bandwidth)),
            None if bandwidth != 50.0 => Some(RigVelocity::Derivative(bandwidth)),
            None => None,
        };
        Ok(RigCommand::Run(Box::new(a)))
    }
}

/// The help text of a rig binary.
pub fn help(model: &dyn RigModel, program: &str) -> String {
    let info = model.info();
    let mut h = format!(
        "{program}: the generated `{}` controllers on the plantc runtime (generated from {}).\n\n\
         Usage: {program} [OPTIONS]\n\nControllers (--controller, default {}):\n",
        info.model,
        info.generated_from,
        info.controllers.first().copied().unwrap_or("-")
    );
    for c in info.controllers {
        h.push_str(&format!(
            "  {c}: gains {}\n",
            model.gain_names(c).join(", ")
        ));
    }
    h.push_str(&format!(
        "Parameters (--param): {}\n",
        info.param_names.join(", ")
    ));
    match info.observer {
        Some(o) => h.push_str(&format!(
            "Velocity observer: generated for {} Hz, {} counts/rev, process noise {} rad/s^2 \
             (poles {:.0} to {:.0} rad/s)\n",
            o.rate_hz, o.counts_per_rev, o.accel_std, o.poles.0, o.poles.1
        )),
        None => h.push_str("Velocity observer: none generated (filtered derivative)\n"),
    }
    h.push_str(
        "\nOptions:\n\
         \x20 --controller NAME          controller to run\n\
         \x20 --gain NAME=VALUE,...      change gains at start-up (repeatable)\n\
         \x20 --param NAME=VALUE,...     change parameters (SI) of the simulated plant and of\n\
         \x20                            the linearizing laws (repeatable); state-feedback gains\n\
         \x20                            and the observer keep their generation-time design\n\
         \x20 --values FILE              `NAME = VALUE` lines (gains or parameters; # comments),\n\
         \x20                            applied before --gain/--param\n\
         \x20 --backend sim|q2usb        default sim\n\
         \x20 --x0 NAME=VALUE,...        initial state of the simulator, e.g. alpha=5deg\n\
         \x20 --sim-noise counts=STD,volts=STD,seed=N   seeded simulator noise\n\
         \x20 --hil-lib PATH             HIL library (default hil.dll / libhil.so)\n\
         \x20 --board ID                 board identifier for hil_open (default 0)\n\
         \x20 --allow-no-watchdog        drive the motor even if the board refuses the watchdog\n\
         \x20 --rate HZ                  loop rate (default: the observer's design rate, else 1000)\n\
         \x20 --duration S               run length (default 10)\n\
         \x20 --arm-limit ANGLE          fault once |theta| exceeds it (default 180deg)\n\
         \x20 --fall-angle ANGLE         fault once the pendulum is this far from upright (default 30deg)\n\
         \x20 --catch-window ANGLE       engage within this of upright (default 10deg)\n\
         \x20 --hanging-window ANGLE, --max-arm-speed RAD_PER_S, --max-pendulum-speed RAD_PER_S\n\
         \x20                            swing-up limits of a controller with a swing-up mode:\n\
         \x20                            start within this of hanging, fault above these speeds\n\
         \x20                            (defaults 20deg, 30, 25)\n\
         \x20 --velocity observer|derivative, --velocity-bandwidth RAD_PER_S (default 50;\n\
         \x20                            with a swing-up mode: derivative at 200)\n\
         \x20 --realtime                 run the simulator in real time\n\
         \x20 --log FILE.csv             CSV log of every sample (never overwritten unless --force)\n\
         \x20 --log-precision fixed|full fixed decimals (default) or round-trip numbers\n\
         \x20 --force                    overwrite an existing log\n\
         \nExit codes: 0 planned end, 1 fault or failure, 2 bad input, 130 Ctrl-C.\n",
    );
    h
}

/// Named values (`NAME`, SI value) in order.
type Assignments = Vec<(String, f64)>;

/// Reads `NAME = VALUE` lines (blank lines and `#` comments ignored) and
/// sorts them into (parameters, gains of `controller`).
fn read_values(
    path: &Path,
    model: &dyn RigModel,
    controller: &str,
) -> Result<(Assignments, Assignments), RigError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| usage(format!("--values {}: {e}", path.display())))?;
    let gains = model.gain_names(controller);
    let params = model.info().param_names;
    let (mut p, mut g) = (Vec::new(), Vec::new());
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let at = |col: usize| format!("{}:{}:{}", path.display(), i + 1, col + 1);
        let col = raw.len() - raw.trim_start().len();
        let Some((name, value)) = line.split_once('=') else {
            return Err(usage(format!(
                "{}: expected `NAME = VALUE`, found `{line}`",
                at(col)
            )));
        };
        let name = name.trim();
        let vcol = raw.find('=').map_or(col, |c| c + 1);
        let v = quantity(value).ok_or_else(|| {
            usage(format!(
                "{}: `{}` is not a finite number",
                at(vcol),
                value.trim()
            ))
        })?;
        let is_gain = gains.contains(&name);
        let is_param = params.contains(&name);
        match (is_gain, is_param) {
            (true, true) => {
                return Err(usage(format!(
                    "{}: `{name}` is both a gain of {controller} and a parameter; \
                     use --gain or --param",
                    at(col)
                )))
            }
            (true, false) => g.push((name.to_string(), v)),
            (false, true) => p.push((name.to_string(), v)),
            (false, false) => {
                return Err(usage(format!(
                    "{}: unknown name `{name}` (gains of {controller}: {}; parameters: {})",
                    at(col),
                    gains.join(", "),
                    params.join(", ")
                )))
            }
        }
    }
    Ok((p, g))
}

/// Initial state from `NAME=VALUE[deg],...` (unnamed states 0).
fn initial_state(text: Option<&str>, names: &[&str]) -> Result<Vec<f64>, RigError> {
    let mut x0 = vec![0.0; names.len()];
    if let Some(text) = text {
        for (name, v) in assignments("--x0", text)? {
            let Some(i) = names.iter().position(|n| *n == name) else {
                return Err(usage(format!(
                    "--x0: unknown state `{name}` (states: {})",
                    names.join(", ")
                )));
            };
            x0[i] = v;
        }
    }
    Ok(x0)
}

/// Counts the allocations of the loop thread from the first controller call
/// to the last one (when the binary installed [`crate::CountingAllocator`]).
struct AllocProbe<'a> {
    inner: &'a mut dyn Controller,
    calls: u64,
    first: u64,
    last: u64,
}

impl Controller for AllocProbe<'_> {
    fn control(&mut self, t: f64, x: &[f64], u: &mut [f64]) {
        if self.calls == 0 {
            alloc_count::count_on_this_thread(true);
            self.first = alloc_count::allocations();
        }
        self.calls += 1;
        self.last = alloc_count::allocations();
        self.inner.control(t, x, u);
    }

    fn reset(&mut self) {
        self.inner.reset();
    }

    fn mode_names(&self) -> Vec<String> {
        self.inner.mode_names()
    }

    fn mode(&self) -> Option<Mode> {
        self.inner.mode()
    }

    fn has_swing_up_mode(&self) -> bool {
        self.inner.has_swing_up_mode()
    }
}

/// Runs the rig with parsed options, writing progress to `err` and the
/// report to `out`.
pub fn execute(
    args: &RigArgs,
    model: &dyn RigModel,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<RunReport, RigError> {
    let info = model.info();
    let controller_name = match &args.controller {
        Some(c) => {
            if !info.controllers.contains(&c.as_str()) {
                return Err(usage(format!(
                    "unknown controller `{c}` (this binary has: {})",
                    info.controllers.join(", ")
                )));
            }
            c.clone()
        }
        None => info
            .controllers
            .first()
            .ok_or_else(|| usage("this binary has no controller"))?
            .to_string(),
    };
    let (mut params, mut gains) = match &args.values {
        Some(p) => read_values(p, model, &controller_name)?,
        None => (Vec::new(), Vec::new()),
    };
    params.extend(args.params.iter().cloned());
    gains.extend(args.gains.iter().cloned());
    for (p, _) in &params {
        if !info.param_names.contains(&p.as_str()) {
            return Err(usage(format!(
                "--param: unknown parameter `{p}` (parameters: {})",
                info.param_names.join(", ")
            )));
        }
    }
    let known = model.gain_names(&controller_name);
    for (g, _) in &gains {
        if !known.contains(&g.as_str()) {
            return Err(usage(format!(
                "--gain: unknown gain `{g}` of {controller_name} (gains: {})",
                known.join(", ")
            )));
        }
    }
    if !params.is_empty() {
        let _ = writeln!(
            err,
            "note: --param changes the simulated plant and the parameters of the linearizing laws; \
             state-feedback gains and the observer keep their generation-time design"
        );
    }
    let mut controller = model
        .controller(&controller_name, &params, &gains)
        .map_err(usage)?;

    let rate = args
        .rate
        .or(info.observer.map(|o| o.rate_hz))
        .unwrap_or(1000.0);
    // A swing-up mode drives the pendulum far from upright, where the
    // observer's linear model does not hold: the filtered derivative, faster.
    let swing_up = controller.has_swing_up_mode();
    let velocity = match (args.velocity, swing_up) {
        (Some(RigVelocity::Observer), true) => {
            return Err(usage(format!(
                "`{controller_name}` has a swing-up mode; the velocity observer's model is \
                 linearized about upright and does not hold while the pendulum swings: \
                 use --velocity derivative"
            )))
        }
        (Some(v), _) => v,
        (None, true) => RigVelocity::Derivative(200.0),
        (None, false) => match info.observer {
            Some(_) => RigVelocity::Observer,
            None => RigVelocity::Derivative(50.0),
        },
    };
    if args.catch_window >= args.fall_angle {
        return Err(usage(format!(
            "--catch-window {:.1}deg must be smaller than --fall-angle {:.1}deg",
            args.catch_window.to_degrees(),
            args.fall_angle.to_degrees()
        )));
    }
    let mut estimator: Box<dyn VelocityEstimator> = match velocity {
        RigVelocity::Observer => {
            let Some(o) = info.observer else {
                return Err(usage(
                    "--velocity observer: this binary was generated without an observer; \
                     use --velocity derivative",
                ));
            };
            if (rate - o.rate_hz).abs() > 1e-9 * o.rate_hz {
                return Err(usage(format!(
                    "--rate {rate}: the observer was designed for {} Hz at generation time \
                     (no linear algebra at start); regenerate with `plantc gen --rig --rate {rate}` \
                     or use --velocity derivative",
                    o.rate_hz
                )));
            }
            model
                .observer()
                .ok_or_else(|| RigError::Failure("the generated observer is missing".into()))?
        }
        RigVelocity::Derivative(wc) => Box::new(DerivativeEstimator::new(
            info.state_names.len() / 2,
            wc,
            1.0 / rate,
        )),
    };

    let mut config = RunConfig {
        rate_hz: rate,
        duration_s: Some(args.duration),
        state_names: info.state_names.iter().map(|s| s.to_string()).collect(),
        input_names: info.input_names.iter().map(|s| s.to_string()).collect(),
        input_limits: info.input_limits.to_vec(),
        ..RunConfig::default()
    };
    config.supervisor.arm_limit_rad = args.arm_limit;
    config.supervisor.fall_angle_rad = args.fall_angle;
    config.supervisor.catch_window_rad = args.catch_window;
    if swing_up {
        let l = args.swing_up;
        config.supervisor.swing_up = Some(l);
        let _ = writeln!(
            err,
            "note: `{controller_name}` has a swing-up mode: swing-up allowed from hanging \
             (within {:.1} deg), arm limit {:.1} deg, speeds up to {} rad/s (arm) and {} rad/s (pendulum)",
            l.hanging_window_rad.to_degrees(),
            args.arm_limit.to_degrees(),
            l.max_arm_speed,
            l.max_pendulum_speed
        );
    }

    let mut backend: Box<dyn Backend> = match args.backend {
        RigBackend::Sim => {
            let x0 = initial_state(args.x0.as_deref(), info.state_names)?;
            let plant = model.plant(&params).map_err(usage)?;
            let sim = SimConfig {
                real_time: args.realtime,
                noise: args.sim_noise,
                ..SimConfig::default()
            };
            Box::new(SimBackend::new(plant, x0, sim).map_err(|e| RigError::Failure(e.to_string()))?)
        }
        RigBackend::Q2Usb => {
            if args.x0.is_some() || args.sim_noise.is_some() {
                let _ = writeln!(
                    err,
                    "note: --x0 and --sim-noise are ignored on hardware (the state comes from the encoders)"
                );
            }
            let cfg = Q2UsbConfig {
                library_path: args.hil_lib.clone(),
                card_identifier: args.board.clone(),
                allow_no_watchdog: args.allow_no_watchdog,
                ..Q2UsbConfig::default()
            };
            let board = Q2Usb::open(cfg).map_err(|e| RigError::Failure(e.to_string()))?;
            for note in board.notes() {
                let _ = writeln!(err, "note: {note}");
            }
            Box::new(board)
        }
    };
    if let (RigVelocity::Observer, Some(o)) = (velocity, info.observer) {
        let other = backend
            .encoders()
            .iter()
            .map(|m| m.counts_per_rev)
            .find(|c| *c != o.counts_per_rev);
        if let Some(c) = other {
            let e = usage(format!(
                "the observer was designed for {} counts/rev encoders, the backend has {c}; \
                 regenerate or use --velocity derivative",
                o.counts_per_rev
            ));
            return Err(with_close(backend.as_mut(), e));
        }
    }
    let mut log = match &args.log {
        Some(path) => {
            if path.exists() && !args.force {
                let e = usage(format!(
                    "log {} exists; pass --force to overwrite it",
                    path.display()
                ));
                return Err(with_close(backend.as_mut(), e));
            }
            // O_EXCL without --force: a run started meanwhile with the same
            // log is refused, not interleaved
            let mut l = LogWriter::open(path, args.force).map_err(|e| {
                let e = match e {
                    LogError::Io {
                        kind: std::io::ErrorKind::AlreadyExists,
                        ..
                    } => usage(format!(
                        "log {} exists; pass --force to overwrite it",
                        path.display()
                    )),
                    e => RigError::Failure(format!("{}: {e}", path.display())),
                };
                with_close(backend.as_mut(), e)
            })?;
            l.set_full_precision(args.log_full_precision);
            Some(l)
        }
        None => None,
    };
    let _ = writeln!(
        out,
        "running `{controller_name}` (generated code) on {:?} at {rate} Hz for {} s",
        args.backend, args.duration
    );
    if let Err(e) = crate::interrupt::stop_on_ctrl_c(config.stop.clone()) {
        let _ = writeln!(
            err,
            "note: signal handlers not installed ({e}); Ctrl-C or kill will end the process without the 0 V stop"
        );
    }
    let mut probe = AllocProbe {
        inner: controller.as_mut(),
        calls: 0,
        first: 0,
        last: 0,
    };
    let err_cell = std::cell::RefCell::new(&mut *err);
    let result = run_with_notes(
        &config,
        backend.as_mut(),
        &mut probe,
        Some(estimator.as_mut()),
        log.as_mut(),
        &mut |t| {
            let _ = writeln!(err_cell.borrow_mut(), "supervisor: {t}");
        },
        &mut |n| {
            let _ = writeln!(err_cell.borrow_mut(), "supervisor: {n}");
        },
    );
    alloc_count::count_on_this_thread(false);
    let report = result.map_err(|e| RigError::Failure(e.to_string()))?;
    let _ = write!(out, "{report}");
    if !report.stop_errors.is_empty() {
        // The safe stop was not clean: a failure whatever the final state.
        return Err(RigError::Failure(format!(
            "run ended in {} and the safe stop failed: {}",
            report.final_state,
            report.stop_errors.join("; ")
        )));
    }
    if alloc_count::installed() && probe.calls > 1 {
        let _ = writeln!(
            out,
            "  loop allocations: {} in {} cycles (counting allocator, loop thread)",
            probe.last - probe.first,
            probe.calls - 1
        );
    }
    match report.final_state {
        SupervisorState::Fault(FaultKind::Stopped) => Err(RigError::Stopped),
        s @ SupervisorState::Fault(_) => Err(RigError::Fault(s)),
        _ if !report.engaged() => Err(RigError::Failure(format!(
            "the controller never engaged: {}",
            report.not_engaged.map_or_else(
                || "the run ended before the pendulum entered the catch window".to_string(),
                |n| n.to_string()
            )
        ))),
        _ => Ok(report),
    }
}

/// Closes `backend` on a path that ends the run with `error`; a failed
/// close is added to the error (a failure then), never dropped.
fn with_close(backend: &mut dyn Backend, error: RigError) -> RigError {
    match backend.close() {
        Ok(()) => error,
        Err(c) => {
            let first = match &error {
                RigError::Usage(m) | RigError::Failure(m) => m.clone(),
                other => other.to_string(),
            };
            RigError::Failure(format!("{first}; then {c}"))
        }
    }
}

/// The `main` of a rig binary: parses `std::env::args`, runs, prints, and
/// returns the exit code.
pub fn rig_main(model: &dyn RigModel) -> std::process::ExitCode {
    let mut argv = std::env::args();
    let program = argv
        .next()
        .as_deref()
        .map(|p| {
            Path::new(p)
                .file_name()
                .map_or(p.to_string(), |f| f.to_string_lossy().into_owned())
        })
        .unwrap_or_else(|| "rig".into());
    let mut out = std::io::stdout();
    let mut err = std::io::stderr();
    let code = match RigArgs::parse(argv) {
        Ok(RigCommand::Help) => {
            let _ = write!(out, "{}", help(model, &program));
            0
        }
        Ok(RigCommand::Run(args)) => match execute(&args, model, &mut out, &mut err) {
            Ok(_) => 0,
            Err(e) => {
                // board and log were released inside `execute`: a waiting
                // Windows console handler may let the process end now
                crate::interrupt::stop_completed();
                let _ = writeln!(err, "{e}");
                e.exit_code()
            }
        },
        Err(e) => {
            let _ = writeln!(err, "{e}");
            e.exit_code()
        }
    };
    let _ = out.flush();
    std::process::ExitCode::from(code)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_plantc_run_options() {
        let cmd = RigArgs::parse([
            "--controller",
            "fl_arm",
            "--gain",
            "a=0.4,b=0.3",
            "--backend=q2usb",
            "--rate",
            "500",
            "--duration",
            "30",
            "--x0",
            "alpha=5deg",
            "--arm-limit",
            "90deg",
            "--velocity",
            "derivative",
            "--velocity-bandwidth",
            "400",
            "--sim-noise",
            "counts=0.5,volts=0.05,seed=7",
            "--log-precision",
            "full",
            "--force",
        ])
        .unwrap();
        let RigCommand::Run(a) = cmd else {
            panic!("{cmd:?}")
        };
        assert_eq!(a.controller.as_deref(), Some("fl_arm"));
        assert_eq!(a.gains, [("a".into(), 0.4), ("b".into(), 0.3)]);
        assert_eq!(a.backend, RigBackend::Q2Usb);
        assert_eq!(a.rate, Some(500.0));
        assert!((a.arm_limit - PI / 2.0).abs() < 1e-15);
        assert_eq!(a.velocity, Some(RigVelocity::Derivative(400.0)));
        assert_eq!(a.sim_noise.map(|n| n.seed), Some(7));
        assert!(a.log_full_precision && a.force);
        assert_eq!(RigArgs::parse(["--help"]).unwrap(), RigCommand::Help);
    }

    #[test]
    fn parses_the_catch_window_and_swing_up_limits() {
        let cmd = RigArgs::parse([
            "--catch-window",
            "12deg",
            "--hanging-window=0.5rad",
            "--max-arm-speed",
            "20",
            "--max-pendulum-speed",
            "15",
        ])
        .unwrap();
        let RigCommand::Run(a) = cmd else {
            panic!("{cmd:?}")
        };
        assert!((a.catch_window - 12f64.to_radians()).abs() < 1e-15);
        assert_eq!(
            a.swing_up,
            SwingUpLimits {
                hanging_window_rad: 0.5,
                max_arm_speed: 20.0,
                max_pendulum_speed: 15.0
            }
        );
        let RigCommand::Run(d) = RigArgs::parse(Vec::<String>::new()).unwrap() else {
            panic!()
        };
        assert_eq!(d.catch_window, SupervisorConfig::default().catch_window_rad);
        assert_eq!(d.swing_up, SwingUpLimits::default());
    }

    #[test]
    fn bad_options_are_usage_errors() {
        for bad in [
            &["--rate", "-3"][..],
            &["--backend", "usb"],
            &["--gain", "a"],
            &["--gain", "a=x"],
            &["--duration"],
            &["--bogus", "1"],
            &["stray"],
            &["--force=yes"],
            &["--sim-noise", "counts=-1"],
            &["--catch-window", "-1deg"],
            &["--max-arm-speed", "0"],
        ] {
            let e = RigArgs::parse(bad.iter().copied()).unwrap_err();
            assert_eq!(e.exit_code(), 2, "{bad:?}: {e}");
        }
    }
}
