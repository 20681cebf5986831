//! A value-numbered straight-line graph between symbolic expressions and the
//! emitted Rust.
//!
//! Every value is created through [`Graph`], which
//!
//! * **numbers values globally**: an operation on the same operands is created
//!   once, across all outputs of all functions built in one graph (operands of
//!   `+` and `*` are ordered, so `a*b` and `b*a` are one value);
//! * **folds constants and structural zeros**: `0*x = 0`, `x + 0 = x`,
//!   `1*x = x`, `-(-x) = x`, `a + (-b) = a - b`; a product or sum of
//!   constants is one literal (so a zero entry of `M` or of a right-hand side
//!   costs nothing);
//! * **tracks how often a value changes** ([`Level`]): constants, values that
//!   depend only on parameters (and controller gains), and values that change
//!   on every call. Products and sums are regrouped so that their
//!   parameter-only part is one value, which the emitter computes once per
//!   parameter change (a coefficient) instead of once per call.
//!
//! Lowering an [`Expr`] ([`Graph::expr`]) turns integer powers into
//! multiplication chains, negative powers into one division per product,
//! `x^(1/2)` into `sqrt`; `sin` and `cos` of one argument are fused into one
//! `sin_cos` when the function is emitted. [`Graph::solve_sym`] solves
//! `M y = b` for a symmetric `M` in closed form (Cramer, one division) for up
//! to three coordinates and by an unrolled LDL^T factorisation beyond.

use std::collections::{HashMap, HashSet};

use proc_macro2::{Ident, TokenStream};
use quote::{format_ident, quote};

use plantc_derive::sym::{Expr, Func, Node, Rational, Symbol};

use crate::lower::lit;
use crate::Error;

/// A value of the graph.
pub(crate) type V = u32;

/// The per-call numerator and denominator of a product (the key terms are
/// collected by).
type PerCall = (Option<V>, Option<V>);

/// How often a value changes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(crate) enum Level {
    /// A literal.
    Const,
    /// Depends on parameters (and gains) only: computed once per parameter change.
    Param,
    /// Depends on the state, the input or the step: computed on every call.
    Call,
    /// Depends on a direction of differentiation (the seeds of a tangent,
    /// [`Graph::tangent`]): computed once per direction, inside the loop of
    /// a Jacobian ([`Function::inner`]).
    Dir,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Op {
    Const(u64),
    Input(u32),
    Add(V, V),
    Sub(V, V),
    Mul(V, V),
    Div(V, V),
    Neg(V),
    Sqrt(V),
    Powf(V, V),
    Atan2(V, V),
    Sin(V),
    Cos(V),
    /// `sin d` of a Runge-Kutta stage increment (`math::sin_cos_step`).
    SinStep(V),
    /// `cos d` of a Runge-Kutta stage increment.
    CosStep(V),
    Func(Func, V),
}

/// Symbol bindings and the memo of lowered expressions for one evaluation
/// context (e.g. one Runge-Kutta stage).
#[derive(Default)]
pub(crate) struct Env {
    map: HashMap<Symbol, V>,
    memo: HashMap<Expr, V>,
}

impl Env {
    /// Bind a symbol to a value.
    pub fn bind(&mut self, s: Symbol, v: V) {
        self.map.insert(s, v);
    }

    /// Use `v` for the expression `e` (instead of lowering it).
    pub fn preset(&mut self, e: Expr, v: V) {
        self.memo.insert(e, v);
    }
}

/// The value-numbered graph. Inputs carry the Rust place expression they read.
pub(crate) struct Graph {
    ops: Vec<Op>,
    level: Vec<Level>,
    index: HashMap<Op, V>,
    inputs: Vec<(TokenStream, Level)>,
}

/// Which parameter-only values are stored as coefficients, and how to compute them.
pub(crate) struct CoeffPlan {
    slot: HashMap<V, usize>,
    /// Statements computing the coefficients (locals `c{i}`).
    pub stmts: Vec<TokenStream>,
    /// One expression per coefficient slot, in slot order.
    pub values: Vec<TokenStream>,
}

impl CoeffPlan {
    /// Number of coefficients.
    pub fn len(&self) -> usize {
        self.values.len()
    }
}

/// Products fused into the sums that use them.
#[derive(Default)]
struct Fused {
    /// sum or difference -> the product fused into it
    into: HashMap<V, V>,
    /// the fused products (not emitted on their own)
    skipped: HashSet<V>,
}

/// Statements of one emitted function and one expression per output.
pub(crate) struct Function {
    pub stmts: Vec<TokenStream>,
    /// Statements of the values that depend on a direction
    /// ([`Level::Dir`]), after `stmts`: the body of a Jacobian's loop.
    pub inner: Vec<TokenStream>,
    pub outputs: Vec<TokenStream>,
}

impl Graph {
    pub fn new() -> Graph {
        Graph {
            ops: Vec::new(),
            level: Vec::new(),
            index: HashMap::new(),
            inputs: Vec::new(),
        }
    }

    fn op(&mut self, op: Op) -> V {
        if let Some(&v) = self.index.get(&op) {
            return v;
        }
        let level = match op {
            Op::Const(_) => Level::Const,
            Op::Input(i) => self.inputs[i as usize].1,
            Op::Add(a, b)
            | Op::Sub(a, b)
            | Op::Mul(a, b)
            | Op::Div(a, b)
            | Op::Powf(a, b)
            | Op::Atan2(a, b) => self.lv(a).max(self.lv(b)),
            Op::Neg(a)
            | Op::Sqrt(a)
            | Op::Sin(a)
            | Op::Cos(a)
            | Op::SinStep(a)
            | Op::CosStep(a)
            | Op::Func(_, a) => self.lv(a),
        };
        let v = self.ops.len() as V;
        self.ops.push(op);
        self.level.push(level);
        self.index.insert(op, v);
        v
    }

