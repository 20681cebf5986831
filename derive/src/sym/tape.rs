//! Compiled numeric tapes: a linear instruction list over `f64` slots.
//!
//! [`Tape::compile`] lowers a set of output expressions once:
//!
//! * common subexpressions come for free from the DAG (each node is lowered once);
//! * integer powers become multiplication chains (`x^5 = (x^2)^2 * x`), negative
//!   powers and `x * y^-1` become divisions, `x^(1/2)` a square root;
//! * `a + (-1)*b` becomes a subtraction, `(-1)*x` a negation;
//! * `sin(u)` and `cos(u)` of the same argument are fused into one `SinCos`;
//! * slots are reused once their value is dead (linear-scan liveness), so the
//!   scratch buffer is small.
//!
//! [`Tape::eval`] then runs without allocation. The instruction list is public
//! (read-only) so a code generator can translate it.
//!
//! [`Tape::split_by_inputs`] partitions a tape into the instructions that
//! depend only on some inputs (e.g. the parameters, constant during a
//! simulation) and the rest, so the former run once per parameter vector
//! ([`SplitTape`]).

use std::collections::{HashMap, HashSet};
use std::fmt;
use std::sync::Arc;

use super::expr::{Expr, Func, Node, Symbol};
use super::jit::Native;
use super::rational::Rational;

/// One tape instruction. Operands and destinations are scratch slot indices.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum Instr {
    /// `dst = value`
    Const {
        /// destination slot
        dst: u32,
        /// constant
        value: f64,
    },
    /// `dst = inputs[index]`
    Input {
        /// destination slot
        dst: u32,
        /// index into the input vector
        index: u32,
    },
    /// `dst = a + b`
    Add {
        /// destination slot
        dst: u32,
        /// left operand
        a: u32,
        /// right operand
        b: u32,
    },
    /// `dst = a - b`
    Sub {
        /// destination slot
        dst: u32,
        /// left operand
        a: u32,
        /// right operand
        b: u32,
    },
    /// `dst = a * b`
    Mul {
        /// destination slot
        dst: u32,
        /// left operand
        a: u32,
        /// right operand
        b: u32,
    },
    /// `dst = a / b`
    Div {
        /// destination slot
        dst: u32,
        /// numerator
        a: u32,
        /// denominator
        b: u32,
    },
    /// `dst = -a`
    Neg {
        /// destination slot
        dst: u32,
        /// operand
        a: u32,
    },
    /// `dst = sqrt(a)`
    Sqrt {
        /// destination slot
        dst: u32,
        /// operand
        a: u32,
    },
    /// `dst = a.powf(b)`
    Pow {
        /// destination slot
        dst: u32,
        /// base
        a: u32,
        /// exponent
        b: u32,
    },
    /// `dst = f(a)`
    Func {
        /// destination slot
        dst: u32,
        /// function
        f: Func,
        /// argument
        a: u32,
    },
    /// `(sin_dst, cos_dst) = a.sin_cos()`
    SinCos {
        /// destination of the sine
        sin_dst: u32,
        /// destination of the cosine
        cos_dst: u32,
        /// argument
        a: u32,
    },
    /// `dst = atan2(y, x)`
    Atan2 {
        /// destination slot
        dst: u32,
        /// y
        y: u32,
        /// x
        x: u32,
    },
}

impl Instr {
    fn operands(&self) -> [Option<u32>; 2] {
        match *self {
            Instr::Const { .. } | Instr::Input { .. } => [None, None],
            Instr::Add { a, b, .. }
            | Instr::Sub { a, b, .. }
            | Instr::Mul { a, b, .. }
            | Instr::Div { a, b, .. }
            | Instr::Pow { a, b, .. } => [Some(a), Some(b)],
            Instr::Atan2 { y, x, .. } => [Some(y), Some(x)],
            Instr::Neg { a, .. }
            | Instr::Sqrt { a, .. }
            | Instr::Func { a, .. }
            | Instr::SinCos { a, .. } => [Some(a), None],
        }
    }

    fn dsts(&self) -> [Option<u32>; 2] {
        match *self {
            Instr::SinCos {
                sin_dst, cos_dst, ..
            } => [Some(sin_dst), Some(cos_dst)],
            Instr::Const { dst, .. }
            | Instr::Input { dst, .. }
            | Instr::Add { dst, .. }
            | Instr::Sub { dst, .. }
            | Instr::Mul { dst, .. }
            | Instr::Div { dst, .. }
            | Instr::Neg { dst, .. }
            | Instr::Sqrt { dst, .. }
            | Instr::Pow { dst, .. }
            | Instr::Func { dst, .. }
            | Instr::Atan2 { dst, .. } => [Some(dst), None],
        }
    }

