//! The hash-consed expression DAG.
//!
//! An [`Expr`] is a `Copy` handle (a `u32`) into a process-wide, append-only
//! arena. Every node is interned: two structurally equal expressions always have
//! the same handle, so equality and hashing are O(1) and shared subexpressions are
//! stored once. Nodes are never freed (the arena lives as long as the process),
//! which suits a compiler: symbolic work happens up front, numeric work runs on
//! compiled tapes.
//!
//! Constructors apply cheap local simplifications only (flattening, constant
//! folding, collecting like terms and powers, sorting operands into a
//! deterministic structural order). Deeper normalisation (expansion, trigonometric
//! identities, common denominators) lives in [`crate::sym::canonical`](mod@crate::sym::canonical).

use std::cmp::Ordering;
use std::collections::HashMap;
use std::fmt;
use std::sync::{Mutex, OnceLock};

use super::fxhash::FxHashMap;
use super::rational::Rational;

/// A handle to an interned expression node.
#[derive(Copy, Clone, PartialEq, Eq, Hash)]
pub struct Expr(u32);

/// An interned symbol name.
#[derive(Copy, Clone, PartialEq, Eq, Hash)]
pub struct Symbol(u32);

/// Unary elementary functions.
#[derive(Copy, Clone, PartialEq, Eq, Hash, Debug, PartialOrd, Ord)]
pub enum Func {
    /// sine
    Sin,
    /// cosine
    Cos,
    /// tangent
    Tan,
    /// exponential
    Exp,
    /// natural logarithm
    Ln,
    /// absolute value
    Abs,
    /// sign (-1, 0, 1)
    Sign,
    /// hyperbolic tangent
    Tanh,
}

impl Func {
    /// The name used in model files and printing.
    pub fn name(self) -> &'static str {
        match self {
            Func::Sin => "sin",
            Func::Cos => "cos",
            Func::Tan => "tan",
            Func::Exp => "exp",
            Func::Ln => "ln",
            Func::Abs => "abs",
            Func::Sign => "sign",
            Func::Tanh => "tanh",
        }
    }

    /// Look a function up by name.
    pub fn from_name(name: &str) -> Option<Func> {
        Some(match name {
            "sin" => Func::Sin,
            "cos" => Func::Cos,
            "tan" => Func::Tan,
            "exp" => Func::Exp,
            "ln" => Func::Ln,
            "abs" => Func::Abs,
            "sign" => Func::Sign,
            "tanh" => Func::Tanh,
            _ => return None,
        })
    }

    /// Evaluate on `f64`.
    pub fn eval(self, x: f64) -> f64 {
        match self {
            Func::Sin => super::trig::sin(x),
            Func::Cos => super::trig::cos(x),
            Func::Tan => x.tan(),
            Func::Exp => x.exp(),
            Func::Ln => x.ln(),
            Func::Abs => x.abs(),
            Func::Sign => {
                if x > 0.0 {
                    1.0
                } else if x < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            }
            Func::Tanh => x.tanh(),
        }
    }
}

/// A floating-point constant compared and hashed by its bits.
#[derive(Copy, Clone, PartialEq, Eq, Hash, Debug)]
pub struct FloatBits(u64);

impl FloatBits {
    /// The value.
    pub fn value(self) -> f64 {
        f64::from_bits(self.0)
    }
}

/// An expression node. Operands of `Add` and `Mul` are flattened and sorted;
/// a rational coefficient of a `Mul`, if any, comes first.
#[derive(Clone, PartialEq, Eq, Hash, Debug)]
pub enum Node {
    /// Exact rational constant.
    Rational(Rational),
    /// Inexact constant (only where exactness was impossible).
    Float(FloatBits),
    /// A named symbol (coordinate, velocity `q'`, acceleration `q''`, parameter, input).
    Symbol(Symbol),
    /// Sum of at least two terms.
    Add(Box<[Expr]>),
    /// Product of at least two factors.
    Mul(Box<[Expr]>),
    /// `base ^ exponent`.
    Pow(Expr, Expr),
    /// Elementary function application.
    Func(Func, Expr),
    /// Two-argument arctangent `atan2(y, x)`.
    Atan2(Expr, Expr),
    /// A named subexpression: equal to its definition, printed by its name.
    /// Sums and products do not flatten through it, so a long sum of named
    /// sums stays a sum of names (the structure of the angle-frame
    /// equations, `M = S^T M_theta S`, instead of their expansion). Every
    /// evaluation, derivative and canonical form looks through it.
    Named(Symbol, Expr),
}

