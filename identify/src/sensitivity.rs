//! Exact forward sensitivities `dx/dtheta` of an experiment simulation with
//! respect to free base parameters `theta`.
//!
//! With `M(q, p) a = r0(x, p) + B(x, p) u` and `z` standing for a state
//! component or a free parameter,
//!
//! ```text
//! da/dz = M^-1 (dr0/dz + dB/dz u - dM/dz a)
//! ```
//!
//! and the variational equations `S' = (df/dx) S + df/dtheta` are integrated
//! alongside the state with the same RK4 and zero-order hold as
//! [`crate::experiment_sim::Simulator`], so the sensitivities are the exact
//! derivatives of the discrete simulation up to rounding.
//!
//! Sensor and actuator effects:
//! - a sensor offset `d(theta)` on coordinate `i`: the initial state is the
//!   measured `q_i(t0) - d`, so `S(0)` is `-dd/dtheta` on that coordinate
//!   (zero elsewhere: the rest of the initial state is measured), and the
//!   measurement `q_i + d` adds `+dd/dtheta` to the output sensitivity;
//! - an input delay `Td(theta)`: for the exact solution, at each switch of
//!   the delayed input from `u_old` to `u_new` at `s = t_k + Td`, moving the
//!   switch later by `dTd` keeps `u_old` acting for `dTd` longer, so `S`
//!   jumps by `(f(x(s), u_old) - f(x(s), u_new)) dTd/dtheta`. The simulation
//!   ends an RK4 segment at each switch inside a sample interval, so its
//!   substep lengths move with `Td`; to stay the exact derivative of the
//!   discrete simulation, each segment `[a, b]` is integrated in the scaled
//!   time `tau = (t - a)/(b - a)` (identical RK4 steps), whose variational
//!   equation gains the term `f (db/dtheta - da/dtheta)/(b - a)`. Summed over
//!   the segments around a switch this is the jump above as the substep goes
//!   to zero. A switch that falls on a sample instant is not a moving
//!   boundary: there the jump is applied as such;
//! - a deadzone width `w(theta)` on input `l`: the simulation holds
//!   `dz(u[k]) = sign(u[k]) max(|u[k]| - w, 0)`, whose derivative is
//!   `-sign(u[k]) dw/dtheta` where `|u[k]| > w` and zero elsewhere, i.e.
//!   `-sign(dz(u[k])) dw/dtheta` in terms of the held value. It enters only
//!   through the input, so the acceleration sensitivity gains the forcing
//!   term `M^-1 B[:, l] d dz/dtheta` (the kink at `|u[k]| = w` is a set of
//!   measure zero in `w`; there the one-sided derivative of the `> w` test
//!   is used);
//! - a saturation level `L(theta)` on input `l`: the simulation holds
//!   `sat(dz(u[k]))`, whose derivative is `sign(u[k]) dL/dtheta` on the
//!   samples the saturation clips (`|held| = L`; there the deadzone width no
//!   longer matters) and the deadzone's elsewhere; the forcing term is the
//!   same `M^-1 B[:, l] d held/dtheta`. In closed loop the law's own
//!   sensitivity passes only where the held value is not clipped and not in
//!   the deadzone;
//! - an input offset is a parameter of the folded forces like any other.
//!
//! The partial derivatives are symbolic: derived quantities (`let`) are
//! expanded into base parameters before differentiating with respect to a
//! parameter, and everything (`M`, `r0`, `B` and their derivatives along
//! every state component and free parameter) goes into one compiled tape,
//! split so that its parameter-only part runs once per simulation.

use std::cell::RefCell;

use plantc_derive::mechanics::stick_slip::{mat_vec, Mode};
use plantc_derive::model::Model;
use plantc_derive::sym::{diff, Expr, SplitTape, Tape};

use crate::closed_loop::{LoopEval, LoopLaw, LoopSens, Replay};
use crate::experiment_sim::{
    check_options, check_start, copy_short, dynamics_outputs, forces, integrate, loop_start,
    parameters_slow, prepare_run, received, received_derivatives, tape_inputs, BlockStart,
    Boundary, Dynamics, Located, Rate, Segment, SignalEffects, Signals, SimError, SimOptions,
    StateDynamics, StiffnessProbe, REFINE,
};

/// The number of coordinates `n` of the per-stage kernels below: a constant
/// for the common small models ([`Fixed`]) so that their loops over two or
/// three rows unroll and lose their bounds checks (those loops cost more in
/// index arithmetic than in products: a third of a fit's instructions on
/// the pendulum), or the model's own ([`Any`]). The same operations in the
/// same order either way, so both give the same bits.
trait Dim: Copy {
    fn n(self) -> usize;
}

/// `n` known when compiling.
#[derive(Copy, Clone)]
struct Fixed<const N: usize>;

impl<const N: usize> Dim for Fixed<N> {
    #[inline(always)]
    fn n(self) -> usize {
        N
    }
}

/// `n` known when running.
#[derive(Copy, Clone)]
struct Any(usize);

impl Dim for Any {
    #[inline(always)]
    fn n(self) -> usize {
        self.0
    }
}

