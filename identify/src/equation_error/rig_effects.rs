//! Equation-error columns of effects whose residual is far from linear in
//! one of their parameters, so that a Gauss-Newton step from a start value
//! (what [`Regressor::Parameters`] does) says nothing: the parameter is
//! scanned instead, the other ones are linear for a given scan value.
//!
//! - **Cogging** `-A sin(N q + phase)` on coordinate `i`: for a given integer
//!   `N` the force is linear in `(A cos phase, A sin phase)`, with columns
//!   `sin(N q)`, `cos(N q)` in equation `i`. `N` runs over `N_min..=N_max`:
//!   `N_min` is [`MIN_PERIODS`] (a motor's detent count is the least common
//!   multiple of its poles and slots, at least 4; one or two periods per
//!   revolution are gravity, an unbalance or a spring), raised so that one
//!   period fits in the coordinate's measured range (a longer one is
//!   indistinguishable from a smooth position-dependent force), with
//!   `N_max` set by the encoder: a period must span at least
//!   [`COUNTS_PER_PERIOD`] of the smallest position step in the data (a
//!   finer detent is not resolved), and at most [`MAX_PERIODS`]. The whole
//!   range is scanned with `sin(N q)` of the smoothed angle (angle-addition
//!   recurrences, a few multiplications per row and `N`); the
//!   [`REFINED`] best are scored again with the columns computed on the raw
//!   angle and smoothed like the states ("filter both sides alike", trap 3
//!   of the identification notes), and the best of those wins.
//! - **Saturation** at level `L` of input `j`: the model assumed `u` where
//!   the plant received `sat(u)`, so the residual holds `(dr/du) (u -
//!   sat(u))`, each held sample clipped, ZOH-averaged and smoothed like the
//!   input. For each level of a scan over the quantiles
//!   [`LEVEL_QUANTILES`] of the commanded `|u|` that term is removed from the
//!   residual (coefficient 1: a saturation has no free scale) and the
//!   nuisance regression redone; the lowest residual wins, refined by a
//!   parabola through its neighbours.
//! - **Speed limit** `-c dz(q', vmax)` on coordinate `i`: for a given `vmax`
//!   linear in `c`, column `dz(q', vmax)` (rounded as in the language) in
//!   equation `i`; `vmax` runs over the same quantiles of the measured
//!   `|q'|` of the coordinate; only `c > 0` counts.
//!
//! - **Stribeck friction** `-(Fc + (Fs - Fc) exp(-(q'/vs)^2)) sign(q')` on
//!   coordinate `i`: for a given `vs` linear in `Fc` and `Fs - Fc`, columns
//!   `sign(q')` (the `tanh` of the ranking) and `exp(-(q'/vs)^2) sign(q')`;
//!   `vs` runs over [`STRIBECK_SPEEDS`] up to a third of the largest
//!   measured speed (the hump has to die out within the record).
//!   Linearised at a start `vs` instead, the hump's column says nothing
//!   about `vs` (the vocabulary's Stribeck friction on the arm, `vs = 0.3`,
//!   ranked with a useless start and its refit stalled at 1.03x). When the
//!   model already has a Coulomb friction there (a gearbox's `Fg1`), the
//!   first column is its own and only the hump is new.
//!
//! Signs: the residual `r = M q'' + bias - Q` of the model without the
//! effect holds the missing force itself (`-c dz`, `-A sin(N q + phase)`),
//! and the missing input term of a saturation, `(dr/du) (u - sat(u))`.
//!
//! The scans compare residual sums of squares after the nuisance columns
//! have been projected out (an orthonormal basis, built once per score);
//! the winner is then scored like every other candidate (least squares with
//! the nuisance columns), with the scanned parameter counted in the BIC
//! penalty.

use plantc_derive::model::Model;

use super::{
    dot, spans, EquationError, EquationErrorError, LinearEstimate, Regressor, Score, Smoothed,
};
use crate::effect_edit::label_of;