    /// The level of a value.
    pub fn lv(&self, v: V) -> Level {
        self.level[v as usize]
    }

    fn as_const(&self, v: V) -> Option<f64> {
        match self.ops[v as usize] {
            Op::Const(b) => Some(f64::from_bits(b)),
            _ => None,
        }
    }

    /// An input read from `place` (e.g. `x[1]`, `p.m1`) at `level`.
    pub fn input(&mut self, place: TokenStream, level: Level) -> V {
        let i = self.inputs.len() as u32;
        self.inputs.push((place, level));
        self.op(Op::Input(i))
    }

    /// A literal.
    pub fn konst(&mut self, x: f64) -> V {
        // one zero (no -0.0 literal)
        let x = if x == 0.0 { 0.0 } else { x };
        self.op(Op::Const(x.to_bits()))
    }

    fn is(&self, v: V, x: f64) -> bool {
        self.as_const(v) == Some(x)
    }

    pub fn add(&mut self, a: V, b: V) -> V {
        if let (Some(x), Some(y)) = (self.as_const(a), self.as_const(b)) {
            return self.konst(x + y);
        }
        if self.is(a, 0.0) {
            return b;
        }
        if self.is(b, 0.0) {
            return a;
        }
        if let Op::Neg(b1) = self.ops[b as usize] {
            return self.sub(a, b1);
        }
        if let Op::Neg(a1) = self.ops[a as usize] {
            return self.sub(b, a1);
        }
        let (a, b) = if a <= b { (a, b) } else { (b, a) };
        self.op(Op::Add(a, b))
    }

    pub fn sub(&mut self, a: V, b: V) -> V {
        if let (Some(x), Some(y)) = (self.as_const(a), self.as_const(b)) {
            return self.konst(x - y);
        }
        if self.is(b, 0.0) {
            return a;
        }
        if self.is(a, 0.0) {
            return self.neg(b);
        }
        if a == b {
            // exact for finite values (a structural cancellation)
            return self.konst(0.0);
        }
        if let Op::Neg(b1) = self.ops[b as usize] {
            return self.add(a, b1);
        }
        self.op(Op::Sub(a, b))
    }

    pub fn neg(&mut self, a: V) -> V {
        if let Some(x) = self.as_const(a) {
            return self.konst(-x);
        }
        match self.ops[a as usize] {
            Op::Neg(a1) => a1,
            Op::Sub(x, y) => self.sub(y, x),
            _ => self.op(Op::Neg(a)),
        }
    }

    pub fn mul(&mut self, a: V, b: V) -> V {
        if let (Some(x), Some(y)) = (self.as_const(a), self.as_const(b)) {
            return self.konst(x * y);
        }
        if self.is(a, 0.0) || self.is(b, 0.0) {
            return self.konst(0.0);
        }
        if self.is(a, 1.0) {
            return b;
        }
        if self.is(b, 1.0) {
            return a;
        }
        if self.is(a, -1.0) {
            return self.neg(b);
        }
        if self.is(b, -1.0) {
            return self.neg(a);
        }
        if let Op::Neg(a1) = self.ops[a as usize] {
            let m = self.mul(a1, b);
            return self.neg(m);
        }
        if let Op::Neg(b1) = self.ops[b as usize] {
            let m = self.mul(a, b1);
            return self.neg(m);
        }
        let (a, b) = if a <= b { (a, b) } else { (b, a) };
        self.op(Op::Mul(a, b))
    }

    pub fn div(&mut self, a: V, b: V) -> V {
        if let (Some(x), Some(y)) = (self.as_const(a), self.as_const(b)) {
            return self.konst(x / y);
        }
        if self.is(a, 0.0) {
            return self.konst(0.0);
        }
        if self.is(b, 1.0) {
            return a;
        }
        if self.is(b, -1.0) {
            return self.neg(a);
        }
        if let Op::Neg(a1) = self.ops[a as usize] {
            let d = self.div(a1, b);
            return self.neg(d);
        }
        self.op(Op::Div(a, b))
    }

    fn unary(&mut self, f: Func, a: V) -> V {
        if let Some(x) = self.as_const(a) {
            return self.konst(f.eval(x));
        }
        match f {
            Func::Sin => self.op(Op::Sin(a)),
            Func::Cos => self.op(Op::Cos(a)),
            _ => self.op(Op::Func(f, a)),
        }
    }

    fn sqrt(&mut self, a: V) -> V {
        if let Some(x) = self.as_const(a) {
            return self.konst(x.sqrt());
        }
        self.op(Op::Sqrt(a))
    }

    /// `a^n`, `n >= 1`, by squaring.
    fn pow_int(&mut self, a: V, n: u64) -> V {
        if n == 1 {
            a
        } else if n.is_multiple_of(2) {
            let h = self.pow_int(a, n / 2);
            self.mul(h, h)
        } else {
            let h = self.pow_int(a, n - 1);
            self.mul(h, a)
        }
    }

    /// Whether `sin(a)` or `cos(a)` has been created.
    pub fn has_trig(&self, a: V) -> bool {
        self.index.contains_key(&Op::Sin(a)) || self.index.contains_key(&Op::Cos(a))
    }