/// `jd[d * n + i] = d a_i / d z_d` for every `d` (the state, then the free
/// parameters), `a = M_FF^-1 (r0 + B u - D sigma)` the acceleration of the
/// stick-slip mode (`minv` is `M_FF^-1` embedded with zero rows and
/// columns for the stuck joints, which makes their rows zero): from the
/// tape's derivative blocks (each `bs = n n + n + n m (+ n)` long: `dM`,
/// `dr0`, `dB` row-major, then `dD` when `dir` is given), `M_FF^-1 (dr0 +
/// dB u - dD sigma - dM a)`. `w` is a buffer of `n`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn acceleration_jacobian<D: Dim, E: Dim>(
    (dim, inputs): (D, E),
    blocks: &[f64],
    u: &[f64],
    dir: Option<&[f64]>,
    acc: &[f64],
    minv: &[f64],
    w: &mut [f64],
    jd: &mut [f64],
) {
    let (n, m) = (dim.n(), inputs.n());
    if n == 0 {
        return;
    }
    let bs = n * n + n + n * m + if dir.is_some() { n } else { 0 };
    let (acc, minv, w, u) = (&acc[..n], &minv[..n * n], &mut w[..n], &u[..m]);
    for (blk, jd_d) in blocks.chunks_exact(bs).zip(jd.chunks_exact_mut(n)) {
        let (dm, rest) = blk.split_at(n * n);
        let (dr, rest) = rest.split_at(n);
        let (db, dd) = rest.split_at(n * m);
        // dr0 + dB u as the acceleration's r0 + B u, then - dD sigma, - dM a
        forces(dr, &db[..n * m], u, w);
        if let Some(dir) = dir {
            for (i, wi) in w.iter_mut().enumerate() {
                let s = dir[i];
                if s != 0.0 {
                    *wi -= dd[i] * s;
                }
            }
        }
        for (i, wi) in w.iter_mut().enumerate() {
            for (k, a) in dm[i * n..(i + 1) * n].iter().zip(acc.iter()) {
                *wi -= k * a;
            }
        }
        mat_vec(minv, n, w, jd_d);
    }
}

/// The sensitivity rows' rates: `d/dt S_q = S_v`, `d/dt S_v = (da/dx) S +
/// da/dtheta` (`nc` columns, the first `p` the free parameters'), from
/// [`acceleration_jacobian`]'s `jd`.
#[inline(always)]
fn sensitivity_rates<D: Dim>(
    dim: D,
    jd: &[f64],
    s: &[f64],
    ds: &mut [f64],
    (p, nc): (usize, usize),
) {
    let n = dim.n();
    let nx = 2 * n;
    ds[..n * nc].copy_from_slice(&s[n * nc..nx * nc]);
    for i in 0..n {
        let row = &mut ds[(n + i) * nc..(n + i + 1) * nc];
        let (params, rest) = row.split_at_mut(p);
        for (r, d) in params.iter_mut().zip(jd[nx * n..].chunks_exact(n)) {
            *r = d[i];
        }
        rest.fill(0.0);
        for k in 0..nx {
            let a = jd[k * n + i];
            if a != 0.0 {
                for (r, sv) in row.iter_mut().zip(&s[k * nc..(k + 1) * nc]) {
                    *r += a * sv;
                }
            }
        }
    }
}

/// Add `M^-1 B du` (from `minv`, the row-major `n x n` inverse, and `b`,
/// `n x m`) to the velocity rows of column `j` of `ds` (`nc` columns);
/// `n` and `m` are the lengths of the buffers `tmp, w` and of `du`.
#[inline]
fn add_input_forcing(
    minv: &[f64],
    b: &[f64],
    du: &[f64],
    (tmp, w): (&mut [f64], &mut [f64]),
    ds: &mut [f64],
    (nc, j): (usize, usize),
) {
    let (n, m) = (tmp.len(), du.len());
    for i in 0..n {
        tmp[i] = (0..m).map(|l| b[i * m + l] * du[l]).sum::<f64>();
    }
    mat_vec(minv, n, tmp, w);
    for i in 0..n {
        ds[(n + i) * nc + j] += w[i];
    }
}

/// What a parameter moves among the signal effects.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum SignalKind {
    /// An input delay.
    Delay,
    /// A sensor offset.
    Offset,
}

/// A sensitivity column that is not a model parameter: the derivative with
/// respect to an initial state component or a per-experiment offset. Its
/// variational equation has no parametric forcing; it starts at `s0`
/// (one value per state component) and `direct` (one per coordinate) is
/// added to the measurement sensitivities (an offset is measured as is).
#[derive(Clone, Debug, PartialEq)]
pub struct ExtraColumn {
    /// `S(0)`, positions then velocities.
    pub s0: Vec<f64>,
    /// Direct derivative of each measured coordinate.
    pub direct: Vec<f64>,
}

/// Simulated coordinates and their sensitivities at the sample instants.
#[derive(Clone, Debug, PartialEq)]
pub struct SensitivityTrajectory {
    /// One vector per model coordinate.
    pub q: Vec<Vec<f64>>,
    /// `dq[i][j][k]`: derivative of coordinate `i` at sample `k` with respect
    /// to column `j` (the free parameters, then any extra columns).
    pub dq: Vec<Vec<Vec<f64>>>,
    /// Whether the simulation was run again at a [`REFINE`] times finer
    /// substep after diverging at the normal one (its sensitivities may
    /// overflow where the plain simulation's states stay finite: then the
    /// two simulators' trajectories differ).
    pub refined: bool,
}

/// Where a sensitivity simulation puts each sample: stored whole
/// ([`SensitivitySimulator::simulate_block`]) or reduced as it comes
/// ([`SensitivitySimulator::visit_block`], e.g. into normal equations).
pub(crate) trait SampleSink {
    /// A run of `n` coordinates and `nc` columns starts (again, after a
    /// divergence, at a finer substep): forget any samples of a previous run.
    fn restart(&mut self, n: usize, nc: usize);
    /// Sample `k` (counted from the block's start): the measurements `y`
    /// (`n`) and their sensitivities `dy[i * nc + j]` to column `j`.
    fn sample(&mut self, k: usize, y: &[f64], dy: &[f64]);
}

/// One sensitivity run's inputs (see [`SensitivitySimulator::simulate_block`]).
#[derive(Clone, Copy)]
struct BlockRun<'a> {
    sig: &'a Signals,
    params: &'a [f64],
    start: &'a BlockStart,
    tied: &'a [bool],
    extra: &'a [ExtraColumn],
    /// The tape evaluated whole at every stage (the tests' reference path).
    unsplit: bool,
}

