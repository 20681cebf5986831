//! Simulation of a model over a measured experiment (single shooting).
//!
//! The initial state comes from the data (coordinates at `t0`, velocities zero
//! or estimated), the measured input is applied with a zero-order hold
//! (`u[k]` acts over `[t_k, t_{k+1})`, which is how the rig's DAC works; using
//! `u` at the sample instant instead shows up as a false ~1 ms delay), and a
//! fixed-step RK4 with substeps aligned to the samples produces the
//! coordinates at the sample instants.
//!
//! The dynamics are one compiled [`Tape`] producing `[M (n*n), r0 (n), B (n*m)]`
//! over `(state, inputs, full parameters)`, with `r0 = Q0 - bias` the
//! right-hand side without input; `M a = r0 + B u` is solved by a small LU
//! with partial pivoting in preallocated buffers (no allocation per step).
//! The tape is split ([`Tape::split_by_inputs`]) so that its parameter-only
//! part runs once per simulation rather than at every RK4 stage (same
//! instructions, so bit-identical results).
//!
//! Sensor and actuator effects of the model are honoured here (the plant
//! equations cannot hold them; see `plantc_derive::model::Model`):
//! - `sensor q = sensor_offset(d)`: the simulated measurement is `q + d`, and
//!   the true initial coordinate is the measured one minus `d`;
//! - `actuator u = input_delay(Td)` (`Td >= 0`): the held input `u[k]` acts
//!   over `[t_k + Td, t_{k+1} + Td)`; before `t_0 + Td` the plant receives
//!   `u[0]` (the input before the experiment is taken as its first sample,
//!   i.e. the rig was holding it). The RK4 substeps are split at the switch
//!   instants, so no step straddles an input change; a switch within 1e-9 of
//!   a sample interval of a sample instant is taken at that instant.
//! - `actuator u = deadzone(w)` (`w >= 0`): the plant receives
//!   `dz(u[k]) = sign(u[k]) * max(|u[k]| - w, 0)`; since the input is held,
//!   the deadzone acts per sample on the commanded value ([`deadzone`]).
//! - `actuator u = saturation(L)` (`L > 0`): the plant receives
//!   `sat(u[k]) = min(max(u[k], -L), L)`, per held sample like the deadzone
//!   ([`saturation`]): a drive's voltage or current limit.
//! - `input_offset` is already folded into the model's forces.
//!
//! Composition order on one input, whatever the order of the lines: the
//! deadzone acts on the commanded samples, the saturation on its result, the
//! delay then shifts the held result in time, and the offset (in the forces)
//! is added to what arrives: the plant receives `sat(dz(u))(t - Td) + V0`.
//! With `w = 0` and no saturation the held input is the commanded one, so
//! the simulation is bit-identical to the model without them.
//!
//! **Dry friction sticks** ([`DryFriction::Sticking`], the default): each
//! coordinate's force is split into a smooth part and `-D_i sign(q_i')`
//! (`plantc_derive::mechanics::dry_friction`), and the simulation switches
//! between sliding and sticking (`plantc_derive::mechanics::stick_slip`): a
//! joint at `q' = 0.0` stays there while the force needed to hold it is
//! within its static level, and breaks away above it. The mode is a function
//! of the state, fixed over each RK4 step; a step that would cross a switch
//! (a sliding joint's velocity reaching zero, a stuck joint's holding force
//! reaching its level) is cut at the switch, located by Illinois iterations
//! on the step length, and the rest of the segment continues from there as
//! a new segment (see `integrate`). The RK4 step is then limited by
//! accuracy only: one substep per sample up to [`MAX_SUBSTEP`].
//!
//! **Spans.** Where every input holds its value over several sample
//! intervals (a free swing, a step, a slow PRBS), one RK4 step covers them,
//! up to [`MAX_SPAN`], and the samples inside come from the step's cubic
//! Hermite interpolant; the step is taken only where its embedded error
//! estimate is within [`SPAN_TOLERANCE`] and no stick-slip guard fails at
//! its end or at a sample inside, otherwise the intervals are stepped one
//! by one as above (see `Span`). A free swing then costs about a third of
//! its RK4 stages. Where the inputs change at every sample (a driven
//! record) and no input has a delay, a deadzone or a saturation, a span
//! replaces each held input by the line of the same integral and first
//! moment ([`crate::affine_input`]), under one more rule: where the line's
//! trajectory may miss the staircase's at a sample inside (the positions
//! by more than [`SPAN_TOLERANCE`], a sliding dry joint's velocity across
//! zero) the span is shorter or not taken (see `AffineSpan`); a driven
//! record then costs about two fifths of its RK4 stages. An explicit [`SimOptions::substep`], a smoothed dry
//! friction and a controller in the loop take no span. Like any step
//! pattern chosen from the state, the spans make the outputs jump, by their
//! own error (below 1e-6 rad), where a parameter moves a span's end (a
//! delayed switch crossing a sample instant, an estimate crossing its
//! tolerance); the sensitivities are the derivatives between such points.
//! A `sign()` that is not a dry friction of one coordinate keeps the smooth
//! law with a note ([`Simulator::notes`]).
//!
//! [`DryFriction::Smooth`] replaces `sign(v)` by `tanh(v/w)` instead (the law
//! of earlier versions): RK4 cannot integrate a discontinuous force, and the
//! identification notes measured that a softer width (1e-2) makes a stuck
//! arm creep (20x worse fit). The smooth law is stiff: it needs a step of
//! about 1 ms or less, set by a stiffness probe (`StiffnessProbe`, a
//! simulation that would need less than [`MIN_SUBSTEP`] is refused as
//! [`SimError::TooStiff`]); that machinery serves only the smooth law (and a
//! smoothed fallback `sign()`).

use std::fmt;

use plantc_derive::mechanics::stick_slip::{first_crossing, mat_vec, Mode, StickSlip, MAX_EVENTS};
use plantc_derive::mechanics::{
    decompose_dry_friction, derive_equations, flat_outputs, small_lu, smooth_signs,
    smooth_signs_with, FALLBACK_SIGN_WIDTH,
};
use plantc_derive::model::Model;
use plantc_derive::sym::{diff, Expr, SplitTape, Symbol, Tape};

use crate::affine_input::Staircase;
use crate::closed_loop::{LoopEval, LoopLaw, Replay};
use crate::data::Experiment;

/// How the initial velocities are chosen.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum InitialVelocity {
    /// All velocities zero (the experiments start at rest).
    Zero,
    /// Slope of a least-squares line through the first `samples` samples of
    /// each coordinate (at least 2).
    Estimate {
        /// Number of samples used.
        samples: usize,
    },
}

/// How dry friction (`-D sign(q')` terms of the forces) is simulated.
#[derive(Copy, Clone, Debug, PartialEq, Default)]
pub enum DryFriction {
    /// Stick-slip: a joint at rest stays at rest while the force needed to
    /// hold it is within its static level, and breaks away above it; the
    /// switches are located inside the RK4 steps (see the module docs).
    #[default]
    Sticking,
    /// `sign(v)` replaced by `tanh(v / width)` (a stiff law that lets a held
    /// joint creep at about `width * atanh(load / level)`).
    Smooth {
        /// The smoothing width in the coordinate's speed unit (rad/s, m/s).
        width: f64,
    },
    /// The smooth law with its width a parameter of the model (the index
    /// of its value in the full parameter vector), so that a fit estimates
    /// it ([`crate::friction_law`]).
    SmoothFitted {
        /// Index of the width among the model's parameters.
        parameter: usize,
    },
}

/// Options of the experiment simulation.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SimOptions {
    /// Largest RK4 substep in s; `None` chooses it (`substep_for`: one
    /// substep per sample up to 2 ms with sticking friction, `min(1 ms,
    /// T/2)` with the smooth law, `T` the experiment's median sample time).
    /// Each sample interval is split into `ceil(dt/h)` equal substeps, so
    /// steps are aligned with the samples.
    pub substep: Option<f64>,
    /// How dry friction is simulated.
    pub dry_friction: DryFriction,
    /// Initial velocities.
    pub initial_velocity: InitialVelocity,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            substep: None,
            dry_friction: DryFriction::Sticking,
            initial_velocity: InitialVelocity::Zero,
        }
    }
}

/// Why a simulation could not be set up or run.
#[derive(Clone, Debug, PartialEq)]
pub enum SimError {
    /// The equations of motion could not be formed.
    Mechanics(String),
    /// A compiled tape could not be built (a symbol without a value).
    Tape(String),
    /// The experiment lacks a channel the model needs.
    MissingChannel {
        /// Experiment name.
        experiment: String,
        /// Channel name (a coordinate or an input of the model).
        channel: String,
    },
    /// The experiment has too few samples.
    TooFewSamples {
        /// Experiment name.
        experiment: String,
        /// Samples found.
        samples: usize,
    },
    /// The parameter vector has the wrong length.
    ParameterCount {
        /// Expected length.
        expected: usize,
        /// Given length.
        found: usize,
    },
    /// A parameter named as free does not exist in the model.
    UnknownParameter {
        /// The name given.
        name: String,
    },
    /// An option is out of range.
    BadOption(String),
    /// A saturation level evaluated to a non-positive or non-finite value.
    BadSaturation {
        /// The input.
        input: String,
        /// The level in the input's SI unit.
        value: f64,
    },
    /// A deadzone width evaluated to a negative or non-finite value.
    BadDeadzone {
        /// The input.
        input: String,
        /// The width in the input's SI unit.
        value: f64,
    },
    /// An input delay evaluated to a negative or non-finite value.
    BadDelay {
        /// The input.
        input: String,
        /// The delay in s.
        value: f64,
    },
    /// The dynamics at these parameter values need an RK4 substep below
    /// [`MIN_SUBSTEP`] (a dry friction far stronger than the inertia it
    /// acts on: its smoothed slope `F / w` through `M^-1`).
    TooStiff {
        /// Experiment name.
        experiment: String,
        /// The substep they would need, in s.
        substep: f64,
    },
    /// The state became non-finite or the mass matrix singular.
    Diverged {
        /// Experiment name.
        experiment: String,
        /// Time in s where it happened.
        time: f64,
    },
    /// The dry friction switched between sticking and sliding faster than
    /// the records are sampled: more than [`MAX_EVENTS`] times within one
    /// sample interval, or, over the block so far, more than once per
    /// coordinate with a dry friction per sample interval beyond one such
    /// burst (see
    /// [`integrate`]).
    Chattering {
        /// Experiment name.
        experiment: String,
        /// Time in s where it happened.
        time: f64,
    },
}

impl fmt::Display for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SimError::Mechanics(m) => write!(f, "equations of motion: {m}"),
            SimError::Tape(m) => write!(f, "compiling the dynamics: {m}"),
            SimError::MissingChannel {
                experiment,
                channel,
            } => write!(f, "experiment `{experiment}` has no channel `{channel}`"),
            SimError::TooFewSamples {
                experiment,
                samples,
            } => write!(
                f,
                "experiment `{experiment}` has {samples} sample(s); at least 2 are needed"
            ),
            SimError::ParameterCount { expected, found } => write!(
                f,
                "expected {expected} parameter values (base then derived), got {found}"
            ),
            SimError::UnknownParameter { name } => {
                write!(f, "the model has no parameter `{name}`")
            }
            SimError::BadOption(m) => write!(f, "bad simulation option: {m}"),
            SimError::BadDeadzone { input, value } => write!(
                f,
                "the deadzone width of input `{input}` must be a finite value >= 0, got {value}"
            ),
            SimError::BadSaturation { input, value } => write!(
                f,
                "the saturation level of input `{input}` must be a finite value > 0, got {value}"
            ),
            SimError::BadDelay { input, value } => write!(
                f,
                "the delay of input `{input}` must be a finite value >= 0 s, got {value} s"
            ),
            SimError::TooStiff {
                experiment,
                substep,
            } => write!(
                f,
                "simulation of `{experiment}` would need an RK4 substep of {substep:.1e} s at these parameter values, below the {MIN_SUBSTEP:.0e} s floor: a dry friction far stronger than the inertia it acts on (a wider dry-friction smoothing width softens it)"
            ),
            SimError::Diverged { experiment, time } => write!(
                f,
                "simulation of `{experiment}` diverged (non-finite state or singular mass matrix) at t = {time} s"
            ),
            SimError::Chattering { experiment, time } => write!(
                f,
                "simulation of `{experiment}`: the dry friction switched between sticking and sliding faster than the records are sampled (more than {MAX_EVENTS} times within one sample interval, or more than once per joint with a dry friction per interval over the record) at t = {time} s"
            ),
        }
    }
}

impl std::error::Error for SimError {}

/// The signals of one experiment in model order, ready for simulation.
#[derive(Clone, Debug, PartialEq)]
pub struct Signals {
    /// Experiment name.
    pub name: String,
    /// Sample instants in s.
    pub t: Vec<f64>,
    /// Measured coordinates, one vector per model coordinate.
    pub q: Vec<Vec<f64>>,
    /// Inputs, one vector per model input.
    pub u: Vec<Vec<f64>>,
    /// The recorded controller replayed on these data (closed-loop
    /// simulation only).
    pub replay: Option<Replay>,
}