    fn map(&self, m: &mut impl FnMut(u32) -> u32, d: &mut impl FnMut(u32) -> u32) -> Instr {
        match *self {
            Instr::Const { dst, value } => Instr::Const { dst: d(dst), value },
            Instr::Input { dst, index } => Instr::Input { dst: d(dst), index },
            Instr::Add { dst, a, b } => {
                let (a, b) = (m(a), m(b));
                Instr::Add { dst: d(dst), a, b }
            }
            Instr::Sub { dst, a, b } => {
                let (a, b) = (m(a), m(b));
                Instr::Sub { dst: d(dst), a, b }
            }
            Instr::Mul { dst, a, b } => {
                let (a, b) = (m(a), m(b));
                Instr::Mul { dst: d(dst), a, b }
            }
            Instr::Div { dst, a, b } => {
                let (a, b) = (m(a), m(b));
                Instr::Div { dst: d(dst), a, b }
            }
            Instr::Pow { dst, a, b } => {
                let (a, b) = (m(a), m(b));
                Instr::Pow { dst: d(dst), a, b }
            }
            Instr::Atan2 { dst, y, x } => {
                let (y, x) = (m(y), m(x));
                Instr::Atan2 { dst: d(dst), y, x }
            }
            Instr::Neg { dst, a } => {
                let a = m(a);
                Instr::Neg { dst: d(dst), a }
            }
            Instr::Sqrt { dst, a } => {
                let a = m(a);
                Instr::Sqrt { dst: d(dst), a }
            }
            Instr::Func { dst, f, a } => {
                let a = m(a);
                Instr::Func { dst: d(dst), f, a }
            }
            Instr::SinCos {
                sin_dst,
                cos_dst,
                a,
            } => {
                let a = m(a);
                Instr::SinCos {
                    sin_dst: d(sin_dst),
                    cos_dst: d(cos_dst),
                    a,
                }
            }
        }
    }
}

impl fmt::Display for Instr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Instr::Const { dst, value } => write!(f, "s{dst} = {value:?}"),
            Instr::Input { dst, index } => write!(f, "s{dst} = in[{index}]"),
            Instr::Add { dst, a, b } => write!(f, "s{dst} = s{a} + s{b}"),
            Instr::Sub { dst, a, b } => write!(f, "s{dst} = s{a} - s{b}"),
            Instr::Mul { dst, a, b } => write!(f, "s{dst} = s{a} * s{b}"),
            Instr::Div { dst, a, b } => write!(f, "s{dst} = s{a} / s{b}"),
            Instr::Neg { dst, a } => write!(f, "s{dst} = -s{a}"),
            Instr::Sqrt { dst, a } => write!(f, "s{dst} = sqrt(s{a})"),
            Instr::Pow { dst, a, b } => write!(f, "s{dst} = s{a} ^ s{b}"),
            Instr::Func { dst, f: g, a } => write!(f, "s{dst} = {}(s{a})", g.name()),
            Instr::SinCos {
                sin_dst,
                cos_dst,
                a,
            } => write!(f, "(s{sin_dst}, s{cos_dst}) = sin_cos(s{a})"),
            Instr::Atan2 { dst, y, x } => write!(f, "s{dst} = atan2(s{y}, s{x})"),
        }
    }
}

/// Why a tape could not be compiled.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum TapeError {
    /// An output mentions a symbol that is not among the inputs.
    UnknownSymbol(Symbol),
}

impl fmt::Display for TapeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TapeError::UnknownSymbol(s) => write!(f, "symbol `{s}` is not among the tape inputs"),
        }
    }
}

impl std::error::Error for TapeError {}

/// A compiled evaluation program for a vector of expressions.
#[derive(Clone)]
pub struct Tape {
    inputs: Vec<Symbol>,
    instrs: Vec<Instr>,
    outputs: Vec<u32>,
    n_slots: usize,
}

/// Lowering to SSA values (value ids are later mapped to slots).
struct Lower {
    instrs: Vec<Instr>,
    n_values: u32,
    memo: HashMap<Expr, u32>,
    consts: HashMap<u64, u32>,
    powi_memo: HashMap<(u32, u64), u32>,
    input_index: HashMap<Symbol, u32>,
    /// Argument -> (sin node, cos node) where both occur.
    fused: HashMap<Expr, (Expr, Expr)>,
}

impl Lower {
    fn fresh(&mut self) -> u32 {
        let v = self.n_values;
        self.n_values += 1;
        v
    }

    fn push2(&mut self, make: impl FnOnce(u32) -> Instr) -> u32 {
        let dst = self.fresh();
        self.instrs.push(make(dst));
        dst
    }

    fn constant(&mut self, value: f64) -> u32 {
        if let Some(&v) = self.consts.get(&value.to_bits()) {
            return v;
        }
        let v = self.push2(|dst| Instr::Const { dst, value });
        self.consts.insert(value.to_bits(), v);
        v
    }

    fn powi(&mut self, base: u32, n: u64) -> u32 {
        if n == 1 {
            return base;
        }
        if let Some(&v) = self.powi_memo.get(&(base, n)) {
            return v;
        }
        let v = if n.is_multiple_of(2) {
            let h = self.powi(base, n / 2);
            self.push2(|dst| Instr::Mul { dst, a: h, b: h })
        } else {
            let h = self.powi(base, n - 1);
            self.push2(|dst| Instr::Mul { dst, a: h, b: base })
        };
        self.powi_memo.insert((base, n), v);
        v
    }

    /// `base ^ r` for a positive rational `r`, or `None` if not special.
    fn pos_pow(&mut self, base: Expr, r: Rational) -> Option<u32> {
        if r.is_integer() {
            let n = u64::try_from(r.numer()).ok()?;
            if n > 64 {
                return None;
            }
            let b = self.lower(base);
            return Some(self.powi(b, n));
        }
        if r.denom() == 2 {
            let n = u64::try_from(r.numer()).ok()?;
            if n > 64 {
                return None;
            }
            let b = self.lower(base);
            let s = self.push2(|dst| Instr::Sqrt { dst, a: b });
            return Some(self.powi(s, n));
        }
        None
    }

    fn product(&mut self, vals: &[u32]) -> Option<u32> {
        let mut it = vals.iter().copied();
        let first = it.next()?;
        Some(it.fold(first, |acc, v| {
            self.push2(|dst| Instr::Mul { dst, a: acc, b: v })
        }))
    }

