//! Exact stability interval of a feedback-linearizing controller whose gains
//! vary together along a line (`a = b = k`).
//!
//! Method: the closed-loop Jacobian `A_cl(k) = d/dx [f + g u(x; k)]` at `x = 0`
//! is formed through the mechanical structure, never the expanded `M^-1`:
//! its lower half is `M0^-1 (dr0/dx + dB/dx u + B du/dx - dM/dx a0)` with
//! `M0 = M(0)` numeric and `u(0; k)`, `du/dx(0; k)` polynomials in `k`
//! (structural degree bound) whose coefficients are the Taylor coefficients
//! `d^m/dk^m / m!` at `k = 0`, evaluated with the parameter values. The
//! characteristic polynomial `det(sI - A_cl(k))` is computed over the ring of
//! polynomials in `k` (Faddeev-LeVerrier: only divisions by integers), then
//! the Hurwitz conditions (every coefficient and every leading Hurwitz minor
//! positive, minors by cofactor expansion over the same ring) are polynomials
//! in `k`. Their real roots (companion-matrix eigenvalues, polished by Newton
//! and bisection to 1e-12) split the real line; each piece is tested at an
//! interior point, and the stable pieces are the result. Every piece's
//! verdict is cross-checked with the closed-loop eigenvalues.

use std::collections::HashMap;
use std::fmt;

use nalgebra::DMatrix;

use crate::control::{Derivation, ResolvedController};
use crate::linear::poles;
use crate::model::{Model, ParameterValues};
use crate::sym::{diff, substitute_symbols, Expr, Node, Symbol};

/// Why the interval could not be computed.
#[derive(Clone, Debug, PartialEq)]
pub enum StabilityError {
    /// Only feedback-linearizing controllers have symbolic gains.
    NotFeedbackLinearization {
        /// Controller name.
        controller: String,
    },
    /// A gain to vary is not a gain of the controller.
    UnknownGain {
        /// The name given.
        name: String,
        /// The controller's gains.
        known: Vec<String>,
    },
    /// No gain to vary.
    NoGain,
    /// The closed-loop Jacobian is not polynomial in the gain.
    NotPolynomial {
        /// Entry `(i, j)`.
        entry: (usize, usize),
    },
    /// A value is not finite at the origin.
    NotFinite {
        /// What.
        what: String,
    },
    /// The state is too large for the cofactor expansion used here.
    TooLarge {
        /// State dimension.
        n: usize,
    },
}

impl fmt::Display for StabilityError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StabilityError::NotFeedbackLinearization { controller } => write!(
                f,
                "controller `{controller}` has no symbolic gains (only `linearize output` controllers can be swept)"
            ),
            StabilityError::UnknownGain { name, known } => {
                write!(f, "`{name}` is not a gain of the controller (gains: {})", known.join(", "))
            }
            StabilityError::NoGain => write!(f, "no gain to vary"),
            StabilityError::NotPolynomial { entry } => write!(
                f,
                "the closed-loop Jacobian entry {entry:?} is not a polynomial in the varied gain"
            ),
            StabilityError::NotFinite { what } => write!(f, "{what} is not finite at the origin"),
            StabilityError::TooLarge { n } => write!(f, "state dimension {n} is too large (at most 10)"),
        }
    }
}

impl std::error::Error for StabilityError {}

/// A polynomial in `k`, coefficients in ascending order.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct KPoly(pub Vec<f64>);