impl Signals {
    /// [`Signals::from_experiment`] for a closed-loop simulation with `law`:
    /// the inputs the law drives may be absent from the data (the replayed
    /// law stands for them), its signal columns must be present.
    pub fn from_experiment_closed(
        model: &Model,
        exp: &Experiment,
        law: &LoopLaw,
    ) -> Result<Signals, SimError> {
        let q = model
            .coordinates
            .iter()
            .map(|c| {
                exp.values(&c.name)
                    .map(<[f64]>::to_vec)
                    .ok_or_else(|| SimError::MissingChannel {
                        experiment: exp.name.clone(),
                        channel: c.name.clone(),
                    })
            })
            .collect::<Result<Vec<_>, _>>()?;
        if exp.t.len() < 2 {
            return Err(SimError::TooFewSamples {
                experiment: exp.name.clone(),
                samples: exp.t.len(),
            });
        }
        let replay = law.replay(exp, &q)?;
        let mut u = Vec::with_capacity(model.inputs.len());
        for (j, inp) in model.inputs.iter().enumerate() {
            match law.driven().iter().position(|&d| d == j) {
                Some(d) => u.push(replay.u[d].clone()),
                None => u.push(exp.values(&inp.name).map(<[f64]>::to_vec).ok_or_else(|| {
                    SimError::MissingChannel {
                        experiment: exp.name.clone(),
                        channel: inp.name.clone(),
                    }
                })?),
            }
        }
        Ok(Signals {
            name: exp.name.clone(),
            t: exp.t.clone(),
            q,
            u,
            replay: Some(replay),
        })
    }

    /// Pick the model's coordinates and inputs out of an experiment by name.
    pub fn from_experiment(model: &Model, exp: &Experiment) -> Result<Signals, SimError> {
        let get = |name: &str| {
            exp.values(name)
                .map(<[f64]>::to_vec)
                .ok_or_else(|| SimError::MissingChannel {
                    experiment: exp.name.clone(),
                    channel: name.to_string(),
                })
        };
        let q = model
            .coordinates
            .iter()
            .map(|c| get(&c.name))
            .collect::<Result<Vec<_>, _>>()?;
        let u = model
            .inputs
            .iter()
            .map(|i| get(&i.name))
            .collect::<Result<Vec<_>, _>>()?;
        if exp.t.len() < 2 {
            return Err(SimError::TooFewSamples {
                experiment: exp.name.clone(),
                samples: exp.t.len(),
            });
        }
        Ok(Signals {
            name: exp.name.clone(),
            t: exp.t.clone(),
            q,
            u,
            replay: None,
        })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// True without samples (never for signals built by [`Signals::from_experiment`]).
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Number of samples with `t <= t0 + horizon` (all for an infinite horizon).
    pub fn samples_within(&self, horizon: f64) -> usize {
        let Some(&t0) = self.t.first() else { return 0 };
        self.t.partition_point(|&t| t <= t0 + horizon)
    }

    /// Median sample interval.
    pub(crate) fn sample_time(&self) -> f64 {
        crate::data::median_dt(&self.t).unwrap_or(1e-3)
    }
}

/// Simulated coordinates at the sample instants.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    /// One vector per model coordinate, `n_samples` long.
    pub q: Vec<Vec<f64>>,
}

/// The dynamics a simulator compiles: the flat outputs `[M (row-major), r0,
/// B (row-major)]`, followed with sticking friction by the levels `D` (one
/// per coordinate) when some coordinate has a dry friction.
#[derive(Clone, Debug)]
pub(crate) struct Compiled {
    /// The tape outputs.
    pub(crate) outs: Vec<Expr>,
    /// Which coordinates stick (all false with the smooth law or without
    /// dry friction).
    pub(crate) dry: Vec<bool>,
    /// Whether the outputs end with the levels `D`.
    pub(crate) levels: bool,
    /// Whether some `sign()` was smoothed (the smooth law, or a fallback):
    /// only then is the dynamics stiff at zero speed and the substep probed.
    pub(crate) smoothed: bool,
    /// The smoothed fallback `sign()`s, one sentence each.
    pub(crate) notes: Vec<String>,
}

/// The equations as flat vectors, dry friction as `law` says.
pub(crate) fn dynamics_outputs(model: &Model, law: DryFriction) -> Result<Compiled, SimError> {
    let eqs = derive_equations(model).map_err(|e| SimError::Mechanics(e.to_string()))?;
    let n = eqs.coords.len();
    let smooth = match law {
        DryFriction::Smooth { width } => Some(smooth_signs(&eqs, width)),
        DryFriction::SmoothFitted { parameter } => {
            let Some(&w) = model.parameter_symbols().get(parameter) else {
                return Err(SimError::BadOption(format!(
                    "the dry friction's width is parameter {parameter}, beyond the model's {}",
                    model.parameters.len()
                )));
            };
            Some(smooth_signs_with(&eqs, |v| (v / Expr::symbol(w)).tanh()))
        }
        DryFriction::Sticking => None,
    };
    if let Some(smooth) = smooth {
        return Ok(Compiled {
            outs: flat_outputs(&smooth),
            dry: vec![false; n],
            levels: false,
            smoothed: plantc_derive::mechanics::has_sign(&eqs),
            notes: Vec::new(),
        });
    }
    let split = decompose_dry_friction(&eqs, FALLBACK_SIGN_WIDTH);
    let mut outs = flat_outputs(&split.smooth);
    let levels = split.any();
    if levels {
        outs.extend(split.levels.iter().copied());
    }
    Ok(Compiled {
        outs,
        dry: (0..n).map(|i| split.has(i)).collect(),
        levels,
        smoothed: !split.notes.is_empty(),
        notes: split.notes,
    })
}

/// Tape input symbols: state, inputs, full parameters.
pub(crate) fn tape_inputs(model: &Model) -> Vec<Symbol> {
    let mut v = model.state_symbols();
    v.extend(model.input_symbols());
    v.extend(model.parameter_symbols());
    v
}

/// LU factorisation for the mass matrix (shared with derive's numeric
/// dynamics); a pivot that is zero or subnormal counts as singular.
pub(crate) fn lu_factor(a: &mut [f64], n: usize, piv: &mut [usize]) -> bool {
    small_lu::lu_factor(a, n, piv, f64::MIN_POSITIVE)
}

pub(crate) use small_lu::lu_solve;

/// Initial state `(q(t0) - d, q'(t0))` from the data, with `offsets` the
/// sensor offsets `d` (the sensors read `q + d`).
pub(crate) fn initial_state(sig: &Signals, how: InitialVelocity, offsets: &[f64]) -> Vec<f64> {
    let n = sig.q.len();
    let mut x = vec![0.0; 2 * n];
    for i in 0..n {
        x[i] = sig.q[i][0] - offsets.get(i).copied().unwrap_or(0.0);
        if let InitialVelocity::Estimate { samples } = how {
            let k = samples.clamp(2, sig.len());
            let t0 = sig.t[0];
            let (mut st, mut sq, mut stt, mut stq) = (0.0, 0.0, 0.0, 0.0);
            for j in 0..k {
                let t = sig.t[j] - t0;
                st += t;
                sq += sig.q[i][j];
                stt += t * t;
                stq += t * sig.q[i][j];
            }
            let kf = k as f64;
            let den = kf * stt - st * st;
            if den > 0.0 {
                x[n + i] = (kf * stq - st * sq) / den;
            }
        }
    }
    x
}

/// The velocity of a measured coordinate at sample `k`: the slope at `t_k`
/// of a least-squares quadratic through the samples within `half_window`
/// s of it (one-sided at the ends of the record; at least two samples on
/// each available side). Works on non-uniform time stamps.
pub fn velocity_at(t: &[f64], y: &[f64], k: usize, half_window: f64) -> f64 {
    let n = t.len().min(y.len());
    if n < 2 || k >= n {
        return 0.0;
    }
    let tk = t[k];
    let mut a = k;
    while a > 0 && (tk - t[a - 1] <= half_window || k - a < 2) {
        a -= 1;
    }
    let mut b = k;
    while b + 1 < n && (t[b + 1] - tk <= half_window || b - k < 2) {
        b += 1;
    }
    // least squares y = c0 + c1 s + c2 s^2 with s = t - t_k
    let mut m = [[0.0f64; 3]; 3];
    let mut r = [0.0f64; 3];
    for i in a..=b {
        let s = t[i] - tk;
        let pw = [1.0, s, s * s];
        for (u, pu) in pw.iter().enumerate() {
            r[u] += pu * y[i];
            for (v, pv) in pw.iter().enumerate() {
                m[u][v] += pu * pv;
            }
        }
    }
    let order = if b - a >= 2 { 3 } else { 2 };
    let flat: Vec<f64> = (0..order)
        .flat_map(|u| (0..order).map(move |v| (u, v)))
        .map(|(u, v)| m[u][v])
        .collect();
    match crate::lm::solve_spd(&flat, order, &r[..order]) {
        Some(c) => c[1],
        None => 0.0,
    }
}

/// What starts or ends an integration segment.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) enum Boundary {
    /// A sample instant (does not move with the parameters).
    Sample,
    /// The delayed switch of this input (moves with its delay).
    Delay(usize),
    /// A stick-slip event located inside a step (moves with everything the
    /// state depends on).
    Event,
}

/// One integration segment: an interval between consecutive boundaries
/// (sample instants, switch instants of delayed inputs and stick-slip
/// events) over which the input is constant.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Segment {
    /// Length in s.
    pub(crate) len: f64,
    /// What starts it.
    pub(crate) start: Boundary,
    /// What ends it (never an event).
    pub(crate) end: Boundary,
}

impl Segment {
    /// A segment of length `len` from one sample instant to another (a
    /// span's).
    fn between_samples(len: f64) -> Segment {
        Segment {
            len,
            start: Boundary::Sample,
            end: Boundary::Sample,
        }
    }
}

/// What [`Dynamics::rhs`] computes.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) enum Rate {
    /// A step of the current segment (integrated in the segment's scaled
    /// time: the moving-end term included).
    Segment,
    /// The final step of length `tau` up to a located event: no moving-end
    /// term, and the tangent `d state / d tau` (the extra entries of
    /// [`Dynamics::tangent_len`], zero at the step's start) with rate
    /// `f_z T + f / tau`.
    Event(f64),
}

/// A located stick-slip event, for [`Dynamics::event`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Located {
    /// The joint whose guard crossed zero.
    pub(crate) joint: usize,
    /// Whether it was stuck (it breaks away) or sliding (its velocity
    /// reached zero).
    pub(crate) stuck: bool,
    /// The step length from the step's start to the event, s.
    pub(crate) tau: f64,
    /// The step's index in its segment and the segment's step count.
    pub(crate) step: (usize, usize),
}

/// What [`integrate`] needs of a simulator: the rates of its integrated
/// vector `z` (the state `x = z[..2n]` first, then anything integrated
/// alongside, e.g. sensitivities) in the stick-slip mode of the last
/// [`Dynamics::classify`], and the events' bookkeeping.
pub(crate) trait Dynamics {
    /// Number of coordinates `n`.
    fn n(&self) -> usize;
    /// Whether some coordinate sticks (events are looked for).
    fn has_dry(&self) -> bool;
    /// The number of coordinates with a dry friction (that may stick).
    fn dry_joints(&self) -> usize;
    /// Entries after `z` integrated in an event's final step (the tangent
    /// of [`Rate::Event`]); 0 without sensitivities.
    fn tangent_len(&self) -> usize {
        0
    }
    /// Decide the mode at the state `x` with input `u` (`release`: a stuck
    /// joint breaking away here); false when the dynamics cannot be
    /// evaluated.
    fn classify(&mut self, x: &[f64], u: &[f64], release: Option<usize>) -> bool;
    /// The rates `dz` of `z` (with `z.len()` entries, or more for
    /// [`Rate::Event`]), `held[j]` the sample input `j` holds.
    fn rhs(&mut self, z: &[f64], u: &[f64], held: &[usize], rate: Rate, dz: &mut [f64]) -> bool;
    /// The state's rates alone (`2n` entries), for event location.
    fn state_rhs(&mut self, x: &[f64], u: &[f64], dx: &mut [f64]) -> bool;
    /// The guards of the mode at state `x` ([`StickSlip::guards`]).
    fn guards(&mut self, x: &[f64], u: &[f64], g: &mut [f64]) -> bool;
    /// The stick-slip mode of the last [`Dynamics::classify`] (with
    /// [`Dynamics::has_dry`]).
    fn mode(&self) -> &Mode;
    /// Whether joint `j` is stuck in the current mode.
    fn stuck(&self, j: usize) -> bool {
        self.mode().stuck[j]
    }
    /// A segment starts.
    fn begin_segment(&mut self, _seg: &Segment) {}
    /// After a [`Dynamics::classify`] at the start of a step: anything
    /// integrated alongside the state that a stuck joint fixes (its
    /// velocity is exactly zero whatever the parameters: the sensitivity
    /// row of a stuck velocity is zero).
    fn held(&mut self, _z: &mut [f64]) {}
    /// After the final step up to a located event (`z` with its tangent
    /// entries): set what the event sets (a velocity reaching zero is set
    /// to 0.0) and anything integrated alongside.
    fn event(&mut self, z: &mut [f64], u: &[f64], held: &[usize], ev: &Located) -> bool;
    /// Whether [`Dynamics::switch`] wants the delayed switches taken at
    /// sample instants.
    fn wants_switches(&self) -> bool {
        false
    }
    /// A delayed switch of input `l` taken at a sample instant, with the
    /// state's rates before (`f_old`) and after (`f_new`) it.
    fn switch(&mut self, _l: usize, _f_old: &[f64], _f_new: &[f64], _z: &mut [f64]) {}
    /// The input gain `G = M^-1 B` of the current mode at `(x, u)`
    /// (`n x m`, row-major; zero rows for stuck joints) into `g`; false
    /// when it cannot be evaluated.
    fn input_gain(&mut self, x: &[f64], u: &[f64], g: &mut [f64]) -> bool;
}