    /// `(sin(a + d), cos(a + d))` by the addition formulas from `sin a`,
    /// `cos a` and `sin_cos_step(d)` (a polynomial for a small stage
    /// increment `d`, so a Runge-Kutta stage needs no full `sin_cos`).
    pub fn sin_cos_shifted(&mut self, a: V, d: V) -> (V, V) {
        let (sa, ca) = (self.op(Op::Sin(a)), self.op(Op::Cos(a)));
        if self.is(d, 0.0) {
            return (sa, ca);
        }
        let (sd, cd) = (self.op(Op::SinStep(d)), self.op(Op::CosStep(d)));
        let (t1, t2) = (self.mul(sa, cd), self.mul(ca, sd));
        let s = self.add(t1, t2);
        let (t3, t4) = (self.mul(ca, cd), self.mul(sa, sd));
        let c = self.sub(t3, t4);
        (s, c)
    }

    /// Product of `vs`, sorted by value number (so equal factor sets share prefixes).
    fn product_of(&mut self, mut vs: Vec<V>, start: Option<V>) -> Option<V> {
        vs.sort_unstable();
        let mut acc = start;
        for v in vs {
            acc = Some(match acc {
                None => v,
                Some(a) => self.mul(a, v),
            });
        }
        acc
    }

    /// Lower an expression in `env`.
    pub fn expr(&mut self, env: &mut Env, e: Expr) -> Result<V, Error> {
        if let Some(&v) = env.memo.get(&e) {
            return Ok(v);
        }
        let v = match e.node() {
            Node::Rational(r) => self.konst(r.to_f64()),
            Node::Float(b) => self.konst(b.value()),
            Node::Symbol(s) => *env.map.get(s).ok_or_else(|| {
                Error::Generate(format!(
                    "symbol `{s}` has no value in the generated function"
                ))
            })?,
            Node::Add(terms) => self.sum(env, terms)?,
            Node::Mul(_) | Node::Pow(..) => {
                let (c, rest) = e.coeff_and_rest();
                self.product(env, c, rest)?
            }
            Node::Func(f @ (Func::Sin | Func::Cos), a) => match self.trig_by_addition(env, *a)? {
                Some((s, c)) => {
                    if *f == Func::Sin {
                        s
                    } else {
                        c
                    }
                }
                None => {
                    let a = self.expr(env, *a)?;
                    self.unary(*f, a)
                }
            },
            Node::Func(f, a) => {
                let a = self.expr(env, *a)?;
                self.unary(*f, a)
            }
            Node::Named(_, d) => self.expr(env, *d)?,
            Node::Atan2(y, x) => {
                let (y, x) = (self.expr(env, *y)?, self.expr(env, *x)?);
                match (self.as_const(y), self.as_const(x)) {
                    (Some(a), Some(b)) => self.konst(a.atan2(b)),
                    _ => self.op(Op::Atan2(y, x)),
                }
            }
        };
        env.memo.insert(e, v);
        Ok(v)
    }

    /// `(sin a, cos a)` of an angle that is an integer combination of at
    /// least two units of simpler angles (`q1 + q2`, `theta3 - theta1`,
    /// `2*alpha`), by the addition formulas from the sines and cosines of its
    /// parts (6 flops instead of a `sin_cos` per distinct angle). `None` for
    /// a single angle or non-integer coefficients.
    fn trig_by_addition(&mut self, env: &mut Env, a: Expr) -> Result<Option<(V, V)>, Error> {
        let terms: Vec<Expr> = match a.node() {
            Node::Add(ts) => ts.to_vec(),
            _ => vec![a],
        };
        let mut units = 0i128;
        for t in &terms {
            let (c, rest) = t.coeff_and_rest();
            if !c.is_integer() || c.numer().abs() > 4 || rest.is_constant() {
                return Ok(None);
            }
            units += c.numer().abs();
        }
        if units < 2 {
            return Ok(None);
        }
        let (c0, r0) = terms[0].coeff_and_rest();
        let sign = if c0.is_negative() { -1 } else { 1 };
        let rest = a - Expr::int(sign) * r0;
        let (s0, c0v) = (self.expr(env, r0.sin())?, self.expr(env, r0.cos())?);
        let s0 = if sign < 0 { self.neg(s0) } else { s0 };
        let (sr, cr) = (self.expr(env, rest.sin())?, self.expr(env, rest.cos())?);
        let (t1, t2) = (self.mul(s0, cr), self.mul(c0v, sr));
        let s = self.add(t1, t2);
        let (t3, t4) = (self.mul(c0v, cr), self.mul(s0, sr));
        let c = self.sub(t3, t4);
        Ok(Some((s, c)))
    }

    /// Flatten nested sums `c * (a + b + ...)` into `(coefficient, term)`
    /// pairs (exact rational coefficients; a product whose coefficient
    /// overflows stays unexpanded).
    fn flatten_sum(terms: &[Expr], coef: Rational, out: &mut Vec<(Rational, Expr)>) {
        for t in terms {
            let (c, rest) = t.coeff_and_rest();
            let c2 = coef.checked_mul(c);
            match (rest.node(), c2) {
                (Node::Add(inner), Some(c2)) => Self::flatten_sum(inner, c2, out),
                (_, Some(c2)) => out.push((c2, rest)),
                (_, None) => out.push((coef, *t)),
            }
        }
    }