    fn lower(&mut self, e: Expr) -> u32 {
        if let Some(&v) = self.memo.get(&e) {
            return v;
        }
        let v = match e.node() {
            Node::Rational(r) => self.constant(r.to_f64()),
            Node::Float(b) => self.constant(b.value()),
            Node::Symbol(s) => {
                let index = self.input_index[s];
                self.push2(|dst| Instr::Input { dst, index })
            }
            Node::Add(ts) => {
                let mut pos = Vec::new();
                let mut neg = Vec::new();
                for t in ts.iter() {
                    let (c, rest) = t.coeff_and_rest();
                    if c.is_negative() {
                        let mag = if c == Rational::MINUS_ONE {
                            rest
                        } else {
                            Expr::rational(c.abs()) * rest
                        };
                        neg.push(self.lower(mag));
                    } else {
                        pos.push(self.lower(*t));
                    }
                }
                let mut acc = match pos.first() {
                    Some(&p) => pos[1..]
                        .iter()
                        .fold(p, |acc, &b| self.push2(|dst| Instr::Add { dst, a: acc, b })),
                    None => {
                        let n0 = neg.remove(0);
                        self.push2(|dst| Instr::Neg { dst, a: n0 })
                    }
                };
                for b in neg {
                    let a = acc;
                    acc = self.push2(|dst| Instr::Sub { dst, a, b });
                }
                acc
            }
            Node::Mul(fs) => {
                let mut negate = false;
                let mut num = Vec::new();
                let mut den = Vec::new();
                for f in fs.iter() {
                    if let Some(c) = f.as_rational() {
                        if c == Rational::MINUS_ONE {
                            negate = true;
                            continue;
                        }
                    }
                    let (b, x) = f.base_and_exp();
                    match x.as_rational() {
                        Some(r) if r.is_negative() => match self.pos_pow(b, r.abs()) {
                            Some(v) => den.push(v),
                            None => num.push(self.lower(*f)),
                        },
                        _ => num.push(self.lower(*f)),
                    }
                }
                let n = self.product(&num);
                let d = self.product(&den);
                let v = match (n, d) {
                    (Some(n), None) => n,
                    (Some(a), Some(b)) => self.push2(|dst| Instr::Div { dst, a, b }),
                    (None, Some(b)) => {
                        let a = self.constant(if negate { -1.0 } else { 1.0 });
                        negate = false;
                        self.push2(|dst| Instr::Div { dst, a, b })
                    }
                    (None, None) => self.constant(1.0),
                };
                if negate {
                    self.push2(|dst| Instr::Neg { dst, a: v })
                } else {
                    v
                }
            }
            Node::Pow(b, x) => {
                let special = match x.as_rational() {
                    Some(r) if r.is_negative() => self.pos_pow(*b, r.abs()).map(|d| {
                        let one = self.constant(1.0);
                        self.push2(|dst| Instr::Div { dst, a: one, b: d })
                    }),
                    Some(r) => self.pos_pow(*b, r),
                    None => None,
                };
                match special {
                    Some(v) => v,
                    None => {
                        let a = self.lower(*b);
                        let bb = self.lower(*x);
                        self.push2(|dst| Instr::Pow { dst, a, b: bb })
                    }
                }
            }
            Node::Func(f, u) => {
                if matches!(f, Func::Sin | Func::Cos) {
                    if let Some(&(s, c)) = self.fused.get(u) {
                        let a = self.lower(*u);
                        let sin_dst = self.fresh();
                        let cos_dst = self.fresh();
                        self.instrs.push(Instr::SinCos {
                            sin_dst,
                            cos_dst,
                            a,
                        });
                        self.memo.insert(s, sin_dst);
                        self.memo.insert(c, cos_dst);
                        return self.memo[&e];
                    }
                }
                let a = self.lower(*u);
                let f = *f;
                self.push2(|dst| Instr::Func { dst, f, a })
            }
            Node::Atan2(y, x) => {
                let y = self.lower(*y);
                let x = self.lower(*x);
                self.push2(|dst| Instr::Atan2 { dst, y, x })
            }
            Node::Named(_, d) => self.lower(*d),
        };
        self.memo.insert(e, v);
        v
    }
}

impl Tape {
    /// Compile `outputs` as functions of `inputs` (in that order).
    pub fn compile(outputs: &[Expr], inputs: &[Symbol]) -> Result<Tape, TapeError> {
        let mut input_index = HashMap::new();
        for (i, s) in inputs.iter().enumerate() {
            input_index.entry(*s).or_insert(i as u32);
        }
        // Scan the DAG: check symbols, find sin/cos pairs.
        let mut seen = HashSet::new();
        let mut stack: Vec<Expr> = outputs.to_vec();
        let mut sins: HashMap<Expr, Expr> = HashMap::new();
        let mut coss: HashMap<Expr, Expr> = HashMap::new();
        let mut unknown: Option<Symbol> = None;
        while let Some(e) = stack.pop() {
            if !seen.insert(e) {
                continue;
            }
            match e.node() {
                Node::Symbol(s)
                    if !input_index.contains_key(s) && unknown.is_none_or(|u| *s < u) =>
                {
                    unknown = Some(*s);
                }
                Node::Func(Func::Sin, u) => {
                    sins.insert(*u, e);
                }
                Node::Func(Func::Cos, u) => {
                    coss.insert(*u, e);
                }
                _ => {}
            }
            stack.extend(e.children());
        }
        if let Some(s) = unknown {
            return Err(TapeError::UnknownSymbol(s));
        }
        let fused = sins
            .iter()
            .filter_map(|(u, s)| coss.get(u).map(|c| (*u, (*s, *c))))
            .collect();
        let mut lw = Lower {
            instrs: Vec::new(),
            n_values: 0,
            memo: HashMap::new(),
            consts: HashMap::new(),
            powi_memo: HashMap::new(),
            input_index,
            fused,
        };
        let out_vals: Vec<u32> = outputs.iter().map(|e| lw.lower(*e)).collect();
        Ok(allocate(
            lw.instrs,
            lw.n_values as usize,
            &out_vals,
            inputs.to_vec(),
        ))
    }