/// `dst.copy_from_slice(src)` for the few numbers of a state, an input or
/// a row (equal lengths): up to 8 entries as inline moves of a fixed-size
/// array. The simulators copy such short slices several times per RK4
/// stage, and a call to the platform's `memcpy` for 2-4 numbers cost more
/// than the copy (6.5 % of the README main job's CPU time went to those
/// calls, perf 2026-11-27; callgrind on `plantc fit` of 3 x 10,000 samples:
/// 170 M fewer instructions in `memcpy`, 125 M more inline, of 5.5 G).
#[inline(always)]
pub(crate) fn copy_short(dst: &mut [f64], src: &[f64]) {
    macro_rules! fixed {
        ($($k:literal)*) => {
            match src.len() {
                $($k => {
                    let s: &[f64; $k] = src.try_into().expect("length checked");
                    let d: &mut [f64; $k] = dst.try_into().expect("equal lengths");
                    *d = *s;
                })*
                _ => dst.copy_from_slice(src),
            }
        };
    }
    fixed!(0 1 2 3 4 5 6 7 8)
}

/// `r0 + B u` into `out` (`b` row-major, `r0.len() x u.len()`), summed in
/// one order: both simulators call it, so their trajectories agree to the
/// bit (and take the same substeps, see [`Substep`]).
#[inline]
pub(crate) fn forces(r0: &[f64], b: &[f64], u: &[f64], out: &mut [f64]) {
    let m = u.len();
    for (i, o) in out.iter_mut().enumerate().take(r0.len()) {
        let mut s = r0[i];
        for j in 0..m {
            s += b[i * m + j] * u[j];
        }
        *o = s;
    }
}

/// The RK4 substep of a simulation: `h`, or a longer one over the sample
/// intervals where it is safe.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Substep {
    /// The substep where nothing else is known.
    pub(crate) h: f64,
    /// `(longer substep, stiff velocity components, dry-friction width)`:
    /// the stiffness that sets `h` comes from the dry friction on those
    /// velocities (the steepest slope of `tanh(v/w)` at zero speed); over a
    /// sample interval where each of them starts at least `5 w` plus twice
    /// the distance its acceleration covers in the interval from zero speed
    /// the slope is below `2e-4` of that, and the longer substep is taken.
    pub(crate) relaxed: Option<(f64, Vec<usize>, f64)>,
    /// The longest single RK4 step over consecutive sample intervals where
    /// every input holds its value (a span, see [`integrate`]); `None`: one
    /// interval at a time (an explicit substep, a smoothed dry friction, a
    /// retry after a divergence, a controller in the loop).
    pub(crate) span: Option<f64>,
    /// Whether a span may also cover intervals where the inputs change
    /// ([`AffineSpan`]): with spans, where no input has a delay, a deadzone
    /// or a saturation (the right-hand side then sees the inputs through
    /// their values alone, in both simulators alike).
    pub(crate) affine: bool,
}

impl Substep {
    /// `h` everywhere.
    pub(crate) fn fixed(h: f64) -> Substep {
        Substep {
            h,
            relaxed: None,
            span: None,
            affine: false,
        }
    }

    /// Substeps `refine` times shorter, never relaxed (a retry after a
    /// divergence).
    pub(crate) fn refined(&self, refine: f64) -> Substep {
        if refine == 1.0 {
            self.clone()
        } else {
            Substep::fixed(self.h / refine)
        }
    }

    /// The number of substeps over a segment of length `len` starting at
    /// state `z` with derivative `dz` there.
    fn count(&self, len: f64, z: &[f64], dz: &[f64]) -> usize {
        let h = match &self.relaxed {
            Some((long, stiff, w))
                if stiff
                    .iter()
                    .all(|&i| z[i].abs() > 5.0 * w + 2.0 * dz[i].abs() * len) =>
            {
                *long
            }
            _ => self.h,
        };
        ((len / h) - 1e-9).ceil().max(1.0) as usize
    }
}

/// RK4 over the sample intervals `range` (block `[k0, k1)`) with
/// zero-order-hold input, each input `j` delayed by `delays[j] >= 0` s (see
/// the module docs).
///
/// `u[j][k]` is the value input `j` holds from sample `k` on (before its
/// delay); `at_sample(k, z, u)` is called at every sample instant `k` of the
/// range with the state there, before the interval that starts at `k` is
/// integrated: it records the state and may write `u[.][k]` (a controller in
/// the loop); it returns false when the state cannot go on (non-finite).
/// [`Dynamics::rhs`] gets the held input values and the sample each of
/// them was taken from, and returns false when the dynamics cannot be
/// evaluated (singular mass matrix). At the start of the block input `j`
/// holds the latest sample `i <= k0` with `t_i + delay_j <= t_k0` (sample 0
/// when there is none: the rig held the first value before the record). A
/// switch that falls on a sample instant (within `1e-9 dt`) is taken there
/// and reported to [`Dynamics::switch`] (with the state derivatives before
/// and after it) when its value changes; a switch inside a sample interval
/// ends a segment instead.
///
/// Stick-slip (when [`Dynamics::has_dry`]): the mode is decided at the start
/// of every step; a step whose end violates a guard is not taken: the
/// first crossing is located on the step length by the state alone
/// ([`first_crossing`]), the step up to it is taken with [`Rate::Event`],
/// [`Dynamics::event`] applies the event, and the rest of the segment is a
/// new segment starting at the event ([`Boundary::Event`]) with as many
/// equal substeps as its length needs. Buffers are allocated once per
/// call, none per step.
///
/// The records show at most one change of a joint's mode per sample
/// interval: a simulation whose joints stick and break away more often
/// than that, on average over the block, describes friction dynamics the
/// records cannot resolve, and each event costs a root search of tens of
/// steps. It is stopped as [`SimError::Chattering`] once the block's mode
/// changes exceed one per joint with a dry friction per interval plus one
/// interval's [`MAX_EVENTS`] (a burst). (A Stribeck friction refitted on
/// a tumbling 4-link chain's third joint from `vs` = 3 mrad/s, `Fs` =
/// 0.06 N m: its negative damping near zero speed has a 50 us time
/// constant; 1 to 3 mode changes per 2 ms interval over whole 0.5 s
/// segments, bursts of 30, and a fit that had not ended after 10
/// minutes.)
#[allow(clippy::too_many_arguments)]
pub(crate) fn integrate<D: Dynamics>(
    name: &str,
    t: &[f64],
    u: &mut [Vec<f64>],
    range: std::ops::Range<usize>,
    substep: &Substep,
    z: &mut [f64],
    delays: &[f64],
    sys: &mut D,
    at_sample: impl FnMut(usize, &[f64], &mut [Vec<f64>]) -> bool,
) -> Result<(), SimError> {
    let dim = z.len();
    let ext = dim + sys.tangent_len();
    let mut zs = vec![0.0; ext];
    let mut zt = vec![0.0; ext];
    // the integrated vector in a buffer of its own, swapped with `zt` after
    // each substep instead of copied back (copied into `z` at the end)
    let mut cur = vec![0.0; ext];
    cur[..dim].copy_from_slice(z);
    let r = integrate_in(
        name,
        t,
        u,
        range,
        substep,
        (&mut cur, &mut zs, &mut zt),
        delays,
        sys,
        at_sample,
    );
    z.copy_from_slice(&cur[..dim]);
    r
}

/// [`integrate`] on `cur` (the integrated vector in its first `dim`
/// entries), with the step buffers `zs` and `zt` of the same length.
#[allow(clippy::too_many_arguments)]
fn integrate_in<D: Dynamics>(
    name: &str,
    t: &[f64],
    u: &mut [Vec<f64>],
    range: std::ops::Range<usize>,
    substep: &Substep,
    (cur, zs, zt): (&mut Vec<f64>, &mut Vec<f64>, &mut Vec<f64>),
    delays: &[f64],
    sys: &mut D,
    mut at_sample: impl FnMut(usize, &[f64], &mut [Vec<f64>]) -> bool,
) -> Result<(), SimError> {
    let n = sys.n();
    let nx = 2 * n;
    let ext = cur.len();
    let dim = ext - sys.tangent_len();
    let dry = sys.has_dry();
    let n_dry = sys.dry_joints();
    let jumps = sys.wants_switches();
    let m = u.len();
    let k1 = range.end.min(t.len());
    let k0 = range.start.min(k1);
    let mut uh = vec![0.0; m];
    let mut u_new = vec![0.0; m];
    let mut k = Stages::new(ext);
    let mut g = vec![0.0; n];
    let mut g_end = vec![0.0; n];
    let mut state = Stages::new(nx);
    let delay = |j: usize| delays.get(j).copied().unwrap_or(0.0);
    // idx[j]: the sample whose value input j currently holds
    let mut idx = vec![0usize; m];
    let mut held_old = vec![0usize; m];
    if k0 < k1 {
        let tol0 = 1e-9 * (t.get(k0 + 1).unwrap_or(&t[k0]) - t[k0]).abs();
        for (j, i) in idx.iter_mut().enumerate() {
            let target = t[k0] - delay(j) + tol0;
            // the latest sample i <= k0 with t_i <= t_k0 - delay
            *i = t[..=k0]
                .partition_point(|&ti| ti <= target)
                .saturating_sub(1);
        }
    }
    // mode changes over the block so far (see the doc above)
    let mut block_events = 0usize;
    // the states at the samples inside a span, before they are recorded
    let mut inside: Vec<f64> = Vec::new();
    let mut carry = Carry {
        at: usize::MAX,
        f: vec![0.0; dim],
        u: vec![0.0; m],
        mode: Mode::new(n),
    };
    // the intervals the next affine span tries (see `AffineSpan::step`)
    let mut hint = usize::MAX;
    let mut line = LineBuffers {
        stairs: Staircase::default(),
        gain: vec![0.0; n * m],
        start: vec![0.0; m],
        mid: vec![0.0; m],
        end: vec![0.0; m],
        held: vec![0.0; m],
    };
    let mut kk = k0;
    while kk < k1 {
        if !at_sample(kk, &cur[..dim], u) {
            return Err(SimError::Diverged {
                experiment: name.to_string(),
                time: t[kk],
            });
        }
        if kk + 1 == k1 {
            break;
        }
        for (j, uj) in uh.iter_mut().enumerate() {
            *uj = u[j][idx[j]];
        }
        // a span: the inputs hold over it, or (without delays, deadzones or
        // saturations) they are replaced by their lines
        let taken = match substep.span {
            Some(max) => match span_end(t, u, (&idx, delays), kk, k1, max) {
                Some(ke) => Span {
                    t,
                    from: kk,
                    to: ke,
                    u: &uh,
                    held: &idx,
                }
                .step(sys, (cur, zt), &mut k, (&mut g, &mut inside), &mut carry)
                .then_some(ke),
                None if substep.affine => {
                    let ke = AffineSpan {
                        t,
                        u,
                        from: kk,
                        held: (&idx, delays),
                    }
                    .step(
                        sys,
                        (cur, zt),
                        &mut k,
                        (&mut g, &mut inside),
                        (k1, max),
                        &mut line,
                        &mut hint,
                    );
                    if ke.is_some() {
                        carry.at = usize::MAX;
                    }
                    ke
                }
                None => None,
            },
            None => None,
        };
        if let Some(ke) = taken {
            for (i, z_i) in inside.chunks_exact(dim).enumerate() {
                if !at_sample(kk + 1 + i, z_i, u) {
                    return Err(SimError::Diverged {
                        experiment: name.to_string(),
                        time: t[kk + 1 + i],
                    });
                }
            }
            // the switches passed (each to the value held already, or
            // within the line); those due at the span's end are left to the
            // interval that starts there, which takes them as the intervals
            // do (a delayed switch there changes the delay's sensitivity)
            let tol = 1e-9 * (t[ke] - t[ke - 1]);
            for (j, i) in idx.iter_mut().enumerate() {
                while *i + 1 < k1 && t[*i + 1] + delay(j) < t[ke] - tol {
                    *i += 1;
                }
            }
            kk = ke;
            continue;
        }
        let (t_end, dt) = (t[kk + 1], t[kk + 1] - t[kk]);
        let tol = 1e-9 * dt;
        let mut a = t[kk];
        let mut a_bound = Boundary::Sample;
        let mut release: Option<usize> = None;
        let mut events = 0usize;
        loop {
            let diverged = |time: f64| SimError::Diverged {
                experiment: name.to_string(),
                time,
            };
            // switches due at `a`; the one that ends the previous segment is
            // a segment boundary, the others are taken as jumps (an event
            // lies strictly inside a segment: none are due there)
            if a_bound != Boundary::Event {
                for j in 0..m {
                    let mut boundary = a_bound == Boundary::Delay(j);
                    while idx[j] + 1 < k1 && t[idx[j] + 1] + delay(j) <= a + tol {
                        held_old.copy_from_slice(&idx);
                        idx[j] += 1;
                        let new = u[j][idx[j]];
                        if boundary {
                            boundary = false;
                        } else if jumps && new != uh[j] {
                            u_new.copy_from_slice(&uh);
                            u_new[j] = new;
                            let (f_old, f_new) = (&mut k.k1[..dim], &mut k.k2[..dim]);
                            if !sys.classify(&cur[..nx], &uh, None)
                                || !sys.rhs(&cur[..dim], &uh, &held_old, Rate::Segment, f_old)
                                || !sys.classify(&cur[..nx], &u_new, None)
                                || !sys.rhs(&cur[..dim], &u_new, &idx, Rate::Segment, f_new)
                            {
                                return Err(diverged(a));
                            }
                            sys.switch(j, f_old, f_new, &mut cur[..dim]);
                        }
                        uh[j] = new;
                    }
                }
            }
            // the next switch inside the interval ends the segment
            let mut seg = Segment {
                len: 0.0,
                start: a_bound,
                end: Boundary::Sample,
            };
            let mut b = t_end;
            for (j, &held) in idx.iter().enumerate() {
                if held + 1 < k1 {
                    let s = t[held + 1] + delay(j);
                    if s < b - tol {
                        b = s;
                        seg.end = Boundary::Delay(j);
                    }
                }
            }
            seg.len = b - a;
            let mut cut = false;
            // (an event at the very end of a segment leaves nothing)
            if seg.len > 0.0 {
                sys.begin_segment(&seg);
                // the first stage's derivative, which also decides the count
                if !sys.classify(&cur[..nx], &uh, release.take()) {
                    return Err(diverged(a));
                }
                sys.held(&mut cur[..dim]);
                if !sys.rhs(&cur[..dim], &uh, &idx, Rate::Segment, &mut k.k1[..dim]) {
                    return Err(diverged(a));
                }
                let steps = substep.count(seg.len, &cur[..dim], &k.k1[..dim]);
                let h = seg.len / steps as f64;
                let mut s = 0;
                while s < steps {
                    if s > 0 {
                        if !sys.classify(&cur[..nx], &uh, None) {
                            return Err(diverged(a));
                        }
                        sys.held(&mut cur[..dim]);
                        if !sys.rhs(&cur[..dim], &uh, &idx, Rate::Segment, &mut k.k1[..dim]) {
                            return Err(diverged(a));
                        }
                    }
                    if !k.finish(
                        sys,
                        &cur[..dim],
                        &uh,
                        &idx,
                        Rate::Segment,
                        h,
                        &mut zt[..dim],
                    ) {
                        return Err(diverged(a));
                    }
                    if dry {
                        if !sys.guards(&zt[..nx], &uh, &mut g) {
                            return Err(diverged(a));
                        }
                        if g.iter().any(|v| *v < 0.0) {
                            events += 1;
                            block_events += 1;
                            if events > MAX_EVENTS || block_events > n_dry * (kk - k0) + MAX_EVENTS
                            {
                                return Err(SimError::Chattering {
                                    experiment: name.to_string(),
                                    time: a + s as f64 * h,
                                });
                            }
                            // the first crossing among the violated guards
                            g_end.copy_from_slice(&g);
                            let x0 = &cur[..nx];
                            let (mut tau, mut which) = (h, None);
                            for i in 0..n {
                                if g_end[i] >= 0.0 {
                                    continue;
                                }
                                let mut guard = |len: f64| {
                                    (state.step(sys, x0, &uh, len)
                                        && sys.guards(&state.out, &uh, &mut g))
                                    .then(|| g[i])
                                };
                                match first_crossing(&mut guard, tau) {
                                    Ok(Some(tt)) => (tau, which) = (tt, Some(i)),
                                    Ok(None) => {}
                                    Err(_) => return Err(diverged(a)),
                                }
                            }
                            let Some(j) = which else {
                                return Err(diverged(a));
                            };
                            let stuck = sys.stuck(j);
                            // the step up to it, with the tangent d x / d tau
                            zs[..dim].copy_from_slice(&cur[..dim]);
                            zs[dim..].iter_mut().for_each(|v| *v = 0.0);
                            if !sys.rhs(&zs[..], &uh, &idx, Rate::Event(tau), &mut k.k1)
                                || !k.finish(
                                    sys,
                                    &zs[..],
                                    &uh,
                                    &idx,
                                    Rate::Event(tau),
                                    tau,
                                    &mut zt[..],
                                )
                            {
                                return Err(diverged(a));
                            }
                            let ev = Located {
                                joint: j,
                                stuck,
                                tau,
                                step: (s, steps),
                            };
                            if !sys.event(&mut zt[..], &uh, &idx, &ev) {
                                return Err(diverged(a));
                            }
                            std::mem::swap(cur, zt);
                            a += s as f64 * h + tau;
                            a_bound = Boundary::Event;
                            release = stuck.then_some(j);
                            cut = true;
                            break;
                        }
                    }
                    std::mem::swap(cur, zt);
                    s += 1;
                }
                if cur[..dim].iter().any(|v| !v.is_finite()) {
                    return Err(diverged(a));
                }
            }
            if cut {
                continue;
            }
            if seg.end == Boundary::Sample {
                break;
            }
            a = b;
            a_bound = seg.end;
        }
        kk += 1;
    }
    Ok(())
}