/// Smallest cogging period count scanned.
pub const MIN_PERIODS: usize = 4;
/// Largest cogging period count scanned.
pub const MAX_PERIODS: usize = 360;
/// A cogging period must span at least this many of the smallest position
/// steps in the data (encoder counts) to be scanned.
pub const COUNTS_PER_PERIOD: f64 = 8.0;
/// Candidates of the coarse cogging scan scored again with smoothed columns.
pub const REFINED: usize = 3;
/// Quantiles of the commanded `|u|` (saturation) or measured `|q'|` (speed
/// limit) tried as the level.
pub const LEVEL_QUANTILES: [f64; 17] = [
    0.3, 0.4, 0.5, 0.6, 0.65, 0.7, 0.75, 0.8, 0.84, 0.88, 0.9, 0.92, 0.94, 0.96, 0.97, 0.98, 0.99,
];

/// The scanned regressor a `Regressor::Parameters` stands for, when its
/// model was edited by `effect_edit` with one of the effects above (the
/// new parameters' label names the effect and its target).
pub(super) fn recognise(model: &Model, names: &[String], n: usize, m: usize) -> Option<Regressor> {
    let (effect, target) = label_of(model, names.first()?)?;
    let coordinate = || {
        model
            .coordinates
            .iter()
            .position(|c| c.name == target)
            .filter(|&i| i < n)
    };
    match (effect.as_str(), names) {
        ("cogging", [a, nn, ph]) => Some(Regressor::Cogging {
            coordinate: coordinate()?,
            names: [a.clone(), nn.clone(), ph.clone()],
        }),
        ("stribeck_friction", [fc, fs, vs]) => Some(Regressor::Stribeck {
            coordinate: coordinate()?,
            names: [fc.clone(), fs.clone(), vs.clone()],
        }),
        ("speed_limit", [v, c]) => Some(Regressor::SpeedLimit {
            coordinate: coordinate()?,
            names: [v.clone(), c.clone()],
        }),
        ("saturation", [l]) => Some(Regressor::Saturation {
            input: model
                .inputs
                .iter()
                .position(|u| u.name == target)
                .filter(|&j| j < m)?,
            name: l.clone(),
        }),
        _ => None,
    }
}

/// An orthonormal basis of the span of `cols` (modified Gram-Schmidt, done
/// twice; columns dependent on earlier ones are dropped).
fn basis(cols: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let mut out: Vec<Vec<f64>> = Vec::new();
    for c in cols {
        let norm0 = dot(c, c).sqrt();
        if !(norm0 > 0.0 && norm0.is_finite()) {
            continue;
        }
        let mut v = c.clone();
        for _ in 0..2 {
            for b in &out {
                let p = dot(b, &v);
                v.iter_mut().zip(b).for_each(|(x, y)| *x -= p * y);
            }
        }
        let norm = dot(&v, &v).sqrt();
        if norm > 1e-9 * norm0 {
            v.iter_mut().for_each(|x| *x /= norm);
            out.push(v);
        }
    }
    out
}

/// Stribeck velocities scanned (rad/s or m/s), those below the largest
/// measured speed.
pub const STRIBECK_SPEEDS: [f64; 13] = [
    0.003, 0.005, 0.01, 0.02, 0.03, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0, 2.0, 5.0,
];

/// Quantiles `ps` of `v` (sorted copy; nearest rank).
fn quantiles(v: &[f64], ps: &[f64]) -> Vec<f64> {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return Vec::new();
    }
    s.sort_by(f64::total_cmp);
    ps.iter()
        .map(|p| s[((p * (s.len() - 1) as f64).round() as usize).min(s.len() - 1)])
        .collect()
}

/// The levels scanned for magnitudes `mags`: their [`LEVEL_QUANTILES`],
/// distinct and positive.
fn level_grid(mags: &[f64]) -> Vec<f64> {
    let mut levels = quantiles(mags, &LEVEL_QUANTILES);
    levels.dedup();
    levels.retain(|l| *l > 0.0);
    levels
}

/// The largest step between neighbours of the sorted `levels` (the scan's
/// resolution).
fn widest_step(levels: &[f64]) -> f64 {
    levels
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(0.0f64, f64::max)
}