    /// The input symbols, in order.
    pub fn inputs(&self) -> &[Symbol] {
        &self.inputs
    }

    /// The instruction list.
    pub fn instructions(&self) -> &[Instr] {
        &self.instrs
    }

    /// The slot holding each output after evaluation.
    pub fn output_slots(&self) -> &[u32] {
        &self.outputs
    }

    /// Required length of the `scratch` buffer.
    pub fn scratch_len(&self) -> usize {
        self.n_slots
    }

    /// Number of outputs.
    pub fn n_outputs(&self) -> usize {
        self.outputs.len()
    }

    /// Evaluate without allocating. Panics if `inputs.len()` differs from the
    /// number of inputs, `out` is shorter than the number of outputs or
    /// `scratch` shorter than [`Tape::scratch_len`].
    pub fn eval(&self, inputs: &[f64], out: &mut [f64], scratch: &mut [f64]) {
        assert_eq!(inputs.len(), self.inputs.len(), "tape input length");
        assert!(out.len() >= self.outputs.len(), "tape output length");
        assert!(scratch.len() >= self.n_slots, "tape scratch length");
        // SAFETY: in_bounds at construction; lengths asserted above
        unsafe { run(&self.instrs, inputs, scratch) };
        for (o, slot) in out.iter_mut().zip(&self.outputs) {
            *o = scratch[*slot as usize];
        }
    }

    /// Evaluate into a fresh vector (allocates).
    pub fn eval_vec(&self, inputs: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.outputs.len()];
        let mut scratch = vec![0.0; self.n_slots];
        self.eval(inputs, &mut out, &mut scratch);
        out
    }
}

/// Map SSA values to slots, reusing a slot once its value is dead.
fn allocate(instrs: Vec<Instr>, n_values: usize, outs: &[u32], inputs: Vec<Symbol>) -> Tape {
    let (instrs, slot_of, n_slots) = assign_slots(&instrs, n_values, outs);
    assert!(
        in_bounds(&instrs, n_slots, inputs.len()),
        "tape slots out of range"
    );
    Tape {
        inputs,
        outputs: outs.iter().map(|o| slot_of[*o as usize]).collect(),
        instrs,
        n_slots,
    }
}

/// Linear-scan slot assignment of an SSA instruction list (value ids as
/// slots, each defined once, operands defined earlier). Values in
/// `live_forever` keep their slot to the end and beyond: no later
/// instruction writes it. Returns the rewritten instructions, the slot of
/// every value and the number of slots.
fn assign_slots(
    instrs: &[Instr],
    n_values: usize,
    live_forever: &[u32],
) -> (Vec<Instr>, Vec<u32>, usize) {
    const LIVE_FOREVER: usize = usize::MAX;
    let mut last_use = vec![0usize; n_values];
    for (i, ins) in instrs.iter().enumerate() {
        for d in ins.dsts().into_iter().flatten() {
            last_use[d as usize] = i;
        }
        for a in ins.operands().into_iter().flatten() {
            last_use[a as usize] = i;
        }
    }
    for &o in live_forever {
        last_use[o as usize] = LIVE_FOREVER;
    }
    let mut slot_of = vec![u32::MAX; n_values];
    let mut free: Vec<u32> = Vec::new();
    let mut n_slots: u32 = 0;
    let mut out_instrs = Vec::with_capacity(instrs.len());
    for (i, ins) in instrs.iter().enumerate() {
        // Operands dying here release their slots before the destination is
        // assigned: every instruction reads all operands before writing.
        let mut dying: Vec<u32> = Vec::new();
        for a in ins.operands().into_iter().flatten() {
            if last_use[a as usize] == i && !dying.contains(&a) {
                dying.push(a);
            }
        }
        let mapped_ops: Vec<u32> = ins
            .operands()
            .into_iter()
            .flatten()
            .map(|a| slot_of[a as usize])
            .collect();
        for a in dying {
            free.push(slot_of[a as usize]);
        }
        free.sort_unstable_by(|a, b| b.cmp(a));
        let mut k = 0;
        let new = ins.map(
            &mut |_| {
                let s = mapped_ops[k];
                k += 1;
                s
            },
            &mut |d| {
                let s = free.pop().unwrap_or_else(|| {
                    n_slots += 1;
                    n_slots - 1
                });
                slot_of[d as usize] = s;
                s
            },
        );
        // Values defined here but never used afterwards are dead at once.
        for d in ins.dsts().into_iter().flatten() {
            if last_use[d as usize] == i {
                free.push(slot_of[d as usize]);
            }
        }
        out_instrs.push(new);
    }
    (out_instrs, slot_of, n_slots as usize)
}