/// The last sample a span from sample `kk` may reach (None: fewer than
/// two intervals): the samples within [`Substep::span`] of `t[kk]`, up to
/// the first switch of an input to another value than the one it holds
/// now (`held[j]`): sample `i`'s value arrives at `t_i + delays[j]`, taken
/// at a sample instant within `1e-9` of an interval of it, as
/// [`integrate`] takes it.
fn span_end(
    t: &[f64],
    u: &[Vec<f64>],
    (held, delays): (&[usize], &[f64]),
    kk: usize,
    k1: usize,
    max: f64,
) -> Option<usize> {
    let limit = t[kk] + max * (1.0 + 1e-9);
    let mut ke = kk + 1;
    while ke + 1 < k1 && t[ke + 1] <= limit {
        ke += 1;
    }
    // (`held[j] <= kk < ke`: the held sample is never past the interval's
    // start; a value at a sample after `ke` arrives after `t[ke]`)
    for (j, uj) in u.iter().enumerate() {
        let i = held[j];
        let v = uj[i];
        if let Some(off) = uj[i + 1..=ke].iter().position(|x| *x != v) {
            let arrives = t[i + 1 + off] + delays.get(j).copied().unwrap_or(0.0);
            let tol = 1e-9 * (t[kk + 1] - t[kk]);
            while ke > kk && t[ke] > arrives + tol {
                ke -= 1;
            }
        }
    }
    (ke >= kk + 2).then_some(ke)
}

/// One RK4 step over the sample intervals from sample `from` to sample
/// `to` (at least two), where every input holds `u` (a span): the
/// samples inside come from the step's cubic Hermite interpolant (the
/// integrated vector and its rates at both ends; the sensitivities so
/// interpolated are the exact derivatives of the interpolated state). The
/// span is taken only where it is as safe as the interval-by-interval
/// steps it replaces, otherwise nothing is changed and the caller steps
/// interval by interval: the step's embedded error estimate (below) is
/// within [`SPAN_TOLERANCE`], no stick-slip guard is violated at its end
/// or at a sample inside (where the interval steps would look for events),
/// and every value is finite. The stick-slip mode is decided at its start,
/// as for any step.
///
/// The error estimate is free: the third-order solution from the same
/// stages with the rate at the end (weights 1/6, 1/3, 1/3, 0, 1/6) differs
/// from RK4's by `len/6 (k4 - f(z1))`; a velocity's estimate counts as the
/// distance it covers over the step (times `len`).
struct Span<'a> {
    t: &'a [f64],
    from: usize,
    to: usize,
    u: &'a [f64],
    held: &'a [usize],
}

/// The rates at the end of the last span taken, for the first stage of a
/// span that starts there with the same input and mode (the same numbers
/// the right-hand side would compute again).
struct Carry {
    /// The sample where the last span ended (`usize::MAX`: none).
    at: usize,
    /// The rates there.
    f: Vec<f64>,
    /// The input held over it.
    u: Vec<f64>,
    /// Its stick-slip mode.
    mode: Mode,
}

impl Span<'_> {
    /// Take the span from `cur` (into `cur`, `zt` a buffer), the states at
    /// the samples inside into `inside` (one after the other): true when
    /// taken.
    fn step<D: Dynamics>(
        &self,
        sys: &mut D,
        (cur, zt): (&mut Vec<f64>, &mut Vec<f64>),
        k: &mut Stages,
        (g, inside): (&mut [f64], &mut Vec<f64>),
        carry: &mut Carry,
    ) -> bool {
        let carried = std::mem::replace(&mut carry.at, usize::MAX) == self.from;
        let n = sys.n();
        let nx = 2 * n;
        let dim = cur.len() - sys.tangent_len();
        let t0 = self.t[self.from];
        let len = self.t[self.to] - t0;
        sys.begin_segment(&Segment::between_samples(len));
        if !sys.classify(&cur[..nx], self.u, None) {
            return false;
        }
        sys.held(&mut cur[..dim]);
        let (u, held) = (self.u, self.held);
        let dry = sys.has_dry();
        if carried && carry.u == u && (!dry || *sys.mode() == carry.mode) {
            k.k1[..dim].copy_from_slice(&carry.f);
        } else if !sys.rhs(&cur[..dim], u, held, Rate::Segment, &mut k.k1[..dim]) {
            return false;
        }
        if !k.finish(
            sys,
            &cur[..dim],
            u,
            held,
            Rate::Segment,
            len,
            &mut zt[..dim],
        ) || !zt[..dim].iter().all(|v| v.is_finite())
            || !sys.rhs(&zt[..dim], u, held, Rate::Segment, &mut k.k2[..dim])
        {
            return false;
        }
        let worst = k.span_estimate(n, len);
        if worst.is_nan() || worst > SPAN_TOLERANCE {
            return false;
        }
        let mut holds =
            |sys: &mut D, x: &[f64]| !dry || (sys.guards(x, u, g) && g.iter().all(|v| *v >= 0.0));
        if !holds(sys, &zt[..nx]) {
            return false;
        }
        // (grown once to the longest span, then reused)
        inside.resize((self.to - self.from - 1) * dim, 0.0);
        let (f0, f1) = (&k.k1[..dim], &k.k2[..dim]);
        for (i, z_i) in inside.chunks_exact_mut(dim).enumerate() {
            let th = (self.t[self.from + 1 + i] - t0) / len;
            hermite((&cur[..dim], &zt[..dim]), (f0, f1), (th, len), z_i);
            if !z_i.iter().all(|v| v.is_finite()) || !holds(sys, &z_i[..nx]) {
                return false;
            }
        }
        carry.f.copy_from_slice(f1);
        carry.u.copy_from_slice(u);
        if dry {
            carry.mode.clone_from(sys.mode());
        }
        carry.at = self.to;
        std::mem::swap(cur, zt);
        true
    }
}

/// A span over sample intervals where the inputs change (a driven
/// record): one RK4 step from sample `from` with each input replaced by the
/// line of the same integral and first moment over the span
/// ([`crate::affine_input`]; the stages take the line's values at their
/// times), the samples inside from the step's cubic Hermite interpolant as
/// for a [`Span`]. Taken under the same rules as a span (embedded estimate
/// within [`SPAN_TOLERANCE`], no guard violated at a sample, every value
/// finite, the mode decided at its start with the held input) and one
/// more: at every sample inside, the positions' response to the staircase's
/// difference from the line, `G E2` with the input gain `G = M^-1 B` at the
/// start, is within [`SPAN_TOLERANCE`] too (where the interpolant would
/// miss the staircase's trajectory), and no sliding dry joint is nearer
/// zero speed at a sample inside than the velocities' miss `G E1` (the
/// two trajectories could stop at different samples). Where the `E2` rule
/// fails, half the span is tried (down to two intervals); where the
/// estimate does, the length it allows (it grows as the length's fourth
/// power), once; then the intervals one by one. The next span starts from
/// the length this one's estimate allows (up to twice this one's): at 1 kHz
/// an 8 ms step's estimate is above the tolerance most of the time, and a
/// refused step costs its five evaluations.
struct AffineSpan<'a> {
    t: &'a [f64],
    u: &'a [Vec<f64>],
    from: usize,
    /// The held samples at its start and the inputs' delays.
    held: (&'a [usize], &'a [f64]),
}

/// Work buffers of [`AffineSpan::step`]: the staircase, the input gain
/// (`n x m`), the line's values at the step's start, middle and end, a
/// held input.
struct LineBuffers {
    stairs: Staircase,
    gain: Vec<f64>,
    start: Vec<f64>,
    mid: Vec<f64>,
    end: Vec<f64>,
    held: Vec<f64>,
}