impl<'a> BlockRun<'a> {
    /// The run of one block with the split tape (the product's path).
    fn split(
        sig: &'a Signals,
        params: &'a [f64],
        start: &'a BlockStart,
        tied: &'a [bool],
        extra: &'a [ExtraColumn],
    ) -> BlockRun<'a> {
        BlockRun {
            sig,
            params,
            start,
            tied,
            extra,
            unsplit: false,
        }
    }
}

/// The sink that stores the trajectory.
struct Store {
    q: Vec<Vec<f64>>,
    dq: Vec<Vec<Vec<f64>>>,
    len: usize,
}

impl SampleSink for Store {
    fn restart(&mut self, n: usize, nc: usize) {
        self.q = vec![vec![0.0; self.len]; n];
        self.dq = vec![vec![vec![0.0; self.len]; nc]; n];
    }

    fn sample(&mut self, k: usize, y: &[f64], dy: &[f64]) {
        let nc = self.dq.first().map_or(0, Vec::len);
        for (i, (q, dq)) in self.q.iter_mut().zip(&mut self.dq).enumerate() {
            q[k] = y[i];
            for (j, d) in dq.iter_mut().enumerate() {
                d[k] = dy[i * nc + j];
            }
        }
    }
}

/// A compiled simulator with forward sensitivities.
#[derive(Clone, Debug)]
pub struct SensitivitySimulator {
    n: usize,
    m: usize,
    n_params: usize,
    free: Vec<usize>,
    names: Vec<String>,
    /// Dynamics and their partial derivatives over `(state, inputs, full
    /// parameters)`.
    tape: Tape,
    /// `tape` split with the parameters as slow inputs.
    split: SplitTape,
    /// The dynamics alone (the plain simulator's tape), for what is decided
    /// on the state: stick-slip modes and events.
    plain: Tape,
    /// `plain` split with the parameters as slow inputs.
    plain_split: SplitTape,
    /// Which coordinates stick.
    dry: Vec<bool>,
    /// Whether the outputs end with the dry-friction levels.
    levels: bool,
    signals: SignalEffects,
    opts: SimOptions,
    law: Option<LoopLaw>,
    /// Only where a `sign()` is smoothed.
    probe: Option<StiffnessProbe>,
}

/// The parameters a model marks `estimate`, in declaration order.
pub fn estimated_parameters(model: &Model) -> Vec<String> {
    model
        .parameters
        .iter()
        .filter(|p| p.estimate.is_some())
        .map(|p| p.name.clone())
        .collect()
}

impl SensitivitySimulator {
    /// Compile the dynamics of `model` with sensitivities for the base
    /// parameters named in `free`.
    pub fn new(
        model: &Model,
        free: &[String],
        opts: SimOptions,
    ) -> Result<SensitivitySimulator, SimError> {
        check_options(&opts)?;
        let mut idx = Vec::with_capacity(free.len());
        for name in free {
            let Some(i) = model.parameters.iter().position(|p| &p.name == name) else {
                return Err(SimError::UnknownParameter { name: name.clone() });
            };
            if idx.contains(&i) {
                return Err(SimError::BadOption(format!(
                    "parameter `{name}` is listed twice"
                )));
            }
            idx.push(i);
        }
        let c = dynamics_outputs(model, opts.dry_friction)?;
        let base = c.outs.clone();
        let expanded: Vec<Expr> = base.iter().map(|e| model.expand_derived(*e)).collect();
        let mut outs = base.clone();
        for x in model.state_symbols() {
            outs.extend(base.iter().map(|e| diff(*e, x)));
        }
        for &i in &idx {
            let p = model.parameters[i].symbol;
            outs.extend(expanded.iter().map(|e| diff(*e, p)));
        }
        let tape =
            Tape::compile(&outs, &tape_inputs(model)).map_err(|e| SimError::Tape(e.to_string()))?;
        let signals = SignalEffects::new(model, &idx)?;
        let probe = if c.smoothed {
            Some(StiffnessProbe::new(model, &base)?)
        } else {
            None
        };
        let (n, m) = (model.coordinates.len(), model.inputs.len());
        let n_params = model.parameter_symbols().len();
        let slow = parameters_slow(2 * n + m, n_params);
        let split = tape.split_by_inputs(&slow);
        let plain =
            Tape::compile(&base, &tape_inputs(model)).map_err(|e| SimError::Tape(e.to_string()))?;
        let plain_split = plain.split_by_inputs(&slow);
        Ok(SensitivitySimulator {
            n,
            m,
            n_params,
            free: idx,
            names: free.to_vec(),
            tape,
            split,
            plain,
            plain_split,
            dry: c.dry,
            levels: c.levels,
            signals,
            opts,
            law: None,
            probe,
        })
    }

    /// What each free parameter moves among the signal effects, at the full
    /// parameter vector `params`: an input delay, a sensor offset, or
    /// neither (a global scan is worth it for the first two).
    pub fn signal_dependencies(&self, params: &[f64]) -> Result<Vec<Option<SignalKind>>, SimError> {
        let v = self.signals.eval(params)?;
        let (n, m) = (self.n, self.m);
        Ok((0..self.free.len())
            .map(|j| {
                if v.d_delays[j * m..(j + 1) * m].iter().any(|d| *d != 0.0) {
                    Some(SignalKind::Delay)
                } else if v.d_offsets[j * n..(j + 1) * n].iter().any(|d| *d != 0.0) {
                    Some(SignalKind::Offset)
                } else {
                    None
                }
            })
            .collect())
    }

    /// Names of the free parameters, in sensitivity order.
    pub fn free_names(&self) -> &[String] {
        &self.names
    }

    /// Indices of the free parameters in the model's base parameter vector.
    pub fn free_indices(&self) -> &[usize] {
        &self.free
    }