struct Arena {
    nodes: boxcar::Vec<Node>,
    index: Mutex<FxHashMap<Node, u32>>,
    names: boxcar::Vec<Box<str>>,
    name_index: Mutex<HashMap<Box<str>, u32>>,
}

fn arena() -> &'static Arena {
    static ARENA: OnceLock<Arena> = OnceLock::new();
    ARENA.get_or_init(|| Arena {
        nodes: boxcar::Vec::new(),
        index: Mutex::new(FxHashMap::default()),
        names: boxcar::Vec::new(),
        name_index: Mutex::new(HashMap::new()),
    })
}

fn intern(node: Node) -> Expr {
    let a = arena();
    let mut idx = a.index.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(&i) = idx.get(&node) {
        return Expr(i);
    }
    let i = a.nodes.push(node.clone());
    let i = u32::try_from(i).expect("expression arena exceeded 2^32 nodes");
    idx.insert(node, i);
    Expr(i)
}

impl Symbol {
    /// Intern a name.
    pub fn new(name: &str) -> Symbol {
        let a = arena();
        let mut idx = a.name_index.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(&i) = idx.get(name) {
            return Symbol(i);
        }
        let i = a.names.push(name.into());
        let i = u32::try_from(i).expect("symbol table exceeded 2^32 names");
        idx.insert(name.into(), i);
        Symbol(i)
    }

    /// The name.
    pub fn name(self) -> &'static str {
        &arena().names[self.0 as usize]
    }
}

impl fmt::Debug for Symbol {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl fmt::Display for Symbol {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl PartialOrd for Symbol {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Symbol {
    fn cmp(&self, other: &Self) -> Ordering {
        if self.0 == other.0 {
            Ordering::Equal
        } else {
            self.name().cmp(other.name())
        }
    }
}

impl Expr {
    /// The node behind this handle.
    pub fn node(self) -> &'static Node {
        &arena().nodes[self.0 as usize]
    }

    /// A stable small integer identifying the node within this process.
    pub fn id(self) -> u32 {
        self.0
    }

    /// An exact rational constant.
    pub fn rational(r: Rational) -> Expr {
        intern(Node::Rational(r))
    }

    /// An integer constant.
    pub fn int(n: i64) -> Expr {
        Expr::rational(Rational::int(n as i128))
    }

    /// `num/den` as an exact constant (`den != 0`).
    pub fn frac(num: i64, den: i64) -> Expr {
        match Rational::new(num as i128, den as i128) {
            Some(r) => Expr::rational(r),
            None => Expr::float(f64::NAN),
        }
    }

    /// A floating-point constant; integral and simple values become exact.
    pub fn float(x: f64) -> Expr {
        if x.is_finite() && x == x.trunc() && x.abs() < 1e15 {
            return Expr::int(x as i64);
        }
        intern(Node::Float(FloatBits(x.to_bits())))
    }

    /// Zero.
    pub fn zero() -> Expr {
        Expr::int(0)
    }

    /// One.
    pub fn one() -> Expr {
        Expr::int(1)
    }

    /// A symbol by name.
    pub fn sym(name: &str) -> Expr {
        intern(Node::Symbol(Symbol::new(name)))
    }

    /// A symbol.
    pub fn symbol(s: Symbol) -> Expr {
        intern(Node::Symbol(s))
    }

    /// The rational value if this is an exact constant.
    pub fn as_rational(self) -> Option<Rational> {
        match self.node() {
            Node::Rational(r) => Some(*r),
            _ => None,
        }
    }

    /// The symbol if this is a symbol.
    pub fn as_symbol(self) -> Option<Symbol> {
        match self.node() {
            Node::Symbol(s) => Some(*s),
            _ => None,
        }
    }

    /// The numeric value if this is any constant.
    pub fn as_f64(self) -> Option<f64> {
        match self.node() {
            Node::Rational(r) => Some(r.to_f64()),
            Node::Float(b) => Some(b.value()),
            _ => None,
        }
    }