impl AffineSpan<'_> {
    /// Take the longest span from `cur` within `max` seconds and before
    /// sample `k1` that the rules allow (into `cur`, `zt` a buffer; the
    /// states at the samples inside into `inside`): its last sample, or
    /// `None` (nothing changed).
    #[allow(clippy::too_many_arguments)]
    fn step<D: Dynamics>(
        &self,
        sys: &mut D,
        (cur, zt): (&mut Vec<f64>, &mut Vec<f64>),
        k: &mut Stages,
        (g, inside): (&mut [f64], &mut Vec<f64>),
        (k1, max): (usize, f64),
        b: &mut LineBuffers,
        hint: &mut usize,
    ) -> Option<usize> {
        let (t, kk) = (self.t, self.from);
        let limit = t[kk] + max * (1.0 + 1e-9);
        let mut ke = kk + 1;
        while ke + 1 < k1 && t[ke + 1] <= limit && ke - kk < *hint {
            ke += 1;
        }
        if ke < kk + 2 {
            return None;
        }
        let n = sys.n();
        let nx = 2 * n;
        let m = self.u.len();
        let dim = cur.len() - sys.tangent_len();
        let t0 = t[kk];
        let tol = 1e-9 * (t[kk + 1] - t0);
        let LineBuffers {
            stairs,
            gain,
            start,
            mid,
            end,
            held: now,
        } = b;
        stairs.over(t, self.u, self.held, (kk, ke), tol);
        for (j, v) in now.iter_mut().enumerate() {
            *v = stairs.first(j);
        }
        if !sys.classify(&cur[..nx], now, None) || !sys.input_gain(&cur[..nx], now, gain) {
            return None;
        }
        // the longest span whose staircase the line follows at the samples
        // inside
        let follows = |stairs: &Staircase, ke: usize| {
            (kk + 1..ke).all(|i| {
                let s = t[i] - t0;
                (0..n).all(|c| {
                    gain_row_times(gain, (c, m), |l| stairs.inside_error(l, s)).abs()
                        <= SPAN_TOLERANCE
                })
            })
        };
        while !follows(stairs, ke) {
            ke = kk + (ke - kk) / 2;
            if ke < kk + 2 {
                return None;
            }
            stairs.over(t, self.u, self.held, (kk, ke), tol);
        }
        let held = self.held.0;
        sys.held(&mut cur[..dim]);
        // the step, shortened once where its estimate is above the
        // tolerance (by the estimate's fourth power in the length); the
        // next span starts from the length this one's estimate allows
        let mut retried = false;
        let len = loop {
            let len = t[ke] - t0;
            sys.begin_segment(&Segment::between_samples(len));
            stairs.line(start, mid, end);
            if !sys.rhs(&cur[..dim], start, held, Rate::Segment, &mut k.k1[..dim])
                || !k.finish_between(
                    sys,
                    &cur[..dim],
                    (mid, end),
                    held,
                    Rate::Segment,
                    len,
                    &mut zt[..dim],
                )
                || !zt[..dim].iter().all(|v| v.is_finite())
                || !sys.rhs(&zt[..dim], end, held, Rate::Segment, &mut k.k2[..dim])
            {
                return None;
            }
            let worst = k.span_estimate(n, len);
            if worst.is_nan() {
                return None;
            }
            // the estimate grows as the length's fourth power: it would
            // equal the tolerance at `(tol / est)^(1/4)` times this length;
            // 0.9 of that (an estimate 0.9^4 = 0.66 of the tolerance) leaves
            // room for its change from one span to the next
            let intervals = (ke - kk) as f64;
            let allowed = intervals * 0.9 * (SPAN_TOLERANCE / worst).sqrt().sqrt();
            *hint = (allowed.floor() as usize).clamp(2, 2 * (ke - kk));
            if worst <= SPAN_TOLERANCE {
                break len;
            }
            if retried || *hint >= ke - kk {
                return None;
            }
            retried = true;
            ke = kk + *hint;
            stairs.over(t, self.u, self.held, (kk, ke), tol);
            if !follows(stairs, ke) {
                return None;
            }
        };
        let dry = sys.has_dry();
        let mut holds = |sys: &mut D, x: &[f64], s: f64, now: &mut [f64]| {
            if !dry {
                return true;
            }
            for (j, v) in now.iter_mut().enumerate() {
                *v = stairs.before(j, s);
            }
            sys.guards(x, now, g) && g.iter().all(|v| *v >= 0.0)
        };
        if !holds(sys, &zt[..nx], len, now) {
            return None;
        }
        inside.resize((ke - kk - 1) * dim, 0.0);
        let (f0, f1) = (&k.k1[..dim], &k.k2[..dim]);
        for (i, z_i) in inside.chunks_exact_mut(dim).enumerate() {
            let s = t[kk + 1 + i] - t0;
            hermite((&cur[..dim], &zt[..dim]), (f0, f1), (s / len, len), z_i);
            if !z_i.iter().all(|v| v.is_finite()) || !holds(sys, &z_i[..nx], s, now) {
                return None;
            }
            // a sliding dry joint's velocity must be farther from zero than
            // the staircase's trajectory can be from the line's there (G
            // E1): otherwise the two may stop at different samples
            if dry {
                let dir = &sys.mode().dir;
                for j in 0..n {
                    if dir[j] != 0.0
                        && z_i[n + j].abs()
                            <= gain_row_times(gain, (j, m), |l| stairs.inside_rate_error(l, s))
                                .abs()
                    {
                        return None;
                    }
                }
            }
        }
        std::mem::swap(cur, zt);
        Some(ke)
    }
}

/// The state at fraction `th` of a step of length `len` from `z0` (rates
/// `f0`) to `z1` (rates `f1`) by the step's cubic Hermite interpolant, into
/// `out`; in the form that leaves a held entry exactly where it is.
fn hermite(
    (z0, z1): (&[f64], &[f64]),
    (f0, f1): (&[f64], &[f64]),
    (th, len): (f64, f64),
    out: &mut [f64],
) {
    let rest = 1.0 - th;
    let h10 = th * rest * rest * len;
    let h01 = th * th * (3.0 - 2.0 * th);
    let h11 = -th * th * rest * len;
    for e in 0..out.len() {
        out[e] = z0[e] + h01 * (z1[e] - z0[e]) + h10 * f0[e] + h11 * f1[e];
    }
}

/// Row `c` of an input gain `G` (`m` columns, row-major) times the inputs'
/// `errors`.
fn gain_row_times(gain: &[f64], (c, m): (usize, usize), errors: impl Fn(usize) -> f64) -> f64 {
    (0..m).map(|l| gain[c * m + l] * errors(l)).sum()
}

/// The stage buffers of one RK4 step over vectors of a given length.
struct Stages {
    k1: Vec<f64>,
    k2: Vec<f64>,
    k3: Vec<f64>,
    k4: Vec<f64>,
    tmp: Vec<f64>,
    out: Vec<f64>,
}

impl Stages {
    fn new(len: usize) -> Stages {
        Stages {
            k1: vec![0.0; len],
            k2: vec![0.0; len],
            k3: vec![0.0; len],
            k4: vec![0.0; len],
            tmp: vec![0.0; len],
            out: vec![0.0; len],
        }
    }

    /// Stages 2 to 4 and the update of an RK4 step of length `h` from `z`
    /// (its first stage in `k1`), into `out` (`z.len()` entries).
    #[allow(clippy::too_many_arguments)]
    fn finish<D: Dynamics>(
        &mut self,
        sys: &mut D,
        z: &[f64],
        u: &[f64],
        held: &[usize],
        rate: Rate,
        h: f64,
        out: &mut [f64],
    ) -> bool {
        self.finish_between(sys, z, (u, u), held, rate, h, out)
    }

