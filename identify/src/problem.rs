//! The least-squares problem of a fit: which unknowns, which residuals.
//!
//! Unknowns come in two levels:
//! - **globals**: the free model parameters (bounded by their `estimate`
//!   boxes), then the per-experiment sensor offsets (one per experiment and
//!   offset coordinate, unbounded);
//! - **locals**: for each *block* (a whole experiment in single shooting, a
//!   segment of one in multiple shooting) the components of its initial
//!   state that are estimated. A block touches only its own locals, so the
//!   normal equations have a block-arrow structure (solved by a Schur
//!   complement on the globals, [`crate::lm`]).
//!
//! Residuals are `w_i (y_hat_i(t_k) - y_i(t_k))` for every coordinate `i`
//! and sample `k` of every block, with `w_i` the channel weights
//! ([`crate::weights`]). A block's initial state is, per component: its
//! local unknown when estimated; else, for a position, the measurement at
//! the block's first sample minus the model's and the experiment's offsets
//! ("tied"); else, for a velocity, a fixed value (zero, or a data
//! estimate). An estimated position is the measurement (minus the
//! offsets) plus a deviation `delta`: the local unknown is `delta`.
//!
//! Every local unknown carries a Gaussian prior from the data
//! ([`crate::initial_state`]): its term `((l - mean) / sigma)^2` is part of
//! the cost (in the same noise units as the weighted residuals, so the
//! fit is a maximum a posteriori estimate), and the unknown is held within
//! [`crate::initial_state::prior_bound`] standard deviations of its mean.
//!
//! Blocks are simulated in parallel (one worker per core, blocks handed out
//! in turn).

use std::ops::Range;

use plantc_derive::model::{Model, ParameterValues};

use crate::experiment_sim::{BlockStart, Signals, SimError, Simulator};
use crate::initial_state::Prior;
use crate::lm::{BlockNormal, Normal};
use crate::sensitivity::{ExtraColumn, SampleSink, SensitivitySimulator};

/// How one block is laid out.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct BlockLayout {
    /// Experiment index.
    pub exp: usize,
    /// Samples of the block.
    pub range: Range<usize>,
    /// State components estimated as locals (positions `0..n`, velocities
    /// `n..2n`), in local order.
    pub free_state: Vec<usize>,
    /// Values of the velocity components that are not estimated (`2n`
    /// long; positions are ignored).
    pub fixed: Vec<f64>,
    /// The prior of each local unknown (in local order): a position's
    /// deviation from its measurement, a velocity.
    pub priors: Vec<Prior>,
    /// Bounds of each local unknown (in local order).
    pub lo: Vec<f64>,
    /// See [`BlockLayout::lo`].
    pub hi: Vec<f64>,
}

impl BlockLayout {
    /// The prior terms `sum ((l - mean) / sigma)^2` of locals `l`.
    pub fn prior_ssr(&self, l: &[f64]) -> f64 {
        self.priors
            .iter()
            .zip(l)
            .filter(|(p, _)| p.sigma.is_finite())
            .map(|(p, v)| p.z(*v).powi(2))
            .sum()
    }

    /// `l` held within the locals' bounds.
    pub fn clamp(&self, l: &mut [f64]) {
        for ((v, lo), hi) in l.iter_mut().zip(&self.lo).zip(&self.hi) {
            *v = v.clamp(*lo, *hi);
        }
    }
}

/// A point of the problem: globals and each block's locals.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Point {
    /// Free model parameters, then per-experiment offsets.
    pub g: Vec<f64>,
    /// Locals per block.
    pub l: Vec<Vec<f64>>,
}

/// The problem.
pub(crate) struct Problem<'a> {
    pub model: &'a Model,
    pub sim: &'a Simulator,
    pub sens: &'a SensitivitySimulator,
    pub sigs: &'a [Signals],
    /// Weight per coordinate (`1 / noise`, [`crate::weights`]).
    pub weights: Vec<f64>,
    /// How much each coordinate moves (its pooled spread, SI): the scale
    /// of [`Problem::relative_cost`].
    pub spreads: Vec<f64>,
    /// Indices of the free model parameters in the base vector.
    pub free: Vec<usize>,
    /// Base parameter values (the free ones are overwritten by the globals).
    pub base: Vec<f64>,
    /// `(experiment, coordinate)` of each offset global, after the free
    /// parameters.
    pub offsets: Vec<(usize, usize)>,
    pub blocks: Vec<BlockLayout>,
    /// Bounds of the globals.
    pub lo: Vec<f64>,
    pub hi: Vec<f64>,
}