    /// Simulate the first `n_samples` samples with sensitivities; `params` is
    /// the full parameter vector (base then derived). The initial state is
    /// the measured one (positions minus the model's sensor offsets,
    /// velocities as the options say).
    pub fn simulate(
        &self,
        sig: &Signals,
        params: &[f64],
        n_samples: usize,
    ) -> Result<SensitivityTrajectory, SimError> {
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
    ) -> Result<SensitivityTrajectory, SimError> {
        let offsets = self.signals.eval(params)?.offsets;
        let start = BlockStart::first_samples(sig, self.opts.initial_velocity, &offsets, n);
        let tied = vec![true; self.n];
        self.run(BlockRun {
            unsplit,
            ..BlockRun::split(sig, params, &start, &tied, &[])
        })
    }

    /// The same simulator with a recorded controller in the loop (compile it
    /// with [`LoopLaw::new`]); signals must then come from
    /// [`Signals::from_experiment_closed`].
    pub fn with_loop(mut self, law: LoopLaw) -> SensitivitySimulator {
        self.law = Some(law);
        self
    }

    /// Simulate one block with sensitivities to the free parameters and to
    /// `extra` columns. `tied[i]` says that the initial position of
    /// coordinate `i` was taken from its measurement minus the model's
    /// sensor offset (so a parameter of that offset moves it: `S(0) =
    /// -dd/dtheta` there). The columns of the result are the free
    /// parameters, then the extras.
    pub fn simulate_block(
        &self,
        sig: &Signals,
        params: &[f64],
        start: &BlockStart,
        tied: &[bool],
        extra: &[ExtraColumn],
    ) -> Result<SensitivityTrajectory, SimError> {
        self.run(BlockRun::split(sig, params, start, tied, extra))
    }

    /// [`SensitivitySimulator::simulate_block`] handing each sample to
    /// `sink` instead of storing the trajectory: memory independent of the
    /// block's length (a whole 1e7-sample record's sensitivities would be
    /// `coordinates x columns x samples` values). Same simulation, same
    /// values. Returns whether the substep was refined
    /// ([`SensitivityTrajectory::refined`]).
    pub(crate) fn visit_block(
        &self,
        sig: &Signals,
        params: &[f64],
        start: &BlockStart,
        (tied, extra): (&[bool], &[ExtraColumn]),
        sink: &mut dyn SampleSink,
    ) -> Result<bool, SimError> {
        self.run_with(BlockRun::split(sig, params, start, tied, extra), sink)
    }

    /// [`SensitivitySimulator::simulate_block`], evaluating the tape split
    /// (parameter part once per call) or, with `unsplit`, whole at every
    /// stage: the reference path the tests compare against.
    fn run(&self, run: BlockRun<'_>) -> Result<SensitivityTrajectory, SimError> {
        let len = run.start.range.end.saturating_sub(run.start.range.start);
        let mut store = Store {
            q: Vec::new(),
            dq: Vec::new(),
            len,
        };
        let refined = self.run_with(run, &mut store)?;
        Ok(SensitivityTrajectory {
            q: store.q,
            dq: store.dq,
            refined,
        })
    }

    /// [`SensitivitySimulator::run`] into `sink`; whether refined.
    fn run_with(&self, run: BlockRun<'_>, sink: &mut dyn SampleSink) -> Result<bool, SimError> {
        match self.run_refined(run, 1.0, sink) {
            Err(SimError::Diverged { .. }) if self.opts.substep.is_none() => {
                self.run_refined(run, REFINE, sink).map(|()| true)
            }
            r => r.map(|()| false),
        }
    }

