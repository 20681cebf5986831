//! Dormand-Prince 5(4) with FSAL and PI step-size control that lands exactly
//! on the requested end time of every [`DormandPrince::advance`] call.

use std::fmt;

/// Tolerances and step limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RkOptions {
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance.
    pub atol: f64,
    /// Largest step (`f64::INFINITY` for none).
    pub max_step: f64,
    /// First trial step (`None`: chosen from the derivative's size).
    pub initial_step: Option<f64>,
    /// Smallest step before giving up.
    pub min_step: f64,
    /// Most steps (accepted and rejected) per [`DormandPrince::advance`].
    pub max_steps: usize,
}

impl Default for RkOptions {
    fn default() -> Self {
        RkOptions {
            rtol: 1e-8,
            atol: 1e-10,
            max_step: f64::INFINITY,
            initial_step: None,
            min_step: 1e-14,
            max_steps: 1_000_000,
        }
    }
}

/// Step counts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RkStats {
    /// Accepted steps.
    pub accepted: usize,
    /// Rejected steps.
    pub rejected: usize,
    /// Right-hand-side evaluations.
    pub evaluations: usize,
}

/// Why integration stopped.
#[derive(Clone, Debug, PartialEq)]
pub enum RkError<E> {
    /// The right-hand side failed.
    Rhs(E),
    /// The step fell below the minimum (stiffness, a singularity, or blow-up).
    StepTooSmall {
        /// Time reached.
        t: f64,
        /// Last step tried.
        h: f64,
    },
    /// The step budget of one `advance` call was exhausted.
    TooManySteps {
        /// Time reached.
        t: f64,
    },
}

impl<E: fmt::Display> fmt::Display for RkError<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RkError::Rhs(e) => write!(f, "{e}"),
            RkError::StepTooSmall { t, h } => write!(
                f,
                "the integrator step fell to {h:.3e} s at t = {t:.6} s (the solution blows up or is not finite)"
            ),
            RkError::TooManySteps { t } => write!(f, "too many integrator steps at t = {t:.6} s"),
        }
    }
}

// Butcher tableau of Dormand & Prince (1980).
const C: [f64; 7] = [0.0, 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0, 1.0, 1.0];
const A: [[f64; 6]; 7] = [
    [0.0; 6],
    [1.0 / 5.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0, 0.0],
    [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0, 0.0],
    [
        19372.0 / 6561.0,
        -25360.0 / 2187.0,
        64448.0 / 6561.0,
        -212.0 / 729.0,
        0.0,
        0.0,
    ],
    [
        9017.0 / 3168.0,
        -355.0 / 33.0,
        46732.0 / 5247.0,
        49.0 / 176.0,
        -5103.0 / 18656.0,
        0.0,
    ],
    [
        35.0 / 384.0,
        0.0,
        500.0 / 1113.0,
        125.0 / 192.0,
        -2187.0 / 6784.0,
        11.0 / 84.0,
    ],
];
/// Fifth-order solution minus embedded fourth-order one.
const E: [f64; 7] = [
    71.0 / 57600.0,
    0.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
];

const SAFETY: f64 = 0.9;
const FAC_MIN: f64 = 0.2;
const FAC_MAX: f64 = 10.0;
const BETA: f64 = 0.04;
const ALPHA: f64 = 0.2 - 0.75 * BETA;

// Dense output of Dormand & Prince (Hairer, Norsett & Wanner, DOPRI5's
// CONTD5): the fourth-order continuous extension of an accepted step.
const D1: f64 = -12715105075.0 / 11282082432.0;
const D3: f64 = 87487479700.0 / 32700410799.0;
const D4: f64 = -10690763975.0 / 1880347072.0;
const D5: f64 = 701980252875.0 / 199316789632.0;
const D6: f64 = -1453857185.0 / 822651844.0;
const D7: f64 = 69997945.0 / 29380423.0;

/// An accepted step with its continuous extension, for an event function
/// ([`DormandPrince::advance_until`],
/// [`super::rosenbrock::Rosenbrock::advance_until`]).
pub struct Dense<'a> {
    /// The step's start time.
    pub t: f64,
    /// Its length.
    pub h: f64,
    pub(crate) y0: &'a [f64],
    pub(crate) y1: &'a [f64],
    pub(crate) kind: DenseKind<'a>,
}

