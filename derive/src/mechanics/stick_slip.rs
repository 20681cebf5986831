//! Switched stick-slip dynamics of joints with dry friction (the numeric
//! side of [`super::dry_friction`]).
//!
//! With `M a = b - D sign(v)` (`b = r + B u` the applied generalised force
//! without dry friction, `D >= 0` the levels), each joint with a dry friction
//! is in one of two modes over an integration step:
//!
//! - **sliding** in direction `sigma_i = +-1`: its friction is `-D_i sigma_i`
//!   (`sigma_i = sign(v_i)`, fixed over the step);
//! - **stuck**: `v_i = 0` and `a_i = 0`; the friction is whatever holds it,
//!   `f_S = M_SF a_F - b_S` with `M_FF a_F = b_F - D_F sigma_F` for the free
//!   joints `F` (the constrained solve), as long as `|f_i| <= Fs_i` with
//!   `Fs_i = max(D_i, 0)` at `v_i = 0` (the static level: `Fs` of a Stribeck
//!   friction).
//!
//! **The mode is a function of the state** ([`StickSlip::classify`]): a joint
//! with `v_i != 0` slides in the direction of its velocity; a joint with
//! `v_i == 0.0` exactly is stuck while its holding force is within its static
//! level. When several stuck joints exceed theirs, the one with the largest
//! excess ratio `|f_i| / Fs_i` is released first (direction of the net
//! applied force, `-sign(f_i)`) and the others are decided again with it
//! sliding (ties: the lowest index); a released joint whose acceleration
//! then points against its direction sticks again and stays stuck for this
//! decision. Callers carry no hidden mode state: a stuck joint has `v = 0.0`
//! exactly, and integration keeps it so (its rate is exactly zero).
//!
//! **Events** end a step where the mode changes ([`StickSlip::guards`], each
//! `>= 0` while the mode holds): a sliding joint's `sigma_i v_i` reaching
//! zero (there the velocity is set to `0.0`, and the joint sticks when its
//! holding force is within the static level, else it reverses), and a stuck
//! joint's `Fs_i - |f_i|` crossing zero (it breaks away in the direction of
//! the net applied force). Integrators locate them on the step length by
//! [`illinois`] iterations and continue from the event with the new mode
//! ([`Rk4Events`] for a fixed-step RK4; identification and Dormand-Prince
//! have their own loops around the same pieces).

use super::small_lu::invert;

/// Which dry-friction joints are stuck, and the friction direction of the
/// sliding ones.
#[derive(Clone, Debug, PartialEq)]
pub struct Mode {
    /// `stuck[i]`: joint `i` is held (`v_i = 0`, `a_i = 0`).
    pub stuck: Vec<bool>,
    /// `dir[i]`: `sigma_i` (`+-1`) of a sliding dry-friction joint; `0` for a
    /// stuck joint and a joint without dry friction.
    pub dir: Vec<f64>,
}

impl Mode {
    /// Every joint free, no direction.
    pub fn new(n: usize) -> Mode {
        Mode {
            stuck: vec![false; n],
            dir: vec![0.0; n],
        }
    }

    /// Whether some joint is stuck.
    pub fn any_stuck(&self) -> bool {
        self.stuck.iter().any(|s| *s)
    }
}

/// Root of `g` on `(lo, hi)` with `g(lo) = g_lo > 0 > g(hi) = g_hi` by the
/// Illinois variant of regula falsi, to a bracket of a few ulps of `hi`
/// (or an exact zero); `g` returns None where it cannot be evaluated. The
/// result is the bracket's upper end, where the guard is `<= 0`: the event
/// has happened there (a holding force just above its level, a velocity
/// just past zero), so the new mode is consistent with the state.
pub fn illinois(
    mut g: impl FnMut(f64) -> Option<f64>,
    (mut lo, mut g_lo): (f64, f64),
    (mut hi, mut g_hi): (f64, f64),
) -> Option<f64> {
    // 4 ulps of the bracket's scale: below that the iterates cannot move
    let tol = 4.0 * f64::EPSILON * hi.abs().max(lo.abs());
    let mut side = 0i8;
    for _ in 0..200 {
        if hi - lo <= tol {
            break;
        }
        let mut x = hi - g_hi * (hi - lo) / (g_hi - g_lo);
        if !(x > lo && x < hi) {
            x = 0.5 * (lo + hi);
        }
        let gx = g(x)?;
        if gx == 0.0 {
            return Some(x);
        }
        if gx > 0.0 {
            lo = x;
            g_lo = gx;
            if side == 1 {
                g_hi *= 0.5;
            }
            side = 1;
        } else {
            hi = x;
            g_hi = gx;
            if side == -1 {
                g_lo *= 0.5;
            }
            side = -1;
        }
    }
    Some(hi)
}