    /// [`Stages::finish`] with the input `mid` at the middle stages and
    /// `end` at the last (an input that is a line over the step, see
    /// [`AffineSpan`]; the first stage's rates in `k1` are the caller's).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn finish_between<D: Dynamics>(
        &mut self,
        sys: &mut D,
        z: &[f64],
        (mid, end): (&[f64], &[f64]),
        held: &[usize],
        rate: Rate,
        h: f64,
        out: &mut [f64],
    ) -> bool {
        let dim = z.len();
        let (k1, k2, k3, k4, tmp) = (
            &self.k1[..dim],
            &mut self.k2[..dim],
            &mut self.k3[..dim],
            &mut self.k4[..dim],
            &mut self.tmp[..dim],
        );
        for i in 0..dim {
            tmp[i] = z[i] + 0.5 * h * k1[i];
        }
        if !sys.rhs(tmp, mid, held, rate, k2) {
            return false;
        }
        for i in 0..dim {
            tmp[i] = z[i] + 0.5 * h * k2[i];
        }
        if !sys.rhs(tmp, mid, held, rate, k3) {
            return false;
        }
        for i in 0..dim {
            tmp[i] = z[i] + h * k3[i];
        }
        if !sys.rhs(tmp, end, held, rate, k4) {
            return false;
        }
        for i in 0..dim {
            out[i] = z[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        true
    }

    /// The largest embedded error estimate of a span's step of length
    /// `len` over the `n` coordinates, whose end rates are in `k2` (see
    /// [`Span`]): a position's `len/6 |k4 - f(z1)|`, a velocity's times
    /// `len` (the distance it covers); NaN when one is.
    fn span_estimate(&self, n: usize, len: f64) -> f64 {
        let mut worst = 0.0f64;
        for i in 0..2 * n {
            let reach = if i < n { len / 6.0 } else { len * len / 6.0 };
            let estimate = reach * (self.k4[i] - self.k2[i]).abs();
            if estimate.is_nan() {
                return f64::NAN;
            }
            worst = worst.max(estimate);
        }
        worst
    }

    /// An RK4 step of the state alone ([`Dynamics::state_rhs`]) of length
    /// `h` from `x`, into `self.out`.
    fn step<D: Dynamics>(&mut self, sys: &mut D, x: &[f64], u: &[f64], h: f64) -> bool {
        let dim = x.len();
        if !sys.state_rhs(x, u, &mut self.k1) {
            return false;
        }
        for i in 0..dim {
            self.tmp[i] = x[i] + 0.5 * h * self.k1[i];
        }
        if !sys.state_rhs(&self.tmp, u, &mut self.k2) {
            return false;
        }
        for i in 0..dim {
            self.tmp[i] = x[i] + 0.5 * h * self.k2[i];
        }
        if !sys.state_rhs(&self.tmp, u, &mut self.k3) {
            return false;
        }
        for i in 0..dim {
            self.tmp[i] = x[i] + h * self.k3[i];
        }
        if !sys.state_rhs(&self.tmp, u, &mut self.k4) {
            return false;
        }
        for i in 0..dim {
            self.out[i] =
                x[i] + h / 6.0 * (self.k1[i] + 2.0 * self.k2[i] + 2.0 * self.k3[i] + self.k4[i]);
        }
        true
    }
}

/// `dz(u) = sign(u) * max(|u| - w, 0)` for `w >= 0`, computed as `u - w`
/// above `w`, `u + w` below `-w` and `0` in between, so `w = 0` returns `u`
/// itself (up to the sign of a zero).
pub fn deadzone(u: f64, w: f64) -> f64 {
    if u > w {
        u - w
    } else if u < -w {
        u + w
    } else {
        0.0
    }
}

/// `sat(u) = min(max(u, -l), l)` for `l > 0` (`l = inf`: no saturation,
/// `u` itself).
pub fn saturation(u: f64, l: f64) -> f64 {
    u.clamp(-l, l)
}

/// What the plant receives for the commanded held value `u` of an input
/// with deadzone half-width `w` and saturation level `l`: `sat(dz(u))`.
pub fn received(u: f64, w: f64, l: f64) -> f64 {
    saturation(deadzone(u, w), l)
}

/// `d received / d(w, l)` at a received held value `v` of an input with
/// saturation level `l`: `(0, sign(v))` where the saturation clips (`|v| =
/// l`), `(-sign(v), 0)` elsewhere (zero inside the deadzone, where `v = 0`).
/// At the kinks (`|dz(u)| = l`, `|u| = w`) the one-sided derivative of the
/// clipped and of the outside branch is used.
pub(crate) fn received_derivatives(v: f64, l: f64) -> (f64, f64) {
    if v.abs() >= l {
        (0.0, v.signum())
    } else if v != 0.0 {
        (-v.signum(), 0.0)
    } else {
        (0.0, 0.0)
    }
}

/// The held input samples with each input `j` passed through
/// `received(u, widths[j], levels[j])` sample by sample (the input is held,
/// so this is exact): the working copy an integration reads (and, in closed
/// loop, writes).
pub(crate) fn held_inputs(sig: &Signals, widths: &[f64], levels: &[f64]) -> Vec<Vec<f64>> {
    sig.u
        .iter()
        .enumerate()
        .map(|(j, u)| {
            let w = widths.get(j).copied().unwrap_or(0.0);
            let l = levels.get(j).copied().unwrap_or(f64::INFINITY);
            if w == 0.0 && l == f64::INFINITY {
                u.clone()
            } else {
                u.iter().map(|&v| received(v, w, l)).collect()
            }
        })
        .collect()
}

/// Sensor offsets, input delays, deadzone widths and saturation levels of a
/// model, compiled over the full parameter vector, with their derivatives
/// along free base parameters. Outputs: offsets (one per coordinate), delays
/// (one per input), widths (one per input), levels (one per input, 0 where
/// the input has none), then per free parameter the derivatives of the
/// offsets, the delays, the widths and the levels.
#[derive(Clone, Debug)]
pub(crate) struct SignalEffects {
    tape: Tape,
    n: usize,
    m: usize,
    p: usize,
    inputs: Vec<String>,
    /// Whether each input has a saturation.
    saturated: Vec<bool>,
    /// True if some delay depends on some free parameter.
    pub(crate) delay_depends_on_free: bool,
    /// True if some deadzone width or saturation level depends on some free
    /// parameter.
    pub(crate) deadzone_depends_on_free: bool,
    /// True if no input has a delay, a deadzone or a saturation (whatever
    /// the parameters' values).
    plain_inputs: bool,
}

/// Evaluated [`SignalEffects`].
pub(crate) struct SignalValues {
    /// Sensor offset per coordinate (SI).
    pub(crate) offsets: Vec<f64>,
    /// Delay per input in s.
    pub(crate) delays: Vec<f64>,
    /// `d offset_i / d theta_j` at `[j * n + i]`.
    pub(crate) d_offsets: Vec<f64>,
    /// `d delay_l / d theta_j` at `[j * m + l]`.
    pub(crate) d_delays: Vec<f64>,
    /// Deadzone width per input (SI, the input's unit).
    pub(crate) widths: Vec<f64>,
    /// `d width_l / d theta_j` at `[j * m + l]`.
    pub(crate) d_widths: Vec<f64>,
    /// Saturation level per input (SI, the input's unit; infinite without
    /// a saturation).
    pub(crate) levels: Vec<f64>,
    /// `d level_l / d theta_j` at `[j * m + l]`.
    pub(crate) d_levels: Vec<f64>,
}

impl SignalEffects {
    /// Compile for `model` with derivatives along the base parameters `free`
    /// (indices into `model.parameters`).
    pub(crate) fn new(model: &Model, free: &[usize]) -> Result<SignalEffects, SimError> {
        let n = model.coordinates.len();
        let m = model.inputs.len();
        let values: Vec<Expr> = (0..n)
            .map(|i| model.sensor_offset(i))
            .chain((0..m).map(|j| model.input_delay(j)))
            .chain((0..m).map(|j| model.input_deadzone(j)))
            .chain((0..m).map(|j| model.input_saturation(j).unwrap_or_else(Expr::zero)))
            .collect();
        let expanded: Vec<Expr> = values.iter().map(|e| model.expand_derived(*e)).collect();
        let mut outs = values;
        let mut delay_depends_on_free = false;
        let mut deadzone_depends_on_free = false;
        for &i in free {
            let p = model.parameters[i].symbol;
            for (k, e) in expanded.iter().enumerate() {
                let d = diff(*e, p);
                if !d.is_zero() {
                    if k >= n + m {
                        deadzone_depends_on_free = true;
                    } else if k >= n {
                        delay_depends_on_free = true;
                    }
                }
                outs.push(d);
            }
        }
        let tape = Tape::compile(&outs, &model.parameter_symbols())
            .map_err(|e| SimError::Tape(e.to_string()))?;
        Ok(SignalEffects {
            tape,
            n,
            m,
            p: free.len(),
            inputs: model.inputs.iter().map(|i| i.name.clone()).collect(),
            saturated: (0..m)
                .map(|j| model.input_saturation(j).is_some())
                .collect(),
            delay_depends_on_free,
            deadzone_depends_on_free,
            plain_inputs: (0..m).all(|j| {
                model.input_delay(j).is_zero()
                    && model.input_deadzone(j).is_zero()
                    && model.input_saturation(j).is_none()
            }),
        })
    }

    /// Evaluate at the full parameter vector; a negative or non-finite
    /// delay or deadzone width, or a saturation level that is not positive
    /// and finite, is an error.
    pub(crate) fn eval(&self, params: &[f64]) -> Result<SignalValues, SimError> {
        if params.len() != self.tape.inputs().len() {
            return Err(SimError::ParameterCount {
                expected: self.tape.inputs().len(),
                found: params.len(),
            });
        }
        let out = self.tape.eval_vec(params);
        let (n, m, p) = (self.n, self.m, self.p);
        let delays = out[n..n + m].to_vec();
        for (j, &d) in delays.iter().enumerate() {
            if !(d >= 0.0 && d.is_finite()) {
                return Err(SimError::BadDelay {
                    input: self.inputs[j].clone(),
                    value: d,
                });
            }
        }
        let widths = out[n + m..n + 2 * m].to_vec();
        for (j, &w) in widths.iter().enumerate() {
            if !(w >= 0.0 && w.is_finite()) {
                return Err(SimError::BadDeadzone {
                    input: self.inputs[j].clone(),
                    value: w,
                });
            }
        }
        let mut levels = out[n + 2 * m..n + 3 * m].to_vec();
        for (j, l) in levels.iter_mut().enumerate() {
            if !self.saturated[j] {
                *l = f64::INFINITY;
            } else if !(*l > 0.0 && l.is_finite()) {
                return Err(SimError::BadSaturation {
                    input: self.inputs[j].clone(),
                    value: *l,
                });
            }
        }
        let blk_len = n + 3 * m;
        let mut d_offsets = Vec::with_capacity(n * p);
        let mut d_delays = Vec::with_capacity(m * p);
        let mut d_widths = Vec::with_capacity(m * p);
        let mut d_levels = Vec::with_capacity(m * p);
        for j in 0..p {
            let blk = &out[blk_len * (j + 1)..blk_len * (j + 2)];
            d_offsets.extend_from_slice(&blk[..n]);
            d_delays.extend_from_slice(&blk[n..n + m]);
            d_widths.extend_from_slice(&blk[n + m..n + 2 * m]);
            d_levels.extend_from_slice(&blk[n + 2 * m..]);
        }
        Ok(SignalValues {
            offsets: out[..n].to_vec(),
            delays,
            d_offsets,
            d_delays,
            widths,
            d_widths,
            levels,
            d_levels,
        })
    }
}

/// The largest stable RK4 substep for a model's stiffest damping: the
/// velocity Jacobian of the right-hand side at zero velocity (where smoothed
/// dry friction `F tanh(v/w)` is steepest, `F/w`), through `M^-1`, bounds
/// the fastest decay rate `lambda` (largest absolute row sum); RK4 is stable
/// for real decays up to `2.78/h`, and the substep is kept below
/// `2.5/lambda`. A gearbox holding the arm (`Fg1 = 0.1 N m` with `w = 1e-3`)
/// needs about 0.1 ms where the default is 1 ms (notes trap 8). Built only
/// where a `sign()` is smoothed ([`DryFriction::Smooth`], or a fallback):
/// a sticking dry friction is not stiff.
#[derive(Clone, Debug)]
pub(crate) struct StiffnessProbe {
    n: usize,
    m: usize,
    /// `(state, inputs, full parameters)` -> `[M (n*n), d r0/d v (n*n)]`.
    tape: Tape,
}

impl StiffnessProbe {
    pub(crate) fn new(model: &Model, outs: &[Expr]) -> Result<StiffnessProbe, SimError> {
        let n = model.coordinates.len();
        let m = model.inputs.len();
        let mut exprs: Vec<Expr> = outs[..n * n].to_vec();
        let vs: Vec<Symbol> = model.state_symbols()[n..].to_vec();
        for i in 0..n {
            for v in &vs {
                exprs.push(diff(outs[n * n + i], *v));
            }
        }
        let tape = Tape::compile(&exprs, &tape_inputs(model))
            .map_err(|e| SimError::Tape(e.to_string()))?;
        Ok(StiffnessProbe { n, m, tape })
    }

    /// The substep limit at positions `q`, zero velocities, input `u`.
    pub(crate) fn limit(&self, q: &[f64], u: &[f64], params: &[f64]) -> f64 {
        let n = self.n;
        let Some(rows) = self.rates(q, &vec![0.0; n], u, params) else {
            return f64::INFINITY;
        };
        let rate = largest_row_sum(&rows, n);
        if rate > 0.0 && rate.is_finite() {
            2.5 / rate
        } else {
            f64::INFINITY
        }
    }

    /// The velocities (state indices `n + j`) whose dry friction alone
    /// keeps the substep below `long` (width `w`): at zero speed their
    /// columns are what makes it short, and at `5 w` on them the whole
    /// matrix allows `long` (a stiffness that does not fade with speed, a
    /// stiff viscous or back-EMF term, does not qualify). None when there
    /// are none.
    pub(crate) fn stiff_velocities(
        &self,
        q: &[f64],
        u: &[f64],
        params: &[f64],
        (long, w): (f64, f64),
    ) -> Option<Vec<usize>> {
        let n = self.n;
        let allowed = 2.5 / long;
        let rows = self.rates(q, &vec![0.0; n], u, params)?;
        let column = |j: usize| (0..n).map(|i| rows[i * n + j].abs()).sum::<f64>();
        let stiff: Vec<usize> = (0..n).filter(|&j| column(j) > 0.5 * allowed).collect();
        if stiff.is_empty() {
            return None;
        }
        let v: Vec<f64> = (0..n)
            .map(|j| if stiff.contains(&j) { 5.0 * w } else { 0.0 })
            .collect();
        let moving = self.rates(q, &v, u, params)?;
        (largest_row_sum(&moving, n) <= allowed).then(|| stiff.iter().map(|j| n + j).collect())
    }

    /// `M^-1 d r0/d v` (row-major) at positions `q`, velocities `v`, input
    /// `u`; None when `M` is singular there.
    fn rates(&self, q: &[f64], v: &[f64], u: &[f64], params: &[f64]) -> Option<Vec<f64>> {
        let (n, m) = (self.n, self.m);
        let mut tin = vec![0.0; 2 * n + m + params.len()];
        tin[..n].copy_from_slice(&q[..n]);
        tin[n..2 * n].copy_from_slice(&v[..n]);
        tin[2 * n..2 * n + m].copy_from_slice(&u[..m]);
        tin[2 * n + m..].copy_from_slice(params);
        let out = self.tape.eval_vec(&tin);
        let mut mm = out[..n * n].to_vec();
        let mut piv = vec![0; n];
        if !lu_factor(&mut mm, n, &mut piv) {
            return None;
        }
        let mut tmp = vec![0.0; n];
        let mut rows = vec![0.0; n * n];
        for j in 0..n {
            let mut col: Vec<f64> = (0..n).map(|i| out[n * n + i * n + j]).collect();
            lu_solve(&mm, n, &piv, &mut col, &mut tmp);
            for i in 0..n {
                rows[i * n + j] = col[i];
            }
        }
        Some(rows)
    }
}

/// The infinity norm of the row-major `n x n` matrix `a` (a bound on its
/// eigenvalues' magnitudes).
fn largest_row_sum(a: &[f64], n: usize) -> f64 {
    (0..n)
        .map(|i| a[i * n..(i + 1) * n].iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0f64, f64::max)
}

/// What both simulators do before integrating: check the parameter vector
/// and the signals against the model's sizes `(n, m, n_params)`, choose the
/// substep (probed for stiffness only where a `sign()` is smoothed; spans
/// only with neither an explicit substep, a smoothed `sign()` nor a
/// controller in the loop, `closed_loop`, which writes the input at every
/// sample), evaluate the signal effects at `params` and make the working
/// copy of the held inputs with the deadzones and saturations applied.
pub(crate) fn prepare_run(
    sig: &Signals,
    params: &[f64],
    (n, m, n_params): (usize, usize, usize),
    opts: &SimOptions,
    signals: &SignalEffects,
    (probe, closed_loop): (Option<&StiffnessProbe>, bool),
    x0: &[f64],
) -> Result<(Substep, SignalValues, Vec<Vec<f64>>), SimError> {
    if params.len() != n_params {
        return Err(SimError::ParameterCount {
            expected: n_params,
            found: params.len(),
        });
    }
    if sig.q.len() != n || sig.u.len() != m {
        return Err(SimError::BadOption(format!(
            "signals of `{}` do not match the model's coordinates and inputs",
            sig.name
        )));
    }
    let h = substep_for(sig, opts)?;
    let effects = signals.eval(params)?;
    let u = held_inputs(sig, &effects.widths, &effects.levels);
    let mut step = Substep::fixed(h);
    if let (None, Some(probe), true) = (opts.substep, probe, x0.len() >= n) {
        let u0: Vec<f64> = u
            .iter()
            .map(|v| v.first().copied().unwrap_or(0.0))
            .collect();
        step.h = h.min(probe.limit(x0, &u0, params));
        if step.h < MIN_SUBSTEP {
            return Err(SimError::TooStiff {
                experiment: sig.name.clone(),
                substep: step.h,
            });
        }
        // away from zero speed the dry friction is not stiff: one substep
        // per sample up to 2 ms (RK4's error at the pendulum's 10 rad/s is
        // then ~3e-11 per step)
        let long = sig.sample_time().min(2e-3);
        let w = match opts.dry_friction {
            DryFriction::Smooth { width } => width,
            DryFriction::SmoothFitted { parameter } => params
                .get(parameter)
                .copied()
                .unwrap_or(FALLBACK_SIGN_WIDTH),
            DryFriction::Sticking => FALLBACK_SIGN_WIDTH,
        };
        if long > step.h {
            if let Some(stiff) = probe.stiff_velocities(x0, &u0, params, (long, w)) {
                step.relaxed = Some((long, stiff, w));
            }
        }
    }
    if opts.substep.is_none() && probe.is_none() && !closed_loop {
        step.span = Some(MAX_SPAN);
        step.affine = signals.plain_inputs;
    }
    Ok((step, effects, u))
}

/// The longest span ([`Substep::span`]): one RK4 step over the sample
/// intervals of up to 8 ms where the inputs hold. At the pendulum's 10.7
/// rad/s, swinging 1.2 rad for 20 s with light damping, 8 ms steps stay
/// within 5.9e-6 rad RMS (1.1e-5 max) of 0.5 ms steps (2 ms steps: 2.5e-8;
/// 16 ms: 8.4e-5), a 75th of a 4096-count encoder's quantisation floor
/// (4.4e-4 rad RMS) and 2e-4 of its cost: a plain RK4 in f64, measured
/// 2026-11-29. Faster dynamics are caught by [`SPAN_TOLERANCE`].
pub const MAX_SPAN: f64 = 8e-3;

/// The largest embedded error estimate of a span's step (in the
/// coordinates' SI unit: rad or m) for the span to be taken: 5e-7, just
/// above the largest an 8 ms step makes on the pendulum of [`MAX_SPAN`]
/// (3.7e-7 rad; 2 ms steps 1.5e-9). The estimate grows as `(len w)^4`:
/// dynamics 1.1 times faster than that pendulum's, or a wider swing, and a
/// span falls back to one step per interval where it would cost accuracy.
pub const SPAN_TOLERANCE: f64 = 5e-7;

/// The shortest automatic RK4 substep with a smoothed dry friction, in s.
/// Below it a simulation is refused ([`SimError::TooStiff`]) rather than
/// run at thousands of substeps per sample: a fit that wandered to a dry
/// friction of 0.084 N m on the QUBE's arm (substep about 6 us) spent 285 s
/// in 143 simulations. Ten times below what a gearbox holding the
/// pendulum's arm needs (`Fg1 = 0.1 N m`, `w = 1e-3`: about 0.1 ms). A
/// sticking dry friction is not stiff and never needs it.
pub const MIN_SUBSTEP: f64 = 1e-5;

/// The longest automatic RK4 substep, in s: 2 ms keeps RK4's local error at
/// the pendulum's 10 rad/s near 3e-11 rad per step, far below an encoder's
/// quantum (1.5e-3 rad at 4096 counts/rev).
pub const MAX_SUBSTEP: f64 = 2e-3;

/// The substep for an experiment under `opts`: the given one, or, with
/// sticking friction (nothing stiff at zero speed), one substep per sample
/// up to [`MAX_SUBSTEP`]; with the smooth law `min(1 ms, T/2)`, which its
/// stiffness at zero speed needs (notes trap 8).
pub(crate) fn substep_for(sig: &Signals, opts: &SimOptions) -> Result<f64, SimError> {
    substep_at(sig.sample_time(), opts)
}

/// [`substep_for`] a record sampled every `dt` seconds.
pub(crate) fn substep_at(dt: f64, opts: &SimOptions) -> Result<f64, SimError> {
    match (opts.substep, opts.dry_friction) {
        (Some(h), _) if h > 0.0 && h.is_finite() => Ok(h),
        (Some(h), _) => Err(SimError::BadOption(format!(
            "substep must be positive, got {h}"
        ))),
        (None, DryFriction::Sticking) => Ok(dt.min(MAX_SUBSTEP)),
        (None, DryFriction::Smooth { .. } | DryFriction::SmoothFitted { .. }) => {
            Ok((dt / 2.0).min(1e-3))
        }
    }
}

/// Where a simulated block of a record starts: the samples it covers, the
/// true state at its first sample, and per-experiment offsets added to the
/// measured coordinates (an encoder's zero, on top of the model's
/// `sensor_offset`s).
#[derive(Clone, Debug, PartialEq)]
pub struct BlockStart {
    /// Samples simulated: `k0..k1` of the record.
    pub range: std::ops::Range<usize>,
    /// True state at `t_k0`: positions then velocities.
    pub x0: Vec<f64>,
    /// Added to each simulated coordinate to give its measurement (one per
    /// coordinate, usually zeros).
    pub offsets: Vec<f64>,
}

impl BlockStart {
    /// The whole record from the state the data give: measured positions
    /// (minus the model's sensor offsets `model_offsets`) and velocities as
    /// `how` says.
    pub fn from_data(sig: &Signals, how: InitialVelocity, model_offsets: &[f64]) -> BlockStart {
        BlockStart {
            range: 0..sig.len(),
            x0: initial_state(sig, how, model_offsets),
            offsets: vec![0.0; sig.q.len()],
        }
    }

    /// [`BlockStart::from_data`] over the first `n` samples only (clamped
    /// to the record's length).
    pub fn first_samples(
        sig: &Signals,
        how: InitialVelocity,
        model_offsets: &[f64],
        n: usize,
    ) -> BlockStart {
        let mut start = BlockStart::from_data(sig, how, model_offsets);
        start.range = 0..n.min(sig.len());
        start
    }
}

/// When a simulation with the automatic substep diverges, it is tried once
/// more with the substep divided by this: a smoothed dry friction (a gearbox
/// holding the arm, notes trap 8) needs steps well below 1 ms, and so may a
/// fit's wild trial point, while most records do not.
pub const REFINE: f64 = 8.0;

/// A compiled simulator of one model.
#[derive(Clone, Debug)]
pub struct Simulator {
    n: usize,
    m: usize,
    n_params: usize,
    /// The dynamics over `(state, inputs, full parameters)`.
    tape: Tape,
    /// `tape` split with the parameters as slow inputs.
    split: SplitTape,
    /// Which coordinates stick.
    dry: Vec<bool>,
    /// Whether the tape's outputs end with the dry-friction levels.
    levels: bool,
    notes: Vec<String>,
    signals: SignalEffects,
    opts: SimOptions,
    /// A recorded controller in the loop.
    law: Option<LoopLaw>,
    /// Only where a `sign()` is smoothed.
    probe: Option<StiffnessProbe>,
}

/// Check the options both simulators compile with: a dry friction width
/// must be positive.
pub(crate) fn check_options(opts: &SimOptions) -> Result<(), SimError> {
    match opts.dry_friction {
        DryFriction::Smooth { width: w } if !(w > 0.0 && w.is_finite()) => Err(
            SimError::BadOption(format!("dry friction width must be positive, got {w}")),
        ),
        _ => Ok(()),
    }
}

/// The plain dynamics of one run over the split tape `[M, r0, B, D]`: the
/// state's rates in the current stick-slip mode, the mode's decisions and
/// its guards, buffers allocated once. Both simulators decide everything
/// that depends on the state alone (modes, events) through it, so their
/// trajectories agree to the bit.
pub(crate) struct StateDynamics<'s> {
    tape: &'s Tape,
    split: &'s SplitTape,
    unsplit: bool,
    n: usize,
    m: usize,
    /// Whether the tape's outputs end with the levels.
    levels: bool,
    dry: bool,
    tin: Vec<f64>,
    out: Vec<f64>,
    scratch: Vec<f64>,
    /// The stick-slip rules (and their solve buffers).
    pub(crate) rules: StickSlip,
    /// The current mode.
    pub(crate) mode: Mode,
    minv: Vec<f64>,
    b: Vec<f64>,
    d: Vec<f64>,
    beff: Vec<f64>,
    acc: Vec<f64>,
    force: Vec<f64>,
    /// `(x, u)` of the outputs in `out`, when `cached`.
    last: Vec<f64>,
    cached: bool,
}

