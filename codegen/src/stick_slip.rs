//! Emission of sticking dry friction for the generated plant: `rk4_step`
//! and `closed_loop_rk4_step` of a model with dry friction switch between
//! sliding and sticking as plantc-derive's `mechanics::stick_slip` does.
//!
//! Generated, for a model whose forces carry `-D_i sign(q_i')` terms
//! (`mechanics::dry_friction`):
//! - `split_k`: `M` (model coordinates), `b = Q0 - bias + B u` without the
//!   dry friction, and the levels `D`, in the plant's value-numbered graph
//!   (sharing its parameter coefficients);
//! - fixed code over `[f64; N_Q]` arrays (no allocation, deterministic):
//!   the mode of a state (`stick_classify`: a joint at `v = 0.0` is held
//!   while its holding force is within `max(D, 0)`; of several, the largest
//!   excess ratio is released first), the constrained accelerations
//!   (`stick_solve`: Gaussian elimination with partial pivoting on the free
//!   joints), the guards, and `stick_step_k`: an RK4 step of the mode at the
//!   step's start, or, when a guard crosses zero inside it, RK4 steps to
//!   each switch (located by Illinois iterations on the step length) and on
//!   from there.
//!
//! `dynamics` and the Jacobians still evaluate `sign()` as written (the
//! vector field off the switching surfaces).

use proc_macro2::TokenStream;
use quote::quote;

use plantc_derive::mechanics::{
    decompose_dry_friction, AngleCoordinates, Equations, FALLBACK_SIGN_WIDTH,
};
use plantc_derive::model::Model;
use plantc_derive::sym::{Expr, Symbol};

use crate::emit::idx;
use crate::ir::{Function, Graph, Level, V};
use crate::plant::{env, rk4_stages, state_derivative_with, Frame};
use crate::Error;

/// The stick-slip values in the plant's graph.
pub(crate) struct StickRoots {
    /// `split_k`: `M` (n x n, row-major), then `b` (n), then `D` (n).
    pub(crate) split: Vec<V>,
    /// `mode_dynamics_k`: `x'` with the friction directions `dir` (every
    /// dry joint sliding).
    pub(crate) mode: Vec<V>,
    /// `rk4_mode_k`: one fused RK4 step of length `h` with `dir`.
    pub(crate) rk: Vec<V>,
    dry: Vec<bool>,
}

impl StickRoots {
    /// Every value, for the graph's plan.
    pub(crate) fn all(&self) -> Vec<V> {
        let mut v = self.split.clone();
        v.extend(&self.mode);
        v.extend(&self.rk);
        v
    }
}

