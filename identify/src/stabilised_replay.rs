//! A stabilising feedback for replaying records whose open-loop replay
//! falls: an unstable plant balanced by a controller the model does not
//! hold.
//!
//! Replayed open loop, a record of the pendulum balanced upright leaves the
//! data within a second; the fit then has to work on short segments, where
//! slow effects hide under the noise (a Coulomb friction of 6e-4 N m on the
//! pendulum gained 1.12x there, 4.1x with the law simulated in the loop).
//! Without the law, the simulated input is the logged one corrected by a
//! state feedback on the distance to the measured angles:
//!
//! ```text
//! u_sim = u_logged - K (x_sim - x_measured)
//! ```
//!
//! with `K` an LQR design on the model linearised at the data's mean
//! position (Bryson's weights from the data's spreads) and velocities by the
//! filtered derivatives a rig's controller uses. Along the measured
//! trajectory the correction is zero and the logged input is applied as it
//! was; where the simulation drifts (an unstable mode, a missing effect) the
//! feedback pulls it back through the input, as the rig's own controller did
//! (if `K` were the rig's gain, `u_sim` would be its law evaluated on the
//! simulated state, exactly). A missing effect then shows over the whole
//! records. The measured coordinates the feedback reads are smoothed
//! (Savitzky-Golay, +-50 ms): on raw encoder steps it would feed their
//! rounding noise into the simulated input. It is written as a `recorded controller` block (signals: the
//! logged input and the measured coordinates, copied into columns of their
//! own), so the closed-loop simulator with its exact sensitivities does the
//! work; the block is removed from every model the story writes.

use std::fmt::Write as _;

use nalgebra::DMatrix;
use plantc_derive::analysis::{linearize, OperatingPoint};
use plantc_derive::lang::units::parse_unit;
use plantc_derive::linear::lqr;
use plantc_derive::linear::poles;
use plantc_derive::mechanics::derive_equations;
use plantc_derive::model::{CoordinateKind, Model, ParameterValues};

use crate::data::{Channel, Experiment};

/// Cut-off of the filtered derivatives of the correction, rad/s.
const CUTOFF: f64 = 100.0;
/// The closed loop's fastest pole is kept below this fraction of
/// [`CUTOFF`] (by raising the input weight).
const POLE_SHARE: f64 = 0.3;

/// The stabilising feedback for one model and one set of records.
#[derive(Clone, Debug, PartialEq)]
pub struct StabilisedReplay {
    /// Name of the recorded controller block.
    pub name: String,
    /// The block's text, appended to the model text.
    pub block: String,
    /// Gains `K` (one row per input, `2n` columns: positions then
    /// velocities), in SI units.
    pub gains: Vec<Vec<f64>>,
    /// The slowest and fastest closed-loop pole magnitudes of the design
    /// (rad/s).
    pub poles: (f64, f64),
    /// Column names added to the records: `(logged input, measured
    /// coordinate)` per input and coordinate.
    columns: (Vec<String>, Vec<String>),
}

/// Why no stabilising feedback could be designed.
#[derive(Clone, Debug, PartialEq)]
pub enum StabiliseError {
    /// The model's equations or its linearisation failed.
    Model(String),
    /// The LQR design failed (the linearisation is not stabilisable).
    Design(String),
    /// A record lacks a coordinate or an input.
    MissingChannel(String),
    /// The model linearised at the data's mean position is stable: its
    /// replay leaving the data is no loop's doing.
    Stable,
    /// An angle coordinate turns through a full revolution in a record
    /// (`coordinate` in `experiment`): the plant tumbled, no loop held it
    /// near an equilibrium, and the data's mean position is none.
    Tumbles {
        /// The record's name.
        experiment: String,
        /// The coordinate that turned.
        coordinate: String,
    },
}

impl std::fmt::Display for StabiliseError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StabiliseError::Model(e) => write!(f, "the model: {e}"),
            StabiliseError::Design(e) => write!(f, "the LQR design: {e}"),
            StabiliseError::MissingChannel(c) => write!(f, "a record has no column `{c}`"),
            StabiliseError::Stable => write!(f, "the linearised plant is stable"),
            StabiliseError::Tumbles {
                experiment,
                coordinate,
            } => write!(
                f,
                "`{coordinate}` turns through a full revolution in `{experiment}`: no loop held it"
            ),
        }
    }
}

