//! Synthetic measurement data with hidden effects (`plantc synth`).
//!
//! The *true* model is the given model text with
//!
//! - each hidden effect added through [`EffectInstance::with_values`] and
//!   [`EffectInstance::apply`] (so every effect `effect_edit` knows works here
//!   without change), and
//! - the true parameter values written into the text with the lossless editor
//!   (`lang::edit::set_parameter_value`).
//!
//! Each experiment is then simulated with the identification [`Simulator`]
//! (fixed-step RK4, zero-order-hold input) on a finer substep
//! ([`SynthOptions::substep`], 0.1 ms by default, against the 2 ms the fits
//! use), sampled at [`SynthOptions::rate`], optionally disturbed by seeded
//! Gaussian noise and quantised like an encoder. Dry friction sticks
//! ([`SynthOptions::friction`]: a joint at rest stays at rest under a force
//! below its static level, as on a real rig); `smooth:WIDTH` makes data with
//! the smooth `tanh(v / WIDTH)` law of earlier versions instead.
//!
//! **Quantisation** rounds each angle to the *nearest* count,
//! `q * round(x / q)` with `q = 2 pi / counts`: the error of a correct model is
//! then zero-mean and uniform on `[-q/2, q/2]`, RMS `q / sqrt(12)` (4.4e-4 rad
//! for 4096 counts/rev). Truncation (`floor`) would add a bias of `q/2` and make
//! the RMS `q / sqrt(3)`. Only angle coordinates are quantised; lengths keep
//! their value (plus noise). Noise is added *before* quantisation, so the data
//! stay on the encoder grid.
//!
//! **Initial state.** The initial coordinates given are the *true* ones, and
//! the initial velocities are zero. The simulator reads the initial state from
//! the first recorded sample; for a hidden `sensor_offset` the recorded angle
//! is the true one plus the offset, so that offset is added to the first
//! sample handed to the simulator.
//!
//! **Samples.** An experiment of duration `D` at rate `r` has `round(D r)`
//! samples at `t = k / r`, `k = 0 .. round(D r) - 1` (20 s at 500 Hz: 10 000
//! samples, the last at 19.998 s), like the shared recordings; a multisine
//! then covers exactly one period of its frequency grid `1/D`.
//!
//! **truth.json** has the shape of the shared recordings' one: `case`,
//! `effect` and `coordinate` (the effect's name and target, which may be an
//! input or a sensor; `null` without effect, arrays with several),
//! `effect_parameters` (by base name, e.g. `Fc`; by model name, e.g.
//! `Fc_alpha`, with several effects), `true_parameters` and
//! `nominal_parameters` (the model's own parameters, SI), `sample_rate_hz`,
//! `encoder_counts_per_rev` (`null` without quantisation) and `experiments`
//! (file stems); then `effects` (each with its target and parameters),
//! `noise_std`, `seed`, `substep_s`, `dry_friction` (`sticking` or
//! `smooth:WIDTH`), `model` and `experiment_specs`, enough to make the data
//! again.
//!
//! **Determinism.** Noise and multisine phases come from a SplitMix64
//! generator seeded from [`SynthOptions::seed`] and the experiment's index;
//! numbers are written with fixed decimals; the same inputs give the same
//! bytes.

use std::f64::consts::PI;
use std::fmt;

use plantc_derive::lang::edit;
use plantc_derive::lang::units::parse_unit;
use plantc_derive::model::{load_model_text, CoordinateKind, Model, ParameterValues};
use serde::ser::{Serialize, SerializeMap, Serializer};

use crate::effect_edit::{templates, EffectEditError, EffectInstance, TEMPLATES};
use crate::experiment_sim::{
    DryFriction, InitialVelocity, Signals, SimError, SimOptions, Simulator,
};

/// Why synthetic data cannot be made.
#[derive(Clone, Debug, PartialEq)]
pub enum SynthError {
    /// A specification token (`--effect`, `--experiment`, `--set`) is malformed.
    BadSpec {
        /// The token as given.
        token: String,
        /// What is wrong.
        message: String,
        /// How to write it.
        help: String,
    },
    /// An effect cannot be built on this model.
    Effect {
        /// The `--effect` token.
        token: String,
        /// Why.
        error: EffectEditError,
    },
    /// The model text (original or made true) does not check.
    Model {
        /// The rendered error messages.
        messages: Vec<String>,
    },
    /// A value could not be written into the model text.
    Edit {
        /// The parameter.
        name: String,
        /// The editor's message.
        message: String,
    },
    /// A generated input leaves the input's limits.
    InputLimit {
        /// The experiment.
        experiment: String,
        /// The input.
        input: String,
        /// Largest |value| generated.
        peak: f64,
        /// The limits.
        limits: (f64, f64),
    },
    /// The simulation failed.
    Sim(SimError),
}

impl fmt::Display for SynthError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SynthError::BadSpec {
                token,
                message,
                help,
            } => write!(f, "`{token}`: {message}\n  help: {help}"),
            SynthError::Effect { token, error } => write!(f, "`{token}`: {error}"),
            SynthError::Model { messages } => {
                write!(f, "the model is invalid: {}", messages.join("; "))
            }
            SynthError::Edit { name, message } => {
                write!(f, "cannot set `{name}` in the model text: {message}")
            }
            SynthError::InputLimit {
                experiment,
                input,
                peak,
                limits,
            } => write!(
                f,
                "experiment `{experiment}`: input `{input}` reaches {peak:.3}, outside its limits [{}, {}]\n  help: lower `rms=` or `amplitude=`",
                limits.0, limits.1
            ),
            SynthError::Sim(e) => write!(f, "simulation failed: {e}"),
        }
    }
}

