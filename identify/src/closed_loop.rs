//! A recorded controller in the loop: closed-loop simulation of recordings.
//!
//! A `recorded controller` block of the model states the discrete-time law
//! that drove some inputs while the data were logged (e.g. the PD law that
//! balanced a pendulum upright). Replaying the logged input open loop
//! through a model of an unstable plant diverges within a second; with the
//! law in the loop the simulation stays near the record and the whole
//! record can be fitted.
//!
//! Semantics, at every sample instant `t_k` of a record (the law runs at the
//! record's rate):
//! - the law reads the *measured* coordinates (in simulation: the simulated
//!   coordinates plus the sensor offsets, what the rig's encoders would
//!   have read), its `signal` columns at `k`, and the outputs of its
//!   filtered derivatives `derivative(x, wc)`: `y_k = a (x_k - x_{k-1}) + b
//!   y_{k-1}` with `b = 1/(1 + wc T)`, `a = wc b`, `T` the record's median
//!   sample period, started at rest (`x_{-1} = y_{-1} = 0`);
//! - the value is clipped to the input's `limits`, then passes the
//!   actuator effects like a logged input (deadzone, delay, offset) and is
//!   held until the next sample.
//!
//! The *replay* evaluates the law on the measured data: it gives the
//! filter states at any sample (a block of the record that starts at `k0`
//! starts its filters there, as the rig's controller had them) and the
//! values held before a block starts. On the QUBE recordings the replay
//! reproduces the logged controller output to 1e-14 V (test
//! `closed_loop::replay_reproduces_the_logged_law`).
//!
//! The law may not depend on model parameters (its gains are the rig
//! code's constants), so the replay depends on the data alone; its
//! sensitivity to the parameters comes only through the simulated
//! measurements.

use plantc_derive::model::{Model, RecordedController};
use plantc_derive::sym::{diff, Expr, Symbol, Tape};

use crate::data::Experiment;
use crate::experiment_sim::SimError;

/// A recorded controller compiled for simulation.
#[derive(Clone, Debug)]
pub struct LoopLaw {
    /// Controller name.
    pub name: String,
    n: usize,
    /// Driven input indices, one per law.
    driven: Vec<usize>,
    /// Limits of the driven inputs.
    limits: Vec<Option<(f64, f64)>>,
    signal_names: Vec<String>,
    cutoffs: Vec<f64>,
    /// Which measured coordinates the law reads.
    reads: Vec<bool>,
    /// `[y (n), signals]` -> `[e (nf), de/dy (nf*n)]`.
    tape_e: Tape,
    /// `[y (n), signals, f (nf)]` -> `[u (nd), du/dy (nd*n), du/df (nd*nf)]`.
    tape_u: Tape,
}

/// The law replayed on one record's measured data.
#[derive(Clone, Debug, PartialEq)]
pub struct Replay {
    /// The signal columns, one vector per `signal` of the controller.
    pub signals: Vec<Vec<f64>>,
    /// The law's value at every sample (after the limits), one vector per
    /// driven input.
    pub u: Vec<Vec<f64>>,
    /// Filter state before sample `k`: `state[k * 2 nf + 2 j]` is `x_{k-1}`
    /// and `+ 1` is `y_{k-1}` of filter `j`.
    pub state: Vec<f64>,
    /// Filter coefficients `(a, b)` at the record's sample period.
    pub coeffs: Vec<(f64, f64)>,
}

impl LoopLaw {
    /// Compile the recorded controller `name` of `model`.
    pub fn new(model: &Model, name: &str) -> Result<LoopLaw, SimError> {
        let Some(rc) = model.recorded_controller(name) else {
            let known: Vec<&str> = model.recorded.iter().map(|r| r.name.as_str()).collect();
            return Err(SimError::BadOption(if known.is_empty() {
                format!(
                    "the model has no recorded controller `{name}` (declare one with `recorded controller {name} {{ ... }}`)"
                )
            } else {
                format!(
                    "the model has no recorded controller `{name}`; it has: {}",
                    known.join(", ")
                )
            }));
        };
        Self::compile(model, rc)
    }