    /// `sum(terms)`: nested sums are flattened, terms with the same per-call
    /// part are collected (`x*b1 + x*c = x*(b1 + c)`, with the parameter sum
    /// one coefficient; exactly cancelling terms vanish), constant and
    /// parameter-only terms come first, negative coefficients become
    /// subtractions.
    fn sum(&mut self, env: &mut Env, terms: &[Expr]) -> Result<V, Error> {
        let mut flat = Vec::with_capacity(terms.len());
        Self::flatten_sum(terms, Rational::ONE, &mut flat);
        // group by per-call part, in order of first appearance
        let mut groups: Vec<(PerCall, Option<(V, bool)>)> = Vec::new();
        let mut at: HashMap<PerCall, usize> = HashMap::new();
        for (c, rest) in flat {
            let (p, n, d) = self.product_parts(env, c.abs(), rest)?;
            let key = (n, d);
            let gi = *at.entry(key).or_insert_with(|| {
                groups.push((key, None));
                groups.len() - 1
            });
            let acc = groups[gi].1;
            groups[gi].1 = Some(self.accumulate(acc, p, c.is_negative()));
        }
        let mut lowered = Vec::with_capacity(groups.len());
        for ((n, d), acc) in groups {
            let Some((p, neg)) = acc else { continue };
            if self.is(p, 0.0) {
                continue;
            }
            lowered.push((self.combine(p, n, d), neg));
        }
        // parameter-level terms summed in order (one coefficient), per-call
        // terms as a balanced tree (short dependency chains)
        let (params, mut calls): (Vec<_>, Vec<_>) = lowered
            .into_iter()
            .partition(|(v, _)| self.lv(*v) < Level::Call);
        let mut acc: Option<(V, bool)> = None;
        for (v, neg) in params {
            acc = Some(self.accumulate(acc, v, neg));
        }
        while calls.len() > 1 {
            let mut next = Vec::with_capacity(calls.len().div_ceil(2));
            for pair in calls.chunks(2) {
                next.push(match pair {
                    [(a, na), (b, nb)] => self.accumulate(Some((*a, *na)), *b, *nb),
                    [one] => *one,
                    _ => unreachable!(),
                });
            }
            calls = next;
        }
        if let Some((v, neg)) = calls.pop() {
            acc = Some(self.accumulate(acc, v, neg));
        }
        Ok(match acc {
            None => self.konst(0.0),
            Some((v, false)) => v,
            Some((v, true)) => self.neg(v),
        })
    }

    /// `acc + v` or `acc - v`, keeping a pending overall sign so that sums
    /// of negative terms need no negation until the end.
    fn accumulate(&mut self, acc: Option<(V, bool)>, v: V, neg: bool) -> (V, bool) {
        match acc {
            None => (v, neg),
            Some((a, false)) => (if neg { self.sub(a, v) } else { self.add(a, v) }, false),
            Some((a, true)) => {
                if neg {
                    (self.add(a, v), true)
                } else {
                    (self.sub(v, a), false)
                }
            }
        }
    }

    /// `p * n / d` (each part optional but `p`).
    fn combine(&mut self, p: V, n: Option<V>, d: Option<V>) -> V {
        match (n, d) {
            (None, None) => p,
            (Some(n), None) => self.mul(p, n),
            (None, Some(d)) => self.div(p, d),
            (Some(n), Some(d)) => {
                let pn = self.mul(p, n);
                self.div(pn, d)
            }
        }
    }

    /// `c * rest` with `rest` a product of powers: parameter-only factors
    /// (with `c`) become one value, the per-call numerator and denominator
    /// one product each, so a product costs at most one division.
    fn product(&mut self, env: &mut Env, c: Rational, rest: Expr) -> Result<V, Error> {
        let (p, n, d) = self.product_parts(env, c, rest)?;
        Ok(self.combine(p, n, d))
    }

    /// The parts of [`Graph::product`]: parameter-level factor, per-call
    /// numerator, per-call denominator.
    fn product_parts(
        &mut self,
        env: &mut Env,
        c: Rational,
        rest: Expr,
    ) -> Result<(V, Option<V>, Option<V>), Error> {
        let mut factors: Vec<Expr> = match rest.node() {
            Node::Mul(fs) => fs.to_vec(),
            _ if rest.is_one() => Vec::new(),
            _ => vec![rest],
        };
        cancel_into_sums(&mut factors);
        let (mut pn, mut pd, mut vn, mut vd) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let half = Rational::new(1, 2).expect("1/2");
        for f in factors {
            let (b, x) = f.base_and_exp();
            let (v, den) = match x.as_rational() {
                Some(r) if r.is_integer() && r.numer() != 0 && r.numer().abs() <= 64 => {
                    let base = self.expr(env, b)?;
                    (
                        self.pow_int(base, r.numer().unsigned_abs() as u64),
                        r.is_negative(),
                    )
                }
                Some(r) if r.abs() == half => {
                    let base = self.expr(env, b)?;
                    (self.sqrt(base), r.is_negative())
                }
                _ if x.is_one() => (self.expr(env, b)?, false),
                _ => {
                    let (base, ex) = (self.expr(env, b)?, self.expr(env, x)?);
                    let v = match (self.as_const(base), self.as_const(ex)) {
                        (Some(a), Some(e)) => self.konst(a.powf(e)),
                        _ => self.op(Op::Powf(base, ex)),
                    };
                    (v, false)
                }
            };
            let call = self.lv(v) >= Level::Call;
            match (call, den) {
                (false, false) => pn.push(v),
                (false, true) => pd.push(v),
                (true, false) => vn.push(v),
                (true, true) => vd.push(v),
            }
        }
        let k = self.konst(c.to_f64());
        let mut p = self.product_of(pn, Some(k)).expect("starts with c");
        if let Some(d) = self.product_of(pd, None) {
            p = self.div(p, d);
        }
        let n = self.product_of(vn, None);
        let d = self.product_of(vd, None);
        Ok((p, n, d))
    }