impl KPoly {
    fn zero() -> KPoly {
        KPoly(vec![0.0])
    }
    fn constant(c: f64) -> KPoly {
        KPoly(vec![c])
    }
    fn add(&self, o: &KPoly) -> KPoly {
        let n = self.0.len().max(o.0.len());
        KPoly(
            (0..n)
                .map(|i| self.0.get(i).unwrap_or(&0.0) + o.0.get(i).unwrap_or(&0.0))
                .collect(),
        )
    }
    fn scale(&self, c: f64) -> KPoly {
        KPoly(self.0.iter().map(|x| x * c).collect())
    }
    fn mul(&self, o: &KPoly) -> KPoly {
        let mut r = vec![0.0; self.0.len() + o.0.len() - 1];
        for (i, a) in self.0.iter().enumerate() {
            for (j, b) in o.0.iter().enumerate() {
                r[i + j] += a * b;
            }
        }
        KPoly(r)
    }
    /// Value at `k` (Horner).
    pub fn eval(&self, k: f64) -> f64 {
        self.0.iter().rev().fold(0.0, |acc, c| acc * k + c)
    }
    fn deriv(&self) -> KPoly {
        if self.0.len() <= 1 {
            return KPoly::zero();
        }
        KPoly(
            self.0
                .iter()
                .enumerate()
                .skip(1)
                .map(|(i, c)| c * i as f64)
                .collect(),
        )
    }
    /// Coefficients with negligible leading terms removed (relative 1e-13).
    fn trimmed(&self) -> Vec<f64> {
        let max = self.0.iter().fold(0.0_f64, |m, c| m.max(c.abs()));
        let mut v = self.0.clone();
        while v.len() > 1 && v.last().is_some_and(|c| c.abs() <= 1e-13 * max) {
            v.pop();
        }
        v
    }
    /// Real roots, refined to about 1e-12.
    pub fn real_roots(&self) -> Vec<f64> {
        let mut c = self.trimmed();
        if c.iter().all(|x| *x == 0.0) {
            return Vec::new();
        }
        // Roots at k = 0 (constant terms that are rounding noise, e.g. det A_cl
        // at a gain where the zero dynamics' eigenvalues sit at 0) are deflated
        // exactly.
        let max = c.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        let mut zero_root = false;
        while c.len() > 1 && c[0].abs() <= 1e-13 * max {
            c.remove(0);
            zero_root = true;
        }
        let deg = c.len() - 1;
        if deg == 0 {
            return if zero_root { vec![0.0] } else { Vec::new() };
        }
        let lead = c[deg];
        let comp = DMatrix::from_fn(deg, deg, |i, j| {
            if i == 0 {
                -c[deg - 1 - j] / lead
            } else if i == j + 1 {
                1.0
            } else {
                0.0
            }
        });
        let Ok(eig) = poles(&comp) else {
            return Vec::new();
        };
        let p = KPoly(c.clone());
        let dp = p.deriv();
        let mut roots: Vec<f64> = Vec::new();
        for z in eig {
            if z.im.abs() > 1e-6 * (1.0 + z.re.abs()) {
                continue;
            }
            let mut x = z.re;
            for _ in 0..50 {
                let d = dp.eval(x);
                if d == 0.0 {
                    break;
                }
                let step = p.eval(x) / d;
                if !step.is_finite() {
                    break;
                }
                x -= step;
                if step.abs() <= 1e-15 * (1.0 + x.abs()) {
                    break;
                }
            }
            // Bisection on a sign change, if there is one nearby.
            let w = 1e-6 * (1.0 + x.abs());
            let (mut lo, mut hi) = (x - w, x + w);
            let (flo, fhi) = (p.eval(lo), p.eval(hi));
            if flo * fhi < 0.0 {
                for _ in 0..200 {
                    let mid = 0.5 * (lo + hi);
                    if hi - lo <= 1e-12 * (1.0 + mid.abs()) * 1e-3 {
                        break;
                    }
                    if p.eval(mid) * flo > 0.0 {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                x = 0.5 * (lo + hi);
            }
            roots.push(x);
        }
        if zero_root {
            roots.push(0.0);
        }
        roots.sort_by(f64::total_cmp);
        roots.dedup_by(|a, b| (*a - *b).abs() <= 1e-12 * (1.0 + a.abs()));
        roots
    }
}

/// The result of a sweep.
#[derive(Clone, Debug)]
pub struct StabilityInterval {
    /// The gains varied together (all equal to `k`).
    pub gains: Vec<String>,
    /// Open intervals of `k` with an asymptotically stable closed-loop
    /// linearization; `None` is an unbounded end.
    pub intervals: Vec<(Option<f64>, Option<f64>)>,
    /// `A_cl(k)` entry polynomials.
    pub a_cl: Vec<Vec<KPoly>>,
    /// Characteristic polynomial `s^n + c_{n-1} s^{n-1} + ... + c_0`:
    /// `c_0 .. c_{n-1}` as polynomials in `k`.
    pub char_poly: Vec<KPoly>,
    /// Routh-Hurwitz conditions (each must be > 0), with names.
    pub conditions: Vec<(String, KPoly)>,
    /// All real roots of the conditions (the candidate interval ends).
    pub boundaries: Vec<f64>,
    /// Pieces where the Hurwitz verdict and the eigenvalues disagreed (should be empty).
    pub disagreements: Vec<f64>,
    /// Description of the method.
    pub method: &'static str,
}

/// Method description printed by the CLI.
pub const METHOD: &str =
    "closed-loop Jacobian at x = 0 as a polynomial matrix in k (symbolic Taylor \
coefficients), characteristic polynomial by Faddeev-LeVerrier over R[k], Routh-Hurwitz conditions \
(coefficients and Hurwitz minors > 0) as polynomials in k, real roots by companion matrix + \
Newton/bisection (1e-12), each piece checked at an interior point and against the eigenvalues";

/// Structural degree of `e` in `k` (an upper bound), `None` if not polynomial.
fn degree_in(e: Expr, k: Symbol, memo: &mut HashMap<Expr, Option<u32>>) -> Option<u32> {
    if !e.contains(k) {
        return Some(0);
    }
    if let Some(d) = memo.get(&e) {
        return *d;
    }
    let d = match e.node() {
        Node::Symbol(_) => Some(1),
        Node::Add(ts) => ts
            .iter()
            .try_fold(0, |m, t| degree_in(*t, k, memo).map(|d| m.max(d))),
        Node::Mul(fs) => fs
            .iter()
            .try_fold(0, |m, f| degree_in(*f, k, memo).map(|d| m + d)),
        Node::Pow(b, x) => {
            match x
                .as_rational()
                .and_then(|r| if r.is_integer() { r.to_i64() } else { None })
            {
                Some(n) if n >= 0 => degree_in(*b, k, memo).map(|d| d * n as u32),
                _ => None,
            }
        }
        _ => None,
    };
    memo.insert(e, d);
    d
}

fn det(m: &[Vec<KPoly>]) -> KPoly {
    let n = m.len();
    if n == 0 {
        return KPoly::constant(1.0);
    }
    if n == 1 {
        return m[0][0].clone();
    }
    let mut acc = KPoly::zero();
    for j in 0..n {
        if m[0][j].0.iter().all(|c| *c == 0.0) {
            continue;
        }
        let minor: Vec<Vec<KPoly>> = m[1..]
            .iter()
            .map(|row| {
                row.iter()
                    .enumerate()
                    .filter(|(c, _)| *c != j)
                    .map(|(_, p)| p.clone())
                    .collect()
            })
            .collect();
        let term = m[0][j].mul(&det(&minor));
        acc = acc.add(&if j % 2 == 0 { term } else { term.scale(-1.0) });
    }
    acc
}

/// `c_0..c_{n-1}` of `det(sI - A) = s^n + c_{n-1} s^{n-1} + ... + c_0`.
fn char_poly(a: &[Vec<KPoly>]) -> Vec<KPoly> {
    let n = a.len();
    let matmul = |x: &[Vec<KPoly>], y: &[Vec<KPoly>]| -> Vec<Vec<KPoly>> {
        (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| (0..n).fold(KPoly::zero(), |s, l| s.add(&x[i][l].mul(&y[l][j]))))
                    .collect()
            })
            .collect()
    };
    // M_0 = 0; M_k = A M_{k-1} + c_{n-k+1} I; c_{n-k} = -tr(A M_k)/k.
    let mut c = vec![KPoly::zero(); n + 1];
    c[n] = KPoly::constant(1.0);
    let mut mk: Vec<Vec<KPoly>> = vec![vec![KPoly::zero(); n]; n];
    for k in 1..=n {
        let mut next = matmul(a, &mk);
        for (i, row) in next.iter_mut().enumerate() {
            row[i] = row[i].add(&c[n - k + 1]);
        }
        mk = next;
        let am = matmul(a, &mk);
        let tr = (0..n).fold(KPoly::zero(), |s, i| s.add(&am[i][i]));
        c[n - k] = tr.scale(-1.0 / k as f64);
    }
    c.truncate(n);
    c
}