/// Identity of an SSA instruction apart from its destinations: operation,
/// immediate (constant bits, input index or function) and operands. Two
/// instructions with the same key compute bit-identical values.
fn value_key(ins: &Instr) -> (u8, u64, u32, u32) {
    match *ins {
        Instr::Const { value, .. } => (0, value.to_bits(), 0, 0),
        Instr::Input { index, .. } => (1, u64::from(index), 0, 0),
        Instr::Add { a, b, .. } => (2, 0, a, b),
        Instr::Sub { a, b, .. } => (3, 0, a, b),
        Instr::Mul { a, b, .. } => (4, 0, a, b),
        Instr::Div { a, b, .. } => (5, 0, a, b),
        Instr::Pow { a, b, .. } => (6, 0, a, b),
        Instr::Atan2 { y, x, .. } => (7, 0, y, x),
        Instr::Neg { a, .. } => (8, 0, a, 0),
        Instr::Sqrt { a, .. } => (9, 0, a, 0),
        Instr::Func { f, a, .. } => (10, f as u64, a, 0),
        Instr::SinCos { a, .. } => (11, 0, a, 0),
    }
}

/// Do all of `instrs`' slots lie below `n_slots` and their input indices
/// below `n_inputs`? Checked once when a tape is built (it is never changed
/// after), which is what makes [`run`]'s unchecked accesses sound.
fn in_bounds(instrs: &[Instr], n_slots: usize, n_inputs: usize) -> bool {
    instrs.iter().all(|ins| {
        let input_ok = match *ins {
            Instr::Input { index, .. } => (index as usize) < n_inputs,
            _ => true,
        };
        input_ok
            && ins
                .operands()
                .into_iter()
                .chain(ins.dsts())
                .flatten()
                .all(|a| (a as usize) < n_slots)
    })
}

/// Execute `instrs` on the slots `s`.
///
/// Without bounds checks on the slots: in a simulation these tapes run at
/// every integrator stage, and three checks per instruction were a fifth of
/// their time.
///
/// # Safety
/// Every slot of `instrs` is below `s.len()` and every input index below
/// `inputs.len()`: the tape's constructors assert [`in_bounds`] for their
/// `n_slots` and input count, and every caller asserts `s.len() >= n_slots`
/// and `inputs.len() ==` the input count before calling.
#[inline(always)]
unsafe fn run(instrs: &[Instr], inputs: &[f64], s: &mut [f64]) {
    // SAFETY (all accesses below): in bounds by the contract above.
    macro_rules! r {
        ($i:expr) => {
            *s.get_unchecked($i as usize)
        };
    }
    macro_rules! w {
        ($i:expr, $v:expr) => {{
            let v = $v;
            *s.get_unchecked_mut($i as usize) = v;
        }};
    }
    for ins in instrs {
        match *ins {
            Instr::Const { dst, value } => w!(dst, value),
            Instr::Input { dst, index } => w!(dst, *inputs.get_unchecked(index as usize)),
            Instr::Add { dst, a, b } => w!(dst, r!(a) + r!(b)),
            Instr::Sub { dst, a, b } => w!(dst, r!(a) - r!(b)),
            Instr::Mul { dst, a, b } => w!(dst, r!(a) * r!(b)),
            Instr::Div { dst, a, b } => w!(dst, r!(a) / r!(b)),
            Instr::Neg { dst, a } => w!(dst, -r!(a)),
            Instr::Sqrt { dst, a } => w!(dst, r!(a).sqrt()),
            Instr::Pow { dst, a, b } => w!(dst, r!(a).powf(r!(b))),
            Instr::Func { dst, f, a } => w!(dst, f.eval(r!(a))),
            Instr::SinCos {
                sin_dst,
                cos_dst,
                a,
            } => {
                let (sv, cv) = super::trig::sin_cos(r!(a));
                w!(sin_dst, sv);
                w!(cos_dst, cv);
            }
            Instr::Atan2 { dst, y, x } => w!(dst, r!(y).atan2(r!(x))),
        }
    }
}

/// A [`Tape`] split into a *slow* part that depends only on the inputs marked
/// slow (and on constants) and a *fast* part for everything else, built by
/// [`Tape::split_by_inputs`].
///
/// Typical use: the slow inputs are a model's parameters, constant during a
/// simulation, and the fast ones the state and inputs that change at every
/// integrator stage. [`SplitTape::eval_slow`] runs once per parameter vector
/// and leaves its results in the scratch buffer; [`SplitTape::eval_fast`]
/// then runs per stage, reading them.
///
/// The two parts are the instructions of the original tape (partitioned,
/// each keeping its operands and operation; exact repeats kept once), so
/// `eval_slow` followed by `eval_fast` yields outputs bit-identical to
/// [`Tape::eval`] at the same inputs.
#[derive(Clone)]
pub struct SplitTape {
    /// The fast part and its output copies as native code, where the
    /// target has it ([`super::jit`]); interpreted otherwise.
    native: Option<Arc<Native>>,
    slow: Vec<bool>,
    slow_instrs: Vec<Instr>,
    fast_instrs: Vec<Instr>,
    outputs: Vec<u32>,
    /// `(output, slot)` of the outputs that depend on a fast input.
    fast_outputs: Vec<(u32, u32)>,
    n_slots: usize,
}