/// Where a guard first crosses zero on a step of length at most `hi`:
/// `guard(tau)` is the guard after a step of length `tau` (None: could not
/// be evaluated). Returns `Ok(None)` when the guard is still `>= 0` at
/// `hi`; otherwise the crossing by [`illinois`], from `tau = 0` or, when the
/// guard starts at zero or below (a joint just released, a holding force
/// exactly at its level), from the first of `hi/2, hi/4, ...` where it is
/// positive (none in 60 halvings: the event is at the last of them, a
/// step of at most `hi / 2^60`).
pub fn first_crossing(
    mut guard: impl FnMut(f64) -> Option<f64>,
    hi: f64,
) -> Result<Option<f64>, StepError> {
    let g_hi = guard(hi).ok_or(StepError::Singular)?;
    if g_hi >= 0.0 {
        return Ok(None);
    }
    let g0 = guard(0.0).ok_or(StepError::Singular)?;
    let (mut lo, mut g_lo, mut hi, mut g_hi) = (0.0, g0, hi, g_hi);
    if g_lo <= 0.0 {
        let mut found = false;
        for _ in 0..60 {
            let mid = 0.5 * hi;
            let gm = guard(mid).ok_or(StepError::Singular)?;
            if gm > 0.0 {
                (lo, g_lo, found) = (mid, gm, true);
                break;
            }
            (hi, g_hi) = (mid, gm);
        }
        if !found {
            return Ok(Some(hi));
        }
    }
    illinois(guard, (lo, g_lo), (hi, g_hi))
        .map(Some)
        .ok_or(StepError::Singular)
}

/// The numeric stick-slip rules for `n` joints, with buffers allocated once
/// (no allocation per call).
#[derive(Clone, Debug)]
pub struct StickSlip {
    n: usize,
    dry: Vec<bool>,
    any_dry: bool,
    sub: Vec<f64>,
    subinv: Vec<f64>,
    lu: Vec<f64>,
    piv: Vec<usize>,
    tmp: Vec<f64>,
    col: Vec<f64>,
    free: Vec<usize>,
    minv: Vec<f64>,
    beff: Vec<f64>,
    acc: Vec<f64>,
    force: Vec<f64>,
    pinned: Vec<bool>,
    released: Vec<bool>,
}

impl StickSlip {
    /// The rules for joints of which `dry[i]` have a dry friction.
    pub fn new(dry: &[bool]) -> StickSlip {
        let n = dry.len();
        StickSlip {
            n,
            dry: dry.to_vec(),
            any_dry: dry.iter().any(|d| *d),
            sub: vec![0.0; n * n],
            subinv: vec![0.0; n * n],
            lu: vec![0.0; n * n],
            piv: vec![0; n],
            tmp: vec![0.0; n],
            col: vec![0.0; n],
            free: Vec::with_capacity(n),
            minv: vec![0.0; n * n],
            beff: vec![0.0; n],
            acc: vec![0.0; n],
            force: vec![0.0; n],
            pinned: vec![false; n],
            released: vec![false; n],
        }
    }

    /// Number of joints.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Which joints have a dry friction.
    pub fn dry(&self) -> &[bool] {
        &self.dry
    }

    /// Whether any joint has a dry friction.
    pub fn any_dry(&self) -> bool {
        self.any_dry
    }