/// The vertex of the parabola through `(x[i], y[i])`, `i = k-1, k, k+1`,
/// when it is a minimum inside the bracket; `x[k]` otherwise.
fn parabola_min(x: &[f64], y: &[f64], k: usize) -> f64 {
    if k == 0 || k + 1 >= x.len() {
        return x[k];
    }
    let (x0, x1, x2) = (x[k - 1], x[k], x[k + 1]);
    let (y0, y1, y2) = (y[k - 1], y[k], y[k + 1]);
    let d = (x1 - x0) * (y1 - y2) - (x1 - x2) * (y1 - y0);
    if d == 0.0 {
        return x1;
    }
    let v = x1 - 0.5 * ((x1 - x0).powi(2) * (y1 - y2) - (x1 - x2).powi(2) * (y1 - y0)) / d;
    if v.is_finite() && v > x0 && v < x2 {
        v
    } else {
        x1
    }
}

/// `dz(v, vmax)` rounded over `vmax/50`, as the language's `speed_limit`.
pub(crate) fn rounded_dead_band(v: f64, vmax: f64) -> f64 {
    let e2 = (vmax / 50.0).powi(2);
    0.5 * (2.0 * v + ((v - vmax).powi(2) + e2).sqrt() - ((v + vmax).powi(2) + e2).sqrt())
}

impl EquationError {
    /// The nuisance basis, the residual after it and that residual's RSS.
    fn projected(&self) -> (Vec<Vec<f64>>, Vec<f64>, f64) {
        let b = basis(&self.nuisance);
        let mut r0 = self.r.clone();
        for v in &b {
            let p = dot(v, &r0);
            r0.iter_mut().zip(v).for_each(|(x, y)| *x -= p * y);
        }
        let rss = dot(&r0, &r0);
        (b, r0, rss)
    }

    /// Rows of equation `i` (indices into the stacked rows).
    fn rows_of(&self, i: usize) -> Vec<usize> {
        (0..self.rows.len())
            .filter(|&r| self.rows[r].2 == i)
            .collect()
    }

    /// RSS reduction of the projected residual `r0` by columns `cols`, each
    /// given on the rows `idx` only (zero elsewhere), and the coefficients.
    fn reduction(
        basis: &[Vec<f64>],
        r0: &[f64],
        idx: &[usize],
        cols: &[Vec<f64>],
    ) -> (f64, Vec<f64>) {
        let k = cols.len();
        // projected columns' Gram matrix and right-hand side
        let bc: Vec<Vec<f64>> = cols
            .iter()
            .map(|c| {
                basis
                    .iter()
                    .map(|b| idx.iter().zip(c).map(|(&r, v)| b[r] * v).sum())
                    .collect()
            })
            .collect();
        let mut g = vec![0.0; k * k];
        let mut rhs = vec![0.0; k];
        for a in 0..k {
            rhs[a] = idx.iter().zip(&cols[a]).map(|(&r, v)| r0[r] * v).sum();
            for c in a..k {
                let v = dot(&cols[a], &cols[c]) - dot(&bc[a], &bc[c]);
                g[a * k + c] = v;
                g[c * k + a] = v;
            }
        }
        match crate::lm::solve_spd(&g, k, &rhs) {
            Some(beta) if beta.iter().all(|b| b.is_finite()) => (dot(&beta, &rhs), beta),
            _ => (0.0, vec![0.0; k]),
        }
    }

    /// Full stacked column from values on rows `idx`.
    fn column(&self, idx: &[usize], vals: &[f64]) -> Vec<f64> {
        let mut c = vec![0.0; self.rows.len()];
        for (&r, v) in idx.iter().zip(vals) {
            c[r] = *v;
        }
        c
    }

    /// The smallest positive step of coordinate `i` between samples (an
    /// encoder count), over all experiments.
    fn position_step(&self, i: usize) -> f64 {
        let mut step = f64::INFINITY;
        for e in &self.exps {
            for w in e.raw_q[i].windows(2) {
                let d = (w[1] - w[0]).abs();
                if d > 1e-12 && d < step {
                    step = d;
                }
            }
        }
        step
    }