/// `f(i)` for `i` in `0..count` on the workers of [`crate::parallel`];
/// results in order.
pub(crate) fn par_each<T: Send>(count: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    crate::parallel::par_map(count, f)
}

impl Problem<'_> {
    /// Number of coordinates.
    pub fn n(&self) -> usize {
        self.model.coordinates.len()
    }

    /// Number of residuals over every whole block.
    pub fn count_all(&self) -> usize {
        self.blocks
            .iter()
            .map(|b| (b.range.end - b.range.start) * self.n())
            .sum()
    }

    /// Number of globals.
    pub fn n_globals(&self) -> usize {
        self.free.len() + self.offsets.len()
    }

    /// Number of locals: the estimated initial-state components of every
    /// block.
    pub fn n_locals(&self) -> usize {
        self.blocks.iter().map(|b| b.free_state.len()).sum()
    }

    /// Number of unknowns: the globals and every block's locals.
    pub fn n_unknowns(&self) -> usize {
        self.n_globals() + self.n_locals()
    }

    /// Base parameter vector at globals `g`.
    pub fn base_at(&self, g: &[f64]) -> Vec<f64> {
        let mut b = self.base.clone();
        for (j, &i) in self.free.iter().enumerate() {
            b[i] = g[j];
        }
        b
    }

    /// Full parameter vector at globals `g`.
    pub fn full_at(&self, g: &[f64]) -> Vec<f64> {
        ParameterValues::from_base(self.model, self.base_at(g)).full
    }

    /// Per-experiment offsets of experiment `e` (one per coordinate).
    pub fn exp_offsets(&self, g: &[f64], e: usize) -> Vec<f64> {
        let mut d = vec![0.0; self.n()];
        for (o, &(ex, i)) in self.offsets.iter().enumerate() {
            if ex == e {
                d[i] = g[self.free.len() + o];
            }
        }
        d
    }

    /// Whether the initial position of each coordinate is tied to its
    /// measurement (minus the offsets): always, an estimated position
    /// being the measurement plus a deviation.
    fn tied(&self) -> Vec<bool> {
        vec![true; self.n()]
    }

    /// `pt` with every block's locals within their priors' bounds.
    pub fn clamped(&self, pt: &Point) -> Point {
        let mut q = pt.clone();
        for (blk, l) in self.blocks.iter().zip(q.l.iter_mut()) {
            blk.clamp(l);
        }
        q
    }

    /// The prior terms of every block's locals at `pt`.
    pub fn prior_ssr(&self, pt: &Point) -> f64 {
        self.blocks
            .iter()
            .zip(&pt.l)
            .map(|(b, l)| b.prior_ssr(l))
            .sum()
    }

    /// The start of block `b` at point `pt`, its range clipped to `range`.
    pub fn block_start(
        &self,
        b: usize,
        pt: &Point,
        model_offsets: &[f64],
        range: Range<usize>,
    ) -> BlockStart {
        let blk = &self.blocks[b];
        let n = self.n();
        let sig = &self.sigs[blk.exp];
        let exp_off = self.exp_offsets(&pt.g, blk.exp);
        let k0 = blk.range.start;
        let mut x0 = vec![0.0; 2 * n];
        for (c, x) in x0.iter_mut().enumerate() {
            let local = blk
                .free_state
                .iter()
                .position(|&s| s == c)
                .map(|j| pt.l[b][j]);
            *x = if c < n {
                sig.q[c][k0] - model_offsets[c] - exp_off[c] + local.unwrap_or(0.0)
            } else {
                local.unwrap_or(blk.fixed[c])
            };
        }
        BlockStart {
            range,
            x0,
            offsets: exp_off,
        }
    }

    /// The samples of block `b` within `horizon` s of its start.
    pub fn block_range(&self, b: usize, horizon: f64) -> Range<usize> {
        let blk = &self.blocks[b];
        if !horizon.is_finite() {
            return blk.range.clone();
        }
        let t = &self.sigs[blk.exp].t;
        let t0 = t[blk.range.start];
        let end = blk.range.start + t[blk.range.clone()].partition_point(|&x| x <= t0 + horizon);
        blk.range.start..end.max(blk.range.start + 1).min(blk.range.end)
    }

    /// Weighted residuals' sum of squares and count over every block
    /// within `horizon` of its start.
    pub fn cost(&self, pt: &Point, horizon: f64) -> Result<(f64, usize), SimError> {
        self.cost_with(pt, horizon, &self.weights)
    }

    /// The residuals' sum of squares with each channel divided by its
    /// spread (how much it moves), and the count: `rms <= 1` means the
    /// simulation stays within the channels' own motion of the data (fit %
    /// above 0), whatever their noise.
    pub fn relative_cost(&self, pt: &Point, horizon: f64) -> Result<(f64, usize), SimError> {
        let w: Vec<f64> = self
            .spreads
            .iter()
            .zip(&self.weights)
            .map(|(s, w)| if *s > 0.0 { 1.0 / s } else { *w })
            .collect();
        self.cost_with(pt, horizon, &w)
    }

    /// [`Problem::cost`] with other channel weights.
    fn cost_with(
        &self,
        pt: &Point,
        horizon: f64,
        weights: &[f64],
    ) -> Result<(f64, usize), SimError> {
        let full = self.full_at(&pt.g);
        let model_off = self.sim.model_offsets(&full)?;
        let parts = par_each(self.blocks.len(), |b| {
            let blk = &self.blocks[b];
            let sig = &self.sigs[blk.exp];
            let start = self.block_start(b, pt, &model_off, self.block_range(b, horizon));
            let k0 = start.range.start;
            let tr = self.sim.simulate_block(sig, &full, &start)?;
            let mut ssr = 0.0;
            for (i, qs) in tr.q.iter().enumerate() {
                let w = weights[i];
                for (k, v) in qs.iter().enumerate() {
                    let r = w * (v - sig.q[i][k0 + k]);
                    ssr += r * r;
                }
            }
            Ok((ssr, tr.q.len() * tr.q.first().map_or(0, Vec::len)))
        });
        let mut ssr = self.prior_ssr(pt);
        let mut count = 0;
        for p in parts {
            let (s, c) = p?;
            ssr += s;
            count += c;
        }
        if !ssr.is_finite() {
            return Err(SimError::Diverged {
                experiment: "(cost)".into(),
                time: f64::NAN,
            });
        }
        Ok((ssr, count))
    }

    /// Simulated measurements over every block (whole blocks), stitched per
    /// experiment: `[experiment][coordinate][sample]`.
    pub fn predict(&self, pt: &Point) -> Result<Vec<Vec<Vec<f64>>>, SimError> {
        let full = self.full_at(&pt.g);
        let model_off = self.sim.model_offsets(&full)?;
        let parts = par_each(self.blocks.len(), |b| {
            let start = self.block_start(b, pt, &model_off, self.blocks[b].range.clone());
            self.sim
                .simulate_block(&self.sigs[self.blocks[b].exp], &full, &start)
        });
        // a block that is its whole record is taken as it is (not copied:
        // a long record's trajectory is large); others are stitched into
        // NaN-filled records
        let mut out: Vec<Vec<Vec<f64>>> = vec![Vec::new(); self.sigs.len()];
        for (b, tr) in parts.into_iter().enumerate() {
            let tr = tr?;
            let blk = &self.blocks[b];
            let len = self.sigs[blk.exp].len();
            let whole = blk.range == (0..len) && tr.q.iter().all(|q| q.len() == len);
            if whole && out[blk.exp].is_empty() {
                out[blk.exp] = tr.q;
                continue;
            }
            let rec = &mut out[blk.exp];
            if rec.is_empty() {
                *rec = vec![vec![f64::NAN; len]; self.n()];
            }
            for (i, q) in tr.q.iter().enumerate() {
                rec[i][blk.range.start..blk.range.start + q.len()].copy_from_slice(q);
            }
        }
        for (rec, s) in out.iter_mut().zip(self.sigs) {
            if rec.is_empty() {
                *rec = vec![vec![f64::NAN; s.len()]; self.n()];
            }
        }
        Ok(out)
    }

    /// The normal equations `J'J`, `J'r` in block-arrow form at `pt` over
    /// every block within `horizon`.
    pub fn normal(&self, pt: &Point, horizon: f64) -> Result<Normal, SimError> {
        let full = self.full_at(&pt.g);
        let model_off = self.sim.model_offsets(&full)?;
        let (ng, n) = (self.n_globals(), self.n());
        // the sensitivity simulator has columns for every free parameter
        // (in `free` order), or none (nuisance-only stages: the parameters'
        // rows stay zero and the caller holds them)
        let p = self.sens.free_indices().len();
        debug_assert!(p == 0 || p == self.free.len());
        let p_glob = self.free.len();
        let parts = par_each(self.blocks.len(), |b| {
            let blk = &self.blocks[b];
            let sig = &self.sigs[blk.exp];
            let start = self.block_start(b, pt, &model_off, self.block_range(b, horizon));
            let k0 = start.range.start;
            // extra columns: this experiment's offsets, then free state
            let tied = self.tied();
            let mut extra = Vec::new();
            let mut map: Vec<Col> = (0..p).map(Col::Global).collect();
            for (o, &(e, i)) in self.offsets.iter().enumerate() {
                if e != blk.exp {
                    continue;
                }
                let mut s0 = vec![0.0; 2 * n];
                if tied[i] {
                    s0[i] = -1.0;
                }
                let mut direct = vec![0.0; n];
                direct[i] = 1.0;
                extra.push(ExtraColumn { s0, direct });
                map.push(Col::Global(p_glob + o));
            }
            for (j, &c) in blk.free_state.iter().enumerate() {
                let mut s0 = vec![0.0; 2 * n];
                s0[c] = 1.0;
                extra.push(ExtraColumn {
                    s0,
                    direct: vec![0.0; n],
                });
                map.push(Col::Local(j));
            }
            // J'J and J'r summed sample by sample as the simulation runs:
            // the Jacobian (samples x columns) is never stored
            let mut acc = NormalSink {
                measured: sig.q.iter().map(|q| &q[k0..]).collect(),
                weights: &self.weights,
                parts: Vec::new(),
                row: Vec::new(),
            };
            let refined = self
                .sens
                .visit_block(sig, &full, &start, (&tied, &extra), &mut acc)?;
            let nc = map.len();
            let (jtj, jtr, ssr, count) = acc.total(nc);
            Ok((map, jtj, jtr, ssr, count, refined))
        });
        let mut nrm = Normal::new(ng, self.blocks.iter().map(|b| b.free_state.len()));
        // the priors: residual (l - mean)/sigma, Jacobian 1/sigma
        for (b, blk) in self.blocks.iter().enumerate() {
            let bn: &mut BlockNormal = &mut nrm.blocks[b];
            for (j, p) in blk.priors.iter().enumerate() {
                if p.sigma.is_finite() {
                    let w = 1.0 / p.sigma;
                    bn.a_ll[j * bn.l + j] += w * w;
                    bn.g_l[j] += w * p.z(pt.l[b][j]);
                    nrm.ssr += p.z(pt.l[b][j]).powi(2);
                }
            }
        }
        for (b, part) in parts.into_iter().enumerate() {
            let (map, jtj, jtr, ssr, count, refined) = part?;
            nrm.ssr += ssr;
            nrm.count += count;
            nrm.refined |= refined;
            let nc = map.len();
            let bn: &mut BlockNormal = &mut nrm.blocks[b];
            for c in 0..nc {
                match map[c] {
                    Col::Global(gc) => nrm.g_g[gc] += jtr[c],
                    Col::Local(lc) => bn.g_l[lc] += jtr[c],
                }
                for d in 0..nc {
                    let v = jtj[c * nc + d];
                    match (map[c], map[d]) {
                        (Col::Global(a), Col::Global(bb)) => nrm.a_gg[a * ng + bb] += v,
                        (Col::Global(a), Col::Local(l)) => bn.a_gl[a * bn.l + l] += v,
                        (Col::Local(l), Col::Local(m)) => bn.a_ll[l * bn.l + m] += v,
                        (Col::Local(_), Col::Global(_)) => {}
                    }
                }
            }
        }
        if !nrm.ssr.is_finite() {
            return Err(SimError::Diverged {
                experiment: "(normal equations)".into(),
                time: f64::NAN,
            });
        }
        Ok(nrm)
    }
}