impl std::error::Error for SynthError {}

impl From<SimError> for SynthError {
    fn from(e: SimError) -> Self {
        SynthError::Sim(e)
    }
}

fn bad(token: &str, message: impl Into<String>, help: impl Into<String>) -> SynthError {
    SynthError::BadSpec {
        token: token.to_string(),
        message: message.into(),
        help: help.into(),
    }
}

/// A hidden effect: `effect:target=value` or `effect:target:a=1,b=2`.
#[derive(Clone, Debug, PartialEq)]
pub struct EffectSpec {
    /// The token as given.
    pub token: String,
    /// Effect name.
    pub effect: String,
    /// Coordinate, input or sensor it acts on.
    pub target: String,
    /// Parameter values by base name, in SI (the template unit).
    pub values: Vec<(String, f64)>,
}

const EFFECT_HELP: &str =
    "write `effect:target=value` (one parameter) or `effect:target:Fc=8e-4,Fs=1.2e-3,vs=0.1`";

/// Parses an `--effect` token (effect and target names are checked later,
/// against the model, by [`synthesize`]).
pub fn parse_effect_spec(token: &str) -> Result<EffectSpec, SynthError> {
    let known = || {
        TEMPLATES
            .iter()
            .map(|(n, _, _)| *n)
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut parts = token.splitn(3, ':');
    let effect = parts.next().unwrap_or("").trim();
    let Some(rest) = parts.next() else {
        return Err(bad(
            token,
            "no target",
            format!("{EFFECT_HELP}; known effects: {}", known()),
        ));
    };
    let Some((_, temps)) = templates(effect) else {
        return Err(bad(
            token,
            format!("unknown effect `{effect}`"),
            format!("known effects: {}", known()),
        ));
    };
    let bases: Vec<&str> = temps.iter().map(|t| t.base).collect();
    let (target, values) = match parts.next() {
        Some(list) => {
            let mut values = Vec::new();
            for item in list.split(',').map(str::trim) {
                let (name, value) = item.split_once('=').ok_or_else(|| {
                    bad(
                        token,
                        format!("`{item}` is not NAME=VALUE"),
                        format!("parameters of `{effect}`: {}", bases.join(", ")),
                    )
                })?;
                let name = name.trim();
                if !bases.contains(&name) {
                    return Err(bad(
                        token,
                        format!("`{effect}` has no parameter `{name}`"),
                        format!("parameters of `{effect}`: {}", bases.join(", ")),
                    ));
                }
                if values.iter().any(|(n, _)| n == name) {
                    return Err(bad(token, format!("`{name}` given twice"), EFFECT_HELP));
                }
                values.push((name.to_string(), number(token, value)?));
            }
            (rest.trim(), values)
        }
        None => {
            let (target, value) = rest.split_once('=').ok_or_else(|| {
                bad(
                    token,
                    "no parameter value",
                    format!(
                        "{EFFECT_HELP}; parameters of `{effect}`: {}",
                        bases.join(", ")
                    ),
                )
            })?;
            if bases.len() != 1 {
                return Err(bad(
                    token,
                    format!(
                        "`{effect}` has {} parameters ({}): name them",
                        bases.len(),
                        bases.join(", ")
                    ),
                    format!(
                        "e.g. `{effect}:{}:{}`",
                        target.trim(),
                        bases
                            .iter()
                            .map(|b| format!("{b}=..."))
                            .collect::<Vec<_>>()
                            .join(",")
                    ),
                ));
            }
            (
                target.trim(),
                vec![(bases[0].to_string(), number(token, value)?)],
            )
        }
    };
    if target.is_empty() {
        return Err(bad(token, "empty target", EFFECT_HELP));
    }
    let missing: Vec<&str> = bases
        .iter()
        .copied()
        .filter(|b| !values.iter().any(|(n, _)| n == b))
        .collect();
    if !missing.is_empty() {
        return Err(bad(
            token,
            format!("missing value(s) for {}", missing.join(", ")),
            format!("parameters of `{effect}`: {}", bases.join(", ")),
        ));
    }
    Ok(EffectSpec {
        token: token.to_string(),
        effect: effect.to_string(),
        target: target.to_string(),
        values,
    })
}

/// A number with an optional unit suffix, in SI: `deg`, `rad`, `s`, `ms`,
/// `Hz`, `V`, `mV` (the suffix is not checked against the quantity).
pub fn parse_quantity(text: &str) -> Option<f64> {
    let t = text.trim();
    let suffixes: [(&str, f64); 7] = [
        ("deg", PI / 180.0),
        ("rad", 1.0),
        ("ms", 1e-3),
        ("mV", 1e-3),
        ("Hz", 1.0),
        ("s", 1.0),
        ("V", 1.0),
    ];
    for (s, f) in suffixes {
        if let Some(n) = t.strip_suffix(s) {
            return n.trim().parse::<f64>().ok().map(|v| v * f);
        }
    }
    t.parse().ok()
}

fn number(token: &str, text: &str) -> Result<f64, SynthError> {
    parse_quantity(text)
        .filter(|v| v.is_finite())
        .ok_or_else(|| {
            bad(
                token,
                format!("`{}` is not a number", text.trim()),
                "numbers are in SI, or with a suffix: 120deg, 20s, 500ms, 6Hz, 1.5V",
            )
        })
}

/// What an experiment does with the input.
#[derive(Clone, Debug, PartialEq)]
pub enum ExperimentKind {
    /// Zero input: released from the initial coordinates.
    FreeSwing,
    /// A zero-mean multisine on one input.
    Driven {
        /// Input name (default: the model's first input).
        input: Option<String>,
        /// Lowest frequency, Hz.
        f_lo: f64,
        /// Highest frequency, Hz.
        f_hi: f64,
        /// RMS in the input's SI unit.
        rms: f64,
        /// Seed of the phases (default: from the global seed and the index).
        seed: Option<u64>,
    },
    /// A step on one input.
    Step {
        /// Input name (default: the model's first input).
        input: Option<String>,
        /// Step height in the input's SI unit.
        amplitude: f64,
        /// Step time, s.
        at: f64,
    },
}

impl ExperimentKind {
    /// `free_swing`, `driven` or `step`.
    pub fn name(&self) -> &'static str {
        match self {
            ExperimentKind::FreeSwing => "free_swing",
            ExperimentKind::Driven { .. } => "driven",
            ExperimentKind::Step { .. } => "step",
        }
    }
}