    /// [`SensitivitySimulator::run`] with the automatic substep divided by
    /// `refine`.
    fn run_refined(
        &self,
        run: BlockRun<'_>,
        refine: f64,
        sink: &mut dyn SampleSink,
    ) -> Result<(), SimError> {
        let BlockRun {
            sig,
            params,
            start,
            tied,
            extra,
            unsplit,
        } = run;
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
        let (n, m, p) = (self.n, self.m, self.free.len());
        check_start(sig, start, n)?;
        let nx = 2 * n;
        for c in extra {
            if c.s0.len() != nx || c.direct.len() != n {
                return Err(SimError::BadOption(format!(
                    "an extra sensitivity column needs {nx} initial values and {n} direct terms"
                )));
            }
        }
        let nc = p + extra.len();
        let (k0, k1) = (start.range.start, start.range.end);
        let (d_width, d_level) = (&effects.d_widths, &effects.d_levels);
        let (widths, levels) = (&effects.widths, &effects.levels);
        let driven: Vec<usize> = self
            .law
            .as_ref()
            .map_or(Vec::new(), |l| l.driven().to_vec());
        let nd = driven.len();
        // closed loop: du_hist[(k - k0) * nd * nc + d * nc + c], the
        // sensitivity of driven input d held from sample k
        let du_hist = RefCell::new(vec![0.0; (k1 - k0) * nd * nc]);
        let mut sys = SensDynamics::new(
            self,
            params,
            (p, nc),
            unsplit,
            &effects,
            &driven,
            &du_hist,
            k0,
        );
        let (off, d_off) = (&effects.offsets, &effects.d_offsets);
        let meas_off: Vec<f64> = off.iter().zip(&start.offsets).map(|(a, b)| a + b).collect();
        let mut z = start.x0.clone();
        z.resize(nx + nx * nc, 0.0);
        for i in 0..n {
            if tied.get(i).copied().unwrap_or(false) {
                for j in 0..p {
                    z[nx + i * nc + j] = -d_off[j * n + i];
                }
            }
        }
        for (e, c) in extra.iter().enumerate() {
            for (i, v) in c.s0.iter().enumerate() {
                z[nx + i * nc + p + e] = *v;
            }
        }
        // the direct part of each column's measurement sensitivity
        let mut direct = vec![0.0; n * nc];
        for i in 0..n {
            for j in 0..p {
                direct[i * nc + j] = d_off[j * n + i];
            }
            for (e, c) in extra.iter().enumerate() {
                direct[i * nc + p + e] = c.direct[i];
            }
        }
        sink.restart(n, nc);
        let mut y = vec![0.0; n];
        let mut dy = vec![0.0; n * nc];
        let mut du_k = vec![0.0; nd * nc];
        let mut closed = self.closed(sig, k0, nc)?;
        let at_sample = |k: usize, z: &[f64], u: &mut [Vec<f64>]| {
            let kk = k - k0;
            for i in 0..n {
                y[i] = z[i] + meas_off[i];
                for j in 0..nc {
                    dy[i * nc + j] = z[nx + i * nc + j] + direct[i * nc + j];
                }
            }
            sink.sample(kk, &y, &dy);
            if let Some((law, rep, ev, fstate, u_law, ls)) = closed.as_mut() {
                ev.step(law, rep, k, &y, fstate, u_law, Some((ls, &dy, &mut du_k)));
                let mut hist = du_hist.borrow_mut();
                for (d, &l) in driven.iter().enumerate() {
                    let (wl, ll) = (widths[l], levels[l]);
                    let v = received(u_law[d], wl, ll);
                    u[l][k] = v;
                    let (gw, gl) = received_derivatives(v, ll);
                    // the law's value passes where neither clipped nor in
                    // the deadzone
                    let passes = v.abs() < ll && (v != 0.0 || wl == 0.0);
                    for j in 0..nc {
                        let mut g = if passes { du_k[d * nc + j] } else { 0.0 };
                        if j < p {
                            g += gw * d_width[j * m + l] + gl * d_level[j * m + l];
                        }
                        hist[kk * nd * nc + d * nc + j] = g;
                    }
                }
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
        Ok(())
    }

    /// Loop state at a block starting at `k0` ([`loop_start`]) and the
    /// law's sensitivities to `nc` columns; None in open loop.
    #[allow(clippy::type_complexity)]
    fn closed<'s>(
        &'s self,
        sig: &'s Signals,
        k0: usize,
        nc: usize,
    ) -> Result<
        Option<(
            &'s LoopLaw,
            &'s Replay,
            LoopEval,
            Vec<f64>,
            Vec<f64>,
            LoopSens,
        )>,
        SimError,
    > {
        Ok(
            loop_start(self.law.as_ref(), sig, k0)?.map(|(law, rep, ev, fstate, u_law)| {
                (law, rep, ev, fstate, u_law, LoopSens::new(law, nc))
            }),
        )
    }
}

/// The sensitivity simulator's dynamics over one run: `z = [x (2n), S (2n
/// rows of nc columns, row-major)]`, the plain dynamics (`plain`) deciding
/// the stick-slip modes and events on the state alone, the full tape giving
/// the state's and the sensitivities' rates (see the module docs).
struct SensDynamics<'s> {
    plain: StateDynamics<'s>,
    tape: &'s Tape,
    split: &'s SplitTape,
    unsplit: bool,
    n: usize,
    m: usize,
    p: usize,
    nc: usize,
    /// Whether the outputs (and each derivative block) end with the levels.
    levels: bool,
    tin: Vec<f64>,
    out: Vec<f64>,
    scratch: Vec<f64>,
    minv: Vec<f64>,
    acc: Vec<f64>,
    w: Vec<f64>,
    tmp: Vec<f64>,
    /// `jd[d * n + i] = d a_i / d z_d`, `z = (state, free parameters)`.
    jd: Vec<f64>,
    du: Vec<f64>,
    /// d held / d(width, level) of each input at the held value.
    dheld: Vec<(f64, f64)>,
    d_width: &'s [f64],
    d_level: &'s [f64],
    d_delay: &'s [f64],
    sat_levels: &'s [f64],
    deadzone_forcing: bool,
    jumps: bool,
    driven: &'s [usize],
    du_hist: &'s RefCell<Vec<f64>>,
    k0: usize,
    /// `d t / d column` of the current segment's start and end, and the
    /// moving-end rate `(d b - d a) / L` of each column.
    da: Vec<f64>,
    db: Vec<f64>,
    rate: Vec<f64>,
    moving: bool,
    /// Whether `da`, `db` and `rate` are all zero (set by a segment
    /// between two samples).
    still: bool,
    /// `d t / d column` of the last event (the start of the segment after it).
    event_start: Vec<f64>,
    /// Event bookkeeping: the guard's gradient along the state and its
    /// derivative along each column, and `d tau / d column`.
    gz: Vec<f64>,
    gcol: Vec<f64>,
    dtau: Vec<f64>,
    scratch_dz: Vec<f64>,
}