/// How a [`Dense`] step interpolates.
pub(crate) enum DenseKind<'a> {
    /// Dormand-Prince's fourth-order extension from its seven stages.
    Dopri(&'a [Vec<f64>; 7]),
    /// The cubic Hermite interpolant of the end values and slopes (third
    /// order; the Rosenbrock method's second-order steps need no more).
    Hermite {
        /// `f` at the start.
        f0: &'a [f64],
        /// `f` at the end.
        f1: &'a [f64],
    },
}

impl Dense<'_> {
    /// The state at the end of the step.
    pub fn end(&self) -> &[f64] {
        self.y1
    }

    /// The state at `t + theta h` (`0 <= theta <= 1`) by the method's
    /// fourth-order dense output (exact at both ends).
    pub fn at(&self, theta: f64, out: &mut [f64]) {
        let h = self.h;
        let s = 1.0 - theta;
        let k = match self.kind {
            DenseKind::Dopri(k) => k,
            DenseKind::Hermite { f0, f1 } => {
                let (t2, t3) = (theta * theta, theta * theta * theta);
                let h00 = 2.0 * t3 - 3.0 * t2 + 1.0;
                let h10 = t3 - 2.0 * t2 + theta;
                let h01 = -2.0 * t3 + 3.0 * t2;
                let h11 = t3 - t2;
                for i in 0..out.len() {
                    out[i] =
                        h00 * self.y0[i] + h10 * h * f0[i] + h01 * self.y1[i] + h11 * h * f1[i];
                }
                if theta == 1.0 {
                    out.copy_from_slice(self.y1);
                }
                return;
            }
        };
        for i in 0..out.len() {
            let ydiff = self.y1[i] - self.y0[i];
            let bspl = h * k[0][i] - ydiff;
            let r5 = h
                * (D1 * k[0][i]
                    + D3 * k[2][i]
                    + D4 * k[3][i]
                    + D5 * k[4][i]
                    + D6 * k[5][i]
                    + D7 * k[6][i]);
            let r4 = ydiff - h * k[6][i] - bspl;
            out[i] = self.y0[i] + theta * (ydiff + s * (bspl + theta * (r4 + s * r5)));
        }
        if theta == 1.0 {
            out.copy_from_slice(self.y1);
        }
    }
}

/// The integrator state: stage buffers, the current step proposal and the
/// first-same-as-last stage. Allocates only in [`DormandPrince::new`].
#[derive(Clone, Debug)]
pub struct DormandPrince {
    opts: RkOptions,
    k: [Vec<f64>; 7],
    y1: Vec<f64>,
    yt: Vec<f64>,
    h: f64,
    err_prev: f64,
    fsal: bool,
    /// Counts since construction.
    pub stats: RkStats,
}

impl DormandPrince {
    /// An integrator for `n` states.
    pub fn new(n: usize, opts: RkOptions) -> DormandPrince {
        DormandPrince {
            opts,
            k: std::array::from_fn(|_| vec![0.0; n]),
            y1: vec![0.0; n],
            yt: vec![0.0; n],
            h: 0.0,
            err_prev: 1e-4,
            fsal: false,
            stats: RkStats::default(),
        }
    }

    /// Forget the stored first stage: call when the right-hand side changes
    /// discontinuously (a new held input). The step proposal is kept.
    pub fn restart(&mut self) {
        self.fsal = false;
        self.err_prev = 1e-4;
    }

    /// The current step proposal (0 before the first step).
    pub fn step_size(&self) -> f64 {
        self.h
    }

    fn norm(&self, x: &[f64], y: &[f64], v: &[f64]) -> f64 {
        let mut s = 0.0;
        for i in 0..v.len() {
            let sc = self.opts.atol + self.opts.rtol * x[i].abs().max(y[i].abs());
            let r = v[i] / sc;
            s += r * r;
        }
        (s / v.len().max(1) as f64).sqrt()
    }