    /// The mode when no dry joint is at rest (`v_i != 0.0` for each):
    /// every dry joint slides in its velocity's direction, nothing needs
    /// evaluating; returns false (mode untouched) when some dry joint is at
    /// rest, so [`StickSlip::classify`] must decide.
    pub fn slide(&self, v: &[f64], mode: &mut Mode) -> bool {
        if self.dry.iter().zip(v).any(|(d, vi)| *d && *vi == 0.0) {
            return false;
        }
        for (i, (&d, &vi)) in self.dry.iter().zip(v).enumerate() {
            mode.stuck[i] = false;
            mode.dir[i] = if d { vi.signum() } else { 0.0 };
        }
        true
    }

    /// `minv` = `M_FF^-1` embedded in an `n x n` matrix with zero rows and
    /// columns for the stuck joints (`M^-1` itself when none is stuck; by
    /// [`invert`], cofactors up to 3 free joints). False when `M_FF` is
    /// singular.
    pub fn free_inverse(&mut self, m: &[f64], stuck: &[bool], minv: &mut [f64]) -> bool {
        let n = self.n;
        let tiny = f64::MIN_POSITIVE;
        if !stuck.iter().any(|s| *s) {
            return invert(
                m,
                n,
                minv,
                (&mut self.lu, &mut self.piv, &mut self.tmp, &mut self.col),
                tiny,
            );
        }
        self.free.clear();
        self.free.extend((0..n).filter(|&i| !stuck[i]));
        let k = self.free.len();
        for (a, &i) in self.free.iter().enumerate() {
            for (b, &j) in self.free.iter().enumerate() {
                self.sub[a * k + b] = m[i * n + j];
            }
        }
        minv[..n * n].iter_mut().for_each(|v| *v = 0.0);
        if k == 0 {
            return true;
        }
        if !invert(
            &self.sub[..k * k],
            k,
            &mut self.subinv[..k * k],
            (&mut self.lu, &mut self.piv, &mut self.tmp, &mut self.col),
            tiny,
        ) {
            return false;
        }
        for (a, &i) in self.free.iter().enumerate() {
            for (b, &j) in self.free.iter().enumerate() {
                minv[i * n + j] = self.subinv[a * k + b];
            }
        }
        true
    }

    /// `out = b - D sigma`: the applied force with the sliding joints'
    /// friction (entries of stuck joints are `b` itself and never used).
    #[inline]
    pub fn effective_forces(b: &[f64], d: &[f64], mode: &Mode, out: &mut [f64]) {
        for i in 0..out.len() {
            let s = mode.dir[i];
            out[i] = if s != 0.0 { b[i] - d[i] * s } else { b[i] };
        }
    }

    /// Accelerations `a` of `mode` (`a_S = 0`) from `M`, `b = r + B u` and
    /// the levels `d` at a state. False when `M_FF` is singular.
    pub fn accelerations(
        &mut self,
        m: &[f64],
        b: &[f64],
        d: &[f64],
        mode: &Mode,
        a: &mut [f64],
    ) -> bool {
        let mut minv = std::mem::take(&mut self.minv);
        let ok = self.free_inverse(m, &mode.stuck, &mut minv);
        if ok {
            Self::effective_forces(b, d, mode, &mut self.beff);
            mat_vec(&minv, self.n, &self.beff, a);
        }
        self.minv = minv;
        ok
    }

    /// The forces `f_i = (M a)_i - b_i` holding the stuck joints (zero for
    /// the others), `a` the accelerations of the mode.
    pub fn holding_forces(&self, m: &[f64], b: &[f64], a: &[f64], mode: &Mode, f: &mut [f64]) {
        let n = self.n;
        for i in 0..n {
            f[i] = if mode.stuck[i] {
                let mut s = 0.0;
                for j in 0..n {
                    s += m[i * n + j] * a[j];
                }
                s - b[i]
            } else {
                0.0
            };
        }
    }