    /// Solve `M y = b` for each right-hand side in `rhs` (symmetric `M`, all
    /// entries given). Closed form (adjugate / determinant, one division
    /// shared by all right-hand sides) for `n <= 3`, unrolled LDL^T beyond.
    pub fn solve_sym(&mut self, m: &[Vec<V>], rhs: &[Vec<V>]) -> Vec<Vec<V>> {
        let n = m.len();
        if n <= 3 {
            let adj = self.adjugate_sym(m);
            let det = match n {
                0 => self.konst(1.0),
                _ => {
                    let mut d = self.konst(0.0);
                    for j in 0..n {
                        let t = self.mul(m[0][j], adj[j][0]);
                        d = self.add(d, t);
                    }
                    d
                }
            };
            let one = self.konst(1.0);
            let inv = self.div(one, det);
            rhs.iter()
                .map(|b| {
                    (0..n)
                        .map(|i| {
                            let mut acc = self.konst(0.0);
                            for j in 0..n {
                                let t = self.mul(adj[i][j], b[j]);
                                acc = self.add(acc, t);
                            }
                            self.mul(acc, inv)
                        })
                        .collect()
                })
                .collect()
        } else {
            self.ldl_solve(m, rhs)
        }
    }

    /// Adjugate of a symmetric matrix of size 1 to 3.
    fn adjugate_sym(&mut self, m: &[Vec<V>]) -> Vec<Vec<V>> {
        let n = m.len();
        match n {
            0 => Vec::new(),
            1 => vec![vec![self.konst(1.0)]],
            2 => {
                let off = self.neg(m[0][1]);
                vec![vec![m[1][1], off], vec![off, m[0][0]]]
            }
            _ => {
                let cof = |s: &mut Graph,
                           a: (usize, usize),
                           b: (usize, usize),
                           c: (usize, usize),
                           d: (usize, usize)| {
                    let x = s.mul(m[a.0][a.1], m[b.0][b.1]);
                    let y = s.mul(m[c.0][c.1], m[d.0][d.1]);
                    s.sub(x, y)
                };
                let a00 = cof(self, (1, 1), (2, 2), (1, 2), (1, 2));
                let a01 = cof(self, (0, 2), (1, 2), (0, 1), (2, 2));
                let a02 = cof(self, (0, 1), (1, 2), (1, 1), (0, 2));
                let a11 = cof(self, (0, 0), (2, 2), (0, 2), (0, 2));
                let a12 = cof(self, (0, 1), (0, 2), (0, 0), (1, 2));
                let a22 = cof(self, (0, 0), (1, 1), (0, 1), (0, 1));
                vec![
                    vec![a00, a01, a02],
                    vec![a01, a11, a12],
                    vec![a02, a12, a22],
                ]
            }
        }
    }

    /// Unrolled LDL^T solve (no square roots, one division per pivot).
    fn ldl_solve(&mut self, m: &[Vec<V>], rhs: &[Vec<V>]) -> Vec<Vec<V>> {
        let n = m.len();
        let zero = self.konst(0.0);
        let one = self.konst(1.0);
        let mut l = vec![vec![zero; n]; n];
        let mut e = vec![vec![zero; n]; n]; // e_jk = L_jk d_k
        let mut dinv = vec![zero; n];
        for j in 0..n {
            let mut dj = m[j][j];
            for k in 0..j {
                let t = self.mul(l[j][k], e[j][k]);
                dj = self.sub(dj, t);
            }
            dinv[j] = self.div(one, dj);
            for i in j + 1..n {
                let mut v = m[i][j];
                for k in 0..j {
                    let t = self.mul(l[i][k], e[j][k]);
                    v = self.sub(v, t);
                }
                e[i][j] = v;
                l[i][j] = self.mul(v, dinv[j]);
            }
        }
        rhs.iter()
            .map(|b| {
                let mut z = vec![zero; n];
                for i in 0..n {
                    let mut v = b[i];
                    for k in 0..i {
                        let t = self.mul(l[i][k], z[k]);
                        v = self.sub(v, t);
                    }
                    z[i] = v;
                }
                let mut y = vec![zero; n];
                for i in (0..n).rev() {
                    let mut v = self.mul(z[i], dinv[i]);
                    for k in i + 1..n {
                        let t = self.mul(l[k][i], y[k]);
                        v = self.sub(v, t);
                    }
                    y[i] = v;
                }
                y
            })
            .collect()
    }