    /// Integrate `x' = f(t, x)` from `t0` to exactly `t1` (`x` updated in place).
    pub fn advance<E, F>(
        &mut self,
        f: &mut F,
        t0: f64,
        t1: f64,
        x: &mut [f64],
    ) -> Result<(), RkError<E>>
    where
        F: FnMut(f64, &[f64], &mut [f64]) -> Result<(), E>,
    {
        self.advance_until(f, &mut |_: &Dense<'_>| Ok(None), t0, t1, x)
            .map(|_| ())
    }

    /// [`DormandPrince::advance`], stopping at an event: after every
    /// accepted step `stop` gets the step with its dense output and returns
    /// `Some(theta)` (`0 < theta <= 1`) where an event falls inside it; the
    /// integration then ends at `t + theta h` with `x` the dense output
    /// there, returns that time, and forgets its first stage (the caller
    /// changes the right-hand side there). `Ok(None)`: `t1` reached.
    #[allow(clippy::needless_range_loop)] // stage sums read clearer indexed
    pub fn advance_until<E, F, S>(
        &mut self,
        f: &mut F,
        stop: &mut S,
        t0: f64,
        t1: f64,
        x: &mut [f64],
    ) -> Result<Option<f64>, RkError<E>>
    where
        F: FnMut(f64, &[f64], &mut [f64]) -> Result<(), E>,
        S: FnMut(&Dense<'_>) -> Result<Option<f64>, E>,
    {
        if t1 <= t0 {
            return Ok(None);
        }
        let n = x.len();
        if !self.fsal {
            f(t0, x, &mut self.k[0]).map_err(RkError::Rhs)?;
            self.stats.evaluations += 1;
            self.fsal = true;
        }
        if self.h <= 0.0 {
            self.h = match self.opts.initial_step {
                Some(h) => h,
                None => {
                    let d0 = self.norm(x, x, x);
                    let d1 = self.norm(x, x, &self.k[0]);
                    let h = if d0 < 1e-5 || d1 < 1e-5 {
                        1e-6
                    } else {
                        0.01 * d0 / d1
                    };
                    h.clamp(1e-6, 1e-2)
                }
            };
        }
        let mut t = t0;
        let mut steps = 0usize;
        let mut rejected_last = false;
        loop {
            let remaining = t1 - t;
            let mut h = self.h.min(self.opts.max_step);
            let last = h >= remaining * (1.0 - 1e-12);
            if last {
                h = remaining;
            }
            steps += 1;
            if steps > self.opts.max_steps {
                return Err(RkError::TooManySteps { t });
            }
            for s in 1..7 {
                for i in 0..n {
                    let mut acc = 0.0;
                    for (j, a) in A[s].iter().enumerate().take(s) {
                        acc += a * self.k[j][i];
                    }
                    self.yt[i] = x[i] + h * acc;
                }
                let ts = if s == 6 { t + h } else { t + C[s] * h };
                f(ts, &self.yt, &mut self.k[s]).map_err(RkError::Rhs)?;
                self.stats.evaluations += 1;
            }
            // Stage 7 (index 6) was evaluated at y1 = yt of the last stage.
            self.y1.copy_from_slice(&self.yt);
            for i in 0..n {
                let mut e = 0.0;
                for (j, c) in E.iter().enumerate() {
                    e += c * self.k[j][i];
                }
                self.yt[i] = h * e;
            }
            let err = self.norm(x, &self.y1, &self.yt);
            let finite = err.is_finite() && self.y1.iter().all(|v| v.is_finite());
            if finite && err <= 1.0 {
                self.stats.accepted += 1;
                let mut fac = SAFETY * err.max(1e-10).powf(-ALPHA) * self.err_prev.powf(BETA);
                fac = fac.clamp(FAC_MIN, FAC_MAX);
                if rejected_last {
                    fac = fac.min(1.0);
                }
                self.err_prev = err.max(1e-4);
                let proposal = h * fac;
                if last && h < self.h {
                    // A shortened landing step says little about larger ones.
                    if fac < 1.0 {
                        self.h = self.h.min(proposal);
                    }
                } else {
                    self.h = proposal;
                }
                let dense = Dense {
                    t,
                    h,
                    y0: x,
                    y1: &self.y1,
                    kind: DenseKind::Dopri(&self.k),
                };
                if let Some(theta) = stop(&dense).map_err(RkError::Rhs)? {
                    let theta = theta.clamp(0.0, 1.0);
                    dense.at(theta, &mut self.yt);
                    x.copy_from_slice(&self.yt);
                    self.fsal = false;
                    self.err_prev = 1e-4;
                    return Ok(Some(if theta == 1.0 { t + h } else { t + theta * h }));
                }
                x.copy_from_slice(&self.y1);
                self.k.swap(0, 6);
                if last {
                    return Ok(None);
                }
                t += h;
                rejected_last = false;
            } else {
                self.stats.rejected += 1;
                let fac = if finite {
                    (SAFETY * err.powf(-0.2)).max(FAC_MIN)
                } else {
                    FAC_MIN
                };
                self.h = h * fac;
                rejected_last = true;
                if self.h < self.opts.min_step.max(1e-15 * t.abs()) {
                    return Err(RkError::StepTooSmall { t, h: self.h });
                }
            }
        }
    }
}