    /// `of(experiment)[k]` on each row `(experiment, k, _)` of `idx`.
    fn on_rows(&self, idx: &[usize], of: impl Fn(&Smoothed) -> &Vec<f64>) -> Vec<f64> {
        idx.iter()
            .map(|&r| {
                let (e, k, _) = self.rows[r];
                of(&self.exps[e])[k]
            })
            .collect()
    }

    /// `f(raw_q[i])` smoothed like the states, on the rows `idx` of
    /// equation `i`, weighted.
    fn smoothed_of_q(&self, i: usize, idx: &[usize], f: impl Fn(f64) -> f64) -> Vec<f64> {
        let per_exp: Vec<Vec<f64>> = self
            .exps
            .iter()
            .map(|e| {
                let y: Vec<f64> = e.raw_q[i].iter().map(|&q| f(q)).collect();
                e.coordinate_like(&y)
            })
            .collect();
        idx.iter()
            .map(|&r| {
                let (e, k, eq) = self.rows[r];
                per_exp[e][k] * self.weight[eq]
            })
            .collect()
    }

    pub(super) fn score_cogging(
        &self,
        i: usize,
        names: &[String; 3],
    ) -> Result<Score, EquationErrorError> {
        if i >= self.n {
            return Err(EquationErrorError::BadIndex(i));
        }
        let (b, r0, _) = self.projected();
        let idx = self.rows_of(i);
        let w = self.weight[i];
        let step = self.position_step(i);
        let n_max = ((2.0 * std::f64::consts::PI / (COUNTS_PER_PERIOD * step)).floor() as usize)
            .min(MAX_PERIODS);
        let q = self.on_rows(&idx, |e| &e.q[i]);
        let range = q.iter().fold(f64::NEG_INFINITY, |a, &v| a.max(v))
            - q.iter().fold(f64::INFINITY, |a, &v| a.min(v));
        let n_min = if range > 0.0 {
            ((2.0 * std::f64::consts::PI / range).ceil() as usize).max(MIN_PERIODS)
        } else {
            usize::MAX
        };
        let (s1, c1): (Vec<f64>, Vec<f64>) = q.iter().map(|x| x.sin_cos()).unzip();
        let (mut sn, mut cn) = (s1.clone(), c1.clone());
        let mut coarse: Vec<(f64, usize)> = Vec::new();
        for nper in 2..=n_max.max(1) {
            // sin((n)q), cos((n)q) from (n-1)q
            for r in 0..q.len() {
                let (s, c) = (sn[r], cn[r]);
                sn[r] = s * c1[r] + c * s1[r];
                cn[r] = c * c1[r] - s * s1[r];
            }
            if nper < n_min {
                continue;
            }
            let cols = [
                sn.iter().map(|v| v * w).collect::<Vec<f64>>(),
                cn.iter().map(|v| v * w).collect::<Vec<f64>>(),
            ];
            let (red, _) = Self::reduction(&b, &r0, &idx, &cols);
            coarse.push((red, nper));
        }
        coarse.sort_by(|a, b| b.0.total_cmp(&a.0));
        // the best few again, with the columns smoothed like the states
        let mut best: Option<(f64, usize, Vec<Vec<f64>>)> = None;
        for &(_, nper) in coarse.iter().take(REFINED) {
            let nf = nper as f64;
            let cols = vec![
                self.smoothed_of_q(i, &idx, |x| (nf * x).sin()),
                self.smoothed_of_q(i, &idx, |x| (nf * x).cos()),
            ];
            let (red, _) = Self::reduction(&b, &r0, &idx, &cols);
            if best.as_ref().is_none_or(|(r, _, _)| red > *r) {
                best = Some((red, nper, cols));
            }
        }
        let Some((_, nper, cols)) = best else {
            return Ok(self.empty_score(names, 0));
        };
        let full: Vec<Vec<f64>> = cols.iter().map(|c| self.column(&idx, c)).collect();
        let (mut score, coef, var) = self.finish(&self.r, &full, 1);
        // the residual r = M q'' + bias - Q of the model without the effect
        // holds the missing force: r = -(A cos ph) sin(Nq) - (A sin ph) cos(Nq)
        let (a, c) = (-coef[0], -coef[1]);
        let amp = a.hypot(c);
        let phase = c.atan2(a);
        let amp_se = if amp > 0.0 {
            ((a * a * var[0] + c * c * var[1]) / (amp * amp)).sqrt()
        } else {
            f64::NAN
        };
        let phase_se = if amp > 0.0 {
            ((c * c * var[0] + a * a * var[1]).sqrt()) / (amp * amp)
        } else {
            f64::NAN
        };
        score.estimates = vec![
            LinearEstimate {
                name: names[0].clone(),
                value: amp,
                std_error: amp_se,
            },
            LinearEstimate {
                name: names[1].clone(),
                value: nper as f64,
                // the scan's resolution
                std_error: 0.5,
            },
            LinearEstimate {
                name: names[2].clone(),
                value: phase,
                std_error: phase_se,
            },
        ];
        Ok(score)
    }