    /// The mode at a state with velocities `v`, from `M`, `b` and the levels
    /// `d` there (see the module docs); `release` names a stuck joint that
    /// breaks away here whatever its holding force (an event located on the
    /// stuck side of the crossing). False when a solve is singular.
    pub fn classify(
        &mut self,
        m: &[f64],
        b: &[f64],
        d: &[f64],
        v: &[f64],
        mut release: Option<usize>,
        mode: &mut Mode,
    ) -> bool {
        let n = self.n;
        let mut any = false;
        for (i, (&dry, &vi)) in self.dry.iter().zip(v).enumerate() {
            mode.stuck[i] = false;
            mode.dir[i] = 0.0;
            if dry {
                if vi != 0.0 {
                    mode.dir[i] = vi.signum();
                } else {
                    mode.stuck[i] = true;
                    any = true;
                }
            }
        }
        if !any {
            return true;
        }
        self.pinned.iter_mut().for_each(|p| *p = false);
        self.released.iter_mut().for_each(|p| *p = false);
        let mut acc = std::mem::take(&mut self.acc);
        let mut force = std::mem::take(&mut self.force);
        let mut ok = true;
        // each round releases or pins one joint, and a pinned joint is never
        // released again: at most 2n rounds
        for _ in 0..=2 * n {
            if !self.accelerations(m, b, d, mode, &mut acc) {
                ok = false;
                break;
            }
            self.holding_forces(m, b, &acc, mode, &mut force);
            if let Some(j) = release.take() {
                if mode.stuck[j] && force[j] != 0.0 {
                    // (located on the crossing: not checked again below,
                    // where rounding could put it back)
                    mode.stuck[j] = false;
                    mode.dir[j] = -force[j].signum();
                    self.pinned[j] = true;
                    continue;
                }
            }
            let mut best: Option<(usize, f64)> = None;
            for i in 0..n {
                if !mode.stuck[i] || self.pinned[i] {
                    continue;
                }
                let fs = d[i].max(0.0);
                let f = force[i].abs();
                if f > fs {
                    let ratio = if fs > 0.0 { f / fs } else { f64::INFINITY };
                    if best.is_none_or(|(_, r)| ratio > r) {
                        best = Some((i, ratio));
                    }
                }
            }
            if let Some((i, _)) = best {
                mode.stuck[i] = false;
                mode.dir[i] = -force[i].signum();
                self.released[i] = true;
                continue;
            }
            let back = (0..n).find(|&i| self.released[i] && acc[i] * mode.dir[i] < 0.0);
            if let Some(i) = back {
                mode.stuck[i] = true;
                mode.dir[i] = 0.0;
                self.released[i] = false;
                self.pinned[i] = true;
                continue;
            }
            break;
        }
        self.acc = acc;
        self.force = force;
        ok
    }

    /// Event functions of `mode` at a state with velocities `v`, levels `d`
    /// and holding forces `f` ([`StickSlip::holding_forces`]): `sigma_i v_i`
    /// for a sliding dry joint, `max(D_i, 0) - |f_i|` for a stuck one,
    /// `+inf` for the others. The mode holds while all are `>= 0`.
    pub fn guards(&self, v: &[f64], d: &[f64], f: &[f64], mode: &Mode, g: &mut [f64]) {
        for i in 0..self.n {
            g[i] = if !self.dry[i] {
                f64::INFINITY
            } else if mode.stuck[i] {
                d[i].max(0.0) - f[i].abs()
            } else {
                mode.dir[i] * v[i]
            };
        }
    }
}

/// `y = a x` for the row-major `n x n` matrix `a` (one summation order,
/// shared by every simulator that must agree to the bit).
#[inline]
pub fn mat_vec(a: &[f64], n: usize, x: &[f64], y: &mut [f64]) {
    for (i, yi) in y.iter_mut().enumerate().take(n) {
        *yi = a[i * n..(i + 1) * n]
            .iter()
            .zip(x)
            .map(|(p, q)| p * q)
            .sum();
    }
}

/// The dynamics at a state as the stick-slip rules need them: `M`
/// (row-major), `b = r + B u` without dry friction and the levels `D` (zero
/// for joints without), the input held.
pub trait SplitDynamics {
    /// Evaluate at state `x = (q, v)`; false when the state cannot be
    /// evaluated.
    fn split(&mut self, x: &[f64], m: &mut [f64], b: &mut [f64], d: &mut [f64]) -> bool;
}