/// Where a block's sensitivity column goes.
#[derive(Copy, Clone, Debug, PartialEq)]
enum Col {
    Global(usize),
    Local(usize),
}

/// One coordinate's share of a block's normal equations.
struct CoordinateNormal {
    /// `J'J` (upper triangle used), `nc x nc`.
    jtj: Vec<f64>,
    jtr: Vec<f64>,
    ssr: f64,
    count: usize,
}

/// Sums a block's `J'J`, `J'r` and SSR as its sensitivity simulation
/// hands over the samples ([`SampleSink`]). One sum per coordinate, each in
/// sample order, added in coordinate order at the end: the same terms in
/// the same order as summing a stored Jacobian coordinate by coordinate,
/// but for the last additions of each coordinate's share (rounding only).
struct NormalSink<'s> {
    /// Each coordinate's measurements from the block's first sample.
    measured: Vec<&'s [f64]>,
    weights: &'s [f64],
    parts: Vec<CoordinateNormal>,
    /// One weighted Jacobian row.
    row: Vec<f64>,
}

impl SampleSink for NormalSink<'_> {
    fn restart(&mut self, n: usize, nc: usize) {
        self.parts = (0..n)
            .map(|_| CoordinateNormal {
                jtj: vec![0.0; nc * nc],
                jtr: vec![0.0; nc],
                ssr: 0.0,
                count: 0,
            })
            .collect();
        self.row = vec![0.0; nc];
    }

    fn sample(&mut self, k: usize, y: &[f64], dy: &[f64]) {
        let nc = self.row.len();
        let row = &mut self.row;
        for (i, part) in self.parts.iter_mut().enumerate() {
            let w = self.weights[i];
            let r = w * (y[i] - self.measured[i][k]);
            part.ssr += r * r;
            part.count += 1;
            for (rc, d) in row.iter_mut().zip(&dy[i * nc..(i + 1) * nc]) {
                *rc = w * d;
            }
            // slices first: the stores into `jtj` then cannot be taken for
            // stores into the vectors' headers, and the loop vectorizes
            let (jtj, jtr) = (&mut part.jtj[..], &mut part.jtr[..]);
            for (c, (&rc, jtr_c)) in row.iter().zip(jtr.iter_mut()).enumerate() {
                if rc == 0.0 {
                    continue;
                }
                *jtr_c += rc * r;
                let upper = &mut jtj[c * nc + c..(c + 1) * nc];
                for (a, &rd) in upper.iter_mut().zip(&row[c..]) {
                    *a += rc * rd;
                }
            }
        }
    }
}

impl NormalSink<'_> {
    /// The block's `J'J` (full, symmetric), `J'r`, SSR and residual count.
    fn total(self, nc: usize) -> (Vec<f64>, Vec<f64>, f64, usize) {
        let mut jtj = vec![0.0; nc * nc];
        let mut jtr = vec![0.0; nc];
        let (mut ssr, mut count) = (0.0, 0);
        for p in &self.parts {
            for (a, b) in jtj.iter_mut().zip(&p.jtj) {
                *a += b;
            }
            for (a, b) in jtr.iter_mut().zip(&p.jtr) {
                *a += b;
            }
            ssr += p.ssr;
            count += p.count;
        }
        for c in 0..nc {
            for d in 0..c {
                jtj[c * nc + d] = jtj[d * nc + c];
            }
        }
        (jtj, jtr, ssr, count)
    }
}
