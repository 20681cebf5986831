//! Linear algebra of a Levenberg-Marquardt step on block-arrow normal
//! equations.
//!
//! With globals `g` (shared by every block) and locals `l_b` (one small
//! vector per block), `J'J` is
//!
//! ```text
//! [ A_gg   A_g1  A_g2 ... ]
//! [ A_1g   A_11           ]
//! [ A_2g         A_22     ]
//! ```
//!
//! and the damped system `(A + lambda D) d = -J'r` (`D` the diagonal of
//! `A`, Marquardt's scale-invariant damping) is solved by eliminating each
//! block's locals: `S = A_gg + lambda D_g - sum_b A_gb B_b^-1 A_bg` with
//! `B_b = A_bb + lambda D_b`, then `d_g` from `S`, then each `d_b` by back
//! substitution. Globals that are held (at an active bound, or frozen) are
//! removed from `S`. The cost is linear in the number of blocks: a fit with
//! hundreds of segment states stays a small dense solve.

/// Block-arrow normal equations.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Normal {
    /// Number of globals.
    pub ng: usize,
    /// `A_gg`, row-major `ng x ng`.
    pub a_gg: Vec<f64>,
    /// `(J'r)_g`.
    pub g_g: Vec<f64>,
    /// One entry per block.
    pub blocks: Vec<BlockNormal>,
    /// Sum of squared (weighted) residuals.
    pub ssr: f64,
    /// Number of residuals.
    pub count: usize,
    /// Whether a block's sensitivity simulation had to refine its substep
    /// ([`crate::sensitivity::SensitivityTrajectory::refined`]).
    pub refined: bool,
}

/// A block's part of [`Normal`].
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct BlockNormal {
    /// Number of locals.
    pub l: usize,
    /// `A_gb`, row-major `ng x l`.
    pub a_gl: Vec<f64>,
    /// `A_bb`, row-major `l x l`.
    pub a_ll: Vec<f64>,
    /// `(J'r)_b`.
    pub g_l: Vec<f64>,
}

impl Normal {
    /// Zero normal equations with `ng` globals and blocks of `ls` locals.
    pub fn new(ng: usize, ls: impl Iterator<Item = usize>) -> Normal {
        Normal {
            ng,
            a_gg: vec![0.0; ng * ng],
            g_g: vec![0.0; ng],
            blocks: ls
                .map(|l| BlockNormal {
                    l,
                    a_gl: vec![0.0; ng * l],
                    a_ll: vec![0.0; l * l],
                    g_l: vec![0.0; l],
                })
                .collect(),
            ssr: 0.0,
            count: 0,
            refined: false,
        }
    }
}

impl Normal {
    /// The equations with the locals where `held[b][j]` is true held at
    /// their values (their rows and columns replaced by the identity and a
    /// zero gradient: their step is zero, the others solved as if they
    /// were constants), for a local at an active bound.
    pub fn holding_locals(&self, held: &[Vec<bool>]) -> Normal {
        let mut out = self.clone();
        let ng = self.ng;
        for (bn, h) in out.blocks.iter_mut().zip(held) {
            let l = bn.l;
            for j in (0..l).filter(|&j| h.get(j).copied().unwrap_or(false)) {
                for k in 0..l {
                    bn.a_ll[j * l + k] = 0.0;
                    bn.a_ll[k * l + j] = 0.0;
                }
                bn.a_ll[j * l + j] = 1.0;
                for g in 0..ng {
                    bn.a_gl[g * l + j] = 0.0;
                }
                bn.g_l[j] = 0.0;
            }
        }
        out
    }
}