    /// True if exactly zero.
    pub fn is_zero(self) -> bool {
        self.as_rational().is_some_and(Rational::is_zero)
    }

    /// True if exactly one.
    pub fn is_one(self) -> bool {
        self.as_rational().is_some_and(Rational::is_one)
    }

    /// True if a constant (rational or float).
    pub fn is_constant(self) -> bool {
        matches!(self.node(), Node::Rational(_) | Node::Float(_))
    }

    /// Sum of any number of terms.
    pub fn add_all<I: IntoIterator<Item = Expr>>(terms: I) -> Expr {
        build_add(terms.into_iter().collect())
    }

    /// Product of any number of factors.
    pub fn mul_all<I: IntoIterator<Item = Expr>>(factors: I) -> Expr {
        build_mul(factors.into_iter().collect())
    }

    /// `self ^ e`.
    pub fn pow(self, e: Expr) -> Expr {
        build_pow(self, e)
    }

    /// `self ^ n` for an integer `n`.
    pub fn powi(self, n: i64) -> Expr {
        build_pow(self, Expr::int(n))
    }

    /// Square root, `self ^ (1/2)`.
    pub fn sqrt(self) -> Expr {
        build_pow(self, Expr::frac(1, 2))
    }

    /// Reciprocal, `self ^ -1`.
    pub fn recip(self) -> Expr {
        build_pow(self, Expr::int(-1))
    }

    /// Apply an elementary function.
    pub fn apply(f: Func, x: Expr) -> Expr {
        build_func(f, x)
    }

    /// `sin(self)`.
    pub fn sin(self) -> Expr {
        build_func(Func::Sin, self)
    }
    /// `cos(self)`.
    pub fn cos(self) -> Expr {
        build_func(Func::Cos, self)
    }
    /// `tan(self)`.
    pub fn tan(self) -> Expr {
        build_func(Func::Tan, self)
    }
    /// `exp(self)`.
    pub fn exp(self) -> Expr {
        build_func(Func::Exp, self)
    }
    /// `ln(self)`.
    pub fn ln(self) -> Expr {
        build_func(Func::Ln, self)
    }
    /// `abs(self)`.
    pub fn abs(self) -> Expr {
        build_func(Func::Abs, self)
    }
    /// `sign(self)`.
    pub fn sign(self) -> Expr {
        build_func(Func::Sign, self)
    }
    /// `tanh(self)`.
    pub fn tanh(self) -> Expr {
        build_func(Func::Tanh, self)
    }

    /// `atan2(y, x)`.
    pub fn atan2(y: Expr, x: Expr) -> Expr {
        match (y.as_f64(), x.as_f64()) {
            (Some(a), Some(b)) if a == 0.0 && b > 0.0 => Expr::zero(),
            _ => intern(Node::Atan2(y, x)),
        }
    }

    /// Split into a rational coefficient and the remaining factor:
    /// `3*x*y -> (3, x*y)`, `x -> (1, x)`, `5 -> (5, 1)`.
    pub fn coeff_and_rest(self) -> (Rational, Expr) {
        match self.node() {
            Node::Rational(r) => (*r, Expr::one()),
            Node::Mul(fs) => match fs[0].node() {
                Node::Rational(r) => {
                    let rest = if fs.len() == 2 {
                        fs[1]
                    } else {
                        intern(Node::Mul(fs[1..].into()))
                    };
                    (*r, rest)
                }
                _ => (Rational::ONE, self),
            },
            _ => (Rational::ONE, self),
        }
    }

    /// Split into base and exponent: `x^2 -> (x, 2)`, `x -> (x, 1)`.
    pub fn base_and_exp(self) -> (Expr, Expr) {
        match self.node() {
            Node::Pow(b, e) => (*b, *e),
            _ => (self, Expr::one()),
        }
    }

    /// `definition`, printed as `name` (see [`Node::Named`]); a constant
    /// or a symbol stays itself.
    pub fn named(name: &str, definition: Expr) -> Expr {
        match definition.node() {
            Node::Rational(_) | Node::Float(_) | Node::Symbol(_) => definition,
            _ => intern(Node::Named(Symbol::new(name), definition)),
        }
    }

    /// The name and definition if this is a named subexpression.
    pub fn as_named(self) -> Option<(Symbol, Expr)> {
        match self.node() {
            Node::Named(s, d) => Some((*s, *d)),
            _ => None,
        }
    }