    pub(super) fn score_saturation(
        &self,
        j: usize,
        name: &str,
    ) -> Result<Score, EquationErrorError> {
        if j >= self.m {
            return Err(EquationErrorError::BadIndex(j));
        }
        let (b, r0, rss0) = self.projected();
        let mags: Vec<f64> = self
            .exps
            .iter()
            .flat_map(|e| e.raw_u[j].iter().map(|u| u.abs()))
            .filter(|u| *u > 0.0)
            .collect();
        let levels = level_grid(&mags);
        if levels.is_empty() {
            return Ok(self.empty_score(std::slice::from_ref(&name.to_string()), 0));
        }
        // the removed term for each level, as a stacked weighted column
        let term = |l: f64| -> Vec<f64> {
            let per_exp: Vec<Vec<f64>> = self
                .exps
                .iter()
                .map(|e| {
                    let u = &e.raw_u[j];
                    let x: Vec<f64> = u.iter().map(|&v| v - v.clamp(-l, l)).collect();
                    e.input_like(&x)
                })
                .collect();
            self.rows
                .iter()
                .zip(&self.dr_du[j])
                .map(|((e, k, _), d)| d * per_exp[*e][*k])
                .collect()
        };
        let rss_after = |c: &[f64]| -> f64 {
            // ||P(r - c)||^2 = ||r0||^2 - 2 c'r0 + ||P c||^2
            let pc: f64 = dot(c, c) - b.iter().map(|v| dot(v, c).powi(2)).sum::<f64>();
            rss0 - 2.0 * dot(c, &r0) + pc
        };
        let rss: Vec<f64> = levels.iter().map(|&l| rss_after(&term(l))).collect();
        let kbest = (0..levels.len())
            .min_by(|&a, &c| rss[a].total_cmp(&rss[c]))
            .unwrap_or(0);
        let mut level = parabola_min(&levels, &rss, kbest);
        let mut c = term(level);
        if rss_after(&c) > rss[kbest] {
            level = levels[kbest];
            c = term(level);
        }
        let target: Vec<f64> = self.r.iter().zip(&c).map(|(r, t)| r - t).collect();
        // (a level that explains nothing still counts its column when it
        // clips the input at all: a low BIC is no proof, the candidate is
        // screened by simulation error when the leaders fail)
        let (mut score, _, _) = self.finish(&target, &[], 1);
        let spacing = widest_step(&levels);
        score.estimates = vec![LinearEstimate {
            name: name.to_string(),
            value: level,
            std_error: 0.5 * spacing,
        }];
        Ok(score)
    }

    /// What a velocity-dependent force on coordinate `i` is scanned on:
    /// the nuisance basis and the residual after it, the rows of equation
    /// `i`, its weight and the smoothed velocity on those rows.
    #[allow(clippy::type_complexity)]
    fn velocity_rows(
        &self,
        i: usize,
    ) -> Result<(Vec<Vec<f64>>, Vec<f64>, Vec<usize>, f64, Vec<f64>), EquationErrorError> {
        if i >= self.n {
            return Err(EquationErrorError::BadIndex(i));
        }
        let (b, r0, _) = self.projected();
        let idx = self.rows_of(i);
        let v = self.on_rows(&idx, |e| &e.qd[i]);
        Ok((b, r0, idx, self.weight[i], v))
    }