/// Cholesky factor (lower, row-major) of the SPD `a` (`n x n`); None if not
/// positive definite.
pub(crate) fn cholesky(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if s.is_nan() || s <= 0.0 || !s.is_finite() {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    Some(l)
}

/// Solve `L L' x = b` in place.
pub(crate) fn cholesky_solve(l: &[f64], n: usize, x: &mut [f64]) {
    for i in 0..n {
        for k in 0..i {
            x[i] -= l[i * n + k] * x[k];
        }
        x[i] /= l[i * n + i];
    }
    for i in (0..n).rev() {
        for k in i + 1..n {
            x[i] -= l[k * n + i] * x[k];
        }
        x[i] /= l[i * n + i];
    }
}

/// The Jacobi-scaled Cholesky factor of an SPD matrix (`a` scaled to a unit
/// diagonal first, which keeps the factorisation of badly scaled problems
/// accurate), factored once for any number of right-hand sides.
pub(crate) struct Spd {
    n: usize,
    /// The scaling, `sqrt(a_ii)`.
    s: Vec<f64>,
    /// Cholesky factor of the scaled matrix.
    l: Vec<f64>,
}

impl Spd {
    /// Factor the `n x n` matrix `a`; None if not positive definite.
    pub fn new(a: &[f64], n: usize) -> Option<Spd> {
        let s: Vec<f64> = (0..n).map(|i| a[i * n + i].max(0.0).sqrt()).collect();
        if s.iter().any(|v| v.is_nan() || *v <= 0.0) {
            return None;
        }
        let scaled: Vec<f64> = (0..n * n).map(|k| a[k] / (s[k / n] * s[k % n])).collect();
        let l = cholesky(&scaled, n)?;
        Some(Spd { n, s, l })
    }

    /// `a^-1 b`.
    pub fn solve(&self, b: &[f64]) -> Vec<f64> {
        let mut x: Vec<f64> = (0..self.n).map(|i| b[i] / self.s[i]).collect();
        cholesky_solve(&self.l, self.n, &mut x);
        x.iter().zip(&self.s).map(|(x, s)| x / s).collect()
    }
}

/// Solve the SPD `a x = b` ([`Spd`]); None if not positive definite.
pub(crate) fn solve_spd(a: &[f64], n: usize, b: &[f64]) -> Option<Vec<f64>> {
    Some(Spd::new(a, n)?.solve(b))
}

/// Inverse of the SPD `a` (Jacobi-scaled Cholesky); None if not positive
/// definite.
pub(crate) fn inverse_spd(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let f = Spd::new(a, n)?;
    let mut inv = vec![0.0; n * n];
    for j in 0..n {
        let mut e = vec![0.0; n];
        e[j] = 1.0;
        let col = f.solve(&e);
        for i in 0..n {
            inv[i * n + j] = col[i];
        }
    }
    Some(inv)
}

/// A damped system with the locals eliminated: gives the globals' step and,
/// for any (possibly clipped) globals' step, the locals' steps.
pub(crate) struct Damped {
    /// `B_b^-1 A_bg`, row-major `l x ng`, per block.
    x: Vec<Vec<f64>>,
    /// `B_b^-1 (J'r)_b` per block.
    y: Vec<Vec<f64>>,
    /// The globals' step (zero for held globals).
    pub dg: Vec<f64>,
}

/// Damping added to a diagonal entry: `lambda * max(d, floor)`.
fn damp(d: f64, lambda: f64, floor: f64) -> f64 {
    lambda * d.max(floor)
}

impl Damped {
    /// Solve `(A + lambda D) d = -J'r` with the globals where `held` is
    /// true kept at zero step. None when a system is not positive definite
    /// (a larger `lambda` will do).
    pub fn solve(nrm: &Normal, lambda: f64, held: &[bool]) -> Option<Damped> {
        let ng = nrm.ng;
        let floor = 1e-12
            * (0..ng)
                .map(|i| nrm.a_gg[i * ng + i])
                .fold(0.0f64, f64::max)
                .max(f64::MIN_POSITIVE);
        let mut s = nrm.a_gg.clone();
        for i in 0..ng {
            s[i * ng + i] += damp(nrm.a_gg[i * ng + i], lambda, floor);
        }
        let mut r: Vec<f64> = nrm.g_g.iter().map(|v| -v).collect();
        let mut xs = Vec::with_capacity(nrm.blocks.len());
        let mut ys = Vec::with_capacity(nrm.blocks.len());
        for b in &nrm.blocks {
            let l = b.l;
            if l == 0 {
                xs.push(Vec::new());
                ys.push(Vec::new());
                continue;
            }
            let lfloor = 1e-12
                * (0..l)
                    .map(|i| b.a_ll[i * l + i])
                    .fold(0.0f64, f64::max)
                    .max(f64::MIN_POSITIVE);
            let mut bb = b.a_ll.clone();
            for i in 0..l {
                bb[i * l + i] += damp(b.a_ll[i * l + i], lambda, lfloor);
            }
            // B^-1 A_bg column by column, B^-1 g_b (B factored once)
            let bf = Spd::new(&bb, l)?;
            let mut x = vec![0.0; l * ng];
            for gcol in 0..ng {
                let rhs: Vec<f64> = (0..l).map(|i| b.a_gl[gcol * l + i]).collect();
                let sol = bf.solve(&rhs);
                for i in 0..l {
                    x[i * ng + gcol] = sol[i];
                }
            }
            let y = bf.solve(&b.g_l);
            // S -= A_gb X ; r += A_gb y
            for gi in 0..ng {
                for gj in 0..ng {
                    let mut v = 0.0;
                    for i in 0..l {
                        v += b.a_gl[gi * l + i] * x[i * ng + gj];
                    }
                    s[gi * ng + gj] -= v;
                }
                let mut v = 0.0;
                for i in 0..l {
                    v += b.a_gl[gi * l + i] * y[i];
                }
                r[gi] += v;
            }
            xs.push(x);
            ys.push(y);
        }
        let idx: Vec<usize> = (0..ng).filter(|&i| !held[i]).collect();
        let nf = idx.len();
        let mut dg = vec![0.0; ng];
        if nf > 0 {
            let sf: Vec<f64> = idx
                .iter()
                .flat_map(|&i| idx.iter().map(move |&j| (i, j)))
                .map(|(i, j)| s[i * ng + j])
                .collect();
            let rf: Vec<f64> = idx.iter().map(|&i| r[i]).collect();
            let sol = solve_spd(&sf, nf, &rf)?;
            for (k, &i) in idx.iter().enumerate() {
                dg[i] = sol[k];
            }
        }
        Some(Damped { x: xs, y: ys, dg })
    }

    /// Each block's locals' step for the globals' step `dg`:
    /// `d_b = -(y_b + X_b dg)`.
    pub fn locals(&self, dg: &[f64]) -> Vec<Vec<f64>> {
        let ng = dg.len();
        self.x
            .iter()
            .zip(&self.y)
            .map(|(x, y)| {
                (0..y.len())
                    .map(|i| -(y[i] + (0..ng).map(|j| x[i * ng + j] * dg[j]).sum::<f64>()))
                    .collect()
            })
            .collect()
    }
}

/// Reduction of the SSR that the undamped quadratic model predicts for the
/// step `(dg, dl)`: `-(2 d'J'r + d'J'J d)`.
pub(crate) fn predicted_reduction(nrm: &Normal, dg: &[f64], dl: &[Vec<f64>]) -> f64 {
    let ng = nrm.ng;
    let mut lin = 0.0;
    let mut quad = 0.0;
    for i in 0..ng {
        lin += dg[i] * nrm.g_g[i];
        for j in 0..ng {
            quad += dg[i] * nrm.a_gg[i * ng + j] * dg[j];
        }
    }
    for (b, d) in nrm.blocks.iter().zip(dl) {
        let l = b.l;
        for i in 0..l {
            lin += d[i] * b.g_l[i];
            for j in 0..l {
                quad += d[i] * b.a_ll[i * l + j] * d[j];
            }
            for g in 0..ng {
                quad += 2.0 * dg[g] * b.a_gl[g * l + i] * d[i];
            }
        }
    }
    -(2.0 * lin + quad)
}

/// The globals' information with the locals marginalised (their Schur
/// complement): `A_gg - sum_b A_gb A_bb^-1 A_bg`. A block whose `A_bb` is
/// singular (a local the data do not see) is regularised by a relative
/// ridge of 1e-12.
pub(crate) fn global_information(nrm: &Normal) -> Vec<f64> {
    let ng = nrm.ng;
    let mut s = nrm.a_gg.clone();
    for b in &nrm.blocks {
        let l = b.l;
        if l == 0 {
            continue;
        }
        let mut bb = b.a_ll.clone();
        let ridge = 1e-12
            * (0..l)
                .map(|i| b.a_ll[i * l + i])
                .fold(0.0f64, f64::max)
                .max(f64::MIN_POSITIVE);
        for i in 0..l {
            bb[i * l + i] += ridge;
        }
        let Some(bf) = Spd::new(&bb, l) else {
            continue;
        };
        for gj in 0..ng {
            let rhs: Vec<f64> = (0..l).map(|i| b.a_gl[gj * l + i]).collect();
            let x = bf.solve(&rhs);
            for gi in 0..ng {
                let v: f64 = (0..l).map(|i| b.a_gl[gi * l + i] * x[i]).sum();
                s[gi * ng + gj] -= v;
            }
        }
    }
    // symmetrise rounding
    for i in 0..ng {
        for j in 0..i {
            let v = 0.5 * (s[i * ng + j] + s[j * ng + i]);
            s[i * ng + j] = v;
            s[j * ng + i] = v;
        }
    }
    s
}

/// The inverse of each block's `A_bb` diagonal (variances of the locals up
/// to `sigma^2`, conditional on the globals); NaN where singular.
pub(crate) fn local_variances(nrm: &Normal) -> Vec<Vec<f64>> {
    nrm.blocks
        .iter()
        .map(|b| match inverse_spd(&b.a_ll, b.l) {
            Some(inv) => (0..b.l).map(|i| inv[i * b.l + i]).collect(),
            None => vec![f64::NAN; b.l],
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random-ish block-arrow least-squares problem: the Schur step with
    /// lambda = 0 equals the dense normal-equation solution.
    #[test]
    fn schur_step_equals_dense_solve() {
        let ng = 3;
        let ls = [2usize, 0, 3];
        let total = ng + ls.iter().sum::<usize>();
        // J: rows per block touching the globals and its locals
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut nrm = Normal::new(ng, ls.iter().copied());
        let mut dense = vec![0.0; total * total];
        let mut dense_g = vec![0.0; total];
        let mut off = ng;
        for (b, &l) in ls.iter().enumerate() {
            for _ in 0..20 {
                let row: Vec<f64> = (0..ng + l).map(|_| rnd()).collect();
                let r = rnd();
                let gidx: Vec<usize> = (0..ng).chain(off..off + l).collect();
                for (a, &ia) in gidx.iter().enumerate() {
                    dense_g[ia] += row[a] * r;
                    for (c, &ic) in gidx.iter().enumerate() {
                        dense[ia * total + ic] += row[a] * row[c];
                    }
                }
                let bn = &mut nrm.blocks[b];
                for a in 0..ng {
                    nrm.g_g[a] += row[a] * r;
                    for c in 0..ng {
                        nrm.a_gg[a * ng + c] += row[a] * row[c];
                    }
                    for c in 0..l {
                        bn.a_gl[a * l + c] += row[a] * row[ng + c];
                    }
                }
                for a in 0..l {
                    bn.g_l[a] += row[ng + a] * r;
                    for c in 0..l {
                        bn.a_ll[a * l + c] += row[ng + a] * row[ng + c];
                    }
                }
            }
            off += l;
        }
        let neg: Vec<f64> = dense_g.iter().map(|v| -v).collect();
        let want = solve_spd(&dense, total, &neg).expect("SPD");
        let d = Damped::solve(&nrm, 0.0, &[false; 3]).expect("SPD");
        let dl = d.locals(&d.dg);
        let mut got = d.dg.clone();
        for v in dl {
            got.extend(v);
        }
        for (a, b) in got.iter().zip(&want) {
            assert!(
                (a - b).abs() < 1e-10 * (1.0 + b.abs()),
                "{got:?} vs {want:?}"
            );
        }
        // the predicted reduction of the exact step is g' A^-1 g
        let dl = d.locals(&d.dg);
        let pred = predicted_reduction(&nrm, &d.dg, &dl);
        let exact: f64 = dense_g.iter().zip(&want).map(|(g, x)| -g * x).sum();
        assert!(
            (pred - exact).abs() < 1e-9 * exact.abs(),
            "{pred} vs {exact}"
        );
        // marginal information = inverse of the dense inverse's global block
        let inv = inverse_spd(&dense, total).expect("SPD");
        let gblock: Vec<f64> = (0..ng * ng)
            .map(|k| inv[(k / ng) * total + k % ng])
            .collect();
        let s = global_information(&nrm);
        let sinv = inverse_spd(&s, ng).expect("SPD");
        for (a, b) in sinv.iter().zip(&gblock) {
            assert!((a - b).abs() < 1e-8 * (1.0 + b.abs()));
        }
    }
}