    /// The direct operands of this node (empty for leaves).
    pub fn children(self) -> Vec<Expr> {
        match self.node() {
            Node::Rational(_) | Node::Float(_) | Node::Symbol(_) => Vec::new(),
            Node::Add(xs) | Node::Mul(xs) => xs.to_vec(),
            Node::Pow(a, b) | Node::Atan2(a, b) => vec![*a, *b],
            Node::Func(_, a) | Node::Named(_, a) => vec![*a],
        }
    }

    /// Does `sym` occur in this expression?
    pub fn contains(self, sym: Symbol) -> bool {
        let mut seen = FxHashMap::default();
        contains_memo(self, sym, &mut seen)
    }

    /// All symbols occurring in this expression, sorted by name.
    pub fn symbols(self) -> Vec<Symbol> {
        let mut out = Vec::new();
        let mut seen = super::fxhash::FxHashSet::default();
        let mut stack = vec![self];
        while let Some(e) = stack.pop() {
            if !seen.insert(e) {
                continue;
            }
            match e.node() {
                Node::Symbol(s) => out.push(*s),
                _ => stack.extend(e.children()),
            }
        }
        out.sort();
        out.dedup();
        out
    }

    /// Number of distinct nodes in the DAG below (and including) this one.
    pub fn dag_size(self) -> usize {
        let mut seen = super::fxhash::FxHashSet::default();
        let mut stack = vec![self];
        while let Some(e) = stack.pop() {
            if seen.insert(e) {
                stack.extend(e.children());
            }
        }
        seen.len()
    }

    /// Evaluate by walking the DAG (memoised). For repeated evaluation compile a
    /// [`crate::sym::Tape`] instead. `value` supplies each symbol's value.
    pub fn eval_with(self, value: &mut dyn FnMut(Symbol) -> f64) -> f64 {
        let mut memo: FxHashMap<Expr, f64> = FxHashMap::default();
        eval_memo(self, value, &mut memo)
    }

    /// Evaluate with a name -> value map; missing symbols evaluate to NaN.
    pub fn eval_map(self, values: &HashMap<Symbol, f64>) -> f64 {
        self.eval_with(&mut |s| values.get(&s).copied().unwrap_or(f64::NAN))
    }