impl<'s> StateDynamics<'s> {
    /// For a tape (and its split) over `(state, inputs, params)` with `n`
    /// coordinates and `m` inputs, `dry` the sticking coordinates, `levels`
    /// whether the outputs end with `D`; the tape's parameter part is
    /// evaluated here, once.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        (tape, split): (&'s Tape, &'s SplitTape),
        (n, m): (usize, usize),
        params: &[f64],
        dry: &[bool],
        levels: bool,
        unsplit: bool,
    ) -> StateDynamics<'s> {
        let mut tin = vec![0.0; 2 * n + m + params.len()];
        tin[2 * n + m..].copy_from_slice(params);
        let mut out = vec![0.0; tape.n_outputs()];
        let mut scratch = vec![0.0; tape.scratch_len().max(split.scratch_len())];
        if !unsplit {
            split.eval_slow_outputs(&tin, &mut out, &mut scratch);
        }
        StateDynamics {
            tape,
            split,
            unsplit,
            n,
            m,
            levels,
            dry: dry.iter().any(|d| *d),
            tin,
            out,
            scratch,
            rules: StickSlip::new(dry),
            mode: Mode::new(n),
            minv: vec![0.0; n * n],
            b: vec![0.0; n],
            d: vec![0.0; n],
            beff: vec![0.0; n],
            acc: vec![0.0; n],
            force: vec![0.0; n],
            last: vec![0.0; 2 * n + m],
            cached: false,
        }
    }

    /// `M`, `b = r0 + B u` and the levels at `(x, u)` (the tape's outputs,
    /// `self.b`, `self.d`); the last evaluation is reused at the same point.
    fn eval(&mut self, x: &[f64], u: &[f64]) {
        let (n, m) = (self.n, self.m);
        let same = self.cached
            && self.last[..2 * n]
                .iter()
                .zip(&x[..2 * n])
                .chain(self.last[2 * n..].iter().zip(u))
                .all(|(a, b)| a.to_bits() == b.to_bits());
        if same {
            return;
        }
        copy_short(&mut self.tin[..2 * n], &x[..2 * n]);
        copy_short(&mut self.tin[2 * n..2 * n + m], u);
        if self.unsplit {
            self.tape.eval(&self.tin, &mut self.out, &mut self.scratch);
        } else {
            self.split
                .eval_fast_changed(&self.tin, &mut self.out, &mut self.scratch);
        }
        let nn = n * n;
        forces(
            &self.out[nn..nn + n],
            &self.out[nn + n..nn + n + n * m],
            u,
            &mut self.b,
        );
        if self.levels {
            let off = nn + n + n * m;
            copy_short(&mut self.d, &self.out[off..off + n]);
        }
        copy_short(&mut self.last[..2 * n], &x[..2 * n]);
        copy_short(&mut self.last[2 * n..], u);
        self.cached = true;
    }

    /// The accelerations of the current mode at `(x, u)` into `self.acc`;
    /// false when the (free part of the) mass matrix is singular.
    fn accelerations(&mut self, x: &[f64], u: &[f64]) -> bool {
        self.eval(x, u);
        let n = self.n;
        if !self
            .rules
            .free_inverse(&self.out[..n * n], &self.mode.stuck, &mut self.minv)
        {
            return false;
        }
        StickSlip::effective_forces(&self.b, &self.d, &self.mode, &mut self.beff);
        mat_vec(&self.minv, n, &self.beff, &mut self.acc);
        true
    }

    /// Decide the mode at `(x, u)`; `release` breaks a stuck joint away.
    pub(crate) fn classify(&mut self, x: &[f64], u: &[f64], release: Option<usize>) -> bool {
        if !self.dry {
            return true;
        }
        let n = self.n;
        if self.rules.slide(&x[n..2 * n], &mut self.mode) {
            return true;
        }
        self.eval(x, u);
        self.rules.classify(
            &self.out[..n * n],
            &self.b,
            &self.d,
            &x[n..2 * n],
            release,
            &mut self.mode,
        )
    }

    /// `M^-1 B` of the current mode at `(x, u)` ([`Dynamics::input_gain`]).
    pub(crate) fn input_gain(&mut self, x: &[f64], u: &[f64], g: &mut [f64]) -> bool {
        self.eval(x, u);
        let (n, m) = (self.n, self.m);
        if !self
            .rules
            .free_inverse(&self.out[..n * n], &self.mode.stuck, &mut self.minv)
        {
            return false;
        }
        let b = &self.out[n * n + n..n * n + n + n * m];
        for i in 0..n {
            for l in 0..m {
                g[i * m + l] = (0..n).map(|k| self.minv[i * n + k] * b[k * m + l]).sum();
            }
        }
        true
    }

    /// `dx = (v, a)` of the current mode.
    pub(crate) fn rates(&mut self, x: &[f64], u: &[f64], dx: &mut [f64]) -> bool {
        if !self.accelerations(x, u) {
            return false;
        }
        let n = self.n;
        copy_short(&mut dx[..n], &x[n..2 * n]);
        copy_short(&mut dx[n..2 * n], &self.acc);
        true
    }

    /// The guards of the current mode at `(x, u)`.
    pub(crate) fn guards(&mut self, x: &[f64], u: &[f64], g: &mut [f64]) -> bool {
        let n = self.n;
        if self.mode.any_stuck() {
            if !self.accelerations(x, u) {
                return false;
            }
            self.rules.holding_forces(
                &self.out[..n * n],
                &self.b,
                &self.acc,
                &self.mode,
                &mut self.force,
            );
        }
        self.rules
            .guards(&x[n..2 * n], &self.d, &self.force, &self.mode, g);
        true
    }
}

impl Dynamics for StateDynamics<'_> {
    fn n(&self) -> usize {
        self.n
    }
    fn has_dry(&self) -> bool {
        self.dry
    }
    fn dry_joints(&self) -> usize {
        self.rules.dry().iter().filter(|d| **d).count()
    }
    fn classify(&mut self, x: &[f64], u: &[f64], release: Option<usize>) -> bool {
        StateDynamics::classify(self, x, u, release)
    }
    fn rhs(&mut self, z: &[f64], u: &[f64], _: &[usize], _: Rate, dz: &mut [f64]) -> bool {
        self.rates(z, u, dz)
    }
    fn state_rhs(&mut self, x: &[f64], u: &[f64], dx: &mut [f64]) -> bool {
        self.rates(x, u, dx)
    }
    fn guards(&mut self, x: &[f64], u: &[f64], g: &mut [f64]) -> bool {
        StateDynamics::guards(self, x, u, g)
    }
    fn mode(&self) -> &Mode {
        &self.mode
    }
    fn event(&mut self, z: &mut [f64], _: &[f64], _: &[usize], ev: &Located) -> bool {
        if !ev.stuck {
            z[self.n + ev.joint] = 0.0;
        }
        true
    }
    fn input_gain(&mut self, x: &[f64], u: &[f64], g: &mut [f64]) -> bool {
        StateDynamics::input_gain(self, x, u, g)
    }
}

/// The loop state at the start of a block: the law, the replay, evaluation
/// buffers, the replayed filter state and a buffer for the law's values.
pub(crate) type LoopStart<'s> = (&'s LoopLaw, &'s Replay, LoopEval, Vec<f64>, Vec<f64>);

/// The loop's state at the start of a block at `k0` of `sig` with `law` in
/// the loop; None in open loop (no law).
pub(crate) fn loop_start<'s>(
    law: Option<&'s LoopLaw>,
    sig: &'s Signals,
    k0: usize,
) -> Result<Option<LoopStart<'s>>, SimError> {
    let Some(law) = law else {
        return Ok(None);
    };
    let Some(rep) = &sig.replay else {
        return Err(SimError::BadOption(format!(
            "closed-loop simulation of `{}` needs its signals read for recorded controller `{}`",
            sig.name, law.name
        )));
    };
    let nf2 = rep.coeffs.len() * 2;
    let fstate = rep.state[k0 * nf2..(k0 + 1) * nf2].to_vec();
    Ok(Some((
        law,
        rep,
        LoopEval::new(law),
        fstate,
        vec![0.0; law.driven().len()],
    )))
}

/// Slow-input mask of a tape over `(state, inputs, parameters)` with
/// `n_fast` state and input entries first: the parameters are slow.
pub(crate) fn parameters_slow(n_fast: usize, n_params: usize) -> Vec<bool> {
    let mut slow = vec![false; n_fast];
    slow.resize(n_fast + n_params, true);
    slow
}