/// The stick-slip values, or None when the model has no dry friction that
/// sticks (then nothing changes in the generated plant). `ac`: the angle
/// coordinates the plant's accelerations are computed in, if any; `h`: the
/// step length input.
pub(crate) fn stick_roots(
    g: &mut Graph,
    model: &Model,
    eqs: &Equations,
    ac: Option<&AngleCoordinates>,
    (xs, us, ps): (&[V], &[V], &[V]),
    h: V,
) -> Result<Option<StickRoots>, Error> {
    let split = decompose_dry_friction(eqs, FALLBACK_SIGN_WIDTH);
    if !split.any() {
        return Ok(None);
    }
    let n = eqs.coords.len();
    // split_k in the model's coordinates
    let mut e = env(g, model, xs, us, ps)?;
    let mut roots = Vec::with_capacity(n * n + 2 * n);
    for i in 0..n {
        for j in 0..n {
            roots.push(g.expr(&mut e, split.smooth.mass_matrix[i][j])?);
        }
    }
    for r in split.smooth.rhs() {
        roots.push(g.expr(&mut e, r)?);
    }
    for d in &split.levels {
        roots.push(g.expr(&mut e, *d)?);
    }
    // the equations with `sign(q_i')` as the mode's direction `dir[i]`
    let dirs: Vec<(Symbol, V)> = (0..n)
        .map(|i| {
            let k = idx(i);
            (
                Symbol::new(&format!("plantc_stick_dir_{i}")),
                g.input(quote!(dir[#k]), Level::Call),
            )
        })
        .collect();
    let mut eqs_dir = split.smooth.clone();
    for i in 0..n {
        eqs_dir.forces[i] = split.smooth.forces[i] - split.levels[i] * Expr::symbol(dirs[i].0);
    }
    let frame = match ac {
        Some(ac) => Frame::Angles(&eqs_dir, ac),
        None => Frame::Model(&eqs_dir),
    };
    let (mode, args0) = state_derivative_with(g, model, &frame, (xs, us, ps), None, &dirs)?;
    let rk = rk4_stages(g, model, &frame, (xs, us, ps), h, (&mode, &args0), &dirs)?;
    Ok(Some(StickRoots {
        split: roots,
        mode,
        rk,
        dry: (0..n).map(|i| split.has(i)).collect(),
    }))
}

/// `let _ = name;` for each of `names` the function does not read.
fn silence(f: &Function, names: &[(&str, &str)]) -> TokenStream {
    // whether the identifier `name` is followed by `rest` somewhere
    let uses = |name: &str, rest: &str| {
        let pat = format!("{name} {rest}");
        f.stmts.iter().chain(f.outputs.iter()).any(|t| {
            let text = format!(" {t}");
            text.match_indices(&pat).any(|(i, _)| {
                text[..i]
                    .chars()
                    .next_back()
                    .is_none_or(|c| !(c.is_alphanumeric() || c == '_'))
            })
        })
    };
    let mut t = TokenStream::new();
    for (name, rest) in names {
        if !uses(name, rest) {
            let id = proc_macro2::Ident::new(name, proc_macro2::Span::call_site());
            t.extend(quote!(let _ = #id;));
        }
    }
    t
}

/// The generated items: the graph functions (`split_k`, `mode_dynamics_k`,
/// `rk4_mode_k`, from their functions in the plant's graph) and the fixed
/// stick-slip code.
pub(crate) fn stick_items(
    roots: &StickRoots,
    (f_split, f_mode, f_rk): (&Function, &Function, &Function),
) -> TokenStream {
    let n = roots.dry.len();
    let outs = &f_split.outputs;
    let m_rows: Vec<TokenStream> = (0..n)
        .map(|i| {
            let r = &outs[i * n..(i + 1) * n];
            quote!([#(#r),*])
        })
        .collect();
    let b = &outs[n * n..n * n + n];
    let d = &outs[n * n + n..n * n + 2 * n];
    let dry = &roots.dry;
    let vars = [
        ("x", "["),
        ("u", "["),
        ("k", ". 0"),
        ("dir", "["),
        ("h", ""),
    ];
    let s_split = silence(f_split, &vars[..3]);
    let s_mode = silence(f_mode, &vars[..4]);
    let s_rk = silence(f_rk, &vars[..4]);
    let (split_stmts, mode_stmts, rk_stmts) = (&f_split.stmts, &f_mode.stmts, &f_rk.stmts);
    let (mode_outs, rk_outs) = (&f_mode.outputs, &f_rk.outputs);
    let nq = idx(n);
    quote! {
        /// Number of coordinates (`N_STATES / 2`).
        const N_Q: usize = #nq;

        /// Which coordinates have a dry friction that sticks.
        pub const STICKING: [bool; N_Q] = [#(#dry),*];

        /// Mode changes allowed within one step before it fails (NaN): a
        /// joint sticks, breaks away and reverses at most a few times per
        /// step; more is a chattering model, reported instead of looping.
        const MAX_EVENTS: usize = 64;

        /// `M` (model coordinates), `b = Q0 - bias + B u` without the dry
        /// friction, and the dry-friction levels `D` at `(x, u)`.
        #[inline(always)]
        #[allow(clippy::type_complexity)]
        fn split_k(x: &[f64; N_STATES], u: &[f64; N_INPUTS], k: &PlantCoeffs) -> ([[f64; N_Q]; N_Q], [f64; N_Q], [f64; N_Q]) {
            #s_split
            #(#split_stmts)*
            ([#(#m_rows),*], [#(#b),*], [#(#d),*])
        }

        /// `x' = f(x, u)` with every dry joint sliding, `sign(q_i')` taken
        /// as `dir[i]` (the mode of a step, fixed over it).
        #[inline(always)]
        fn mode_dynamics_k(x: &[f64; N_STATES], u: &[f64; N_INPUTS], k: &PlantCoeffs, dir: &[f64; N_Q]) -> [f64; N_STATES] {
            #s_mode
            #(#mode_stmts)*
            [#(#mode_outs),*]
        }

        /// One classical Runge-Kutta step of [`mode_dynamics_k`] of length
        /// `h` with `u` held (the four stages inlined, their sines and
        /// cosines by the addition formulas as in [`rk4_step`]).
        #[inline(always)]
        fn rk4_mode_k(x: &[f64; N_STATES], u: &[f64; N_INPUTS], k: &PlantCoeffs, h: f64, dir: &[f64; N_Q]) -> [f64; N_STATES] {
            #s_rk
            #(#rk_stmts)*
            [#(#rk_outs),*]
        }

        /// The stick-slip mode of a step: stuck joints, and the friction
        /// direction (+-1) of the sliding ones (0 for stuck joints and
        /// joints without dry friction).
        #[derive(Clone, Copy, Debug, PartialEq)]
        struct StickMode {
            stuck: [bool; N_Q],
            dir: [f64; N_Q],
        }

        /// `a` with `a_S = 0` and `M_FF a_F = rhs_F` (Gaussian elimination
        /// with partial pivoting); None when singular.
        fn stick_solve(m: &[[f64; N_Q]; N_Q], rhs: &[f64; N_Q], stuck: &[bool; N_Q]) -> Option<[f64; N_Q]> {
            let mut a = [[0.0; N_Q]; N_Q];
            let mut r = [0.0; N_Q];
            for i in 0..N_Q {
                for j in 0..N_Q {
                    a[i][j] = if stuck[i] || stuck[j] {
                        if i == j { 1.0 } else { 0.0 }
                    } else {
                        m[i][j]
                    };
                }
                r[i] = if stuck[i] { 0.0 } else { rhs[i] };
            }
            for c in 0..N_Q {
                let mut p = c;
                for i in c + 1..N_Q {
                    if math::abs(a[i][c]) > math::abs(a[p][c]) {
                        p = i;
                    }
                }
                let pivot = a[p][c];
                if pivot == 0.0 || !pivot.is_finite() {
                    return None;
                }
                a.swap(c, p);
                r.swap(c, p);
                for i in c + 1..N_Q {
                    let l = a[i][c] / a[c][c];
                    if l != 0.0 {
                        let (upper, lower) = a.split_at_mut(i);
                        for (x, y) in lower[0][c..].iter_mut().zip(&upper[c][c..]) {
                            *x -= l * y;
                        }
                        r[i] -= l * r[c];
                    }
                }
            }
            let mut out = [0.0; N_Q];
            for i in (0..N_Q).rev() {
                let mut s = r[i];
                for j in i + 1..N_Q {
                    s -= a[i][j] * out[j];
                }
                out[i] = s / a[i][i];
            }
            for i in 0..N_Q {
                if stuck[i] {
                    out[i] = 0.0;
                }
            }
            Some(out)
        }

        /// The accelerations of `mode` from `M`, `b` and `D`.
        #[inline]
        fn stick_accel(m: &[[f64; N_Q]; N_Q], b: &[f64; N_Q], d: &[f64; N_Q], mode: &StickMode) -> Option<[f64; N_Q]> {
            let mut rhs = *b;
            for i in 0..N_Q {
                if mode.dir[i] != 0.0 {
                    rhs[i] = b[i] - d[i] * mode.dir[i];
                }
            }
            stick_solve(m, &rhs, &mode.stuck)
        }

        /// The forces holding the stuck joints (`(M a)_i - b_i`; 0 for the
        /// others).
        #[inline]
        fn stick_holding(m: &[[f64; N_Q]; N_Q], b: &[f64; N_Q], a: &[f64; N_Q], mode: &StickMode) -> [f64; N_Q] {
            let mut f = [0.0; N_Q];
            for i in 0..N_Q {
                if mode.stuck[i] {
                    let mut s = 0.0;
                    for j in 0..N_Q {
                        s += m[i][j] * a[j];
                    }
                    f[i] = s - b[i];
                }
            }
            f
        }

        /// The mode at a state with velocities `v`: a sliding joint slides
        /// in its velocity's direction; a dry joint at `v = 0.0` is held
        /// while its holding force is within `max(D, 0)`; of several above
        /// it, the one with the largest excess ratio is released first (in
        /// the direction of the net force) and the rest decided again; a
        /// released joint whose acceleration then points back is held again
        /// for good. `release` (or `N_Q`) breaks a joint away whatever its
        /// force (an event located on the crossing).
        fn stick_classify(m: &[[f64; N_Q]; N_Q], b: &[f64; N_Q], d: &[f64; N_Q], v: &[f64; N_Q], mut release: usize) -> Option<StickMode> {
            let mut mode = StickMode { stuck: [false; N_Q], dir: [0.0; N_Q] };
            let mut any = false;
            for i in 0..N_Q {
                if STICKING[i] {
                    if v[i] != 0.0 {
                        mode.dir[i] = math::sign(v[i]);
                    } else {
                        mode.stuck[i] = true;
                        any = true;
                    }
                }
            }
            if !any {
                return Some(mode);
            }
            let mut pinned = [false; N_Q];
            let mut released = [false; N_Q];
            for _ in 0..=2 * N_Q {
                let a = stick_accel(m, b, d, &mode)?;
                let f = stick_holding(m, b, &a, &mode);
                if release < N_Q {
                    let j = release;
                    release = N_Q;
                    if mode.stuck[j] && f[j] != 0.0 {
                        mode.stuck[j] = false;
                        mode.dir[j] = -math::sign(f[j]);
                        pinned[j] = true;
                        continue;
                    }
                }
                let mut best = N_Q;
                let mut best_ratio = 0.0;
                for i in 0..N_Q {
                    if !mode.stuck[i] || pinned[i] {
                        continue;
                    }
                    let fs = if d[i] > 0.0 { d[i] } else { 0.0 };
                    let fa = math::abs(f[i]);
                    if fa > fs {
                        let ratio = if fs > 0.0 { fa / fs } else { f64::INFINITY };
                        if best == N_Q || ratio > best_ratio {
                            best = i;
                            best_ratio = ratio;
                        }
                    }
                }
                if best < N_Q {
                    mode.stuck[best] = false;
                    mode.dir[best] = -math::sign(f[best]);
                    released[best] = true;
                    continue;
                }
                let mut back = N_Q;
                for i in 0..N_Q {
                    if released[i] && a[i] * mode.dir[i] < 0.0 {
                        back = i;
                        break;
                    }
                }
                if back < N_Q {
                    mode.stuck[back] = true;
                    mode.dir[back] = 0.0;
                    released[back] = false;
                    pinned[back] = true;
                    continue;
                }
                break;
            }
            Some(mode)
        }

        /// The input at a stage: a held one, or a controller's.
        #[inline(always)]
        fn stick_split<F: FnMut(&[f64; N_STATES]) -> [f64; N_INPUTS]>(x: &[f64; N_STATES], k: &PlantCoeffs, uf: &mut F) -> ([[f64; N_Q]; N_Q], [f64; N_Q], [f64; N_Q]) {
            split_k(x, &uf(x), k)
        }

        /// The mode at `x`.
        #[inline]
        fn stick_mode_at<F: FnMut(&[f64; N_STATES]) -> [f64; N_INPUTS]>(x: &[f64; N_STATES], k: &PlantCoeffs, release: usize, uf: &mut F) -> Option<StickMode> {
            let mut v = [0.0; N_Q];
            let mut rest = false;
            for i in 0..N_Q {
                v[i] = x[N_Q + i];
                rest |= STICKING[i] && v[i] == 0.0;
            }
            if !rest {
                let mut mode = StickMode { stuck: [false; N_Q], dir: [0.0; N_Q] };
                for i in 0..N_Q {
                    if STICKING[i] {
                        mode.dir[i] = math::sign(v[i]);
                    }
                }
                return Some(mode);
            }
            let (m, b, d) = stick_split(x, k, uf);
            stick_classify(&m, &b, &d, &v, release)
        }

        /// `x' = (v, a)` of `mode` at `x`.
        #[inline]
        fn stick_rates<F: FnMut(&[f64; N_STATES]) -> [f64; N_INPUTS]>(x: &[f64; N_STATES], k: &PlantCoeffs, mode: &StickMode, uf: &mut F) -> Option<[f64; N_STATES]> {
            if !mode.stuck.iter().any(|s| *s) {
                return Some(mode_dynamics_k(x, &uf(x), k, &mode.dir));
            }
            let (m, b, d) = stick_split(x, k, uf);
            let a = stick_accel(&m, &b, &d, mode)?;
            let mut dx = [0.0; N_STATES];
            dx[..N_Q].copy_from_slice(&x[N_Q..]);
            dx[N_Q..].copy_from_slice(&a);
            Some(dx)
        }

        /// One classical RK4 step of `mode` of length `h` (with a held
        /// input and every dry joint sliding, the fused [`rk4_mode_k`]).
        fn stick_rk4<F: FnMut(&[f64; N_STATES]) -> [f64; N_INPUTS]>(x: &[f64; N_STATES], k: &PlantCoeffs, h: f64, mode: &StickMode, uf: &mut F, held: Option<&[f64; N_INPUTS]>) -> Option<[f64; N_STATES]> {
            if let Some(u) = held {
                if !mode.stuck.iter().any(|s| *s) {
                    return Some(rk4_mode_k(x, u, k, h, &mode.dir));
                }
            }
            let k1 = stick_rates(x, k, mode, uf)?;
            let mut y = [0.0; N_STATES];
            for i in 0..N_STATES { y[i] = x[i] + 0.5 * h * k1[i]; }
            let k2 = stick_rates(&y, k, mode, uf)?;
            for i in 0..N_STATES { y[i] = x[i] + 0.5 * h * k2[i]; }
            let k3 = stick_rates(&y, k, mode, uf)?;
            for i in 0..N_STATES { y[i] = x[i] + h * k3[i]; }
            let k4 = stick_rates(&y, k, mode, uf)?;
            let mut out = [0.0; N_STATES];
            for i in 0..N_STATES {
                out[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
            Some(out)
        }

        /// The guards of `mode` at `x`: `dir_i v_i` of a sliding dry joint,
        /// `max(D_i, 0) - |f_i|` of a stuck one, infinite for the others;
        /// the mode holds while all are `>= 0`.
        fn stick_guards<F: FnMut(&[f64; N_STATES]) -> [f64; N_INPUTS]>(x: &[f64; N_STATES], k: &PlantCoeffs, mode: &StickMode, uf: &mut F) -> Option<[f64; N_Q]> {
            let mut g = [f64::INFINITY; N_Q];
            let mut any_stuck = false;
            for i in 0..N_Q {
                any_stuck |= mode.stuck[i];
                if STICKING[i] && !mode.stuck[i] {
                    g[i] = mode.dir[i] * x[N_Q + i];
                }
            }
            if any_stuck {
                let (m, b, d) = stick_split(x, k, uf);
                let a = stick_accel(&m, &b, &d, mode)?;
                let f = stick_holding(&m, &b, &a, mode);
                for i in 0..N_Q {
                    if mode.stuck[i] {
                        g[i] = (if d[i] > 0.0 { d[i] } else { 0.0 }) - math::abs(f[i]);
                    }
                }
            }
            Some(g)
        }

        /// Where in `(0, hi]` guard `i` of `mode` crosses zero from `x`
        /// (Illinois on the step length, ending on the crossed side);
        /// `Some(None)`: not before `hi`; None: not evaluable.
        fn stick_crossing<F: FnMut(&[f64; N_STATES]) -> [f64; N_INPUTS]>(x: &[f64; N_STATES], k: &PlantCoeffs, mode: &StickMode, i: usize, hi: f64, uf: &mut F, held: Option<&[f64; N_INPUTS]>) -> Option<Option<f64>> {
            let guard = |tau: f64, uf: &mut F| -> Option<f64> {
                let y = stick_rk4(x, k, tau, mode, uf, held)?;
                Some(stick_guards(&y, k, mode, uf)?[i])
            };
            let mut g_hi = guard(hi, uf)?;
            if g_hi >= 0.0 {
                return Some(None);
            }
            let mut hi = hi;
            let mut lo = 0.0;
            let mut g_lo = guard(0.0, uf)?;
            if g_lo <= 0.0 {
                let mut found = false;
                for _ in 0..60 {
                    let mid = 0.5 * hi;
                    let gm = guard(mid, uf)?;
                    if gm > 0.0 {
                        lo = mid;
                        g_lo = gm;
                        found = true;
                        break;
                    }
                    hi = mid;
                    g_hi = gm;
                }
                if !found {
                    return Some(Some(hi));
                }
            }
            let tol = 4.0 * f64::EPSILON * hi;
            let mut side = 0i8;
            for _ in 0..200 {
                if hi - lo <= tol {
                    break;
                }
                let mut t = hi - g_hi * (hi - lo) / (g_hi - g_lo);
                if !(t > lo && t < hi) {
                    t = 0.5 * (lo + hi);
                }
                let gt = guard(t, uf)?;
                if gt == 0.0 {
                    return Some(Some(t));
                }
                if gt > 0.0 {
                    lo = t;
                    g_lo = gt;
                    if side == 1 {
                        g_hi *= 0.5;
                    }
                    side = 1;
                } else {
                    hi = t;
                    g_hi = gt;
                    if side == -1 {
                        g_lo *= 0.5;
                    }
                    side = -1;
                }
            }
            Some(Some(hi))
        }

        /// One step of length `h` with dry friction sticking: an RK4 step of
        /// the mode at `x`, or RK4 steps to each located switch and on from
        /// there (a velocity reaching zero set to 0.0, a breakaway
        /// released). NaN when the dynamics cannot be evaluated or the
        /// friction chatters (more than [`MAX_EVENTS`] switches). `held`:
        /// the input when it is held over the step (`uf` returns it).
        fn stick_step_k<F: FnMut(&[f64; N_STATES]) -> [f64; N_INPUTS]>(x: &[f64; N_STATES], k: &PlantCoeffs, h: f64, uf: &mut F, held: Option<&[f64; N_INPUTS]>) -> [f64; N_STATES] {
            let nan = [f64::NAN; N_STATES];
            let mut x = *x;
            let mut left = h;
            let mut release = N_Q;
            for _ in 0..=MAX_EVENTS {
                let Some(mode) = stick_mode_at(&x, k, release, uf) else { return nan };
                release = N_Q;
                let Some(x1) = stick_rk4(&x, k, left, &mode, uf, held) else { return nan };
                if !x1.iter().all(|v| v.is_finite()) {
                    return nan;
                }
                let Some(g) = stick_guards(&x1, k, &mode, uf) else { return nan };
                if g.iter().all(|v| *v >= 0.0) {
                    return x1;
                }
                let mut tau = left;
                let mut which = N_Q;
                for (i, gi) in g.iter().enumerate() {
                    if *gi < 0.0 {
                        match stick_crossing(&x, k, &mode, i, tau, uf, held) {
                            Some(Some(t)) => {
                                tau = t;
                                which = i;
                            }
                            Some(None) => {}
                            None => return nan,
                        }
                    }
                }
                if which == N_Q {
                    return nan;
                }
                let Some(xe) = stick_rk4(&x, k, tau, &mode, uf, held) else { return nan };
                x = xe;
                if mode.stuck[which] {
                    release = which;
                } else {
                    x[N_Q + which] = 0.0;
                }
                left -= tau;
                if left <= 0.0 {
                    return x;
                }
            }
            nan
        }
    }
}