    /// [`Expr::eval_map`] of several expressions sharing one memo (their
    /// common subexpressions are evaluated once).
    pub fn eval_all(exprs: &[Expr], values: &HashMap<Symbol, f64>) -> Vec<f64> {
        let mut ev = Evaluator::new(values);
        exprs.iter().map(|e| ev.eval(*e)).collect()
    }
}

/// Evaluation of many expressions at one point, every subexpression once
/// (the memo lives as long as the evaluator).
pub struct Evaluator<'a> {
    values: &'a HashMap<Symbol, f64>,
    memo: FxHashMap<Expr, f64>,
}

impl<'a> Evaluator<'a> {
    /// An evaluator at `values` (missing symbols evaluate to NaN).
    pub fn new(values: &'a HashMap<Symbol, f64>) -> Evaluator<'a> {
        Evaluator {
            values,
            memo: FxHashMap::default(),
        }
    }

    /// The value of `e`.
    pub fn eval(&mut self, e: Expr) -> f64 {
        let values = self.values;
        let mut value = |s: Symbol| values.get(&s).copied().unwrap_or(f64::NAN);
        eval_memo(e, &mut value, &mut self.memo)
    }
}

fn contains_memo(e: Expr, sym: Symbol, seen: &mut FxHashMap<Expr, bool>) -> bool {
    if let Some(&b) = seen.get(&e) {
        return b;
    }
    let r = match e.node() {
        Node::Symbol(s) => *s == sym,
        Node::Rational(_) | Node::Float(_) => false,
        _ => e
            .children()
            .into_iter()
            .any(|c| contains_memo(c, sym, seen)),
    };
    seen.insert(e, r);
    r
}

fn eval_memo(
    e: Expr,
    value: &mut dyn FnMut(Symbol) -> f64,
    memo: &mut FxHashMap<Expr, f64>,
) -> f64 {
    if let Some(&v) = memo.get(&e) {
        return v;
    }
    let v = match e.node() {
        Node::Rational(r) => r.to_f64(),
        Node::Float(b) => b.value(),
        Node::Symbol(s) => value(*s),
        Node::Add(xs) => xs.iter().map(|x| eval_memo(*x, value, memo)).sum(),
        Node::Mul(xs) => xs.iter().map(|x| eval_memo(*x, value, memo)).product(),
        Node::Pow(b, x) => {
            let bv = eval_memo(*b, value, memo);
            match x.as_rational() {
                Some(r) if r.is_integer() && r.numer().abs() <= i32::MAX as i128 => {
                    bv.powi(r.numer() as i32)
                }
                Some(r) if r == Rational::new(1, 2).unwrap() => bv.sqrt(),
                _ => bv.powf(eval_memo(*x, value, memo)),
            }
        }
        Node::Func(f, x) => f.eval(eval_memo(*x, value, memo)),
        Node::Atan2(y, x) => eval_memo(*y, value, memo).atan2(eval_memo(*x, value, memo)),
        Node::Named(_, d) => eval_memo(*d, value, memo),
    };
    memo.insert(e, v);
    v
}

/// Deterministic structural order used to sort operands (independent of
/// interning order, so printing and generated code are reproducible).
pub fn structural_cmp(a: Expr, b: Expr) -> Ordering {
    if a == b {
        return Ordering::Equal;
    }
    fn rank(n: &Node) -> u8 {
        match n {
            Node::Rational(_) => 0,
            Node::Float(_) => 1,
            Node::Symbol(_) => 2,
            Node::Pow(..) => 3,
            Node::Mul(_) => 4,
            Node::Add(_) => 5,
            Node::Func(..) => 6,
            Node::Atan2(..) => 7,
            Node::Named(..) => 8,
        }
    }
    let (na, nb) = (a.node(), b.node());
    match rank(na).cmp(&rank(nb)) {
        Ordering::Equal => {}
        o => return o,
    }
    match (na, nb) {
        (Node::Rational(x), Node::Rational(y)) => x.cmp(y),
        (Node::Float(x), Node::Float(y)) => x.value().total_cmp(&y.value()),
        (Node::Symbol(x), Node::Symbol(y)) => x.cmp(y),
        (Node::Add(xs), Node::Add(ys)) | (Node::Mul(xs), Node::Mul(ys)) => {
            for (x, y) in xs.iter().zip(ys.iter()) {
                match structural_cmp(*x, *y) {
                    Ordering::Equal => {}
                    o => return o,
                }
            }
            xs.len().cmp(&ys.len())
        }
        (Node::Pow(b1, e1), Node::Pow(b2, e2)) | (Node::Atan2(b1, e1), Node::Atan2(b2, e2)) => {
            structural_cmp(*b1, *b2).then_with(|| structural_cmp(*e1, *e2))
        }
        (Node::Func(f1, x1), Node::Func(f2, x2)) => {
            f1.cmp(f2).then_with(|| structural_cmp(*x1, *x2))
        }
        (Node::Named(s1, x1), Node::Named(s2, x2)) => {
            s1.cmp(s2).then_with(|| structural_cmp(*x1, *x2))
        }
        _ => Ordering::Equal,
    }
}

/// Order for factors in a product: sort by base first so that powers of the
/// same base sit together and print naturally.
fn factor_cmp(a: Expr, b: Expr) -> Ordering {
    let (ba, ea) = a.base_and_exp();
    let (bb, eb) = b.base_and_exp();
    structural_cmp(ba, bb).then_with(|| structural_cmp(ea, eb))
}

fn fold_float(x: f64) -> Expr {
    Expr::float(x)
}

fn build_add(terms: Vec<Expr>) -> Expr {
    // Flatten.
    let mut flat: Vec<Expr> = Vec::with_capacity(terms.len());
    for t in terms {
        match t.node() {
            Node::Add(xs) => flat.extend(xs.iter().copied()),
            _ => flat.push(t),
        }
    }
    // Collect constants and like terms: term = coeff * rest.
    let mut constant = Rational::ZERO;
    let mut float_const = 0.0f64;
    let mut has_float = false;
    let mut order: Vec<Expr> = Vec::new();
    let mut coeffs: FxHashMap<Expr, Rational> = FxHashMap::default();
    let mut float_coeffs: FxHashMap<Expr, f64> = FxHashMap::default();
    for t in flat {
        match t.node() {
            Node::Rational(r) => match constant.checked_add(*r) {
                Some(c) => constant = c,
                None => {
                    has_float = true;
                    float_const += r.to_f64();
                }
            },
            Node::Float(b) => {
                has_float = true;
                float_const += b.value();
            }
            _ => {
                let (c, rest) = t.coeff_and_rest();
                match coeffs.get_mut(&rest) {
                    Some(acc) => match acc.checked_add(c) {
                        Some(s) => *acc = s,
                        None => {
                            *float_coeffs.entry(rest).or_insert(0.0) += c.to_f64();
                        }
                    },
                    None => {
                        order.push(rest);
                        coeffs.insert(rest, c);
                    }
                }
            }
        }
    }
    let mut out: Vec<Expr> = Vec::with_capacity(order.len() + 1);
    for rest in order {
        let c = coeffs[&rest];
        let extra = float_coeffs.get(&rest).copied();
        let term = match extra {
            Some(f) => build_mul(vec![fold_float(c.to_f64() + f), rest]),
            None if c.is_zero() => continue,
            None if c.is_one() => rest,
            None => build_mul(vec![Expr::rational(c), rest]),
        };
        if !term.is_zero() {
            out.push(term);
        }
    }
    if has_float {
        let v = constant.to_f64() + float_const;
        if v != 0.0 {
            out.push(fold_float(v));
        }
    } else if !constant.is_zero() {
        out.push(Expr::rational(constant));
    }
    match out.len() {
        0 => Expr::zero(),
        1 => out[0],
        _ => {
            out.sort_by(|a, b| structural_cmp(*a, *b));
            intern(Node::Add(out.into_boxed_slice()))
        }
    }
}

/// The constant factor of a product: exact while the rational arithmetic
/// fits, with an inexact float part for what overflowed or was a float.
struct ProductCoefficient {
    exact: Rational,
    float: f64,
    inexact: bool,
}

impl ProductCoefficient {
    fn new() -> Self {
        ProductCoefficient {
            exact: Rational::ONE,
            float: 1.0,
            inexact: false,
        }
    }