impl std::error::Error for StabiliseError {}

/// Standard deviation of `v` (0 for fewer than two values).
fn spread(v: &[f64]) -> f64 {
    let n = v.len();
    if n < 2 {
        return 0.0;
    }
    let mean = v.iter().sum::<f64>() / n as f64;
    (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
}

/// Half window (s) and degree of the Savitzky-Golay smoothing of the
/// measured coordinates the feedback reads.
const SMOOTHING: (f64, usize) = (0.05, 5);

/// `y` (sampled at `t`) smoothed by a centred Savitzky-Golay polynomial
/// ([`SMOOTHING`]; the median period), the first and last half windows
/// left as measured.
fn smoothed(t: &[f64], y: &[f64]) -> Vec<f64> {
    let dt = crate::data::median_dt(t).unwrap_or(0.0);
    let h = if dt > 0.0 {
        (SMOOTHING.0 / dt).round().max(3.0) as usize
    } else {
        0
    };
    let Ok(w) = crate::savitzky_golay::kernel(h, SMOOTHING.1, 0, dt) else {
        return y.to_vec();
    };
    let mid = crate::savitzky_golay::apply(&w, y);
    let mut out = y.to_vec();
    for (k, v) in mid.into_iter().enumerate() {
        out[k + h] = v;
    }
    out
}

/// A name not among `taken`: `base`, else `base` with `_` appended.
fn unique(base: String, taken: &[String]) -> String {
    let mut name = base;
    while taken.contains(&name) {
        name.push('_');
    }
    name
}

/// Every name a model declares: recorded controllers, parameters,
/// coordinates, inputs, outputs, derived quantities.
fn model_names(model: &Model) -> Vec<String> {
    let mut names: Vec<String> = model.recorded.iter().map(|r| r.name.clone()).collect();
    names.extend(model.parameters.iter().map(|p| p.name.clone()));
    names.extend(model.coordinates.iter().map(|c| c.name.clone()));
    names.extend(model.inputs.iter().map(|i| i.name.clone()));
    names.extend(model.outputs.iter().map(|o| o.name.clone()));
    names.extend(model.derived.iter().map(|d| d.name.clone()));
    names
}

impl StabilisedReplay {
    /// Design the feedback for `model` (nominal values) on `experiments`.
    pub fn design(model: &Model, experiments: &[Experiment]) -> Result<Self, StabiliseError> {
        let n = model.coordinates.len();
        let m = model.inputs.len();
        let column = |e: &Experiment, name: &str| -> Result<Vec<f64>, StabiliseError> {
            e.values(name)
                .map(<[f64]>::to_vec)
                .ok_or_else(|| StabiliseError::MissingChannel(name.to_string()))
        };
        // the data's mean position, spreads of positions, velocities, inputs
        let mut q_all: Vec<Vec<f64>> = vec![Vec::new(); n];
        let mut v_all: Vec<Vec<f64>> = vec![Vec::new(); n];
        let mut u_all: Vec<Vec<f64>> = vec![Vec::new(); m];
        for e in experiments.iter().filter(|e| !e.t.is_empty()) {
            for (i, c) in model.coordinates.iter().enumerate() {
                let q = column(e, &c.name)?;
                // a loop that balances the plant keeps it near one
                // equilibrium: an angle that turns a full revolution (its
                // range 2 pi or more) was held by none, and the mean
                // position of a tumbling record is no operating point
                if c.kind == CoordinateKind::Angle
                    && e.range(&c.name).unwrap_or(0.0) >= std::f64::consts::TAU
                {
                    return Err(StabiliseError::Tumbles {
                        experiment: e.name.clone(),
                        coordinate: c.name.clone(),
                    });
                }
                // velocities over 20 ms, quantisation averaged out
                let span = e.t.partition_point(|&t| t < e.t[0] + 0.02).max(1);
                for k in span..q.len() {
                    let dt = e.t[k] - e.t[k - span];
                    if dt > 0.0 {
                        v_all[i].push((q[k] - q[k - span]) / dt);
                    }
                }
                q_all[i].extend(q);
            }
            for (j, inp) in model.inputs.iter().enumerate() {
                u_all[j].extend(column(e, &inp.name)?);
            }
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        let mut x0 = vec![0.0; 2 * n];
        for i in 0..n {
            x0[i] = mean(&q_all[i]);
        }
        let u0: Vec<f64> = u_all.iter().map(|u| mean(u)).collect();
        let values = ParameterValues::new(model, None, &[])
            .map_err(|e| StabiliseError::Model(e.to_string()))?;
        let eqs = derive_equations(model).map_err(|e| StabiliseError::Model(e.to_string()))?;
        let lin = linearize(model, &eqs, &values, &OperatingPoint { x: x0, u: u0 })
            .map_err(|e| StabiliseError::Model(e.to_string()))?;
        // only an unstable plant: a stable one whose replay leaves the data
        // is far from its values, and a feedback would hide what is wrong
        let open = poles(&lin.a).map_err(|e| StabiliseError::Model(e.to_string()))?;
        if !open.iter().any(|p| p.re > 0.0) {
            return Err(StabiliseError::Stable);
        }
        // Bryson's rule: each state and input weighted by the inverse square
        // of its spread in the data (a floor keeps a still channel finite)
        let floor = |s: f64, f: f64| if s.is_finite() && s > f { s } else { f };
        let mut q_w = DMatrix::zeros(2 * n, 2 * n);
        for i in 0..n {
            q_w[(i, i)] = 1.0 / floor(spread(&q_all[i]), 1e-3).powi(2);
            q_w[(n + i, n + i)] = 1.0 / floor(spread(&v_all[i]), 1e-2).powi(2);
        }
        let mut r_scale = 1.0;
        let mut tries = 0;
        let (k, poles) = loop {
            let mut r_w = DMatrix::zeros(m, m);
            for j in 0..m {
                r_w[(j, j)] = r_scale / floor(spread(&u_all[j]), 1e-3).powi(2);
            }
            let d = lqr(&lin.a, &lin.b, &q_w, &r_w)
                .map_err(|e| StabiliseError::Design(e.to_string()))?;
            let mags: Vec<f64> = d
                .closed_loop_poles
                .iter()
                .map(|p| p.re.hypot(p.im))
                .collect();
            let fastest = mags.iter().copied().fold(0.0, f64::max);
            let slowest = mags.iter().copied().fold(f64::INFINITY, f64::min);
            tries += 1;
            if fastest <= POLE_SHARE * CUTOFF || tries == 12 {
                break (d.k, (slowest, fastest));
            }
            r_scale *= 4.0;
        };
        let gains: Vec<Vec<f64>> = (0..m)
            .map(|j| (0..2 * n).map(|c| k[(j, c)]).collect())
            .collect();
        // the signal columns the block adds: clear of the files' columns
        // and of every name of the model
        let names = model_names(model);
        let mut taken: Vec<String> = experiments
            .iter()
            .flat_map(|e| e.channels.iter().map(|c| c.name.clone()))
            .collect();
        taken.extend(names.iter().cloned());
        let logged: Vec<String> = model
            .inputs
            .iter()
            .map(|i| unique(format!("logged_{}", i.name), &taken))
            .collect();
        let measured: Vec<String> = model
            .coordinates
            .iter()
            .map(|c| unique(format!("measured_{}", c.name), &taken))
            .collect();
        let name = unique("stabilised_replay".to_string(), &names);
        let unit_of = |i: usize| match model.coordinates[i].kind {
            CoordinateKind::Angle => "rad",
            _ => "m",
        };
        let input_unit = |j: usize| {
            let u = model.inputs[j].unit.trim();
            if u.is_empty() {
                "1".to_string()
            } else {
                u.to_string()
            }
        };
        // K is in SI; a gain written in the input's unit is scaled by it
        let input_scale = |j: usize| parse_unit(&input_unit(j)).map_or(1.0, |u| u.scale.to_f64());
        // the block's own names (errors and gains), clear of every name
        // the model or the block already uses
        let mut used = names;
        used.extend(logged.iter().chain(&measured).cloned());
        used.push(name.clone());
        let mut local = |base: String| {
            let fresh = unique(base, &used);
            used.push(fresh.clone());
            fresh
        };
        let errs: Vec<String> = model
            .coordinates
            .iter()
            .map(|c| local(format!("err_{}", c.name)))
            .collect();
        let gain_names: Vec<Vec<(String, String)>> = model
            .inputs
            .iter()
            .map(|inp| {
                model
                    .coordinates
                    .iter()
                    .map(|c| {
                        (
                            local(format!("kp_{}_{}", inp.name, c.name)),
                            local(format!("kd_{}_{}", inp.name, c.name)),
                        )
                    })
                    .collect()
            })
            .collect();
        let mut block = String::new();
        let _ = writeln!(
            block,
            "\n# Added by `identify`, removed from the models it writes: the logged\n# input with a stabilising feedback on the distance to the measured\n# coordinates (LQR on the model linearised at the data's mean position)."
        );
        let _ = writeln!(
            block,
            "recorded controller {name} \"logged input, stabilised replay\" {{"
        );
        for (j, inp) in model.inputs.iter().enumerate() {
            let _ = writeln!(
                block,
                "    signal {} [{}] \"logged {}\"",
                logged[j],
                input_unit(j),
                inp.name
            );
        }
        for (i, c) in model.coordinates.iter().enumerate() {
            let _ = writeln!(
                block,
                "    signal {} [{}] \"measured {}\"",
                measured[i],
                unit_of(i),
                c.name
            );
        }
        for (i, c) in model.coordinates.iter().enumerate() {
            let _ = writeln!(block, "    let {} = {} - {}", errs[i], c.name, measured[i]);
        }
        for (j, inp) in model.inputs.iter().enumerate() {
            let mut law = format!("    {} = {}", inp.name, logged[j]);
            for i in 0..n {
                let (kp, kd) = (k[(j, i)] / input_scale(j), k[(j, n + i)] / input_scale(j));
                let (gp, gd) = &gain_names[j][i];
                let (uu, cu) = (input_unit(j), unit_of(i));
                let _ = writeln!(block, "    gain {gp} = {kp:e} [{uu}/{cu}]");
                let _ = writeln!(block, "    gain {gd} = {kd:e} [{uu}*s/{cu}]");
                let err = &errs[i];
                let _ = write!(
                    law,
                    " - {gp}*{err} - {gd}*derivative({err}, {CUTOFF} [rad/s])"
                );
            }
            let _ = writeln!(block, "{law}");
        }
        block.push_str("}\n");
        Ok(StabilisedReplay {
            name,
            block,
            gains,
            poles,
            columns: (logged, measured),
        })
    }

    /// `experiments` with the columns the block reads: each input's logged
    /// values and each coordinate's measured ones, copied.
    pub fn augment(
        &self,
        model: &Model,
        experiments: &[Experiment],
    ) -> Result<Vec<Experiment>, StabiliseError> {
        experiments
            .iter()
            .map(|e| {
                let mut e = e.clone();
                let sources = model
                    .inputs
                    .iter()
                    .map(|i| &i.name)
                    .zip(&self.columns.0)
                    .chain(
                        model
                            .coordinates
                            .iter()
                            .map(|c| &c.name)
                            .zip(&self.columns.1),
                    );
                let n_inputs = model.inputs.len();
                for (k, (from, to)) in sources.enumerate() {
                    let raw = e
                        .values(from)
                        .ok_or_else(|| StabiliseError::MissingChannel(from.clone()))?
                        .to_vec();
                    // the measured coordinates smoothed: the feedback on
                    // raw encoder steps would feed their rounding noise
                    // into the simulated input (a residual 1.3x the floor
                    // on clean records)
                    let values = if k < n_inputs {
                        raw
                    } else {
                        smoothed(&e.t, &raw)
                    };
                    e.channels.push(Channel {
                        name: to.clone(),
                        unit_note: None,
                        values,
                    });
                }
                Ok(e)
            })
            .collect()
    }

    /// `text` without the block (as appended by the caller).
    pub fn strip(&self, text: &str) -> String {
        text.replacen(&self.block, "", 1)
    }

    /// One line for the user.
    pub fn note(&self) -> String {
        format!(
            "the records cannot be replayed open loop and the model holds no recorded controller: the logged input is replayed with a stabilising feedback on the distance to the measured coordinates (LQR on the model linearised at the data's mean position, closed-loop poles {:.1} to {:.1} rad/s), so the whole records are fitted; where the simulation follows the data the logged input is applied unchanged",
            self.poles.0, self.poles.1
        )
    }
}