impl Tape {
    /// Split the tape by which inputs are slow: `slow[i]` marks input `i`.
    ///
    /// An instruction is slow when it is a constant, reads a slow input, or
    /// has only slow operands; the slow instructions keep their relative
    /// order and run first, the fast ones keep theirs. An instruction that
    /// repeats an earlier one (same operation on the same values, as product
    /// chains of different terms often do) is kept once. Slots are reassigned
    /// so that every slow value the fast part (or an output) reads keeps its
    /// own slot, never written by the fast part.
    ///
    /// Panics if `slow.len()` differs from the number of inputs (as
    /// [`Tape::eval`] does for a wrong input length).
    pub fn split_by_inputs(&self, slow: &[bool]) -> SplitTape {
        assert_eq!(slow.len(), self.inputs.len(), "slow-input mask length");
        // Back to SSA: every destination write is a new value, except that
        // an instruction repeating an earlier one (same operation on the same
        // values) is dropped and its destinations alias the earlier values.
        let mut current = vec![u32::MAX; self.n_slots];
        let mut n_values: u32 = 0;
        let mut seen: HashMap<(u8, u64, u32, u32), [Option<u32>; 2]> = HashMap::new();
        let mut ssa: Vec<Instr> = Vec::with_capacity(self.instrs.len());
        for ins in &self.instrs {
            // Operands are read (in `operands` order) before any write.
            let ops: Vec<u32> = ins
                .operands()
                .into_iter()
                .flatten()
                .map(|a| current[a as usize])
                .collect();
            let mut k = 0;
            let probe = ins.map(
                &mut |_| {
                    k += 1;
                    ops[k - 1]
                },
                &mut |_| 0,
            );
            let key = value_key(&probe);
            let vals = match seen.get(&key) {
                Some(&vals) => vals,
                None => {
                    let fresh = probe.map(&mut |a| a, &mut |_| {
                        n_values += 1;
                        n_values - 1
                    });
                    seen.insert(key, fresh.dsts());
                    ssa.push(fresh);
                    fresh.dsts()
                }
            };
            for (slot, v) in ins
                .dsts()
                .into_iter()
                .flatten()
                .zip(vals.into_iter().flatten())
            {
                current[slot as usize] = v;
            }
        }
        let out_vals: Vec<u32> = self.outputs.iter().map(|o| current[*o as usize]).collect();
        // Classify values; order slow instructions before fast ones.
        let mut is_slow = vec![false; n_values as usize];
        let (mut slow_ssa, mut fast_ssa) = (Vec::new(), Vec::new());
        for ins in &ssa {
            let s = match *ins {
                Instr::Const { .. } => true,
                Instr::Input { index, .. } => slow[index as usize],
                _ => ins
                    .operands()
                    .into_iter()
                    .flatten()
                    .all(|a| is_slow[a as usize]),
            };
            for d in ins.dsts().into_iter().flatten() {
                is_slow[d as usize] = s;
            }
            if s {
                slow_ssa.push(*ins);
            } else {
                fast_ssa.push(*ins);
            }
        }
        // Slow values read by the fast part must survive every fast call.
        let mut keep: Vec<u32> = out_vals.clone();
        for ins in &fast_ssa {
            keep.extend(
                ins.operands()
                    .into_iter()
                    .flatten()
                    .filter(|a| is_slow[*a as usize]),
            );
        }
        keep.sort_unstable();
        keep.dedup();
        let n_slow = slow_ssa.len();
        let mut ordered = slow_ssa;
        ordered.extend(fast_ssa);
        let (mut instrs, slot_of, n_slots) = assign_slots(&ordered, n_values as usize, &keep);
        assert!(
            in_bounds(&instrs, n_slots, slow.len()),
            "tape slots out of range"
        );
        let fast_instrs = instrs.split_off(n_slow);
        let outputs: Vec<u32> = out_vals.iter().map(|v| slot_of[*v as usize]).collect();
        let fast_outputs: Vec<(u32, u32)> = (0u32..)
            .zip(&out_vals)
            .filter(|(_, v)| !is_slow[**v as usize])
            .map(|(i, _)| (i, outputs[i as usize]))
            .collect();
        let native = Native::compile(
            &fast_instrs,
            &fast_outputs,
            n_slots,
            slow.len(),
            outputs.len(),
        )
        .map(Arc::new);
        SplitTape {
            native,
            slow: slow.to_vec(),
            slow_instrs: instrs,
            fast_instrs,
            outputs,
            fast_outputs,
            n_slots,
        }
    }
}

impl SplitTape {
    /// Which inputs are slow (the mask given to [`Tape::split_by_inputs`]).
    pub fn slow_inputs(&self) -> &[bool] {
        &self.slow
    }

    /// Instructions run by [`SplitTape::eval_slow`].
    pub fn slow_instructions(&self) -> &[Instr] {
        &self.slow_instrs
    }

    /// Instructions run by [`SplitTape::eval_fast`].
    pub fn fast_instructions(&self) -> &[Instr] {
        &self.fast_instrs
    }

    /// Required length of the `scratch` buffer (may exceed the unsplit
    /// tape's, since slow values stay live across fast calls).
    pub fn scratch_len(&self) -> usize {
        self.n_slots
    }

    /// Number of outputs.
    pub fn n_outputs(&self) -> usize {
        self.outputs.len()
    }

    /// Evaluate the slow part into `scratch`, reading only the slow entries
    /// of `inputs` (the full input vector; fast entries are ignored). Call it
    /// again whenever a slow input changes. Does not allocate. Panics if
    /// `inputs.len()` differs from the number of inputs or `scratch` is
    /// shorter than [`SplitTape::scratch_len`].
    pub fn eval_slow(&self, inputs: &[f64], scratch: &mut [f64]) {
        assert_eq!(inputs.len(), self.slow.len(), "tape input length");
        assert!(scratch.len() >= self.n_slots, "tape scratch length");
        // SAFETY: in_bounds at construction; lengths asserted above
        unsafe { run(&self.slow_instrs, inputs, scratch) };
    }