/// One experiment to synthesise.
#[derive(Clone, Debug, PartialEq)]
pub struct ExperimentSpec {
    /// The token as given.
    pub token: String,
    /// What happens.
    pub kind: ExperimentKind,
    /// File name (without `.csv`), if given.
    pub name: Option<String>,
    /// True initial coordinates, SI, by coordinate name (`alpha0=120deg`).
    pub initial: Vec<(String, f64)>,
    /// Length, s.
    pub duration: f64,
}

const EXPERIMENT_HELP: &str = "write `free_swing:alpha0=120deg,duration=20`, `driven:alpha0=180deg,band=0.3-6,rms=1.5,seed=1,duration=20` or `step:amplitude=1,at=0.5,duration=5`";

/// Parses an `--experiment` token; coordinate names are checked by
/// [`synthesize`].
pub fn parse_experiment_spec(token: &str) -> Result<ExperimentSpec, SynthError> {
    let (kind, rest) = match token.split_once(':') {
        Some((k, r)) => (k.trim(), r),
        None => (token.trim(), ""),
    };
    let keys: &[&str] = match kind {
        "free_swing" => &["duration", "name"],
        "driven" => &["duration", "name", "band", "rms", "seed", "input"],
        "step" => &["duration", "name", "amplitude", "at", "input"],
        _ => {
            return Err(bad(
                token,
                format!("unknown experiment kind `{kind}`"),
                format!("known kinds: free_swing, driven, step; {EXPERIMENT_HELP}"),
            ))
        }
    };
    let mut spec = ExperimentSpec {
        token: token.to_string(),
        kind: ExperimentKind::FreeSwing,
        name: None,
        initial: Vec::new(),
        duration: 20.0,
    };
    let (mut f_lo, mut f_hi, mut rms, mut seed, mut input) = (0.3, 6.0, 1.5, None, None);
    let (mut amplitude, mut at) = (1.0, 0.0);
    let mut seen: Vec<String> = Vec::new();
    for item in rest.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let (key, value) = item
            .split_once('=')
            .ok_or_else(|| bad(token, format!("`{item}` is not KEY=VALUE"), EXPERIMENT_HELP))?;
        let (key, value) = (key.trim(), value.trim());
        if seen.iter().any(|k| k == key) {
            return Err(bad(token, format!("`{key}` given twice"), EXPERIMENT_HELP));
        }
        seen.push(key.to_string());
        match key {
            _ if !keys.contains(&key) && key.ends_with('0') && key.len() > 1 => {
                spec.initial
                    .push((key[..key.len() - 1].to_string(), number(token, value)?));
            }
            "duration" => spec.duration = number(token, value)?,
            "name" => {
                let ok = !value.is_empty()
                    && value
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
                if !ok {
                    return Err(bad(
                        token,
                        format!("bad name `{value}`"),
                        "a file name of letters, digits, `_` or `-`",
                    ));
                }
                spec.name = Some(value.to_string());
            }
            "band" => {
                let (a, b) = value.split_once('-').ok_or_else(|| {
                    bad(
                        token,
                        format!("bad band `{value}`"),
                        "e.g. `band=0.3-6` (Hz)",
                    )
                })?;
                f_lo = number(token, a)?;
                f_hi = number(token, b)?;
                if !(f_lo > 0.0 && f_hi >= f_lo) {
                    return Err(bad(
                        token,
                        format!("band `{value}` must have 0 < low <= high"),
                        "e.g. `band=0.3-6` (Hz)",
                    ));
                }
            }
            "rms" => rms = number(token, value)?,
            "seed" => {
                seed = Some(value.parse::<u64>().map_err(|_| {
                    bad(
                        token,
                        format!("seed `{value}` is not a non-negative integer"),
                        EXPERIMENT_HELP,
                    )
                })?)
            }
            "input" => input = Some(value.to_string()),
            "amplitude" => amplitude = number(token, value)?,
            "at" => at = number(token, value)?,
            _ => {
                return Err(bad(
                    token,
                    format!("`{kind}` has no setting `{key}`"),
                    format!(
                        "settings of `{kind}`: {}, and initial coordinates `<coordinate>0=<value>`",
                        keys.join(", ")
                    ),
                ))
            }
        }
    }
    if !(spec.duration > 0.0 && spec.duration.is_finite()) {
        return Err(bad(
            token,
            format!("duration {} must be positive", spec.duration),
            EXPERIMENT_HELP,
        ));
    }
    if rms < 0.0 {
        return Err(bad(token, "rms must not be negative", EXPERIMENT_HELP));
    }
    spec.kind = match kind {
        "free_swing" => ExperimentKind::FreeSwing,
        "driven" => ExperimentKind::Driven {
            input,
            f_lo,
            f_hi,
            rms,
            seed,
        },
        _ => ExperimentKind::Step {
            input,
            amplitude,
            at,
        },
    };
    Ok(spec)
}