/// Evaluate a recorded law at sample `k` of a block: the measured
/// coordinates are the state's positions plus `offsets`; writes the held
/// value of every driven input at `k` (deadzone and saturation applied).
#[allow(clippy::too_many_arguments)] // the loop state of one sample, passed as it is
pub(crate) fn control_at(
    law: &LoopLaw,
    rep: &Replay,
    ev: &mut LoopEval,
    k: usize,
    y: &[f64],
    fstate: &mut [f64],
    u_law: &mut [f64],
    (widths, levels): (&[f64], &[f64]),
    u: &mut [Vec<f64>],
) {
    ev.step(law, rep, k, y, fstate, u_law, None);
    for (d, &j) in law.driven().iter().enumerate() {
        u[j][k] = received(
            u_law[d],
            widths.get(j).copied().unwrap_or(0.0),
            levels.get(j).copied().unwrap_or(f64::INFINITY),
        );
    }
}

impl Simulator {
    /// Derive and compile the dynamics of `model`.
    pub fn new(model: &Model, opts: SimOptions) -> Result<Simulator, SimError> {
        check_options(&opts)?;
        let c = dynamics_outputs(model, opts.dry_friction)?;
        let tape = Tape::compile(&c.outs, &tape_inputs(model))
            .map_err(|e| SimError::Tape(e.to_string()))?;
        let (n, m) = (model.coordinates.len(), model.inputs.len());
        let n_params = model.parameter_symbols().len();
        let split = tape.split_by_inputs(&parameters_slow(2 * n + m, n_params));
        let probe = if c.smoothed {
            Some(StiffnessProbe::new(model, &c.outs)?)
        } else {
            None
        };
        Ok(Simulator {
            n,
            m,
            n_params,
            tape,
            split,
            dry: c.dry,
            levels: c.levels,
            notes: c.notes,
            signals: SignalEffects::new(model, &[])?,
            opts,
            law: None,
            probe,
        })
    }

    /// The `sign()` terms that are not a dry friction of one coordinate and
    /// keep the smooth law, one sentence each (empty with the smooth law).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Which coordinates have a sticking dry friction (all false with the
    /// smooth law).
    pub fn sticking(&self) -> &[bool] {
        &self.dry
    }

    /// The same simulator with a recorded controller in the loop: every
    /// simulation then needs signals made by
    /// [`Signals::from_experiment_closed`] with the same law.
    pub fn with_loop(mut self, law: LoopLaw) -> Simulator {
        self.law = Some(law);
        self
    }

    /// The recorded controller in the loop, if any.
    pub fn law(&self) -> Option<&LoopLaw> {
        self.law.as_ref()
    }

    /// The options in use.
    pub fn options(&self) -> &SimOptions {
        &self.opts
    }

    /// The model's sensor offsets at `params` (one per coordinate).
    pub fn model_offsets(&self, params: &[f64]) -> Result<Vec<f64>, SimError> {
        Ok(self.signals.eval(params)?.offsets)
    }

    /// Simulate the first `n_samples` samples (clamped to the experiment's
    /// length) with parameter values `params` (the `full` vector of
    /// [`plantc_derive::model::ParameterValues`]: base then derived), from
    /// the measured initial state with velocities as the options say.
    pub fn simulate(
        &self,
        sig: &Signals,
        params: &[f64],
        n_samples: usize,
    ) -> Result<Trajectory, SimError> {
        self.run_n(sig, params, n_samples, false)
    }

    /// The first `n` samples from the measured state, the tape split or
    /// (`unsplit`, the tests' reference) not.
    fn run_n(
        &self,
        sig: &Signals,
        params: &[f64],
        n: usize,
        unsplit: bool,
    ) -> Result<Trajectory, SimError> {
        let offsets = self.model_offsets(params)?;
        let start = BlockStart::first_samples(sig, self.opts.initial_velocity, &offsets, n);
        self.run(sig, params, &start, unsplit)
    }

    /// Simulate one block of a record from a given state; the trajectory
    /// holds the predicted measurements at samples `k0..k1`.
    pub fn simulate_block(
        &self,
        sig: &Signals,
        params: &[f64],
        start: &BlockStart,
    ) -> Result<Trajectory, SimError> {
        self.run(sig, params, start, false)
    }

    /// [`Simulator::simulate_block`], evaluating the dynamics with the split
    /// tape (parameter part once per call) or, with `unsplit`, the whole
    /// tape at every stage: the reference path the tests compare against.
    fn run(
        &self,
        sig: &Signals,
        params: &[f64],
        start: &BlockStart,
        unsplit: bool,
    ) -> Result<Trajectory, SimError> {
        match self.run_refined(sig, params, start, unsplit, 1.0) {
            Err(SimError::Diverged { .. }) if self.opts.substep.is_none() => {
                self.run_refined(sig, params, start, unsplit, REFINE)
            }
            r => r,
        }
    }

    /// [`Simulator::run`] with the automatic substep divided by `refine`.
    fn run_refined(
        &self,
        sig: &Signals,
        params: &[f64],
        start: &BlockStart,
        unsplit: bool,
        refine: f64,
    ) -> Result<Trajectory, SimError> {
        let (h, effects, mut u) = prepare_run(
            sig,
            params,
            (self.n, self.m, self.n_params),
            &self.opts,
            &self.signals,
            (self.probe.as_ref(), self.law.is_some()),
            &start.x0,
        )?;
        let h = h.refined(refine);
        let (n, m) = (self.n, self.m);
        check_start(sig, start, n)?;
        let (k0, k1) = (start.range.start, start.range.end);
        let mut sys = StateDynamics::new(
            (&self.tape, &self.split),
            (n, m),
            params,
            &self.dry,
            self.levels,
            unsplit,
        );
        let meas_off: Vec<f64> = effects
            .offsets
            .iter()
            .zip(&start.offsets)
            .map(|(a, b)| a + b)
            .collect();
        let mut q = vec![vec![0.0; k1 - k0]; n];
        let mut z = start.x0.clone();
        let mut y = vec![0.0; n];
        let mut closed = loop_start(self.law.as_ref(), sig, k0)?;
        let (widths, levels) = (&effects.widths, &effects.levels);
        let at_sample = |k: usize, z: &[f64], u: &mut [Vec<f64>]| {
            for i in 0..n {
                y[i] = z[i] + meas_off[i];
                q[i][k - k0] = y[i];
            }
            if let Some((law, rep, ev, fstate, u_law)) = closed.as_mut() {
                control_at(law, rep, ev, k, &y, fstate, u_law, (widths, levels), u);
            }
            z.iter().all(|v| v.is_finite())
        };
        integrate(
            &sig.name,
            &sig.t,
            &mut u,
            k0..k1,
            &h,
            &mut z,
            &effects.delays,
            &mut sys,
            at_sample,
        )?;
        Ok(Trajectory { q })
    }
}

/// Check a block start against the record.
pub(crate) fn check_start(sig: &Signals, start: &BlockStart, n: usize) -> Result<(), SimError> {
    let r = &start.range;
    if r.start > r.end || r.end > sig.len() {
        return Err(SimError::BadOption(format!(
            "block {}..{} does not lie within the {} samples of `{}`",
            r.start,
            r.end,
            sig.len(),
            sig.name
        )));
    }
    if start.x0.len() != 2 * n || start.offsets.len() != n {
        return Err(SimError::BadOption(format!(
            "a block of `{}` needs {} initial state values and {n} offsets",
            sig.name,
            2 * n
        )));
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use plantc_derive::model::{load_model_text, ParameterValues};

    /// The repository's rotary pendulum, plus (with `effects`) a sensor
    /// offset on `alpha` and an input delay on `Vm`, both estimated.
    pub(crate) fn pendulum(effects: bool) -> Model {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../models/rotary_pendulum.plant"
        );
        let mut text = std::fs::read_to_string(path).expect("model file");
        if effects {
            text += "\nparameter d_alpha = 0.01 [rad] estimate [-0.2, 0.2]\n\
                     parameter Td_Vm = 1.3e-3 [s] estimate [0, 0.05]\n\
                     sensor alpha = sensor_offset(d_alpha)\n\
                     actuator Vm = input_delay(Td_Vm)\n";
        }
        load_model_text("rotary_pendulum", &text)
            .expect("model loads")
            .model
    }

    /// 1000 samples at 2 ms of a swinging pendulum driven by a sine plus
    /// steps (input switches exercise the delay path); only the first
    /// sample of `q` matters (the initial state).
    pub(crate) fn signals(model: &Model) -> Signals {
        let k = 1000;
        let t: Vec<f64> = (0..k).map(|i| i as f64 * 2e-3).collect();
        let mut q = vec![vec![0.0; k]; model.coordinates.len()];
        for (i, qi) in q.iter_mut().enumerate() {
            qi[0] = 0.1 + 0.3 * i as f64;
        }
        let u = vec![t
            .iter()
            .map(|&t| 2.0 * (7.0 * t).sin() + if (t * 3.0) as i64 % 2 == 0 { 1.0 } else { -1.0 })
            .collect()];
        Signals {
            name: "synthetic".into(),
            t,
            q,
            u,
            replay: None,
        }
    }

    /// Nominal parameters scaled by `1 + 0.1 k` for the k-th parameter (so
    /// no parameter sits at a round value).
    pub(crate) fn perturbed(model: &Model) -> Vec<f64> {
        let base = model
            .parameters
            .iter()
            .enumerate()
            .map(|(k, p)| p.value * (1.0 + 0.01 * k as f64))
            .collect();
        ParameterValues::from_base(model, base).full
    }

    /// With the smooth law, a gearbox friction that holds the arm (0.1 N m:
    /// a substep of about 0.2 ms) simulates; one fifty times stronger would
    /// need about 4 us, below [`MIN_SUBSTEP`], and is refused with its
    /// reason instead of running thousands of substeps per sample. With
    /// sticking friction (the default) neither is stiff: both simulate.
    #[test]
    fn a_dry_friction_too_stiff_to_simulate_is_refused() {
        let model = pendulum(false);
        let smooth = SimOptions {
            dry_friction: DryFriction::Smooth { width: 1e-3 },
            ..SimOptions::default()
        };
        let sim = Simulator::new(&model, smooth).expect("compiles");
        let sticking = Simulator::new(&model, SimOptions::default()).expect("compiles");
        let sig = signals(&model);
        let fg1 = model
            .parameters
            .iter()
            .position(|p| p.name == "Fg1")
            .expect("Fg1");
        let with = |v: f64| {
            let mut base: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
            base[fg1] = v;
            ParameterValues::from_base(&model, base).full
        };
        sim.simulate(&sig, &with(0.1), 200)
            .expect("a gearbox holding the arm simulates");
        match sim.simulate(&sig, &with(5.0), 200) {
            Err(SimError::TooStiff {
                experiment,
                substep,
            }) => {
                assert_eq!(experiment, "synthetic");
                assert!(substep < MIN_SUBSTEP && substep > 0.0, "{substep}");
                let msg = SimError::TooStiff {
                    experiment,
                    substep,
                }
                .to_string();
                assert!(
                    msg.contains("substep") && msg.contains("dry friction"),
                    "{msg}"
                );
            }
            other => panic!("expected TooStiff, got {:?}", other.map(|_| ())),
        }
        for v in [0.1, 5.0] {
            sticking
                .simulate(&sig, &with(v), 200)
                .expect("sticking friction is not stiff");
        }
    }

    /// The split tape (parameter part once per simulation) reproduces the
    /// whole-tape simulation bit for bit: the same instructions run on the
    /// same operands.
    #[test]
    fn split_simulation_is_bit_identical() {
        for effects in [false, true] {
            let model = pendulum(effects);
            let sim = Simulator::new(&model, SimOptions::default()).expect("compiles");
            assert!(
                sim.split.slow_instructions().len() > 10,
                "the parameter part is not trivial: {:?}",
                sim.split
            );
            let sig = signals(&model);
            let p = perturbed(&model);
            let split = sim.run_n(&sig, &p, sig.len(), false).expect("simulates");
            let whole = sim.run_n(&sig, &p, sig.len(), true).expect("simulates");
            assert!(split.q[0].iter().any(|v| (v - split.q[0][0]).abs() > 1e-3));
            let bits = |tr: &Trajectory| -> Vec<Vec<u64>> {
                tr.q.iter()
                    .map(|qi| qi.iter().map(|v| v.to_bits()).collect())
                    .collect()
            };
            assert_eq!(bits(&split), bits(&whole), "effects: {effects}");
        }
    }

    /// Median seconds of `f` over `reps` runs.
    pub(crate) fn median_seconds(reps: usize, mut f: impl FnMut()) -> f64 {
        let mut t: Vec<f64> = (0..reps)
            .map(|_| {
                let s = std::time::Instant::now();
                f();
                s.elapsed().as_secs_f64()
            })
            .collect();
        t.sort_by(f64::total_cmp);
        t[reps / 2]
    }

    /// Split against whole-tape simulation time, interleaved so that machine
    /// load affects both alike. Run with `cargo test -p plantc-identify
    /// --release --lib split_timing -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn split_timing() {
        let model = pendulum(false);
        let sim = Simulator::new(&model, SimOptions::default()).expect("compiles");
        let mut sig = signals(&model);
        let k = 10_000;
        sig.t = (0..k).map(|i| i as f64 * 2e-3).collect();
        sig.q = sig.q.iter().map(|q| vec![q[0]; k]).collect();
        sig.u = vec![sig.t.iter().map(|t| 2.0 * (7.0 * t).sin()).collect()];
        let p = perturbed(&model);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for _ in 0..5 {
            a.push(median_seconds(3, || {
                sim.run_n(&sig, &p, k, false).expect("simulates");
            }));
            b.push(median_seconds(3, || {
                sim.run_n(&sig, &p, k, true).expect("simulates");
            }));
        }
        a.sort_by(f64::total_cmp);
        b.sort_by(f64::total_cmp);
        eprintln!(
            "plain simulation, {k} samples: split {:.4} s, whole tape {:.4} s ({} slow + {} fast instructions)",
            a[2],
            b[2],
            sim.split.slow_instructions().len(),
            sim.split.fast_instructions().len()
        );
    }
}