    /// The directional derivatives of `roots` (forward mode over the graph):
    /// `seeds` gives the derivative of some per-call values (inputs), every
    /// other value's follows by the chain rule; parameter-level values and
    /// constants have derivative 0. With seeds read from a direction
    /// ([`Level::Dir`] inputs), the derivatives are the body of a
    /// Jacobian's loop over directions.
    pub fn tangent(&mut self, roots: &[V], seeds: &HashMap<V, V>) -> Result<Vec<V>, Error> {
        let mut order: Vec<V> = self
            .reach(roots, true)
            .into_iter()
            .filter(|v| self.lv(*v) >= Level::Call)
            .collect();
        order.sort_unstable();
        let zero = self.konst(0.0);
        let mut d: HashMap<V, V> = seeds.clone();
        for v in order {
            if d.contains_key(&v) {
                continue;
            }
            let get = |d: &HashMap<V, V>, x: V| d.get(&x).copied().unwrap_or(zero);
            let dv = match self.ops[v as usize] {
                Op::Const(_) | Op::Input(_) => zero,
                Op::Add(a, b) => {
                    let (da, db) = (get(&d, a), get(&d, b));
                    self.add(da, db)
                }
                Op::Sub(a, b) => {
                    let (da, db) = (get(&d, a), get(&d, b));
                    self.sub(da, db)
                }
                Op::Neg(a) => {
                    let da = get(&d, a);
                    self.neg(da)
                }
                Op::Mul(a, b) => {
                    let (da, db) = (get(&d, a), get(&d, b));
                    let (x, y) = (self.mul(da, b), self.mul(a, db));
                    self.add(x, y)
                }
                Op::Div(a, b) => {
                    // (da - v db) / b
                    let (da, db) = (get(&d, a), get(&d, b));
                    let t = self.mul(v, db);
                    let n = self.sub(da, t);
                    self.div(n, b)
                }
                Op::Sqrt(a) => {
                    let da = get(&d, a);
                    let two = self.konst(2.0);
                    let den = self.mul(two, v);
                    self.div(da, den)
                }
                Op::Sin(a) => {
                    let da = get(&d, a);
                    let c = self.op(Op::Cos(a));
                    self.mul(c, da)
                }
                Op::Cos(a) => {
                    let da = get(&d, a);
                    let s = self.op(Op::Sin(a));
                    let t = self.mul(s, da);
                    self.neg(t)
                }
                Op::Atan2(y, x) => {
                    // (x dy - y dx) / (x^2 + y^2)
                    let (dy, dx) = (get(&d, y), get(&d, x));
                    let (p, q) = (self.mul(x, dy), self.mul(y, dx));
                    let num = self.sub(p, q);
                    let (xx, yy) = (self.mul(x, x), self.mul(y, y));
                    let den = self.add(xx, yy);
                    self.div(num, den)
                }
                Op::Powf(a, b) => {
                    // v (db ln a + b da / a)
                    let (da, db) = (get(&d, a), get(&d, b));
                    let ln = self.unary(Func::Ln, a);
                    let t1 = self.mul(db, ln);
                    let t2 = self.mul(b, da);
                    let t2 = self.div(t2, a);
                    let s = self.add(t1, t2);
                    self.mul(v, s)
                }
                Op::Func(f, a) => {
                    let da = get(&d, a);
                    let slope = match f {
                        Func::Sin => self.op(Op::Cos(a)),
                        Func::Cos => {
                            let s = self.op(Op::Sin(a));
                            self.neg(s)
                        }
                        Func::Tan | Func::Tanh => {
                            let vv = self.mul(v, v);
                            let one = self.konst(1.0);
                            if f == Func::Tan {
                                self.add(one, vv)
                            } else {
                                self.sub(one, vv)
                            }
                        }
                        Func::Exp => v,
                        Func::Ln => {
                            let one = self.konst(1.0);
                            self.div(one, a)
                        }
                        Func::Abs => self.unary(Func::Sign, a),
                        Func::Sign => zero,
                    };
                    self.mul(slope, da)
                }
                Op::SinStep(_) | Op::CosStep(_) => {
                    return Err(Error::Generate(
                        "internal: a tangent through a Runge-Kutta stage increment".into(),
                    ))
                }
            };
            d.insert(v, dv);
        }
        Ok(roots
            .iter()
            .map(|r| d.get(r).copied().unwrap_or(zero))
            .collect())
    }

    /// Values reachable from `roots` (including them).
    fn reach(&self, roots: &[V], stop_at_param: bool) -> HashSet<V> {
        let mut seen = HashSet::new();
        let mut stack: Vec<V> = roots.to_vec();
        while let Some(v) = stack.pop() {
            if !seen.insert(v) {
                continue;
            }
            if stop_at_param && self.lv(v) < Level::Call {
                continue;
            }
            stack.extend(self.operands(v));
        }
        seen
    }

    fn operands(&self, v: V) -> Vec<V> {
        match self.ops[v as usize] {
            Op::Const(_) | Op::Input(_) => Vec::new(),
            Op::Add(a, b)
            | Op::Sub(a, b)
            | Op::Mul(a, b)
            | Op::Div(a, b)
            | Op::Powf(a, b)
            | Op::Atan2(a, b) => vec![a, b],
            Op::Neg(a)
            | Op::Sqrt(a)
            | Op::Sin(a)
            | Op::Cos(a)
            | Op::SinStep(a)
            | Op::CosStep(a)
            | Op::Func(_, a) => vec![a],
        }
    }