/// Sampling and measurement settings.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthOptions {
    /// Sample rate, Hz.
    pub rate: f64,
    /// Encoder counts per revolution for angle coordinates (None: no
    /// quantisation).
    pub counts: Option<u32>,
    /// Standard deviation of the Gaussian noise added to each coordinate (SI).
    pub noise: f64,
    /// Seed of noise and default multisine phases.
    pub seed: u64,
    /// RK4 substep of the simulation, s.
    pub substep: f64,
    /// How the true model's dry friction acts (sticking by default).
    pub friction: DryFriction,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            rate: 500.0,
            counts: Some(4096),
            noise: 0.0,
            seed: 1,
            substep: 1e-4,
            friction: DryFriction::Sticking,
        }
    }
}

/// The dry-friction law of `plantc synth --friction`: `sticking` (stick-slip,
/// the default) or `smooth:WIDTH` (`sign(v)` as `tanh(v / WIDTH)`, WIDTH a
/// positive speed in the coordinate's SI unit, e.g. `smooth:1e-3`).
pub fn parse_friction(token: &str) -> Result<DryFriction, SynthError> {
    let bad = |message: &str| SynthError::BadSpec {
        token: token.to_string(),
        message: message.to_string(),
        help: "write `sticking` or `smooth:WIDTH` with WIDTH a positive speed, e.g. `smooth:1e-3`"
            .to_string(),
    };
    match token.trim() {
        "sticking" => Ok(DryFriction::Sticking),
        t => match t.strip_prefix("smooth:") {
            Some(w) => match w.trim().parse::<f64>() {
                Ok(width) if width > 0.0 && width.is_finite() => Ok(DryFriction::Smooth { width }),
                _ => Err(bad("the smoothing width must be a positive number")),
            },
            None => Err(bad("unknown dry-friction law")),
        },
    }
}

/// How truth.json writes a dry-friction law: `sticking` or `smooth:WIDTH`.
pub fn friction_name(law: DryFriction) -> String {
    match law {
        DryFriction::Sticking => "sticking".to_string(),
        DryFriction::Smooth { width } => format!("smooth:{width:e}"),
        DryFriction::SmoothFitted { .. } => "smooth:fitted".to_string(),
    }
}

/// Everything [`synthesize`] needs besides the model text.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct SynthSpec {
    /// The data set's name (`case` in truth.json).
    pub case: String,
    /// The model file's name, recorded in truth.json.
    pub model_name: String,
    /// Hidden effects.
    pub effects: Vec<EffectSpec>,
    /// A named parameter set of the model to start from.
    pub parameter_set: Option<String>,
    /// True parameter values (SI) overriding the model's.
    pub values: Vec<(String, f64)>,
    /// The experiments.
    pub experiments: Vec<ExperimentSpec>,
    /// Sampling and measurement.
    pub options: SynthOptions,
}

/// One generated file.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthFile {
    /// File name, e.g. `free_swing.csv`.
    pub file_name: String,
    /// Its content.
    pub text: String,
}

/// The result of [`synthesize`].
#[derive(Clone, Debug, PartialEq)]
pub struct Synthesized {
    /// One CSV per experiment, in the order given.
    pub files: Vec<SynthFile>,
    /// `truth.json`.
    pub truth: String,
    /// The true model text (effects added, true values written).
    pub true_model: String,
}

/// A map serialised in insertion order.
struct Ordered<'a, V: Serialize>(&'a [(String, V)]);

impl<V: Serialize> Serialize for Ordered<'_, V> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in self.0 {
            m.serialize_entry(k, v)?;
        }
        m.end()
    }
}

#[derive(serde::Serialize)]
struct EffectTruth<'a> {
    effect: &'a str,
    target: &'a str,
    parameters: Ordered<'a, f64>,
}

#[derive(serde::Serialize)]
struct Truth<'a> {
    case: &'a str,
    effect: serde_json::Value,
    coordinate: serde_json::Value,
    effect_parameters: Ordered<'a, f64>,
    true_parameters: Ordered<'a, f64>,
    nominal_parameters: Ordered<'a, f64>,
    sample_rate_hz: f64,
    encoder_counts_per_rev: Option<u32>,
    experiments: Vec<&'a str>,
    effects: Vec<EffectTruth<'a>>,
    noise_std: f64,
    seed: u64,
    substep_s: f64,
    dry_friction: String,
    model: &'a str,
    experiment_specs: Vec<&'a str>,
}