    /// [`SplitTape::eval_slow`], then write every output's slot into `out`:
    /// the outputs that depend on slow inputs only are then final, for
    /// [`SplitTape::eval_fast_changed`] to leave them there (the others hold
    /// stale values until it runs). Panics as `eval_slow` does, or if `out` is shorter
    /// than the number of outputs.
    pub fn eval_slow_outputs(&self, inputs: &[f64], out: &mut [f64], scratch: &mut [f64]) {
        self.eval_slow(inputs, scratch);
        assert!(out.len() >= self.outputs.len(), "tape output length");
        for (o, slot) in out.iter_mut().zip(&self.outputs) {
            *o = scratch[*slot as usize];
        }
    }

    /// [`SplitTape::eval_fast`] writing only the outputs that depend on a
    /// fast input: the others keep the values the last
    /// [`SplitTape::eval_slow_outputs`] wrote into `out` (a simulation's
    /// derivative blocks are mostly such constants, zeros among them, and
    /// copying them at every stage was a fifth of the tape's time). Same
    /// requirements and panics as `eval_fast`, and `out` untouched by
    /// anything else since that `eval_slow_outputs`.
    pub fn eval_fast_changed(&self, inputs: &[f64], out: &mut [f64], scratch: &mut [f64]) {
        assert_eq!(inputs.len(), self.slow.len(), "tape input length");
        assert!(out.len() >= self.outputs.len(), "tape output length");
        assert!(scratch.len() >= self.n_slots, "tape scratch length");
        if let Some(native) = &self.native {
            // SAFETY: compiled for these bounds (n_slots, the input count,
            // the output count); lengths asserted above
            unsafe { native.run(inputs, scratch, out) };
            return;
        }
        // SAFETY: in_bounds at construction; lengths asserted above
        unsafe { run(&self.fast_instrs, inputs, scratch) };
        for &(o, slot) in &self.fast_outputs {
            out[o as usize] = scratch[slot as usize];
        }
    }

    /// Evaluate the fast part and write every output (slow-only outputs are
    /// copied from `scratch`). Reads only the fast entries of `inputs`.
    ///
    /// Requires a previous [`SplitTape::eval_slow`] on the same `scratch`
    /// with the same slow input values, and no other writes to `scratch` in
    /// between; otherwise the outputs are meaningless (this is not checked).
    /// Does not allocate. Panics if `inputs.len()` differs from the number
    /// of inputs, `out` is shorter than the number of outputs or `scratch`
    /// shorter than [`SplitTape::scratch_len`].
    pub fn eval_fast(&self, inputs: &[f64], out: &mut [f64], scratch: &mut [f64]) {
        assert_eq!(inputs.len(), self.slow.len(), "tape input length");
        assert!(out.len() >= self.outputs.len(), "tape output length");
        assert!(scratch.len() >= self.n_slots, "tape scratch length");
        match &self.native {
            // SAFETY: compiled for these bounds (n_slots, the input count,
            // the output count); lengths asserted above
            Some(native) => unsafe { native.run(inputs, scratch, out) },
            // SAFETY: in_bounds at construction; lengths asserted above
            None => unsafe { run(&self.fast_instrs, inputs, scratch) },
        }
        for (o, slot) in out.iter_mut().zip(&self.outputs) {
            *o = scratch[*slot as usize];
        }
    }

    /// Does the fast part run as native code ([`super::jit`]: x86-64 Linux,
    /// unless the environment sets `PLANTC_INTERPRET_TAPES`)?
    pub fn is_native(&self) -> bool {
        self.native.is_some()
    }

    /// The same tape with its fast part interpreted (to compare the two:
    /// their results are bit-identical).
    pub fn interpreted(&self) -> SplitTape {
        SplitTape {
            native: None,
            ..self.clone()
        }
    }
}

impl fmt::Debug for SplitTape {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "SplitTape({} inputs, {} slow, {} slow + {} fast instructions, {} slots)",
            self.slow.len(),
            self.slow.iter().filter(|s| **s).count(),
            self.slow_instrs.len(),
            self.fast_instrs.len(),
            self.n_slots
        )?;
        writeln!(f, "  slow:")?;
        for ins in &self.slow_instrs {
            writeln!(f, "  {ins}")?;
        }
        writeln!(f, "  fast:")?;
        for ins in &self.fast_instrs {
            writeln!(f, "  {ins}")?;
        }
        for (i, o) in self.outputs.iter().enumerate() {
            writeln!(f, "  out[{i}] = s{o}")?;
        }
        Ok(())
    }
}