    pub(super) fn score_speed_limit(
        &self,
        i: usize,
        names: &[String; 2],
    ) -> Result<Score, EquationErrorError> {
        let (b, r0, idx, w, v) = self.velocity_rows(i)?;
        let mags: Vec<f64> = v.iter().map(|x| x.abs()).collect();
        let levels = level_grid(&mags);
        let col = |vmax: f64| -> Vec<f64> {
            v.iter()
                .map(|&x| rounded_dead_band(x, vmax) * w)
                .collect::<Vec<f64>>()
        };
        let mut best: Option<(f64, f64)> = None;
        let mut reds = Vec::with_capacity(levels.len());
        for &l in &levels {
            let (red, beta) = Self::reduction(&b, &r0, &idx, &[col(l)]);
            // the residual holds the missing force -c dz, and a speed limit
            // damps: c = -beta > 0
            let red = if beta[0] < 0.0 { red } else { 0.0 };
            reds.push(-red);
            if red > 0.0 && best.is_none_or(|(r, _)| red > r) {
                best = Some((red, l));
            }
        }
        let Some((_, level)) = best else {
            return Ok(self.empty_score(names, usize::from(!levels.is_empty())));
        };
        let kbest = levels.iter().position(|&l| l == level).unwrap_or(0);
        let mut vmax = parabola_min(&levels, &reds, kbest);
        let (red_v, beta_v) = Self::reduction(&b, &r0, &idx, &[col(vmax)]);
        if !(beta_v[0] < 0.0 && -red_v <= reds[kbest]) {
            vmax = level;
        }
        let full = vec![self.column(&idx, &col(vmax))];
        let (mut score, coef, var) = self.finish(&self.r, &full, 1);
        let spacing = widest_step(&levels);
        score.estimates = vec![
            LinearEstimate {
                name: names[0].clone(),
                value: vmax,
                std_error: 0.5 * spacing,
            },
            LinearEstimate {
                name: names[1].clone(),
                value: -coef[0],
                std_error: var[0].sqrt(),
            },
        ];
        Ok(score)
    }

    pub(super) fn score_stribeck(
        &self,
        i: usize,
        names: &[String; 3],
    ) -> Result<Score, EquationErrorError> {
        let (b, r0, idx, w, v) = self.velocity_rows(i)?;
        let top = v.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let sgn: Vec<f64> = v.iter().map(|&x| (x / self.width).tanh() * w).collect();
        // is the Coulomb column the model's own already (projected away)?
        let coulomb = self.column(&idx, &sgn);
        let norm = dot(&coulomb, &coulomb);
        // what the orthonormal nuisance basis leaves of it
        let left = norm - b.iter().map(|u| dot(u, &coulomb).powi(2)).sum::<f64>();
        let own = norm <= 0.0 || spans(left, &coulomb);
        let hump = |vs: f64| -> Vec<f64> {
            v.iter()
                .zip(&sgn)
                .map(|(&x, s)| (-(x / vs).powi(2)).exp() * s)
                .collect()
        };
        let mut best: Option<(f64, f64)> = None;
        // the hump must die out within the speeds the record reaches (at
        // 3 vs it is down to 1e-4): a "Stribeck velocity" near the top speed
        // is a smooth speed-dependent force, not a breakaway (on Coulomb
        // data the scan took vs = 5 rad/s of a 5.5 rad/s record, and the
        // refit from there stuck the arm: cost 130x the baseline)
        let speeds: Vec<f64> = STRIBECK_SPEEDS
            .iter()
            .copied()
            .filter(|&vs| 3.0 * vs <= top)
            .collect();
        for &vs in &speeds {
            let cols = if own {
                vec![hump(vs)]
            } else {
                vec![sgn.clone(), hump(vs)]
            };
            let (red, beta) = Self::reduction(&b, &r0, &idx, &cols);
            // the residual holds the missing force: the coefficients are
            // -Fc < 0 and -(Fs - Fc) < 0 (a negative Coulomb level with a
            // hump on top is not friction: on Coulomb-only data it fitted
            // the noise, Fc = -1.1e-3 N m under vs = 5 rad/s)
            let ok = beta.last().is_some_and(|d| *d < 0.0) && (own || beta[0] < 0.0);
            if ok && red > 0.0 && best.is_none_or(|(r, _)| red > r) {
                best = Some((red, vs));
            }
        }
        let Some((_, vs)) = best else {
            // (none when no Stribeck velocity the record's speeds could
            // show was scanned; the hump, and the Coulomb level unless the
            // model's own, otherwise)
            let columns = match (speeds.is_empty(), own) {
                (true, _) => 0,
                (false, true) => 1,
                (false, false) => 2,
            };
            return Ok(self.empty_score(names, columns));
        };
        let mut full = Vec::new();
        if !own {
            full.push(coulomb);
        }
        full.push(self.column(&idx, &hump(vs)));
        let (mut score, coef, var) = self.finish(&self.r, &full, 1);
        let (fc, fc_se) = if own {
            (f64::NAN, f64::NAN)
        } else {
            (-coef[0], var[0].sqrt())
        };
        let k = full.len() - 1;
        let d = -coef[k];
        score.estimates = vec![
            LinearEstimate {
                name: names[0].clone(),
                value: fc,
                std_error: fc_se,
            },
            LinearEstimate {
                name: names[1].clone(),
                value: if own { d } else { fc + d },
                std_error: var[k].sqrt(),
            },
            LinearEstimate {
                name: names[2].clone(),
                value: vs,
                std_error: f64::NAN,
            },
        ];
        Ok(score)
    }