impl<'s> SensDynamics<'s> {
    #[allow(clippy::too_many_arguments)]
    fn new(
        sim: &'s SensitivitySimulator,
        params: &[f64],
        (p, nc): (usize, usize),
        unsplit: bool,
        effects: &'s crate::experiment_sim::SignalValues,
        driven: &'s [usize],
        du_hist: &'s RefCell<Vec<f64>>,
        k0: usize,
    ) -> SensDynamics<'s> {
        let (n, m) = (sim.n, sim.m);
        let nx = 2 * n;
        let plain = StateDynamics::new(
            (&sim.plain, &sim.plain_split),
            (n, m),
            params,
            &sim.dry,
            sim.levels,
            unsplit,
        );
        let mut tin = vec![0.0; nx + m + sim.n_params];
        tin[nx + m..].copy_from_slice(params);
        let mut out = vec![0.0; sim.tape.n_outputs()];
        let mut scratch = vec![0.0; sim.tape.scratch_len().max(sim.split.scratch_len())];
        if !unsplit {
            sim.split.eval_slow_outputs(&tin, &mut out, &mut scratch);
        }
        SensDynamics {
            plain,
            tape: &sim.tape,
            split: &sim.split,
            unsplit,
            n,
            m,
            p,
            nc,
            levels: sim.levels,
            tin,
            out,
            scratch,
            minv: vec![0.0; n * n],
            acc: vec![0.0; n],
            w: vec![0.0; n],
            tmp: vec![0.0; n],
            jd: vec![0.0; (nx + p) * n],
            du: vec![0.0; m],
            dheld: vec![(0.0, 0.0); m],
            d_width: &effects.d_widths,
            d_level: &effects.d_levels,
            d_delay: &effects.d_delays,
            sat_levels: &effects.levels,
            deadzone_forcing: sim.signals.deadzone_depends_on_free,
            jumps: sim.signals.delay_depends_on_free,
            driven,
            du_hist,
            k0,
            da: vec![0.0; nc],
            db: vec![0.0; nc],
            rate: vec![0.0; nc],
            moving: false,
            still: true,
            event_start: vec![0.0; nc],
            gz: vec![0.0; nx],
            gcol: vec![0.0; nc],
            dtau: vec![0.0; nc],
            scratch_dz: vec![0.0; nx + nx * nc],
        }
    }

    /// `d t / d column c` of a segment boundary.
    fn boundary_derivative(&self, b: Boundary, c: usize) -> f64 {
        match b {
            Boundary::Sample => 0.0,
            Boundary::Delay(l) if c < self.p => self.d_delay[c * self.m + l],
            Boundary::Delay(_) => 0.0,
            Boundary::Event => self.event_start[c],
        }
    }

    /// `d held input / d column c` into `self.du` (deadzone widths and
    /// saturation levels of inputs from the data, the law's inputs in closed
    /// loop); false when all zero.
    fn input_derivative(&mut self, u: &[f64], held: &[usize], c: usize) -> bool {
        let (m, p) = (self.m, self.p);
        let mut any = false;
        self.du.iter_mut().for_each(|v| *v = 0.0);
        if self.deadzone_forcing && c < p {
            for l in 0..m {
                if self.driven.contains(&l) {
                    continue;
                }
                let (gw, gl) = received_derivatives(u[l], self.sat_levels[l]);
                let g = gw * self.d_width[c * m + l] + gl * self.d_level[c * m + l];
                if g != 0.0 {
                    self.du[l] = g;
                    any = true;
                }
            }
        }
        let nd = self.driven.len();
        if nd > 0 {
            let hist = self.du_hist.borrow();
            for (d, &l) in self.driven.iter().enumerate() {
                let k = held[l];
                if k >= self.k0 {
                    let v = hist[(k - self.k0) * nd * self.nc + d * self.nc + c];
                    if v != 0.0 {
                        self.du[l] = v;
                        any = true;
                    }
                }
            }
        }
        any
    }

    /// The breakaway guard `Fs_j - |f_j|` of stuck joint `j` at state `x`:
    /// its gradient along the state into `self.gz`, and `g_theta + g_u
    /// du/dcolumn` of each column into `self.gcol` (the full tape at `x`,
    /// the mode's constrained accelerations and their Jacobian).
    fn breakaway_gradient(&mut self, z: &[f64], u: &[f64], held: &[usize], j: usize) -> bool {
        let (n, m, p, nc) = (self.n, self.m, self.p, self.nc);
        let nx = 2 * n;
        let dim = nx + nx * nc;
        let mut dz = std::mem::take(&mut self.scratch_dz);
        let ok = self.rhs(&z[..dim], u, held, Rate::Event(1.0), &mut dz[..dim]);
        self.scratch_dz = dz;
        if !ok {
            return false;
        }
        let nn = n * n;
        let bs = nn + n + n * m + if self.levels { n } else { 0 };
        let out_buf = std::mem::take(&mut self.out);
        let out = &out_buf;
        let mm = &out[..nn];
        let (r0, bmat) = (&out[nn..nn + n], &out[nn + n..nn + n + n * m]);
        let level = if self.levels {
            out[nn + n + n * m + j]
        } else {
            0.0
        };
        let mut b_j = r0[j];
        for l in 0..m {
            b_j += bmat[j * m + l] * u[l];
        }
        let f_j: f64 = (0..n).map(|k| mm[j * n + k] * self.acc[k]).sum::<f64>() - b_j;
        let sgn = f_j.signum();
        let grad = |d: usize| -> f64 {
            let blk = &out[bs * (d + 1)..bs * (d + 2)];
            let (dm, dr, db) = (&blk[..nn], &blk[nn..nn + n], &blk[nn + n..nn + n + n * m]);
            let mut df = -dr[j];
            for k in 0..n {
                df += dm[j * n + k] * self.acc[k] + mm[j * n + k] * self.jd[d * n + k];
            }
            for l in 0..m {
                df -= db[j * m + l] * u[l];
            }
            let dl = if self.levels && level > 0.0 {
                blk[nn + n + n * m + j]
            } else {
                0.0
            };
            dl - sgn * df
        };
        for d in 0..nx {
            self.gz[d] = grad(d);
        }
        for c in 0..nc {
            self.gcol[c] = if c < p { grad(nx + c) } else { 0.0 };
        }
        for c in 0..nc {
            if !self.input_derivative(u, held, c) {
                continue;
            }
            // the input's force B du, through the mode's accelerations
            for i in 0..n {
                self.w[i] = (0..m).map(|l| bmat[i * m + l] * self.du[l]).sum::<f64>();
            }
            mat_vec(&self.minv, n, &self.w, &mut self.tmp);
            let df_u: f64 = (0..n).map(|k| mm[j * n + k] * self.tmp[k]).sum::<f64>() - self.w[j];
            self.gcol[c] -= sgn * df_u;
        }
        self.out = out_buf;
        true
    }
}