/// SplitMix64: a small, well-mixed 64-bit generator (enough for noise and
/// phases; deterministic across platforms).
struct SplitMix(u64);

impl SplitMix {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in (0, 1).
    fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Standard normal (Box-Muller, one value per call).
    fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
    }
}

fn stream(seed: u64, experiment: usize, purpose: u64) -> SplitMix {
    let mut s = SplitMix(seed ^ purpose.wrapping_mul(0xA076_1D64_78BD_642F));
    for _ in 0..=experiment {
        s.next_u64();
    }
    SplitMix(s.next_u64())
}

/// `v` with `d` decimals, without a minus sign on a zero (`-0.000`).
fn fixed(v: f64, d: usize) -> String {
    let s = format!("{v:.d$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.bytes().all(|b| b == b'0' || b == b'.') => rest.to_string(),
        _ => s,
    }
}

/// Decimals that write `k / rate` exactly (4 to 9).
fn time_decimals(rate: f64) -> usize {
    (4..=9)
        .find(|&d| {
            let x = 10f64.powi(d as i32) / rate;
            (x - x.round()).abs() < 1e-9
        })
        .unwrap_or(9)
}

/// Most components of a multisine: the cost is samples x components, and
/// the number of multiples of `1/duration` in the band grows with the
/// duration (a 2000 s experiment has 11,400 in 0.3-6 Hz: hours of work).
/// Longer experiments space their components by `m/duration` instead, which
/// repeats the multisine `m` times over the record (same band, same
/// amplitudes): linear in the duration.
pub const MAX_MULTISINE_COMPONENTS: usize = 512;

/// The frequency step and the first and last multiple of it in the band
/// (see [`MAX_MULTISINE_COMPONENTS`]).
fn multisine_grid(duration: f64, f_lo: f64, f_hi: f64) -> (f64, usize, usize) {
    let count = |df: f64| {
        let k_lo = (f_lo / df - 1e-9).ceil().max(1.0) as usize;
        let k_hi = (f_hi / df + 1e-9).floor() as usize;
        (k_lo, k_hi)
    };
    let mut df = 1.0 / duration;
    let (k_lo, k_hi) = count(df);
    let fitting = (k_hi + 1).saturating_sub(k_lo);
    if fitting > MAX_MULTISINE_COMPONENTS {
        df *= fitting.div_ceil(MAX_MULTISINE_COMPONENTS) as f64;
    }
    let (k_lo, k_hi) = count(df);
    (df, k_lo, k_hi)
}

/// The zero-mean multisine: components at multiples of `1/duration` in
/// `[f_lo, f_hi]` (of `m/duration` when more than
/// [`MAX_MULTISINE_COMPONENTS`] would fit) with equal amplitude and seeded
/// random phases, scaled so that the RMS over the samples is `rms`.
fn multisine(
    t: &[f64],
    duration: f64,
    f_lo: f64,
    f_hi: f64,
    rms: f64,
    rng: &mut SplitMix,
    token: &str,
) -> Result<Vec<f64>, SynthError> {
    let (df, k_lo, k_hi) = multisine_grid(duration, f_lo, f_hi);
    if k_hi < k_lo {
        return Err(bad(
            token,
            format!(
                "no multisine component fits in the band: the frequency resolution is 1/duration = {df} Hz"
            ),
            "widen the band or lengthen the experiment",
        ));
    }
    let comps: Vec<(f64, f64)> = (k_lo..=k_hi)
        .map(|k| (2.0 * PI * k as f64 * df, 2.0 * PI * rng.uniform()))
        .collect();
    let mut u: Vec<f64> = t
        .iter()
        .map(|&tk| comps.iter().map(|(w, ph)| (w * tk + ph).sin()).sum())
        .collect();
    let mean = u.iter().sum::<f64>() / u.len() as f64;
    u.iter_mut().for_each(|v| *v -= mean);
    let r = (u.iter().map(|v| v * v).sum::<f64>() / u.len() as f64).sqrt();
    if r > 0.0 {
        u.iter_mut().for_each(|v| *v *= rms / r);
    }
    Ok(u)
}

fn check_model(name: &str, text: &str) -> Result<Model, SynthError> {
    load_model_text(name, text)
        .map(|l| l.model)
        .map_err(|e| SynthError::Model {
            messages: vec![e.render()],
        })
}

/// Writes an SI value into the text as a literal in the parameter's declared
/// unit.
fn write_value(text: &str, model: &Model, name: &str, si: f64) -> Result<String, SynthError> {
    let err = |message: String| SynthError::Edit {
        name: name.to_string(),
        message,
    };
    let Some(p) = model.parameters.iter().find(|p| p.name == name) else {
        let known: Vec<&str> = model.parameters.iter().map(|p| p.name.as_str()).collect();
        return Err(bad(
            &format!("{name}={si}"),
            format!("the model has no parameter `{name}`"),
            format!("parameters: {}", known.join(", ")),
        ));
    };
    let scale = parse_unit(&p.unit)
        .map(|u| u.scale.to_f64())
        .map_err(|e| err(e.message))?;
    edit::set_parameter_value(text, name, &edit::number_text(si / scale))
        .map_err(|e| err(e.to_string()))
}