impl fmt::Debug for Tape {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "Tape({} inputs, {} instructions, {} slots)",
            self.inputs.len(),
            self.instrs.len(),
            self.n_slots
        )?;
        for (i, s) in self.inputs.iter().enumerate() {
            writeln!(f, "  in[{i}] = {s}")?;
        }
        for ins in &self.instrs {
            writeln!(f, "  {ins}")?;
        }
        for (i, o) in self.outputs.iter().enumerate() {
            writeln!(f, "  out[{i}] = s{o}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fuses_and_matches_tree() {
        let x = Expr::sym("x");
        let y = Expr::sym("y");
        let e1 = x.sin() * x.cos() - y.powi(5) / (x + 1);
        let e2 = x.sin().powi(-2) + (x * x + 1).sqrt() - 3 * y;
        let t = Tape::compile(&[e1, e2], &[Symbol::new("x"), Symbol::new("y")]).unwrap();
        let n_sincos = t
            .instructions()
            .iter()
            .filter(|i| matches!(i, Instr::SinCos { .. }))
            .count();
        assert_eq!(n_sincos, 1, "{t:?}");
        assert!(!t
            .instructions()
            .iter()
            .any(|i| matches!(i, Instr::Pow { .. })));
        let v = t.eval_vec(&[0.3, -1.7]);
        for (got, e) in v.iter().zip([e1, e2]) {
            let want = e.eval_with(&mut |s| if s.name() == "x" { 0.3 } else { -1.7 });
            assert!((got - want).abs() <= 1e-12 * want.abs().max(1.0));
        }
    }

    #[test]
    fn unknown_symbol_is_named() {
        let e = Expr::sym("x") + Expr::sym("zeta");
        let err = Tape::compile(&[e], &[Symbol::new("x")]).unwrap_err();
        assert_eq!(err, TapeError::UnknownSymbol(Symbol::new("zeta")));
        assert!(err.to_string().contains("zeta"));
    }

    #[test]
    fn send_sync_clone() {
        fn check<T: Send + Sync + Clone>() {}
        check::<Tape>();
        check::<SplitTape>();
    }

    /// Inputs `[x, p, q]` with `p, q` slow: the parameter-only products run
    /// in the slow part, the fast part reads only `x`, and a parameter-only
    /// output is still written by `eval_fast`.
    #[test]
    fn split_moves_parameter_work_to_slow_part() {
        let (x, p, q) = (Expr::sym("x"), Expr::sym("p"), Expr::sym("q"));
        let outs = [p * q * x.sin() + p.powi(3) / q, (p + q).sqrt(), x * x];
        let syms = [Symbol::new("x"), Symbol::new("p"), Symbol::new("q")];
        let t = Tape::compile(&outs, &syms).unwrap();
        let split = t.split_by_inputs(&[false, true, true]);
        let reads = |instrs: &[Instr], i: u32| {
            instrs
                .iter()
                .any(|ins| matches!(ins, Instr::Input { index, .. } if *index == i))
        };
        assert!(!reads(split.slow_instructions(), 0), "{split:?}");
        assert!(!reads(split.fast_instructions(), 1), "{split:?}");
        assert!(!reads(split.fast_instructions(), 2), "{split:?}");
        // Fast part: x, sin x, (p q) sin x, + (p^3/q), x*x: no division, no sqrt.
        assert!(!split
            .fast_instructions()
            .iter()
            .any(|i| matches!(i, Instr::Div { .. } | Instr::Sqrt { .. })));
        let mut scratch = vec![f64::NAN; split.scratch_len()];
        let mut out = [f64::NAN; 3];
        let mut inp = [0.0, 1.5, -0.25];
        split.eval_slow(&inp, &mut scratch);
        for xv in [0.3, -2.0, 7.5] {
            inp[0] = xv;
            split.eval_fast(&inp, &mut out, &mut scratch);
            let want = t.eval_vec(&inp);
            assert_eq!(
                out.map(f64::to_bits).to_vec(),
                want.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            );
        }
    }

    /// All-fast and all-slow masks: constants still go to the slow part;
    /// with everything slow the fast part is empty and only copies outputs.
    #[test]
    fn split_extreme_masks() {
        let (x, y) = (Expr::sym("x"), Expr::sym("y"));
        let outs = [x.cos() * 3 + y, Expr::int(2).sqrt()];
        let t = Tape::compile(&outs, &[Symbol::new("x"), Symbol::new("y")]).unwrap();
        let inp = [0.7, -1.1];
        for mask in [[false, false], [true, true]] {
            let split = t.split_by_inputs(&mask);
            if mask[0] {
                assert!(split.fast_instructions().is_empty(), "{split:?}");
            } else {
                assert!(split
                    .fast_instructions()
                    .iter()
                    .all(|i| !matches!(i, Instr::Const { .. })));
            }
            let mut scratch = vec![f64::NAN; split.scratch_len()];
            let mut out = [0.0; 2];
            split.eval_slow(&inp, &mut scratch);
            split.eval_fast(&inp, &mut out, &mut scratch);
            assert_eq!(out.to_vec(), t.eval_vec(&inp));
        }
    }

    /// `a b c` and `a b d` lower to two product chains both starting with
    /// `a * b`; the split keeps that multiplication once.
    #[test]
    fn split_drops_repeated_instructions() {
        let [a, b, c, d] = ["a", "b", "c", "d"].map(Expr::sym);
        let syms = ["a", "b", "c", "d"].map(Symbol::new);
        let t = Tape::compile(&[a * b * c, a * b * d], &syms).unwrap();
        let muls = |instrs: &[Instr]| {
            instrs
                .iter()
                .filter(|i| matches!(i, Instr::Mul { .. }))
                .count()
        };
        assert_eq!(muls(t.instructions()), 4, "{t:?}");
        let split = t.split_by_inputs(&[false; 4]);
        assert_eq!(muls(split.fast_instructions()), 3, "{split:?}");
        let inp = [0.1, 1.0 / 3.0, -7.0, 2.5];
        let mut scratch = vec![f64::NAN; split.scratch_len()];
        let mut out = [0.0; 2];
        split.eval_slow(&inp, &mut scratch);
        split.eval_fast(&inp, &mut out, &mut scratch);
        assert_eq!(out.to_vec(), t.eval_vec(&inp));
    }

    #[test]
    #[should_panic(expected = "slow-input mask length")]
    fn split_mask_length_is_checked() {
        let t = Tape::compile(&[Expr::sym("x")], &[Symbol::new("x")]).unwrap();
        t.split_by_inputs(&[true, false]);
    }
}