    /// A score that explains nothing, with NaN estimates: no scan value
    /// to try (`columns` 0: the candidate adds nothing the data can show),
    /// or none admissible (`columns`: those the candidate would add). A
    /// scan that finds no admissible value is no proof the effect is
    /// absent (a Stribeck hump on an arm whose gearbox friction the model
    /// already has: every hump's linearised coefficient came out positive,
    /// while the simulation-error refit found the truth at the floor), so
    /// such a candidate stays eligible for simulation-error screening.
    fn empty_score(&self, names: &[String], columns: usize) -> Score {
        let (by_experiment, by_speed) = self.shares(&self.r0);
        Score {
            bic_gain: 0.0,
            residual_share: 0.0,
            columns,
            estimates: names
                .iter()
                .map(|n| LinearEstimate {
                    name: n.clone(),
                    value: f64::NAN,
                    std_error: f64::NAN,
                })
                .collect(),
            by_experiment,
            by_speed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_is_orthonormal_and_drops_dependent_columns() {
        let a: Vec<f64> = (0..40).map(|k| (k as f64 * 0.3).sin()).collect();
        let b: Vec<f64> = a.iter().map(|v| 2.0 * v).collect();
        let c: Vec<f64> = (0..40).map(|k| k as f64).collect();
        let q = basis(&[a, b, c]);
        assert_eq!(q.len(), 2);
        assert!((dot(&q[0], &q[0]) - 1.0).abs() < 1e-12);
        assert!(dot(&q[0], &q[1]).abs() < 1e-12);
    }

    #[test]
    fn parabola_vertex() {
        let x = [1.0, 2.0, 3.0];
        let y: Vec<f64> = x.iter().map(|v: &f64| (v - 2.3).powi(2)).collect();
        assert!((parabola_min(&x, &y, 1) - 2.3).abs() < 1e-12);
        assert_eq!(parabola_min(&x, &y, 0), 1.0);
    }

    /// The rounded dead band against `v - clip(v, vmax)`: within `vmax/100`
    /// everywhere (half the rounding width) and zero at rest.
    #[test]
    fn rounded_dead_band_is_close_to_the_sharp_one() {
        let vmax = 3.0;
        for k in -300..=300 {
            let v = k as f64 * 0.03;
            let sharp = v - v.clamp(-vmax, vmax);
            assert!((rounded_dead_band(v, vmax) - sharp).abs() <= vmax / 100.0 + 1e-12);
        }
        assert_eq!(rounded_dead_band(0.0, vmax), 0.0);
    }
}