/// Why a stick-slip step failed.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum StepError {
    /// The dynamics could not be evaluated or a mass matrix was singular.
    Singular,
    /// More than [`MAX_EVENTS`] mode changes within one step.
    TooManyEvents,
}

/// Mode changes allowed within one fixed step before [`StepError::TooManyEvents`]:
/// a joint sticks, breaks away and reverses at most a few times per step of
/// a rig's simulation (0.1-2 ms); 64 leaves room for several joints and
/// reports a chattering model instead of looping.
pub const MAX_EVENTS: usize = 64;

/// A fixed-step classical RK4 with event-located stick-slip switching: one
/// [`Rk4Events::step`] of length `h` with the input held is one RK4 step of
/// the mode at the start, or, when an event falls inside it, RK4 steps up
/// to each event (located by [`illinois`] on the step length) and on from
/// there with the new mode. Without dry friction it is exactly the
/// classical RK4 step. Buffers allocated once; no allocation per step.
#[derive(Clone, Debug)]
pub struct Rk4Events {
    rules: StickSlip,
    mode: Mode,
    m: Vec<f64>,
    b: Vec<f64>,
    d: Vec<f64>,
    a: Vec<f64>,
    f: Vec<f64>,
    g: Vec<f64>,
    g_end: Vec<f64>,
    k1: Vec<f64>,
    k2: Vec<f64>,
    k3: Vec<f64>,
    k4: Vec<f64>,
    tmp: Vec<f64>,
    x1: Vec<f64>,
}

impl Rk4Events {
    /// A stepper for `n` joints of which `dry[i]` have a dry friction.
    pub fn new(dry: &[bool]) -> Rk4Events {
        let n = dry.len();
        Rk4Events {
            rules: StickSlip::new(dry),
            mode: Mode::new(n),
            m: vec![0.0; n * n],
            b: vec![0.0; n],
            d: vec![0.0; n],
            a: vec![0.0; n],
            f: vec![0.0; n],
            g: vec![0.0; n],
            g_end: vec![0.0; n],
            k1: vec![0.0; 2 * n],
            k2: vec![0.0; 2 * n],
            k3: vec![0.0; 2 * n],
            k4: vec![0.0; 2 * n],
            tmp: vec![0.0; 2 * n],
            x1: vec![0.0; 2 * n],
        }
    }

    /// The mode in force at the end of the last step.
    pub fn mode(&self) -> &Mode {
        &self.mode
    }

    /// `dx = (v, a)` of the current mode at `x`.
    fn rate(
        rules: &mut StickSlip,
        mode: &Mode,
        (m, b, d, a): (&mut [f64], &mut [f64], &mut [f64], &mut [f64]),
        sys: &mut impl SplitDynamics,
        x: &[f64],
        dx: &mut [f64],
    ) -> bool {
        let n = rules.n;
        if !sys.split(x, m, b, d) || !rules.accelerations(m, b, d, mode, a) {
            return false;
        }
        dx[..n].copy_from_slice(&x[n..2 * n]);
        dx[n..2 * n].copy_from_slice(a);
        true
    }