    fn compile(model: &Model, rc: &RecordedController) -> Result<LoopLaw, SimError> {
        let n = model.coordinates.len();
        let ys: Vec<Symbol> = model.coordinates.iter().map(|c| c.symbols.q).collect();
        let ss: Vec<Symbol> = rc.signals.iter().map(|s| s.symbol).collect();
        let fs: Vec<Symbol> = rc.filters.iter().map(|f| f.symbol).collect();
        let params: Vec<Symbol> = model.parameter_symbols();
        for e in rc
            .filters
            .iter()
            .map(|f| f.input)
            .chain(rc.laws.iter().map(|l| l.1))
        {
            if let Some(p) = e.symbols().into_iter().find(|s| params.contains(s)) {
                return Err(SimError::BadOption(format!(
                    "recorded controller `{}`: its law uses the model parameter `{}`; a recorded law may use only numbers, its gains, signals and measured coordinates",
                    rc.name,
                    p.name()
                )));
            }
        }
        for f in &rc.filters {
            if !(f.cutoff > 0.0 && f.cutoff.is_finite()) {
                return Err(SimError::BadOption(format!(
                    "recorded controller `{}`: a derivative cutoff must be a positive rate, got {} rad/s",
                    rc.name, f.cutoff
                )));
            }
        }
        let tape_err = |e: plantc_derive::sym::tape::TapeError| {
            SimError::Tape(format!("recorded controller `{}`: {e}", rc.name))
        };
        let mut in_e = ys.clone();
        in_e.extend(&ss);
        let mut out_e: Vec<Expr> = rc.filters.iter().map(|f| f.input).collect();
        for f in &rc.filters {
            out_e.extend(ys.iter().map(|y| diff(f.input, *y)));
        }
        let tape_e = Tape::compile(&out_e, &in_e).map_err(tape_err)?;
        let mut in_u = in_e.clone();
        in_u.extend(&fs);
        let mut out_u: Vec<Expr> = rc.laws.iter().map(|l| l.1).collect();
        for l in &rc.laws {
            out_u.extend(ys.iter().map(|y| diff(l.1, *y)));
        }
        for l in &rc.laws {
            out_u.extend(fs.iter().map(|f| diff(l.1, *f)));
        }
        let tape_u = Tape::compile(&out_u, &in_u).map_err(tape_err)?;
        let driven: Vec<usize> = rc.laws.iter().map(|l| l.0).collect();
        let reads = ys
            .iter()
            .map(|y| {
                rc.filters
                    .iter()
                    .map(|f| f.input)
                    .chain(rc.laws.iter().map(|l| l.1))
                    .any(|e| e.contains(*y))
            })
            .collect();
        Ok(LoopLaw {
            reads,
            name: rc.name.clone(),
            n,
            limits: driven.iter().map(|&j| model.inputs[j].limits).collect(),
            driven,
            signal_names: rc.signals.iter().map(|s| s.name.clone()).collect(),
            cutoffs: rc.filters.iter().map(|f| f.cutoff).collect(),
            tape_e,
            tape_u,
        })
    }

    /// Indices of the inputs the law drives.
    pub fn driven(&self) -> &[usize] {
        &self.driven
    }

    /// Whether the law reads the measured coordinate `i` of `model`.
    pub fn reads_coordinate(&self, model: &Model, i: usize) -> bool {
        let _ = model;
        i < self.n && self.reads[i]
    }

    /// Names of the data columns the law reads.
    pub fn signal_names(&self) -> &[String] {
        &self.signal_names
    }

    fn nf(&self) -> usize {
        self.cutoffs.len()
    }