    fn mul_rational(&mut self, r: Rational) {
        match self.exact.checked_mul(r) {
            Some(c) => self.exact = c,
            None => self.mul_float(r.to_f64()),
        }
    }

    fn mul_float(&mut self, x: f64) {
        self.inexact = true;
        self.float *= x;
    }
}

fn build_mul(factors: Vec<Expr>) -> Expr {
    let mut flat: Vec<Expr> = Vec::with_capacity(factors.len());
    for f in factors {
        match f.node() {
            Node::Mul(xs) => flat.extend(xs.iter().copied()),
            _ => flat.push(f),
        }
    }
    let mut k = ProductCoefficient::new();
    let mut order: Vec<Expr> = Vec::new();
    let mut exps: FxHashMap<Expr, Vec<Expr>> = FxHashMap::default();
    for f in flat {
        match f.node() {
            Node::Rational(r) => {
                if r.is_zero() {
                    return Expr::zero();
                }
                k.mul_rational(*r);
            }
            Node::Float(b) => k.mul_float(b.value()),
            _ => {
                let (base, e) = f.base_and_exp();
                match exps.get_mut(&base) {
                    Some(v) => v.push(e),
                    None => {
                        order.push(base);
                        exps.insert(base, vec![e]);
                    }
                }
            }
        }
    }
    let mut out: Vec<Expr> = Vec::with_capacity(order.len() + 1);
    for base in order {
        let es = &exps[&base];
        let e = if es.len() == 1 {
            es[0]
        } else {
            build_add(es.clone())
        };
        let p = build_pow(base, e);
        match p.node() {
            Node::Rational(r) => k.mul_rational(*r),
            Node::Float(b) => k.mul_float(b.value()),
            Node::Mul(xs) => {
                // e.g. (a*b)^n distributed by build_pow: merge its factors.
                for x in xs.iter() {
                    match x.node() {
                        Node::Rational(r) => k.mul_rational(*r),
                        _ => out.push(*x),
                    }
                }
            }
            _ => out.push(p),
        }
    }
    let ProductCoefficient {
        exact: coeff,
        float: float_coeff,
        inexact: has_float,
    } = k;
    if coeff.is_zero() {
        return Expr::zero();
    }
    // Merge any duplicated bases produced by distribution.
    if out.len() > 1 {
        let mut seen = super::fxhash::FxHashSet::default();
        if out.iter().any(|x| !seen.insert(x.base_and_exp().0)) {
            let mut all = out;
            all.push(Expr::rational(coeff));
            if has_float {
                all.push(fold_float(float_coeff));
            }
            return build_mul(all);
        }
    }
    out.sort_by(|a, b| factor_cmp(*a, *b));
    let lead = if has_float {
        Some(fold_float(coeff.to_f64() * float_coeff))
    } else if !coeff.is_one() {
        Some(Expr::rational(coeff))
    } else {
        None
    };
    match (lead, out.len()) {
        (None, 0) => Expr::one(),
        (Some(c), 0) => c,
        (None, 1) => out[0],
        (lead, _) => {
            let mut v = Vec::with_capacity(out.len() + 1);
            if let Some(c) = lead {
                if c.is_zero() {
                    return Expr::zero();
                }
                if !c.is_one() {
                    v.push(c);
                }
            }
            v.extend(out);
            if v.len() == 1 {
                v[0]
            } else {
                intern(Node::Mul(v.into_boxed_slice()))
            }
        }
    }
}

fn build_pow(base: Expr, e: Expr) -> Expr {
    if e.is_zero() {
        return Expr::one();
    }
    if e.is_one() {
        return base;
    }
    if base.is_one() {
        return Expr::one();
    }
    if let (Some(b), Some(r)) = (base.as_rational(), e.as_rational()) {
        if b.is_zero() {
            return if r.is_negative() {
                Expr::float(f64::INFINITY)
            } else {
                Expr::zero()
            };
        }
        if let Some(v) = b.checked_pow_rational(r) {
            return Expr::rational(v);
        }
        if !r.is_integer() {
            // Keep exact irrational powers symbolic, e.g. 2^(1/2).
            return intern(Node::Pow(base, e));
        }
        return fold_float(b.to_f64().powf(r.to_f64()));
    }
    if let (Some(b), Some(x)) = (base.as_f64(), e.as_f64()) {
        return fold_float(b.powf(x));
    }
    if let Some(r) = e.as_rational() {
        match base.node() {
            // (x^a)^n = x^(a*n) for integer n.
            Node::Pow(b, a) if r.is_integer() => {
                return build_pow(*b, build_mul(vec![*a, e]));
            }
            // (a*b)^n = a^n * b^n for integer n.
            Node::Mul(fs) if r.is_integer() => {
                return build_mul(fs.iter().map(|f| build_pow(*f, e)).collect());
            }
            _ => {}
        }
    }
    intern(Node::Pow(base, e))
}

fn build_func(f: Func, x: Expr) -> Expr {
    if let Some(v) = x.as_rational() {
        if v.is_zero() {
            return match f {
                Func::Sin | Func::Tan | Func::Tanh | Func::Abs | Func::Sign => Expr::zero(),
                Func::Cos | Func::Exp => Expr::one(),
                Func::Ln => Expr::float(f64::NEG_INFINITY),
            };
        }
        match f {
            Func::Abs => return Expr::rational(v.abs()),
            Func::Sign => return Expr::int(if v.is_negative() { -1 } else { 1 }),
            Func::Ln if v.is_one() => return Expr::zero(),
            _ => {}
        }
    }
    if let Some(v) = x.as_f64() {
        if matches!(x.node(), Node::Float(_)) {
            return fold_float(f.eval(v));
        }
    }
    // Odd/even symmetry: pull a negative coefficient out.
    let (c, rest) = x.coeff_and_rest();
    if c.is_negative() {
        let pos = build_mul(vec![Expr::rational(c.abs()), rest]);
        match f {
            Func::Sin | Func::Tan | Func::Tanh | Func::Sign => {
                return build_mul(vec![Expr::int(-1), build_func(f, pos)]);
            }
            Func::Cos | Func::Abs => return build_func(f, pos),
            _ => {}
        }
    }
    match (f, x.node()) {
        (Func::Ln, Node::Func(Func::Exp, y)) => return *y,
        (Func::Abs, Node::Func(Func::Abs, _)) => return x,
        (Func::Sign, Node::Func(Func::Sign, _)) => return x,
        _ => {}
    }
    intern(Node::Func(f, x))
}

macro_rules! binop {
    ($tr:ident, $method:ident, $body:expr) => {
        impl std::ops::$tr for Expr {
            type Output = Expr;
            fn $method(self, rhs: Expr) -> Expr {
                let f: fn(Expr, Expr) -> Expr = $body;
                f(self, rhs)
            }
        }
        impl std::ops::$tr<i64> for Expr {
            type Output = Expr;
            fn $method(self, rhs: i64) -> Expr {
                let f: fn(Expr, Expr) -> Expr = $body;
                f(self, Expr::int(rhs))
            }
        }
        impl std::ops::$tr<Expr> for i64 {
            type Output = Expr;
            fn $method(self, rhs: Expr) -> Expr {
                let f: fn(Expr, Expr) -> Expr = $body;
                f(Expr::int(self), rhs)
            }
        }
    };
}

binop!(Add, add, |a, b| build_add(vec![a, b]));
binop!(Sub, sub, |a, b| build_add(vec![
    a,
    build_mul(vec![Expr::int(-1), b])
]));
binop!(Mul, mul, |a, b| build_mul(vec![a, b]));
binop!(Div, div, |a, b| build_mul(vec![
    a,
    build_pow(b, Expr::int(-1))
]));

impl std::ops::Neg for Expr {
    type Output = Expr;
    fn neg(self) -> Expr {
        build_mul(vec![Expr::int(-1), self])
    }
}

impl std::ops::AddAssign for Expr {
    fn add_assign(&mut self, rhs: Expr) {
        *self = *self + rhs;
    }
}

impl std::ops::SubAssign for Expr {
    fn sub_assign(&mut self, rhs: Expr) {
        *self = *self - rhs;
    }
}

impl std::ops::MulAssign for Expr {
    fn mul_assign(&mut self, rhs: Expr) {
        *self = *self * rhs;
    }
}

impl std::iter::Sum for Expr {
    fn sum<I: Iterator<Item = Expr>>(iter: I) -> Expr {
        Expr::add_all(iter)
    }
}

impl std::iter::Product for Expr {
    fn product<I: Iterator<Item = Expr>>(iter: I) -> Expr {
        Expr::mul_all(iter)
    }
}

impl From<i64> for Expr {
    fn from(n: i64) -> Expr {
        Expr::int(n)
    }
}

impl From<Rational> for Expr {
    fn from(r: Rational) -> Expr {
        Expr::rational(r)
    }
}

impl From<Symbol> for Expr {
    fn from(s: Symbol) -> Expr {
        Expr::symbol(s)
    }
}

impl fmt::Debug for Expr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interning_gives_equal_handles() {
        let x = Expr::sym("x");
        let y = Expr::sym("y");
        assert_eq!(x + y, y + x);
        assert_eq!(x * y * 2, 2 * (y * x));
        assert_eq!((x + y).node(), (y + x).node());
    }