    /// One RK4 step of length `h` from `x` with the current mode; the
    /// result in `self.x1`.
    fn rk4(&mut self, sys: &mut impl SplitDynamics, x: &[f64], h: f64) -> bool {
        let dim = x.len();
        let bufs = (
            &mut self.m[..],
            &mut self.b[..],
            &mut self.d[..],
            &mut self.a[..],
        );
        let (rules, mode) = (&mut self.rules, &self.mode);
        let (k1, k2, k3, k4, tmp) = (
            &mut self.k1,
            &mut self.k2,
            &mut self.k3,
            &mut self.k4,
            &mut self.tmp,
        );
        let (m, b, d, a) = bufs;
        if !Self::rate(rules, mode, (m, b, d, a), sys, x, k1) {
            return false;
        }
        for i in 0..dim {
            tmp[i] = x[i] + 0.5 * h * k1[i];
        }
        if !Self::rate(rules, mode, (m, b, d, a), sys, tmp, k2) {
            return false;
        }
        for i in 0..dim {
            tmp[i] = x[i] + 0.5 * h * k2[i];
        }
        if !Self::rate(rules, mode, (m, b, d, a), sys, tmp, k3) {
            return false;
        }
        for i in 0..dim {
            tmp[i] = x[i] + h * k3[i];
        }
        if !Self::rate(rules, mode, (m, b, d, a), sys, tmp, k4) {
            return false;
        }
        for i in 0..dim {
            self.x1[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        true
    }

    /// The guards of the current mode at `self.x1` into `self.g`.
    fn guards_at_end(&mut self, sys: &mut impl SplitDynamics) -> bool {
        let n = self.rules.n;
        if self.mode.any_stuck() {
            if !sys.split(&self.x1, &mut self.m, &mut self.b, &mut self.d)
                || !self
                    .rules
                    .accelerations(&self.m, &self.b, &self.d, &self.mode, &mut self.a)
            {
                return false;
            }
            self.rules
                .holding_forces(&self.m, &self.b, &self.a, &self.mode, &mut self.f);
        }
        self.rules.guards(
            &self.x1[n..2 * n],
            &self.d,
            &self.f,
            &self.mode,
            &mut self.g,
        );
        true
    }

    /// Decide the mode at `x` (`release`: a joint breaking away here).
    fn classify(
        &mut self,
        sys: &mut impl SplitDynamics,
        x: &[f64],
        release: Option<usize>,
    ) -> bool {
        let n = self.rules.n;
        if self.rules.slide(&x[n..2 * n], &mut self.mode) {
            return true;
        }
        if !sys.split(x, &mut self.m, &mut self.b, &mut self.d) {
            return false;
        }
        self.rules.classify(
            &self.m,
            &self.b,
            &self.d,
            &x[n..2 * n],
            release,
            &mut self.mode,
        )
    }

    /// Advance `x` (`2n` entries) by `h` with the input held (inside `sys`).
    pub fn step(
        &mut self,
        sys: &mut impl SplitDynamics,
        x: &mut [f64],
        h: f64,
    ) -> Result<(), StepError> {
        let n = self.rules.n;
        if !self.rules.any_dry {
            if !self.rk4(sys, x, h) {
                return Err(StepError::Singular);
            }
            x.copy_from_slice(&self.x1);
            return Ok(());
        }
        let mut left = h;
        let mut release = None;
        for _ in 0..=MAX_EVENTS {
            if !self.classify(sys, x, release.take())
                || !self.rk4(sys, x, left)
                || !self.guards_at_end(sys)
            {
                return Err(StepError::Singular);
            }
            if self.g.iter().all(|g| *g >= 0.0) {
                x.copy_from_slice(&self.x1);
                return Ok(());
            }
            // the first crossing among the violated guards
            self.g_end.copy_from_slice(&self.g);
            let (mut tau, mut which) = (left, None);
            for i in 0..n {
                if self.g_end[i] < 0.0 {
                    if let Some(t) = self.locate(sys, x, i, tau)? {
                        tau = t;
                        which = Some(i);
                    }
                }
            }
            let Some(j) = which else {
                return Err(StepError::Singular);
            };
            if !self.rk4(sys, x, tau) {
                return Err(StepError::Singular);
            }
            x.copy_from_slice(&self.x1);
            if self.mode.stuck[j] {
                release = Some(j);
            } else {
                x[n + j] = 0.0;
            }
            left -= tau;
            if left <= 0.0 {
                return Ok(());
            }
        }
        Err(StepError::TooManyEvents)
    }

    /// The step length in `[0, hi]` where guard `i` of the current mode
    /// crosses zero from `x` ([`first_crossing`]).
    fn locate(
        &mut self,
        sys: &mut impl SplitDynamics,
        x: &[f64],
        i: usize,
        hi: f64,
    ) -> Result<Option<f64>, StepError> {
        first_crossing(
            |tau| (self.rk4(sys, x, tau) && self.guards_at_end(sys)).then(|| self.g[i]),
            hi,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One joint: held while `|b| <= D`, released against the holding
    /// force (along `b`) above it; a sliding joint keeps its velocity's
    /// direction.
    #[test]
    fn one_joint_rules() {
        let mut r = StickSlip::new(&[true]);
        let mut mode = Mode::new(1);
        assert!(r.classify(&[2.0], &[0.3], &[0.5], &[0.0], None, &mut mode));
        assert!(mode.stuck[0]);
        let mut a = [0.0];
        r.accelerations(&[2.0], &[0.3], &[0.5], &mode, &mut a);
        let mut f = [0.0];
        r.holding_forces(&[2.0], &[0.3], &a, &mode, &mut f);
        assert_eq!((a[0], f[0]), (0.0, -0.3));
        assert!(r.classify(&[2.0], &[-0.7], &[0.5], &[0.0], None, &mut mode));
        assert_eq!((mode.stuck[0], mode.dir[0]), (false, -1.0));
        r.accelerations(&[2.0], &[-0.7], &[0.5], &mode, &mut a);
        // (-0.7 + 0.5) / 2
        assert!((a[0] + 0.1).abs() < 1e-15, "{}", a[0]);
        assert!(r.classify(&[2.0], &[-0.7], &[0.5], &[0.2], None, &mut mode));
        assert_eq!((mode.stuck[0], mode.dir[0]), (false, 1.0));
        let mut g = [0.0];
        r.guards(&[0.2], &[0.5], &[0.0], &mode, &mut g);
        assert_eq!(g[0], 0.2);
    }

    /// Random coupled joints (symmetric positive definite `M`): the joints
    /// released by [`StickSlip::classify`] accelerate in their direction,
    /// the held ones (but the few held again after a release, whose force
    /// may exceed their level) within their level; the decision is
    /// deterministic.
    #[test]
    fn coupled_joints_are_decided_consistently() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let (mut held, mut over) = (0, 0);
        for n in [2usize, 3] {
            let mut r = StickSlip::new(&vec![true; n]);
            for _ in 0..2000 {
                let l: Vec<f64> = (0..n * n).map(|_| next()).collect();
                let mut m = vec![0.0; n * n];
                for i in 0..n {
                    for j in 0..n {
                        m[i * n + j] = (0..n).map(|k| l[i * n + k] * l[j * n + k]).sum::<f64>()
                            + if i == j { 0.3 } else { 0.0 };
                    }
                }
                let b: Vec<f64> = (0..n).map(|_| next()).collect();
                let d: Vec<f64> = (0..n).map(|_| 0.5 * (next() + 0.5)).collect();
                let v = vec![0.0; n];
                let mut mode = Mode::new(n);
                assert!(r.classify(&m, &b, &d, &v, None, &mut mode));
                let mut again = Mode::new(n);
                r.classify(&m, &b, &d, &v, None, &mut again);
                assert_eq!(mode, again);
                let mut a = vec![0.0; n];
                let mut f = vec![0.0; n];
                r.accelerations(&m, &b, &d, &mode, &mut a);
                r.holding_forces(&m, &b, &a, &mode, &mut f);
                for i in 0..n {
                    if mode.stuck[i] {
                        assert_eq!(a[i], 0.0);
                        held += 1;
                        over += usize::from(f[i].abs() > d[i] * (1.0 + 1e-12));
                    } else {
                        assert!(a[i] * mode.dir[i] >= -1e-12, "{m:?} {b:?} {d:?}");
                    }
                }
            }
        }
        assert!(
            held > 1000 && over * 20 < held,
            "{over} of {held} held above their level"
        );
    }

    /// Illinois finds a root to a few ulps and ends on the crossed side.
    #[test]
    fn illinois_ends_past_the_root() {
        let root = 0.3f64;
        let t = illinois(|x| Some(root - x * x * 3.0), (0.0, root), (1.0, root - 3.0)).unwrap();
        assert!((t - 0.1f64.sqrt()).abs() < 1e-15);
        assert!(root - t * t * 3.0 <= 0.0);
    }
}