/// File names (without `.csv`): the kind, numbered from 1 when a kind
/// repeats (`free_swing_1`, `free_swing_2`), unless named with `name=`.
pub fn file_names(specs: &[ExperimentSpec]) -> Result<Vec<String>, SynthError> {
    let mut names = Vec::new();
    for (i, s) in specs.iter().enumerate() {
        let name = match &s.name {
            Some(n) => n.clone(),
            None => {
                let kind = s.kind.name();
                let same: Vec<usize> = specs
                    .iter()
                    .enumerate()
                    .filter(|(_, o)| o.name.is_none() && o.kind.name() == kind)
                    .map(|(j, _)| j)
                    .collect();
                if same.len() > 1 {
                    let idx = same.iter().position(|&j| j == i).unwrap_or(0) + 1;
                    format!("{kind}_{idx}")
                } else {
                    kind.to_string()
                }
            }
        };
        if names.contains(&name) {
            return Err(bad(
                &s.token,
                format!("two experiments are named `{name}`"),
                "give each a distinct `name=`",
            ));
        }
        names.push(name);
    }
    Ok(names)
}

/// Builds the true model and synthesises every experiment (see the module
/// docs).
pub fn synthesize(model_text: &str, spec: &SynthSpec) -> Result<Synthesized, SynthError> {
    let opts = &spec.options;
    if !(opts.rate > 0.0 && opts.rate.is_finite()) {
        return Err(bad(
            &format!("--rate {}", opts.rate),
            "the sample rate must be positive",
            "e.g. `--rate 500`",
        ));
    }
    if !(opts.substep > 0.0 && opts.substep.is_finite()) {
        return Err(bad(
            &format!("substep {}", opts.substep),
            "the substep must be positive",
            "e.g. 1e-4 s",
        ));
    }
    if !(opts.noise >= 0.0 && opts.noise.is_finite()) {
        return Err(bad(
            &format!("--noise {}", opts.noise),
            "the noise must be a non-negative number",
            "e.g. `--noise 1e-4` (rad)",
        ));
    }
    if opts.counts == Some(0) {
        return Err(bad(
            "--counts 0",
            "an encoder needs at least one count per revolution",
            "leave `--counts` out for no quantisation",
        ));
    }
    if spec.experiments.is_empty() {
        return Err(bad("", "no experiment given", EXPERIMENT_HELP));
    }
    let nominal = check_model(&spec.model_name, model_text)?;

    // True parameter values: the set, then the overrides.
    let true_values =
        ParameterValues::new(&nominal, spec.parameter_set.as_deref(), &[]).map_err(|e| {
            bad(
                &format!("--set {}", spec.parameter_set.clone().unwrap_or_default()),
                e.to_string(),
                if nominal.sets.is_empty() {
                    "the model defines no named sets; give single values as NAME=VALUE".to_string()
                } else {
                    format!(
                        "named sets of the model: {}",
                        nominal
                            .sets
                            .iter()
                            .map(|s| s.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                },
            )
        })?;
    let mut text = model_text.to_string();
    for (p, (&v, &nominal_v)) in nominal.parameters.iter().zip(
        true_values
            .base
            .iter()
            .zip(nominal.parameters.iter().map(|p| &p.value)),
    ) {
        if v != nominal_v {
            text = write_value(&text, &nominal, &p.name, v)?;
        }
    }
    for (name, v) in &spec.values {
        if !v.is_finite() {
            return Err(bad(
                &format!("{name}={v}"),
                "the value must be finite",
                "e.g. `--set J1=1.6e-3`",
            ));
        }
        text = write_value(&text, &nominal, name, *v)?;
    }
    // Hidden effects.
    let mut instances = Vec::new();
    for e in &spec.effects {
        let current = check_model(&spec.model_name, &text)?;
        let inst = EffectInstance::with_values(&current, &e.effect, &e.target, &e.values).map_err(
            |error| SynthError::Effect {
                token: e.token.clone(),
                error,
            },
        )?;
        text = inst.apply(&text).map_err(|error| SynthError::Effect {
            token: e.token.clone(),
            error,
        })?;
        instances.push(inst);
    }
    let model = check_model(&spec.model_name, &text)?;
    let values = ParameterValues::new(&model, None, &[]).map_err(|e| SynthError::Model {
        messages: vec![e.to_string()],
    })?;
    let sim = Simulator::new(
        &model,
        SimOptions {
            substep: Some(opts.substep),
            dry_friction: opts.friction,
            initial_velocity: InitialVelocity::Zero,
        },
    )?;

    let names = file_names(&spec.experiments)?;
    let coord_names: Vec<&str> = model.coordinates.iter().map(|c| c.name.as_str()).collect();
    let input_names: Vec<&str> = model.inputs.iter().map(|i| i.name.as_str()).collect();
    let header: Vec<&str> = std::iter::once("t")
        .chain(coord_names.iter().copied())
        .chain(input_names.iter().copied())
        .collect();
    let t_dec = time_decimals(opts.rate);
    let mut files = Vec::new();
    for (idx, (e, name)) in spec.experiments.iter().zip(&names).enumerate() {
        // true initial coordinates
        let mut x0 = vec![0.0; model.coordinates.len()];
        for (c, v) in &e.initial {
            let Some(i) = coord_names.iter().position(|n| n == c) else {
                return Err(bad(
                    &e.token,
                    format!("`{c}0`: the model has no coordinate `{c}`"),
                    format!(
                        "initial coordinates: {}",
                        coord_names
                            .iter()
                            .map(|n| format!("{n}0"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            };
            x0[i] = *v;
        }
        let n = (e.duration * opts.rate).round() as usize;
        if n < 2 {
            return Err(bad(
                &e.token,
                "shorter than one sample interval",
                "lengthen the experiment or raise `--rate`",
            ));
        }
        let t_text: Vec<String> = (0..n).map(|k| fixed(k as f64 / opts.rate, t_dec)).collect();
        let t: Vec<f64> = t_text
            .iter()
            .map(|s| s.parse().unwrap_or(f64::NAN))
            .collect();
        // inputs, rounded to what the file holds
        let mut u = vec![vec![0.0; n]; model.inputs.len()];
        let pick_input = |given: &Option<String>| -> Result<usize, SynthError> {
            match given {
                None if !model.inputs.is_empty() => Ok(0),
                None => Err(bad(
                    &e.token,
                    "the model has no input to drive",
                    "use `free_swing`",
                )),
                Some(g) => input_names.iter().position(|n| n == g).ok_or_else(|| {
                    bad(
                        &e.token,
                        format!("the model has no input `{g}`"),
                        format!("inputs: {}", input_names.join(", ")),
                    )
                }),
            }
        };
        match &e.kind {
            ExperimentKind::FreeSwing => {}
            ExperimentKind::Driven {
                input,
                f_lo,
                f_hi,
                rms,
                seed,
            } => {
                let j = pick_input(input)?;
                let mut rng = match seed {
                    Some(s) => SplitMix(*s),
                    None => stream(opts.seed, idx, 1),
                };
                u[j] = multisine(&t, e.duration, *f_lo, *f_hi, *rms, &mut rng, &e.token)?;
            }
            ExperimentKind::Step {
                input,
                amplitude,
                at,
            } => {
                let j = pick_input(input)?;
                for (k, &tk) in t.iter().enumerate() {
                    if tk >= *at {
                        u[j][k] = *amplitude;
                    }
                }
            }
        }
        let u_text: Vec<Vec<String>> = u
            .iter()
            .map(|col| col.iter().map(|v| fixed(*v, 6)).collect())
            .collect();
        for (col, txt) in u.iter_mut().zip(&u_text) {
            for (v, s) in col.iter_mut().zip(txt) {
                *v = s.parse().unwrap_or(f64::NAN);
            }
        }
        for (j, inp) in model.inputs.iter().enumerate() {
            if let Some((lo, hi)) = inp.limits {
                let (mn, mx) = u[j]
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                        (a.min(*v), b.max(*v))
                    });
                if mn < lo || mx > hi {
                    return Err(SynthError::InputLimit {
                        experiment: name.clone(),
                        input: inp.name.clone(),
                        peak: if mx > hi { mx } else { mn },
                        limits: (lo, hi),
                    });
                }
            }
        }
        // The first recorded sample: true initial coordinates, plus any
        // hidden sensor offset (the simulator takes the measured first
        // sample minus the offset as the true initial state).
        let mut first = x0.clone();
        for inst in &instances {
            if inst.effect == "sensor_offset" {
                if let (Some(i), Some(p)) = (
                    coord_names.iter().position(|c| *c == inst.target),
                    inst.parameters.first(),
                ) {
                    first[i] += p.value;
                }
            }
        }
        let sig = Signals {
            name: name.clone(),
            t: t.clone(),
            q: first.iter().map(|&v| vec![v; n]).collect(),
            u,
            replay: None,
        };
        let traj = sim.simulate(&sig, &values.full, n)?;
        let mut rng = stream(opts.seed, idx, 2);
        let q_step = opts.counts.map(|c| 2.0 * PI / c as f64);
        let mut q = traj.q;
        for (i, col) in q.iter_mut().enumerate() {
            let angle = model.coordinates[i].kind == CoordinateKind::Angle;
            for v in col.iter_mut() {
                if opts.noise > 0.0 {
                    *v += opts.noise * rng.normal();
                }
                if let (true, Some(s)) = (angle, q_step) {
                    *v = s * (*v / s).round();
                }
            }
        }
        let mut csv = header.join(",");
        csv.push('\n');
        for k in 0..n {
            csv.push_str(&t_text[k]);
            for col in &q {
                csv.push(',');
                csv.push_str(&fixed(col[k], 9));
            }
            for col in &u_text {
                csv.push(',');
                csv.push_str(&col[k]);
            }
            csv.push('\n');
        }
        files.push(SynthFile {
            file_name: format!("{name}.csv"),
            text: csv,
        });
    }

    // truth.json
    let nominal_params: Vec<(String, f64)> = nominal
        .parameters
        .iter()
        .map(|p| (p.name.clone(), p.value))
        .collect();
    let true_params: Vec<(String, f64)> = nominal
        .parameters
        .iter()
        .map(|p| {
            let v = model
                .parameters
                .iter()
                .find(|m| m.name == p.name)
                .map_or(p.value, |m| m.value);
            (p.name.clone(), v)
        })
        .collect();
    let eff_params: Vec<Vec<(String, f64)>> = instances
        .iter()
        .map(|i| {
            i.parameters
                .iter()
                .map(|p| (p.base.clone(), p.value))
                .collect()
        })
        .collect();
    let flat: Vec<(String, f64)> = if instances.len() == 1 {
        eff_params[0].clone()
    } else {
        instances
            .iter()
            .flat_map(|i| i.parameters.iter().map(|p| (p.name.clone(), p.value)))
            .collect()
    };
    let (effect, coordinate) = match instances.len() {
        0 => (serde_json::Value::Null, serde_json::Value::Null),
        1 => (
            instances[0].effect.clone().into(),
            instances[0].target.clone().into(),
        ),
        _ => (
            instances.iter().map(|i| i.effect.clone()).collect(),
            instances.iter().map(|i| i.target.clone()).collect(),
        ),
    };
    let truth = Truth {
        case: &spec.case,
        effect,
        coordinate,
        effect_parameters: Ordered(&flat),
        true_parameters: Ordered(&true_params),
        nominal_parameters: Ordered(&nominal_params),
        sample_rate_hz: opts.rate,
        encoder_counts_per_rev: opts.counts,
        experiments: names.iter().map(String::as_str).collect(),
        effects: instances
            .iter()
            .zip(&eff_params)
            .map(|(i, p)| EffectTruth {
                effect: &i.effect,
                target: &i.target,
                parameters: Ordered(p),
            })
            .collect(),
        noise_std: opts.noise,
        seed: opts.seed,
        substep_s: opts.substep,
        dry_friction: friction_name(opts.friction),
        model: &spec.model_name,
        experiment_specs: spec.experiments.iter().map(|e| e.token.as_str()).collect(),
    };
    let mut truth_text = serde_json::to_string_pretty(&truth).map_err(|e| SynthError::Model {
        messages: vec![e.to_string()],
    })?;
    truth_text.push('\n');
    Ok(Synthesized {
        files,
        truth: truth_text,
        true_model: text,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reliability reproducer 16b: the components of a 2000 s experiment made
    /// synth quadratic in the duration; they are capped (linear), and short
    /// experiments keep every multiple of 1/duration (the bundled data).
    #[test]
    fn multisine_components_are_capped_for_long_experiments() {
        let (df, lo, hi) = multisine_grid(20.0, 0.3, 6.0);
        assert_eq!((df, lo, hi), (0.05, 6, 120));
        let (df, lo, hi) = multisine_grid(2000.0, 0.3, 6.0);
        assert!(hi - lo < MAX_MULTISINE_COMPONENTS, "{lo}..{hi}");
        // an integer number of periods in the record, the same band
        let periods = 2000.0 * df;
        assert!((periods - periods.round()).abs() < 1e-9, "{periods}");
        assert!(lo as f64 * df >= 0.3 && hi as f64 * df <= 6.0 + 1e-9);
        assert!((lo as f64 - 1.0) * df < 0.3 && (hi as f64 + 1.0) * df > 6.0);
    }

    #[test]
    fn multisine_is_zero_mean_with_the_asked_rms() {
        let t: Vec<f64> = (0..5001).map(|k| k as f64 / 500.0).collect();
        let mut rng = SplitMix(3);
        let u = multisine(&t, 10.0, 0.3, 6.0, 1.5, &mut rng, "driven").unwrap();
        let n = u.len() as f64;
        let mean = u.iter().sum::<f64>() / n;
        let rms = (u.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
        assert!(mean.abs() < 1e-12, "mean {mean}");
        assert!((rms - 1.5).abs() < 1e-12, "rms {rms}");
        // a band narrower than the resolution 1/duration has no component
        let mut rng = SplitMix(3);
        assert!(multisine(&t, 10.0, 0.31, 0.32, 1.0, &mut rng, "x").is_err());
    }

    #[test]
    fn number_formats() {
        assert_eq!(time_decimals(500.0), 4);
        assert_eq!(time_decimals(1000.0), 4);
        assert_eq!(time_decimals(3.2e4), 8); // 1/32000 s = 0.00003125 s
        assert_eq!(fixed(-1e-12, 9), "0.000000000");
        assert_eq!(fixed(-0.5, 2), "-0.50");
    }

    #[test]
    fn gaussian_generator_has_unit_variance() {
        // 20 000 draws: the sample mean has standard error 1/sqrt(20000) = 0.007
        // and the sample variance about sqrt(2/20000) = 0.01; 5 sigma bounds.
        let mut g = stream(42, 0, 2);
        let x: Vec<f64> = (0..20_000).map(|_| g.normal()).collect();
        let m = x.iter().sum::<f64>() / x.len() as f64;
        let v = x.iter().map(|a| (a - m).powi(2)).sum::<f64>() / x.len() as f64;
        assert!(m.abs() < 0.035, "mean {m}");
        assert!((v - 1.0).abs() < 0.05, "variance {v}");
    }

    #[test]
    fn effect_specs() {
        let e = parse_effect_spec("coulomb_friction:alpha=8e-4").unwrap();
        assert_eq!(
            (e.effect.as_str(), e.target.as_str()),
            ("coulomb_friction", "alpha")
        );
        assert_eq!(e.values, vec![("Fc".to_string(), 8e-4)]);
        let e = parse_effect_spec("stribeck_friction:alpha:Fc=8e-4,Fs=1.2e-3,vs=0.1").unwrap();
        assert_eq!(e.values.len(), 3);
        let x = parse_experiment_spec("free_swing:alpha0=120deg,duration=20").unwrap();
        assert_eq!(x.initial, vec![("alpha".to_string(), 120f64.to_radians())]);
        assert_eq!(x.duration, 20.0);
    }
}
