//! An input held sample by sample, replaced over a span of several sample
//! intervals by the straight line with the same integral and the same first
//! moment, for one RK4 step over the span where the input changes at every
//! sample (a driven record; see [`crate::experiment_sim`]'s spans).
//!
//! Over a span of length `L` the held input `u(s)` (a staircase, each
//! value from its arrival `t_i + delay` on) and the line `a(s)` agree in
//! `int u` and `int s u`. The response of the positions to the difference
//! `e = u - a`, with the input gain `G = M^-1 B` frozen over the span, is
//! `G E2(s)`, `E2(s) = int_0^s (s - r) e(r) dr`: zero at the span's end by
//! the two moments (the double integrator's end state is exact), not inside
//! it. [`Staircase::inside_error`] gives `E2` at the samples inside, where
//! the span's Hermite interpolant would miss the staircase's trajectory by
//! `G E2`; the span is taken only where that is within the simulation's
//! span tolerance. What remains at the end is the coupling of `e`'s
//! response with the state's own Jacobian, `J int G E1` with
//! `E1 = E2'`, whose integral over the span is `J G E2(L) = 0`: it is of
//! higher order again (checked against the interval-by-interval
//! simulation in `tests/spans.rs`).

/// The held values of every input over one span, as pieces `(from, to,
/// value)` in seconds from the span's start, with each input's line.
/// Rebuilt for every span in the same buffers ([`Staircase::over`]).
#[derive(Default)]
pub(crate) struct Staircase {
    /// Span length `L`.
    len: f64,
    /// Every input's pieces, in time order, covering `[0, L]`.
    pieces: Vec<(f64, f64, f64)>,
    /// Where each input's pieces start in `pieces` (one more entry: the
    /// end).
    first: Vec<usize>,
    /// Per input: mean and slope of its line.
    line: Vec<(f64, f64)>,
}

impl Staircase {
    /// Make this the staircase over `[t[from], t[to]]`: input `j` holds
    /// `u[j][i]` from `t[i] + delays[j]` to the next sample's arrival,
    /// starting from `held[j]` and the switches due at the span's start
    /// (within `tol`, as the interval steps take them).
    pub(crate) fn over(
        &mut self,
        t: &[f64],
        u: &[Vec<f64>],
        (held, delays): (&[usize], &[f64]),
        (from, to): (usize, usize),
        tol: f64,
    ) {
        let (t0, t1) = (t[from], t[to]);
        let len = t1 - t0;
        self.len = len;
        self.pieces.clear();
        self.first.clear();
        self.line.clear();
        for (j, uj) in u.iter().enumerate() {
            self.first.push(self.pieces.len());
            let last = t.len().min(uj.len());
            let d = delays.get(j).copied().unwrap_or(0.0);
            let mut i = held[j];
            while i + 1 < last && t[i + 1] + d <= t0 + tol {
                i += 1;
            }
            let mut a = 0.0;
            loop {
                match (i + 1 < last).then(|| t[i + 1] + d - t0) {
                    Some(b) if b < len - tol => {
                        self.pieces.push((a, b, uj[i]));
                        a = b;
                        i += 1;
                    }
                    _ => {
                        self.pieces.push((a, len, uj[i]));
                        break;
                    }
                }
            }
            let p = &self.pieces[self.first[j]..];
            self.line.push(fit(p, len));
        }
        self.first.push(self.pieces.len());
    }

    /// Input `j`'s pieces.
    fn of(&self, j: usize) -> &[(f64, f64, f64)] {
        &self.pieces[self.first[j]..self.first[j + 1]]
    }

    /// The value input `j` holds at the span's start.
    pub(crate) fn first(&self, j: usize) -> f64 {
        self.of(j)[0].2
    }

    /// The value input `j` holds just before `s` (seconds from the start):
    /// over the interval that ends there.
    pub(crate) fn before(&self, j: usize, s: f64) -> f64 {
        let p = self.of(j);
        p.iter()
            .find(|(a, b, _)| *a < s && s <= *b)
            .map_or(p[p.len() - 1].2, |x| x.2)
    }

    /// Per input, the line's value at the start, the middle and the end of
    /// the span (the RK4 stages' inputs), into `start`, `mid`, `end`.
    pub(crate) fn line(&self, start: &mut [f64], mid: &mut [f64], end: &mut [f64]) {
        let half = 0.5 * self.len;
        for (j, &(mean, slope)) in self.line.iter().enumerate() {
            start[j] = mean - slope * half;
            mid[j] = mean;
            end[j] = mean + slope * half;
        }
    }