    #[test]
    fn like_terms_and_powers_collect() {
        let x = Expr::sym("x");
        let y = Expr::sym("y");
        assert_eq!(x + x, 2 * x);
        assert_eq!(x - x, Expr::zero());
        assert_eq!(x * x, x.powi(2));
        assert_eq!(x / x, Expr::one());
        assert_eq!((x * y).powi(2) / y, x.powi(2) * y);
        assert_eq!(3 * x * y - 2 * (y * x), x * y);
        assert_eq!(Expr::frac(1, 2) + Expr::frac(1, 3), Expr::frac(5, 6));
    }

    #[test]
    fn function_symmetries() {
        let x = Expr::sym("x");
        assert_eq!((-x).sin(), -x.sin());
        assert_eq!((-x).cos(), x.cos());
        assert_eq!(Expr::zero().cos(), Expr::one());
        assert_eq!(Expr::int(-3).abs(), Expr::int(3));
    }

    #[test]
    fn eval_matches() {
        let x = Expr::sym("x");
        let e = (x.sin() + x.powi(2)) / (Expr::one() + x.cos().abs());
        let v = e.eval_with(&mut |_| 0.7);
        let want = (0.7f64.sin() + 0.49) / (1.0 + 0.7f64.cos().abs());
        assert!((v - want).abs() < 1e-15);
    }
}