    /// Replay the law on an experiment's measured coordinates (`q`, model
    /// order) and its signal columns; `t` gives the sample period.
    pub fn replay(&self, exp: &Experiment, q: &[Vec<f64>]) -> Result<Replay, SimError> {
        let signals = self
            .signal_names
            .iter()
            .map(|s| {
                exp.values(s)
                    .map(<[f64]>::to_vec)
                    .ok_or_else(|| SimError::MissingChannel {
                        experiment: exp.name.clone(),
                        channel: format!("{s}` (read by recorded controller `{}`", self.name),
                    })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let len = exp.t.len();
        let dt = exp.sample_time().unwrap_or(1e-3);
        let coeffs: Vec<(f64, f64)> = self
            .cutoffs
            .iter()
            .map(|&wc| {
                let b = 1.0 / (1.0 + wc * dt);
                (wc * b, b)
            })
            .collect();
        let nf = self.nf();
        let nd = self.driven.len();
        let mut rep = Replay {
            signals,
            u: vec![vec![0.0; len]; nd],
            state: vec![0.0; 2 * nf * len],
            coeffs,
        };
        let mut ev = LoopEval::new(self);
        let mut fstate = vec![0.0; 2 * nf];
        let mut y = vec![0.0; self.n];
        let mut u = vec![0.0; nd];
        for k in 0..len {
            rep.state[k * 2 * nf..(k + 1) * 2 * nf].copy_from_slice(&fstate);
            for (i, yi) in y.iter_mut().enumerate() {
                *yi = q[i][k];
            }
            ev.step(self, &rep, k, &y, &mut fstate, &mut u, None);
            for (d, ud) in rep.u.iter_mut().enumerate() {
                ud[k] = u[d];
            }
        }
        Ok(rep)
    }
}

/// Buffers for evaluating a [`LoopLaw`] (allocated once per simulation).
pub(crate) struct LoopEval {
    in_e: Vec<f64>,
    out_e: Vec<f64>,
    scratch_e: Vec<f64>,
    in_u: Vec<f64>,
    out_u: Vec<f64>,
    scratch_u: Vec<f64>,
    /// Whether the law's value at the current sample was clipped.
    clipped: Vec<bool>,
    /// Filter outputs at the current sample.
    f: Vec<f64>,
}

/// Sensitivity bookkeeping of a closed loop: for `nc` columns, the
/// measured-output sensitivities at the current sample come in, the input
/// sensitivities go out; the filters' state sensitivities are kept.
pub(crate) struct LoopSens {
    nc: usize,
    /// `dx_prev[j * nc + c]`, `dy_prev[j * nc + c]`.
    dx_prev: Vec<f64>,
    dy_prev: Vec<f64>,
    de: Vec<f64>,
    df: Vec<f64>,
}

impl LoopSens {
    /// Zero sensitivities (a block starts from the replayed, data-only state).
    pub(crate) fn new(law: &LoopLaw, nc: usize) -> LoopSens {
        let nf = law.nf();
        LoopSens {
            nc,
            dx_prev: vec![0.0; nf * nc],
            dy_prev: vec![0.0; nf * nc],
            de: vec![0.0; nf * nc],
            df: vec![0.0; nf * nc],
        }
    }
}

impl LoopEval {
    pub(crate) fn new(law: &LoopLaw) -> LoopEval {
        LoopEval {
            in_e: vec![0.0; law.tape_e.inputs().len()],
            out_e: vec![0.0; law.tape_e.n_outputs()],
            scratch_e: vec![0.0; law.tape_e.scratch_len()],
            in_u: vec![0.0; law.tape_u.inputs().len()],
            out_u: vec![0.0; law.tape_u.n_outputs()],
            scratch_u: vec![0.0; law.tape_u.scratch_len()],
            clipped: vec![false; law.driven.len()],
            f: vec![0.0; law.nf()],
        }
    }

    /// One sample of the law: measured coordinates `y`, filter state
    /// `fstate` (updated), law values after the limits into `u` (one per
    /// driven input). With `sens = Some((ls, dy, du))`: `dy[i * nc + c]` is
    /// the sensitivity of measured coordinate `i` to column `c`, and
    /// `du[d * nc + c]` receives that of driven input `d` (zero where a
    /// limit clips).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn step(
        &mut self,
        law: &LoopLaw,
        rep: &Replay,
        k: usize,
        y: &[f64],
        fstate: &mut [f64],
        u: &mut [f64],
        sens: Option<(&mut LoopSens, &[f64], &mut [f64])>,
    ) {
        let (n, nf, nd) = (law.n, law.nf(), law.driven.len());
        let ns = rep.signals.len();
        self.in_e[..n].copy_from_slice(y);
        for (s, col) in rep.signals.iter().enumerate() {
            self.in_e[n + s] = col[k];
        }
        law.tape_e
            .eval(&self.in_e, &mut self.out_e, &mut self.scratch_e);
        for j in 0..nf {
            let (a, b) = rep.coeffs[j];
            let e = self.out_e[j];
            self.f[j] = a * (e - fstate[2 * j]) + b * fstate[2 * j + 1];
            fstate[2 * j] = e;
            fstate[2 * j + 1] = self.f[j];
        }
        self.in_u[..n + ns].copy_from_slice(&self.in_e[..n + ns]);
        self.in_u[n + ns..].copy_from_slice(&self.f);
        law.tape_u
            .eval(&self.in_u, &mut self.out_u, &mut self.scratch_u);
        for d in 0..nd {
            let v = self.out_u[d];
            let (c, clip) = match law.limits[d] {
                Some((lo, _)) if v < lo => (lo, true),
                Some((_, hi)) if v > hi => (hi, true),
                _ => (v, false),
            };
            u[d] = c;
            self.clipped[d] = clip;
        }
        let Some((ls, dy, du)) = sens else {
            return;
        };
        let nc = ls.nc;
        // de = de/dy dy; df = a (de - dx_prev) + b dy_prev
        for j in 0..nf {
            let (a, b) = rep.coeffs[j];
            let dedy = &self.out_e[nf + j * n..nf + (j + 1) * n];
            for c in 0..nc {
                let mut s = 0.0;
                for i in 0..n {
                    s += dedy[i] * dy[i * nc + c];
                }
                ls.de[j * nc + c] = s;
                ls.df[j * nc + c] = a * (s - ls.dx_prev[j * nc + c]) + b * ls.dy_prev[j * nc + c];
            }
        }
        ls.dx_prev.copy_from_slice(&ls.de);
        ls.dy_prev.copy_from_slice(&ls.df);
        for d in 0..nd {
            let dudy = &self.out_u[nd + d * n..nd + (d + 1) * n];
            let dudf = &self.out_u[nd + nd * n + d * nf..nd + nd * n + (d + 1) * nf];
            let clip = self.clipped[d];
            for c in 0..nc {
                du[d * nc + c] = if clip {
                    0.0
                } else {
                    let mut s = 0.0;
                    for i in 0..n {
                        s += dudy[i] * dy[i * nc + c];
                    }
                    for j in 0..nf {
                        s += dudf[j] * ls.df[j * nc + c];
                    }
                    s
                };
            }
        }
    }
}