    /// `E1(s) = int_0^s (u(r) - line(r)) dr` of input `j` at `s`: `G E1`
    /// is the velocities' miss where `G E2` is the positions'.
    pub(crate) fn inside_rate_error(&self, j: usize, s: f64) -> f64 {
        let (mean, slope) = self.line[j];
        let staircase = self.up_to(j, s, |v, a, b| v * (b - a));
        staircase - (mean * s + slope * (s * s / 2.0 - self.len * s / 2.0))
    }

    /// `E2(s) = int_0^s (s - r) (u(r) - line(r)) dr` of input `j` at `s`
    /// (see the module docs).
    pub(crate) fn inside_error(&self, j: usize, s: f64) -> f64 {
        let (mean, slope) = self.line[j];
        let staircase = self.up_to(j, s, |v, a, b| {
            v * 0.5 * ((s - a).powi(2) - (s - b).powi(2))
        });
        let line = mean * s * s / 2.0 + slope * (s.powi(3) / 6.0 - self.len * s * s / 4.0);
        staircase - line
    }

    /// The sum of `term(value, from, to)` over input `j`'s pieces, cut at
    /// `s`.
    fn up_to(&self, j: usize, s: f64, term: impl Fn(f64, f64, f64) -> f64) -> f64 {
        let mut sum = 0.0;
        for &(a, b, v) in self.of(j) {
            if a >= s {
                break;
            }
            sum += term(v, a, b.min(s));
        }
        sum
    }
}

/// Mean and slope of the line with the pieces' integral and first moment
/// over `[0, len]` (about the middle: `slope = 12 mu1 / L^3`).
fn fit(p: &[(f64, f64, f64)], len: f64) -> (f64, f64) {
    let half = 0.5 * len;
    let (mut integral, mut moment) = (0.0, 0.0);
    for &(a, b, v) in p {
        integral += v * (b - a);
        moment += v * 0.5 * ((b - half).powi(2) - (a - half).powi(2));
    }
    (integral / len, 12.0 * moment / len.powi(3))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `E2` by Simpson's rule on each piece (exact: the integrand is a
    /// quadratic there), against the closed form.
    fn e2_numeric(st: &Staircase, j: usize, s: f64) -> f64 {
        let (mean, slope) = st.line[j];
        let f = |r: f64, v: f64| (s - r) * (v - (mean + slope * (r - 0.5 * st.len)));
        st.of(j)
            .iter()
            .filter(|(a, _, _)| *a < s)
            .map(|&(a, b, v)| {
                let b = b.min(s);
                (b - a) / 6.0 * (f(a, v) + 4.0 * f(0.5 * (a + b), v) + f(b, v))
            })
            .sum()
    }

    #[test]
    fn line_keeps_the_two_moments_and_e2_vanishes_at_the_end() {
        let t: Vec<f64> = (0..12).map(|k| k as f64 * 1e-3).collect();
        let u = vec![vec![
            0.3, 1.0, -0.5, 0.25, 2.0, 1.5, -1.0, 0.0, 0.7, 0.1, 0.2, 0.3,
        ]];
        for delay in [0.0, 4e-4, 2e-3] {
            let held = [if delay == 0.0 {
                2
            } else if delay < 1e-3 {
                1
            } else {
                0
            }];
            let mut st = Staircase::default();
            st.over(&t, &u, (&held, &[delay]), (2, 10), 1e-12);
            let (mut a, mut m, mut e) = ([0.0], [0.0], [0.0]);
            st.line(&mut a, &mut m, &mut e);
            // the integral: (start + end)/2 L
            let integral: f64 = st.of(0).iter().map(|(a, b, v)| v * (b - a)).sum();
            assert!((0.5 * (a[0] + e[0]) * st.len - integral).abs() < 1e-15);
            assert!(
                st.inside_error(0, st.len).abs() < 1e-18,
                "{}",
                st.inside_error(0, st.len)
            );
            assert!(st.inside_rate_error(0, st.len).abs() < 1e-15);
            for k in 1..8 {
                let s = k as f64 * 1e-3;
                let closed = st.inside_error(0, s);
                let numeric = e2_numeric(&st, 0, s);
                assert!(
                    (closed - numeric).abs() < 1e-9 * numeric.abs() + 1e-18,
                    "{closed} {numeric}"
                );
            }
        }
    }

    /// A ramp's staircase over two intervals misses the line by nothing
    /// at the middle sample: `E2(h) = 0` (worked out by hand).
    #[test]
    fn ramp_over_two_intervals() {
        let t = [0.0, 1e-3, 2e-3];
        let u = vec![vec![1.0, 1.5, 2.0]];
        let mut st = Staircase::default();
        st.over(&t, &u, (&[0], &[0.0]), (0, 2), 1e-12);
        assert!(st.inside_error(0, 1e-3).abs() < 1e-20);
        assert_eq!(st.first(0), 1.0);
        assert_eq!(st.before(0, 2e-3), 1.5);
    }
}