    /// Choose the coefficient slots for functions with outputs `roots`: every
    /// parameter-level value (parameters themselves included) that a per-call
    /// value or an output uses directly, so the functions read coefficients only.
    pub fn plan(&self, roots: &[V]) -> Result<CoeffPlan, Error> {
        let needed = self.reach(roots, true);
        let mut slots: Vec<V> = needed
            .iter()
            .copied()
            .filter(|&v| self.lv(v) == Level::Param)
            .collect();
        slots.sort_unstable();
        let slot: HashMap<V, usize> = slots.iter().enumerate().map(|(i, v)| (*v, i)).collect();
        // compute them: all parameter-level values below the slots
        let below = self.reach(&slots, false);
        let mut order: Vec<V> = below
            .into_iter()
            .filter(|&v| self.lv(v) == Level::Param)
            .collect();
        order.sort_unstable();
        let name = |v: V| format_ident!("c{}", v);
        let mut bound: HashMap<V, TokenStream> = HashMap::new();
        let mut stmts = Vec::new();
        for v in order {
            if let Op::Input(i) = self.ops[v as usize] {
                bound.insert(v, self.inputs[i as usize].0.clone());
                continue;
            }
            let ops = self.operands(v);
            for o in &ops {
                if self.lv(*o) == Level::Const {
                    bound.insert(*o, lit(self.as_const(*o).expect("const"))?);
                }
            }
            let rhs = self.rhs(v, &|o| bound[&o].clone());
            let id = name(v);
            stmts.push(quote!(let #id = #rhs;));
            bound.insert(v, quote!(#id));
        }
        let values = slots.iter().map(|v| bound[v].clone()).collect();
        Ok(CoeffPlan {
            slot,
            stmts,
            values,
        })
    }

    /// The right-hand side of `v` from its operands' expressions (`sin_cos`
    /// pairs are fused by [`Graph::function`]).
    fn rhs(&self, v: V, get: &dyn Fn(V) -> TokenStream) -> TokenStream {
        match self.ops[v as usize] {
            Op::Const(_) | Op::Input(_) => unreachable!("leaves are bound, not computed"),
            Op::Add(a, b) => {
                let (a, b) = (get(a), get(b));
                quote!(#a + #b)
            }
            Op::Sub(a, b) => {
                let (a, b) = (get(a), get(b));
                quote!(#a - #b)
            }
            Op::Mul(a, b) => {
                let (a, b) = (get(a), get(b));
                quote!(#a * #b)
            }
            Op::Div(a, b) => {
                let (a, b) = (get(a), get(b));
                quote!(#a / #b)
            }
            Op::Neg(a) => {
                let a = get(a);
                quote!(-#a)
            }
            Op::Sqrt(a) => {
                let a = get(a);
                quote!(math::sqrt(#a))
            }
            Op::Powf(a, b) => {
                let (a, b) = (get(a), get(b));
                quote!(math::powf(#a, #b))
            }
            Op::Atan2(y, x) => {
                let (y, x) = (get(y), get(x));
                quote!(math::atan2(#y, #x))
            }
            Op::Sin(a) => {
                let a = get(a);
                quote!(math::sin(#a))
            }
            Op::Cos(a) => {
                let a = get(a);
                quote!(math::cos(#a))
            }
            Op::SinStep(a) => {
                let a = get(a);
                quote!(math::sin_cos_step(#a).0)
            }
            Op::CosStep(a) => {
                let a = get(a);
                quote!(math::sin_cos_step(#a).1)
            }
            Op::Func(f, a) => {
                let a = get(a);
                let name = format_ident!("{}", f.name());
                quote!(math::#name(#a))
            }
        }
    }

    /// Per-call products used once, by a sum or difference: emitted fused
    /// into it as `math::fma` (one rounding where the target has FMA).
    fn fused_products(&self, order: &[V], outputs: &[V]) -> Fused {
        let mut uses: HashMap<V, usize> = HashMap::new();
        for &v in order {
            if self.lv(v) >= Level::Call {
                for o in self.operands(v) {
                    *uses.entry(o).or_default() += 1;
                }
            }
        }
        for o in outputs {
            *uses.entry(*o).or_default() += 1;
        }
        let mut f = Fused::default();
        for &v in order {
            if self.lv(v) < Level::Call {
                continue;
            }
            let (Op::Add(a, b) | Op::Sub(a, b)) = self.ops[v as usize] else {
                continue;
            };
            let single = |m: V| {
                self.lv(m) >= Level::Call
                    && self.lv(m) <= self.lv(v)
                    && matches!(self.ops[m as usize], Op::Mul(..))
                    && uses.get(&m) == Some(&1)
            };
            let pick = [b, a]
                .into_iter()
                .find(|m| single(*m) && !f.skipped.contains(m));
            if let Some(m) = pick {
                f.skipped.insert(m);
                f.into.insert(v, m);
            }
        }
        f
    }

    /// `v = a ± b` with the product `m` (one of `a`, `b`) fused.
    fn fma_rhs(&self, v: V, m: V, get: &dyn Fn(V) -> TokenStream) -> TokenStream {
        let Op::Mul(x, y) = self.ops[m as usize] else {
            unreachable!("fused value is a product")
        };
        let (x, y) = (get(x), get(y));
        match self.ops[v as usize] {
            Op::Add(a, b) => {
                let c = get(if a == m { b } else { a });
                quote!(math::fma(#x, #y, #c))
            }
            Op::Sub(a, b) if a == m => {
                let c = get(b);
                quote!(math::fma(#x, #y, -#c))
            }
            Op::Sub(a, _) => {
                let c = get(a);
                quote!(math::fma(-#x, #y, #c))
            }
            _ => unreachable!("fused into a sum or difference"),
        }
    }

    /// Emit the per-call statements computing `outputs`; parameter-level
    /// values are read as `#coeffs[slot]` (from `plan`), per-call locals are
    /// `t{k}` numbered in order of appearance.
    pub fn function(
        &self,
        outputs: &[V],
        plan: &CoeffPlan,
        coeffs: &TokenStream,
    ) -> Result<Function, Error> {
        let needed = self.reach(outputs, true);
        let mut order: Vec<V> = needed.iter().copied().collect();
        order.sort_unstable();
        let fused = self.fused_products(&order, outputs);
        let mut bound: HashMap<V, TokenStream> = HashMap::new();
        let mut stmts = Vec::new();
        let mut inner = Vec::new();
        let mut counter = 0usize;
        let mut fresh = || {
            let id: Ident = format_ident!("t{}", counter);
            counter += 1;
            id
        };
        for v in order {
            if bound.contains_key(&v) || fused.skipped.contains(&v) {
                continue;
            }
            match self.lv(v) {
                Level::Const => {
                    bound.insert(v, lit(self.as_const(v).expect("const"))?);
                    continue;
                }
                Level::Param => {
                    let s = plan.slot.get(&v).copied().ok_or_else(|| {
                        Error::Generate("internal: coefficient without a slot".into())
                    })?;
                    let s = proc_macro2::Literal::usize_unsuffixed(s);
                    bound.insert(v, quote!(#coeffs[#s]));
                    continue;
                }
                Level::Call | Level::Dir => {}
            }
            let stmts = if self.lv(v) == Level::Dir {
                &mut inner
            } else {
                &mut stmts
            };
            match self.ops[v as usize] {
                Op::Input(i) => {
                    bound.insert(v, self.inputs[i as usize].0.clone());
                }
                Op::Sin(a) | Op::Cos(a) | Op::SinStep(a) | Op::CosStep(a) => {
                    let (sin_op, cos_op, fun) = match self.ops[v as usize] {
                        Op::Sin(_) | Op::Cos(_) => (Op::Sin(a), Op::Cos(a), quote!(math::sin_cos)),
                        _ => (Op::SinStep(a), Op::CosStep(a), quote!(math::sin_cos_step)),
                    };
                    let is_sin = self.ops[v as usize] == sin_op;
                    let partner = self
                        .index
                        .get(if is_sin { &cos_op } else { &sin_op })
                        .copied()
                        .filter(|p| needed.contains(p));
                    let arg = bound[&a].clone();
                    match partner {
                        Some(p) => {
                            let (s, c) = (fresh(), fresh());
                            stmts.push(quote!(let (#s, #c) = #fun(#arg);));
                            let (sv, cv) = if is_sin { (v, p) } else { (p, v) };
                            bound.insert(sv, quote!(#s));
                            bound.insert(cv, quote!(#c));
                        }
                        None => {
                            let rhs = self.rhs(v, &|o| bound[&o].clone());
                            let t = fresh();
                            stmts.push(quote!(let #t = #rhs;));
                            bound.insert(v, quote!(#t));
                        }
                    }
                }
                _ => {
                    let rhs = match fused.into.get(&v) {
                        Some(&m) => self.fma_rhs(v, m, &|o| bound[&o].clone()),
                        None => self.rhs(v, &|o| bound[&o].clone()),
                    };
                    let t = fresh();
                    stmts.push(quote!(let #t = #rhs;));
                    bound.insert(v, quote!(#t));
                }
            }
        }
        let outputs = outputs.iter().map(|v| bound[v].clone()).collect();
        Ok(Function {
            stmts,
            inner,
            outputs,
        })
    }
}

/// `D * (a/D + b)` -> `a + b*D`: a factor `D` (power 1) of a product is
/// multiplied into a sum factor one of whose terms divides by `D`, saving the
/// division (the symbolic core cancels `D * D^-1`). Repeats while it applies.
fn cancel_into_sums(factors: &mut Vec<Expr>) {
    let minus_one = Expr::int(-1);
    loop {
        let mut hit = None;
        'search: for (i, s) in factors.iter().enumerate() {
            let Node::Add(terms) = s.node() else { continue };
            for (j, d) in factors.iter().enumerate() {
                if i == j {
                    continue;
                }
                let divides = |t: &Expr| match t.node() {
                    Node::Mul(fs) => fs.iter().any(|f| f.base_and_exp() == (*d, minus_one)),
                    _ => t.base_and_exp() == (*d, minus_one),
                };
                if terms.iter().any(divides) {
                    hit = Some((i, j));
                    break 'search;
                }
            }
        }
        let Some((i, j)) = hit else { return };
        let (s, d) = (factors[i], factors[j]);
        let Node::Add(terms) = s.node() else { return };
        let distributed = Expr::add_all(terms.iter().map(|t| Expr::mul_all([*t, d])));
        factors[i] = distributed;
        factors.remove(j);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Solve with constant entries (everything folds) and compare with the
    /// residual of the original system.
    fn check_solve(n: usize) {
        let mut g = Graph::new();
        // SPD: A^T A + n I from a fixed integer pattern
        let a = |i: usize, j: usize| ((3 * i + 5 * j + 1) % 7) as f64 - 3.0;
        let m: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| {
                        (0..n).map(|k| a(k, i) * a(k, j)).sum::<f64>()
                            + if i == j { n as f64 } else { 0.0 }
                    })
                    .collect()
            })
            .collect();
        let b: Vec<f64> = (0..n).map(|i| i as f64 - 1.5).collect();
        let mv: Vec<Vec<V>> = m
            .iter()
            .map(|r| r.iter().map(|x| g.konst(*x)).collect())
            .collect();
        let bv: Vec<V> = b.iter().map(|x| g.konst(*x)).collect();
        let y = g.solve_sym(&mv, &[bv]).remove(0);
        let y: Vec<f64> = y.iter().map(|v| g.as_const(*v).expect("folded")).collect();
        for i in 0..n {
            let r: f64 = (0..n).map(|j| m[i][j] * y[j]).sum::<f64>() - b[i];
            assert!(r.abs() < 1e-10, "n = {n}: residual {r} in row {i}");
        }
    }

    #[test]
    fn closed_form_and_ldl_solves() {
        for n in 1..=6 {
            check_solve(n);
        }
    }

    #[test]
    fn value_numbering_and_folding() {
        let mut g = Graph::new();
        let x = g.input(quote!(x[0]), Level::Call);
        let p = g.input(quote!(p.a), Level::Param);
        assert_eq!(g.mul(x, p), g.mul(p, x));
        let z = g.konst(0.0);
        assert_eq!(g.mul(x, z), z);
        assert_eq!(g.add(x, z), x);
        assert_eq!(g.sub(x, x), z);
        let nx = g.neg(x);
        assert_eq!(g.neg(nx), x);
        assert_eq!(g.add(p, nx), g.sub(p, x));
        let xp = g.mul(x, p);
        assert_eq!(g.lv(xp), Level::Call);
        let pp = g.mul(p, p);
        assert_eq!(g.lv(pp), Level::Param);
    }
}