impl Dynamics for SensDynamics<'_> {
    fn n(&self) -> usize {
        self.n
    }

    fn has_dry(&self) -> bool {
        self.plain.has_dry()
    }

    fn dry_joints(&self) -> usize {
        self.plain.dry_joints()
    }

    fn tangent_len(&self) -> usize {
        2 * self.n
    }

    fn classify(&mut self, x: &[f64], u: &[f64], release: Option<usize>) -> bool {
        self.plain.classify(x, u, release)
    }

    fn state_rhs(&mut self, x: &[f64], u: &[f64], dx: &mut [f64]) -> bool {
        self.plain.rates(x, u, dx)
    }

    fn guards(&mut self, x: &[f64], u: &[f64], g: &mut [f64]) -> bool {
        self.plain.guards(x, u, g)
    }

    fn mode(&self) -> &Mode {
        &self.plain.mode
    }

    fn begin_segment(&mut self, seg: &Segment) {
        // a whole sample interval (the common case): every boundary
        // derivative is zero, as the loop below would write them
        if seg.start == Boundary::Sample && seg.end == Boundary::Sample {
            if !self.still {
                self.da.fill(0.0);
                self.db.fill(0.0);
                self.rate.fill(0.0);
                self.still = true;
            }
            self.moving = false;
            return;
        }
        self.still = false;
        let mut moving = false;
        for c in 0..self.nc {
            let a = self.boundary_derivative(seg.start, c);
            let b = self.boundary_derivative(seg.end, c);
            self.da[c] = a;
            self.db[c] = b;
            self.rate[c] = (b - a) / seg.len;
            moving |= self.rate[c] != 0.0;
        }
        self.moving = moving;
    }

    fn wants_switches(&self) -> bool {
        self.jumps
    }

    fn input_gain(&mut self, x: &[f64], u: &[f64], g: &mut [f64]) -> bool {
        self.plain.input_gain(x, u, g)
    }

    fn held(&mut self, z: &mut [f64]) {
        let mode = &self.plain.mode;
        if !mode.any_stuck() {
            return;
        }
        let (n, nc) = (self.n, self.nc);
        let nx = 2 * n;
        for j in 0..n {
            if mode.stuck[j] {
                z[nx + (n + j) * nc..nx + (n + j + 1) * nc]
                    .iter_mut()
                    .for_each(|v| *v = 0.0);
            }
        }
    }

    /// Jump of `S` at a switch of input `l`: `(f_old - f_new) dTd_l/dtheta`.
    fn switch(&mut self, l: usize, f_old: &[f64], f_new: &[f64], z: &mut [f64]) {
        let (nx, nc, m) = (2 * self.n, self.nc, self.m);
        for i in 0..nx {
            let df = f_old[i] - f_new[i];
            if df != 0.0 {
                for j in 0..self.p {
                    z[nx + i * nc + j] += df * self.d_delay[j * m + l];
                }
            }
        }
    }

    fn rhs(&mut self, z: &[f64], u: &[f64], held: &[usize], rate: Rate, dz: &mut [f64]) -> bool {
        let (n, m, p, nc) = (self.n, self.m, self.p, self.nc);
        let nx = 2 * n;
        let dim = nx + nx * nc;
        copy_short(&mut self.tin[..nx], &z[..nx]);
        copy_short(&mut self.tin[nx..nx + m], u);
        if self.unsplit {
            self.tape.eval(&self.tin, &mut self.out, &mut self.scratch);
        } else {
            self.split
                .eval_fast_changed(&self.tin, &mut self.out, &mut self.scratch);
        }
        let nn = n * n;
        let bs = nn + n + n * m + if self.levels { n } else { 0 };
        let mode = &self.plain.mode;
        // M_FF^-1 once (M^-1 with no joint stuck); every right-hand side is
        // then a product
        if !self
            .plain
            .rules
            .free_inverse(&self.out[..nn], &mode.stuck, &mut self.minv)
        {
            return false;
        }
        let r0 = &self.out[nn..nn + n];
        let b = &self.out[nn + n..nn + n + n * m];
        forces(r0, b, u, &mut self.tmp);
        let dir = if self.levels {
            let d = &self.out[nn + n + n * m..bs];
            for i in 0..n {
                let s = mode.dir[i];
                if s != 0.0 {
                    self.tmp[i] -= d[i] * s;
                }
            }
            Some(&mode.dir[..])
        } else {
            None
        };
        mat_vec(&self.minv, n, &self.tmp, &mut self.acc);
        copy_short(&mut dz[..n], &z[n..nx]);
        copy_short(&mut dz[n..nx], &self.acc);
        let s = &z[nx..dim];
        let (ds, tangent) = dz[nx..].split_at_mut(nx * nc);
        let blocks = &self.out[bs..bs * (nx + p + 1)];
        let (acc, minv, w, jd) = (&self.acc, &self.minv, &mut self.w, &mut self.jd);
        macro_rules! kernels {
            ($dim:expr, $inputs:expr) => {{
                acceleration_jacobian(($dim, $inputs), blocks, u, dir, acc, minv, w, jd);
                sensitivity_rates($dim, jd, s, ds, (p, nc));
            }};
        }
        // (one input, the common case, known when compiling too)
        match (n, m) {
            (1, 1) => kernels!(Fixed::<1>, Fixed::<1>),
            (2, 1) => kernels!(Fixed::<2>, Fixed::<1>),
            (3, 1) => kernels!(Fixed::<3>, Fixed::<1>),
            (1, _) => kernels!(Fixed::<1>, Any(m)),
            (2, _) => kernels!(Fixed::<2>, Any(m)),
            (3, _) => kernels!(Fixed::<3>, Any(m)),
            _ => kernels!(Any(n), Any(m)),
        }
        // deadzone widths and saturation levels of inputs from the data:
        // M^-1 B d held/dtheta, with d held/d(w, L) from the held value
        if self.deadzone_forcing {
            for l in 0..m {
                self.dheld[l] = received_derivatives(u[l], self.sat_levels[l]);
            }
            for j in 0..p {
                let mut any = false;
                for l in 0..m {
                    let (gw, gl) = self.dheld[l];
                    let g = gw * self.d_width[j * m + l] + gl * self.d_level[j * m + l];
                    self.du[l] = if g != 0.0 && !self.driven.contains(&l) {
                        any = true;
                        g
                    } else {
                        0.0
                    };
                }
                if !any {
                    continue;
                }
                add_input_forcing(
                    &self.minv,
                    b,
                    &self.du,
                    (&mut self.tmp, &mut self.w),
                    ds,
                    (nc, j),
                );
            }
        }
        // inputs computed in the loop: M^-1 B du/dcolumn of the held sample
        let nd = self.driven.len();
        if nd > 0 {
            let hist = self.du_hist.borrow();
            for j in 0..nc {
                let mut any = false;
                for l in 0..m {
                    self.du[l] = 0.0;
                }
                for (d, &l) in self.driven.iter().enumerate() {
                    let k = held[l];
                    if k >= self.k0 {
                        let v = hist[(k - self.k0) * nd * nc + d * nc + j];
                        if v != 0.0 {
                            self.du[l] = v;
                            any = true;
                        }
                    }
                }
                if !any {
                    continue;
                }
                add_input_forcing(
                    &self.minv,
                    b,
                    &self.du,
                    (&mut self.tmp, &mut self.w),
                    ds,
                    (nc, j),
                );
            }
        }
        match rate {
            // moving segment boundaries (delayed switches, events): f (b' - a') / L
            Rate::Segment => {
                if self.moving {
                    for (j, &r) in self.rate.iter().enumerate() {
                        if r != 0.0 {
                            for i in 0..n {
                                ds[i * nc + j] += z[n + i] * r;
                                ds[(n + i) * nc + j] += self.acc[i] * r;
                            }
                        }
                    }
                }
            }
            // the step up to an event: the tangent d x / d tau, f_z T + f / tau
            Rate::Event(len) => {
                if tangent.len() >= nx && z.len() >= dim + nx {
                    let t = &z[dim..dim + nx];
                    for i in 0..n {
                        tangent[i] = t[n + i] + z[n + i] / len;
                        let mut v = self.acc[i] / len;
                        for (k, tk) in t.iter().enumerate() {
                            v += self.jd[k * n + i] * tk;
                        }
                        tangent[n + i] = v;
                    }
                }
            }
        }
        true
    }

    /// `S(tau) = S0 + F dtau/dtheta` with `dtau/dtheta = -(g_z S0 +
    /// g_theta) / (g_z F)`, `F` the tangent (see the module docs); a
    /// velocity reaching zero is set to 0.0 with its sensitivity row.
    fn event(&mut self, z: &mut [f64], u: &[f64], held: &[usize], ev: &Located) -> bool {
        let (n, nc) = (self.n, self.nc);
        let nx = 2 * n;
        let dim = nx + nx * nc;
        let j = ev.joint;
        let gf = if ev.stuck {
            if !self.breakaway_gradient(z, u, held, j) {
                return false;
            }
            for c in 0..nc {
                let mut g = self.gcol[c];
                for d in 0..nx {
                    g += self.gz[d] * z[nx + d * nc + c];
                }
                self.gcol[c] = g;
            }
            (0..nx).map(|d| self.gz[d] * z[dim + d]).sum::<f64>()
        } else {
            // g = sigma v_j: sigma cancels
            for c in 0..nc {
                self.gcol[c] = z[nx + (n + j) * nc + c];
            }
            z[dim + n + j]
        };
        for c in 0..nc {
            self.dtau[c] = if gf != 0.0 && gf.is_finite() {
                -self.gcol[c] / gf
            } else {
                0.0
            };
        }
        for i in 0..nx {
            let f = z[dim + i];
            if f != 0.0 {
                for c in 0..nc {
                    z[nx + i * nc + c] += f * self.dtau[c];
                }
            }
        }
        if !ev.stuck {
            z[n + j] = 0.0;
            z[nx + (n + j) * nc..nx + (n + j + 1) * nc]
                .iter_mut()
                .for_each(|v| *v = 0.0);
        }
        let (s, steps) = ev.step;
        let frac = s as f64 / steps as f64;
        for c in 0..nc {
            self.event_start[c] = self.da[c] + frac * (self.db[c] - self.da[c]) + self.dtau[c];
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment_sim::tests::{median_seconds, pendulum, perturbed, signals};

    /// As for the plain simulator: split and whole-tape sensitivity
    /// simulations agree bit for bit, with and without a delay and offset.
    #[test]
    fn split_sensitivities_are_bit_identical() {
        for effects in [false, true] {
            let model = pendulum(effects);
            let free = estimated_parameters(&model);
            let sim =
                SensitivitySimulator::new(&model, &free, SimOptions::default()).expect("compiles");
            let sig = signals(&model);
            let p = perturbed(&model);
            let split = sim.run_n(&sig, &p, sig.len(), false).expect("simulates");
            let whole = sim.run_n(&sig, &p, sig.len(), true).expect("simulates");
            let flat = |tr: &SensitivityTrajectory| -> Vec<u64> {
                let q = tr.q.iter().flatten();
                let dq = tr.dq.iter().flatten().flatten();
                q.chain(dq).map(|v| v.to_bits()).collect()
            };
            assert!(split.dq[0].iter().any(|d| d.iter().any(|v| *v != 0.0)));
            assert_eq!(flat(&split), flat(&whole), "effects: {effects}");
        }
    }
    /// Split against whole-tape sensitivity simulation time (interleaved).
    /// Run with `cargo test -p plantc-identify --release --lib
    /// split_timing -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn split_timing_sensitivities() {
        let model = pendulum(false);
        let free = estimated_parameters(&model);
        let sim =
            SensitivitySimulator::new(&model, &free, SimOptions::default()).expect("compiles");
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
            "sensitivity simulation, {k} samples, {} parameters: split {:.4} s, whole tape {:.4} s ({} slow + {} fast instructions)",
            free.len(),
            a[2],
            b[2],
            sim.split.slow_instructions().len(),
            sim.split.fast_instructions().len()
        );
    }
}