fn max_real_eig(a: &[Vec<KPoly>], k: f64) -> f64 {
    let n = a.len();
    let m = DMatrix::from_fn(n, n, |i, j| a[i][j].eval(k));
    poles(&m).map_or(f64::NAN, |p| {
        p.iter().map(|z| z.re).fold(f64::MIN, f64::max)
    })
}

/// The intervals of `k` (with every gain in `vary` equal to `k`, the other
/// gains at their values) for which the closed-loop linearization about the
/// origin is asymptotically stable.
pub fn stability_interval(
    model: &Model,
    derivation: &Derivation,
    controller: &ResolvedController,
    vary: &[&str],
    values: &ParameterValues,
) -> Result<StabilityInterval, StabilityError> {
    let ResolvedController::FeedbackLinearization { law, gains, .. } = controller else {
        return Err(StabilityError::NotFeedbackLinearization {
            controller: controller.name().to_string(),
        });
    };
    if vary.is_empty() {
        return Err(StabilityError::NoGain);
    }
    for v in vary {
        if !gains.iter().any(|(g, _)| g.name() == *v) {
            return Err(StabilityError::UnknownGain {
                name: v.to_string(),
                known: gains.iter().map(|(g, _)| g.name().to_string()).collect(),
            });
        }
    }
    let eqs = &derivation.equations;
    let nq = eqs.coords.len();
    let n = 2 * nq;
    if n > 10 {
        return Err(StabilityError::TooLarge { n });
    }
    let state = model.state_symbols();
    let k = Symbol::new("k\u{2032}sweep");
    let mut gain_map: HashMap<Symbol, Expr> = HashMap::new();
    for (g, val) in gains {
        let e = if vary.contains(&g.name()) {
            Expr::symbol(k)
        } else {
            Expr::float(*val)
        };
        gain_map.insert(*g, e);
    }
    let u = substitute_symbols(*law, &gain_map);
    let zero_state: HashMap<Symbol, Expr> = state.iter().map(|s| (*s, Expr::zero())).collect();
    let mut point = values.symbol_map(model);
    point.insert(k, 0.0);
    for s in &state {
        point.insert(*s, 0.0);
    }
    for s in &eqs.inputs {
        point.insert(*s, 0.0);
    }
    let mut memo = HashMap::new();
    // A polynomial in k from an expression (Taylor coefficients at k = 0).
    let mut kpoly = |e: Expr, what: &dyn Fn() -> String, entry: (usize, usize)| {
        let e = substitute_symbols(e, &zero_state);
        let deg = degree_in(e, k, &mut memo).ok_or(StabilityError::NotPolynomial { entry })?;
        let mut coeffs = Vec::with_capacity(deg as usize + 1);
        let mut dm = e;
        let mut fact = 1.0;
        for m in 0..=deg {
            if m > 0 {
                dm = diff(dm, k);
                fact *= m as f64;
            }
            let v = dm.eval_map(&point) / fact;
            if !v.is_finite() {
                return Err(StabilityError::NotFinite { what: what() });
            }
            coeffs.push(v);
        }
        Ok(KPoly(coeffs))
    };
    let num = |e: Expr, what: &str| -> Result<f64, StabilityError> {
        let v = e.eval_map(&point);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(StabilityError::NotFinite {
                what: what.to_string(),
            })
        }
    };
    // M(0), r0 = Q0 - bias, B (single input) and their derivatives at the origin
    let b: Vec<Expr> = eqs.input_matrix.iter().map(|r| r[0]).collect();
    let r0: Vec<Expr> = (0..nq).map(|i| eqs.forces[i] - eqs.bias[i]).collect();
    let m0 = DMatrix::from_fn(nq, nq, |i, j| eqs.mass_matrix[i][j].eval_map(&point));
    if m0.iter().any(|v| !v.is_finite()) {
        return Err(StabilityError::NotFinite { what: "M".into() });
    }
    let lu = m0.lu();
    let solve = |v: &[KPoly]| -> Result<Vec<KPoly>, StabilityError> {
        // M0^-1 applied to a vector of polynomials, coefficient by coefficient
        let deg = v.iter().map(|p| p.0.len()).max().unwrap_or(0);
        let mut out = vec![KPoly(vec![0.0; deg]); v.len()];
        for d in 0..deg {
            let col =
                nalgebra::DVector::from_fn(v.len(), |i, _| v[i].0.get(d).copied().unwrap_or(0.0));
            let x = lu.solve(&col).ok_or(StabilityError::NotFinite {
                what: "M^-1 (singular mass matrix)".into(),
            })?;
            for i in 0..v.len() {
                out[i].0[d] = x[i];
            }
        }
        Ok(out)
    };
    let u0 = kpoly(u, &|| "the law".into(), (0, 0))?;
    // accelerations at the origin: a0 = M0^-1 (r(0) with u = u0(k))
    let acc_rhs: Vec<KPoly> = (0..nq)
        .map(|i| {
            let r = num(substitute_symbols(r0[i], &zero_state), "Q0 - bias")?;
            let bi = num(substitute_symbols(b[i], &zero_state), "B")?;
            Ok(KPoly::constant(r).add(&u0.scale(bi)))
        })
        .collect::<Result<_, StabilityError>>()?;
    let a0 = solve(&acc_rhs)?;
    let mut a_cl = vec![vec![KPoly::zero(); n]; n];
    for i in 0..nq {
        a_cl[i][nq + i] = KPoly::constant(1.0);
    }
    for (j, xj) in state.iter().enumerate() {
        let du = kpoly(
            diff(u, *xj),
            &|| format!("d law / d {}", xj.name()),
            (nq, j),
        )?;
        let mut col = Vec::with_capacity(nq);
        for i in 0..nq {
            let z = |e: Expr| substitute_symbols(diff(e, *xj), &zero_state);
            let mut c = KPoly::constant(num(z(r0[i]), "d(Q0 - bias)/dx")?)
                .add(&u0.scale(num(z(b[i]), "dB/dx")?))
                .add(&du.scale(num(substitute_symbols(b[i], &zero_state), "B")?));
            for (jj, a0j) in a0.iter().enumerate() {
                let dm = z(eqs.mass_matrix[i][jj]);
                if !dm.is_zero() {
                    c = c.add(&a0j.scale(-num(dm, "dM/dx")?));
                }
            }
            col.push(c);
        }
        for (i, v) in solve(&col)?.into_iter().enumerate() {
            a_cl[nq + i][j] = v;
        }
    }
    let cp = char_poly(&a_cl);
    // Hurwitz matrix of a_0 s^n + a_1 s^{n-1} + ... + a_n, a_0 = 1, a_i = c_{n-i}.
    let coef = |i: i64| -> KPoly {
        if i == 0 {
            KPoly::constant(1.0)
        } else if i < 0 || i > n as i64 {
            KPoly::zero()
        } else {
            cp[n - i as usize].clone()
        }
    };
    let mut conditions: Vec<(String, KPoly)> =
        (1..=n).map(|i| (format!("a{i}"), coef(i as i64))).collect();
    for size in 2..n {
        let h: Vec<Vec<KPoly>> = (1..=size)
            .map(|r| (1..=size).map(|c| coef(2 * c as i64 - r as i64)).collect())
            .collect();
        conditions.push((format!("Hurwitz minor {size}"), det(&h)));
    }
    let mut boundaries: Vec<f64> = conditions
        .iter()
        .flat_map(|(_, p)| p.real_roots())
        .collect();
    boundaries.sort_by(f64::total_cmp);
    boundaries.dedup_by(|a, b| (*a - *b).abs() <= 1e-12 * (1.0 + a.abs()));
    let holds = |x: f64| conditions.iter().all(|(_, p)| p.eval(x) > 0.0);
    // Pieces: (-inf, b0), (b0, b1), ..., (b_last, inf).
    let mut pieces: Vec<(Option<f64>, Option<f64>, f64)> = Vec::new();
    if boundaries.is_empty() {
        pieces.push((None, None, 0.0));
    } else {
        let b0 = boundaries[0];
        pieces.push((None, Some(b0), b0 - b0.abs().max(1.0)));
        for w in boundaries.windows(2) {
            pieces.push((Some(w[0]), Some(w[1]), 0.5 * (w[0] + w[1])));
        }
        let bl = *boundaries.last().unwrap_or(&0.0);
        pieces.push((Some(bl), None, bl + bl.abs().max(1.0)));
    }
    let mut intervals: Vec<(Option<f64>, Option<f64>)> = Vec::new();
    let mut disagreements = Vec::new();
    for (lo, hi, x) in pieces {
        let stable = holds(x);
        let eig = max_real_eig(&a_cl, x);
        if eig.is_finite() && (eig < 0.0) != stable && eig.abs() > 1e-9 {
            disagreements.push(x);
        }
        if !stable {
            continue;
        }
        // Merge across a boundary where nothing actually changes (a spurious
        // root of a redundant condition) only if the boundary itself is stable.
        if let (Some(last), Some(l)) = (intervals.last_mut(), lo) {
            if last.1 == Some(l) && holds(l) {
                last.1 = hi;
                continue;
            }
        }
        intervals.push((lo, hi));
    }
    Ok(StabilityInterval {
        gains: vary.iter().map(|s| s.to_string()).collect(),
        intervals,
        a_cl,
        char_poly: cp,
        conditions,
        boundaries,
        disagreements,
        method: METHOD,
    })
}
