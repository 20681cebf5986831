//! Semantic checks: name resolution, duplicates, let cycles, derivatives,
//! dimensional analysis, parameter sets and controllers.

use super::ast::*;
use super::diagnostic::{Diagnostic, Severity};
use super::effects::{self, ArgUnit, EffectKind};
use super::parser::parse;
use super::span::Span;
use super::units::{parse_unit, Dim, Ratio, Unit};
use std::collections::{BTreeMap, HashMap};
use std::ops::{Add, Div, Mul, Neg};

mod controllers;
pub use controllers::CONTROLLER_FUNCTIONS;

/// The error for a call of `function` with `found` arguments where it
/// takes `arity` (e.g. `2` or `1 or 2`).
pub(super) fn wrong_arity(
    function: &str,
    arity: impl std::fmt::Display,
    found: usize,
    span: Span,
) -> Diagnostic {
    Diagnostic::error(
        "plantc::wrong_arity",
        format!("`{function}` takes {arity} argument(s), found {found}"),
        span,
        "wrong number of arguments",
    )
}
#[path = "check_recorded.rs"]
mod recorded;

/// Result of [`parse_and_check`].
#[derive(Debug, Clone)]
pub struct Checked {
    /// The tree, when the file parsed without syntax errors (it may still
    /// have semantic errors: see [`Checked::has_errors`]). Force expressions
    /// have their effects expanded ([`Force::expr`]).
    pub model: Option<ModelFile>,
    /// All diagnostics, sorted by position.
    pub diagnostics: Vec<Diagnostic>,
    /// Resolved declarations (units, SI values, dimensions), when `model` is set.
    pub symbols: Option<Symbols>,
}

impl Checked {
    /// True if any diagnostic is an error.
    pub fn has_errors(&self) -> bool {
        self.diagnostics
            .iter()
            .any(|d| d.severity == Severity::Error)
    }

    /// The errors only.
    pub fn errors(&self) -> impl Iterator<Item = &Diagnostic> {
        self.diagnostics.iter().filter(|d| d.is_error())
    }
}

/// What a name denotes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SymbolKind {
    /// A generalised coordinate.
    Coordinate(CoordKind),
    /// A control input.
    Input,
    /// A parameter.
    Parameter,
    /// A `let` definition.
    Let,
    /// A named output (`output tip = ...`).
    Output,
    /// The kinetic or potential energy name.
    Energy,
}

impl SymbolKind {
    fn describe(self) -> &'static str {
        match self {
            SymbolKind::Coordinate(_) => "a coordinate",
            SymbolKind::Input => "an input",
            SymbolKind::Parameter => "a parameter",
            SymbolKind::Let => "a `let` definition",
            SymbolKind::Output => "an output",
            SymbolKind::Energy => "an energy",
        }
    }
}

/// A declared name.
#[derive(Debug, Clone, PartialEq)]
pub struct Symbol {
    /// What it is.
    pub kind: SymbolKind,
    /// Where its name is declared.
    pub span: Span,
    /// Its dimension, if known (unknown after an error).
    pub dim: Option<Dim>,
}

/// A parameter's declared unit and its value converted to SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamValue {
    /// Declared unit (dimension and exact scale to SI).
    pub unit: Unit,
    /// Value in SI (`literal * unit.scale`).
    pub si_value: f64,
}

/// Resolved declarations of a model.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Symbols {
    /// Every declared name.
    pub names: BTreeMap<String, Symbol>,
    /// Parameters with units and SI values.
    pub parameters: BTreeMap<String, ParamValue>,
    /// Inputs with their units.
    pub inputs: BTreeMap<String, Unit>,
    /// `let` names in an order where each only uses earlier ones (cycles left out).
    pub let_order: Vec<String>,
}

impl Symbols {
    /// Dimension of a declared name.
    pub fn dim(&self, name: &str) -> Option<Dim> {
        self.names.get(name).and_then(|s| s.dim)
    }
}

/// Built-in functions: name, number of arguments.
pub const BUILTINS: &[(&str, usize)] = &[
    ("sin", 1),
    ("cos", 1),
    ("tan", 1),
    ("sqrt", 1),
    ("exp", 1),
    ("ln", 1),
    ("abs", 1),
    ("sign", 1),
    ("tanh", 1),
    ("atan2", 2),
];

/// Parser errors after which checking still makes sense.
const NON_BLOCKING: &[&str] = &["plantc::unknown_coordinate_kind"];

/// Short human-readable number.
fn fmt_num(v: f64) -> String {
    if v == 0.0 || (1e-3..1e4).contains(&v.abs()) {
        let s = format!("{v:.6}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.4e}")
    }
}

/// Parses and checks a model file: syntax errors stop before the semantic
/// checks (so a half-parsed statement does not cause follow-up errors), and
/// several syntax or several semantic errors are reported in one run.
pub fn parse_and_check(file_name: &str, text: &str) -> Checked {
    let _ = file_name;
    let (file, mut diags) = parse(text);
    if diags
        .iter()
        .any(|d| d.is_error() && !NON_BLOCKING.contains(&d.code))
    {
        diags.sort_by_key(|d| (d.primary.start, d.primary.end));
        return Checked {
            model: None,
            diagnostics: diags,
            symbols: None,
        };
    }
    let mut c = Checker {
        syms: Symbols::default(),
        diags,
        lets: HashMap::new(),
    };
    let file = c.check(file);
    let mut diags = c.diags;
    diags.sort_by_key(|d| (d.primary.start, d.primary.end));
    Checked {
        model: Some(file),
        diagnostics: diags,
        symbols: Some(c.syms),
    }
}

/// Dimension of an expression given resolved symbols (e.g. from
/// [`Checked::symbols`]); the first problem found is returned as an error.
#[allow(clippy::result_large_err)] // cold path; Diagnostic is plain data
pub fn dimension_of(expr: &Expr, symbols: &Symbols) -> Result<Dim, Diagnostic> {
    let mut diags = Vec::new();
    let d = Infer {
        syms: symbols,
        diags: &mut diags,
        ctx: Ctx::Force,
    }
    .infer(expr);
    match (d, diags.into_iter().find(|d| d.is_error())) {
        (_, Some(e)) => Err(e),
        (Some(d), None) => Ok(d),
        (None, None) => Err(Diagnostic::error(
            "plantc::unknown_dimension",
            "dimension unknown",
            expr.span,
            "here",
        )),
    }
}

/// The value of `a op b`.
fn apply(op: BinOp, a: f64, b: f64) -> f64 {
    match op {
        BinOp::Add => a + b,
        BinOp::Sub => a - b,
        BinOp::Mul => a * b,
        BinOp::Div => a / b,
        BinOp::Pow => a.powf(b),
    }
}

/// Evaluates a constant expression over parameters (SI values), `pi` and
/// built-in functions. `None` if it uses anything else.
pub fn eval_si(expr: &Expr, symbols: &Symbols) -> Option<f64> {
    Some(match &expr.kind {
        ExprKind::Number(n) => n.value(),
        ExprKind::Quantity(n, u) => n.value() * parse_unit(&u.text).ok()?.scale.to_f64(),
        ExprKind::Name(n) => symbols.parameters.get(n)?.si_value,
        ExprKind::Pi => std::f64::consts::PI,
        ExprKind::Deriv(..) => return None,
        ExprKind::Neg(a) => -eval_si(a, symbols)?,
        ExprKind::Binary(op, a, b) => apply(*op, eval_si(a, symbols)?, eval_si(b, symbols)?),
        ExprKind::Call(f, args) => {
            let v: Option<Vec<f64>> = args.iter().map(|a| eval_si(a, symbols)).collect();
            let v = v?;
            let x = *v.first()?;
            match (f.name.as_str(), v.len()) {
                ("sin", 1) => x.sin(),
                ("cos", 1) => x.cos(),
                ("tan", 1) => x.tan(),
                ("sqrt", 1) => x.sqrt(),
                ("exp", 1) => x.exp(),
                ("ln", 1) => x.ln(),
                ("abs", 1) => x.abs(),
                ("sign", 1) => {
                    if x == 0.0 {
                        0.0
                    } else {
                        x.signum()
                    }
                }
                ("tanh", 1) => x.tanh(),
                ("atan2", 2) => x.atan2(v[1]),
                _ => return None,
            }
        }
    })
}

/// The most edits a suggestion may be away from the name written. The rule
/// is a third of the name's length (a misspelling is a few keystrokes in a
/// name); the cap of 8 leaves every suggestion for names of up to 26
/// characters as the rule alone gives it (the longest names of the bundled
/// models have 15) and bounds the work on a hostile name: the distance is
/// computed in a band of `2 * 8 + 1` diagonals, `O(17 n)` per candidate
/// instead of `O(n m)` (a 100,000-character name took 54 s).
pub const MAX_SUGGESTION_EDITS: usize = 8;

/// [`eval_si`] that also finds, in one pass, the first node whose operands
/// are finite numbers but whose value is not; it goes to `first`.
fn eval_reporting<'e>(
    expr: &'e Expr,
    symbols: &Symbols,
    first: &mut Option<(&'e Expr, f64)>,
) -> Option<f64> {
    let v = match &expr.kind {
        ExprKind::Neg(a) => -eval_reporting(a, symbols, first)?,
        ExprKind::Binary(op, a, b) => {
            let x = eval_reporting(a, symbols, first);
            let y = eval_reporting(b, symbols, first);
            let (a, b) = (x?, y?);
            if !(a.is_finite() && b.is_finite()) {
                return Some(f64::NAN);
            }
            apply(*op, a, b)
        }
        ExprKind::Call(_, args) => {
            let mut all = Some(());
            let mut finite = true;
            for a in args {
                match eval_reporting(a, symbols, first) {
                    Some(v) => finite &= v.is_finite(),
                    None => all = None,
                }
            }
            all?;
            if !finite {
                return Some(f64::NAN);
            }
            eval_si(expr, symbols)?
        }
        _ => eval_si(expr, symbols)?,
    };
    // (a literal that overflows is reported by the parser already)
    let operation = matches!(expr.kind, ExprKind::Binary(..) | ExprKind::Call(..));
    if operation && !v.is_finite() && first.is_none() {
        *first = Some((expr, v));
    }
    Some(v)
}

/// Names Rust reserves even as raw identifiers (`r#self` is not allowed):
/// refused as names in a model, since `plantc gen` writes Rust from them.
/// Other Rust keywords are fine (generated as raw identifiers, `r#fn`).
pub const RUST_RESERVED: [&str; 5] = ["_", "self", "Self", "crate", "super"];

/// Up to three names from `candidates` close to `name` (edit distance at
/// most a third of its length, [`MAX_SUGGESTION_EDITS`] at most, or equal
/// ignoring case), best first.
pub fn suggest<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    let max = (name.chars().count() / 3).clamp(1, MAX_SUGGESTION_EDITS);
    let mut v: Vec<(usize, String)> = candidates
        .into_iter()
        .filter(|c| *c != name)
        .filter_map(|c| {
            let d = edit_distance_within(name, c, max).or_else(|| {
                // equal but for case: the count of differing characters
                (c.len() == name.len() && c.to_lowercase() == name.to_lowercase())
                    .then(|| c.chars().zip(name.chars()).filter(|(x, y)| x != y).count())
            })?;
            Some((d, c.to_string()))
        })
        .collect();
    v.sort();
    v.dedup();
    v.into_iter().take(3).map(|(_, c)| c).collect()
}

/// Levenshtein distance over chars, if it is at most `max` (`None` beyond).
/// Only the band of diagonals `|i - j| <= max` is computed: `O(max * n)`.
pub fn edit_distance_within(a: &str, b: &str, max: usize) -> Option<usize> {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    if a.len().abs_diff(b.len()) > max {
        return None;
    }
    let (n, m) = (a.len(), b.len());
    let inf = max + 1;
    // row i holds columns j in [i - max, i + max], stored at j - i + max
    let width = 2 * max + 1;
    let mut prev = vec![inf; width];
    for (k, p) in prev.iter_mut().enumerate() {
        // row 0: distance j for j = k - max >= 0
        if k >= max && k - max <= m {
            *p = (k - max).min(inf);
        }
    }
    let mut cur = vec![inf; width];
    for i in 1..=n {
        let mut row_min = inf;
        for k in 0..width {
            cur[k] = inf;
            let Some(j) = (i + k).checked_sub(max) else {
                continue;
            };
            if j > m {
                continue;
            }
            let v = if j == 0 {
                i.min(inf)
            } else {
                let sub = prev[k] + usize::from(a[i - 1] != b[j - 1]);
                let del = if k + 1 < width { prev[k + 1] + 1 } else { inf };
                let ins = if k > 0 { cur[k - 1] + 1 } else { inf };
                sub.min(del).min(ins).min(inf)
            };
            cur[k] = v;
            row_min = row_min.min(v);
        }
        if row_min > max {
            return None;
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    let d = prev[m + max - n];
    (d <= max).then_some(d)
}

/// Levenshtein distance over chars. Cost `O(n m)`: for names the user
/// wrote, use [`edit_distance_within`].
pub fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().collect();
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for i in 1..=a.len() {
        let mut cur = vec![i; b.len() + 1];
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            cur[j] = (prev[j] + 1).min(cur[j - 1] + 1).min(prev[j - 1] + cost);
        }
        prev = cur;
    }
    prev[b.len()]
}

fn did_you_mean(s: &[String]) -> Option<String> {
    match s.len() {
        0 => None,
        1 => Some(format!("did you mean `{}`?", s[0])),
        _ => Some(format!(
            "did you mean one of {}?",
            s.iter()
                .map(|x| format!("`{x}`"))
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

/// Where an expression appears; decides which names and calls are allowed.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Ctx {
    /// let, output, kinetic, potential.
    Model,
    /// force line (effects already expanded).
    Force,
    /// set value or controller gain: parameters and constants only.
    Constant,
    /// a hybrid controller's switch condition: no inputs; `energy(q)` and
    /// `sat(x)` are available.
    Controller,
    /// a recorded controller's law: measured coordinates (no velocities),
    /// its signals, gains and lets, parameters, `derivative(x, wc)`.
    Recorded,
}

struct Infer<'a> {
    syms: &'a Symbols,
    diags: &'a mut Vec<Diagnostic>,
    ctx: Ctx,
}

fn coord_dim(k: CoordKind) -> Dim {
    match k {
        CoordKind::Angle => Dim::NONE,
        CoordKind::Length => Dim::length(),
    }
}

/// The constant rational value of an exponent expression, if it is one.
pub fn const_ratio(e: &Expr) -> Option<Ratio> {
    match &e.kind {
        ExprKind::Number(n) => Ratio::parse_decimal(&n.text),
        ExprKind::Neg(a) => const_ratio(a).map(Ratio::neg),
        ExprKind::Binary(op, a, b) => {
            let (a, b) = (const_ratio(a)?, const_ratio(b)?);
            match op {
                BinOp::Add => Some(a.add(b)),
                BinOp::Sub => Some(a.add(b.neg())),
                BinOp::Mul => Some(a.mul(b)),
                BinOp::Div if !b.is_zero() => Some(a.mul(b.recip())),
                _ => None,
            }
        }
        _ => None,
    }
}

impl Infer<'_> {
    fn unknown_name(&mut self, name: &str, span: Span) {
        let cands: Vec<&str> = self
            .syms
            .names
            .iter()
            .filter(|(_, s)| match self.ctx {
                Ctx::Constant => s.kind == SymbolKind::Parameter,
                _ => !matches!(s.kind, SymbolKind::Output | SymbolKind::Energy),
            })
            .map(|(n, _)| n.as_str())
            .chain(std::iter::once("pi"))
            .collect();
        let mut d = Diagnostic::error(
            "plantc::unknown_name",
            format!("unknown name `{name}`"),
            span,
            "not declared",
        );
        d.help = did_you_mean(&suggest(name, cands)).or(Some(
            "declare it with `parameter`, `let`, `coordinate` or `input`".into(),
        ));
        self.diags.push(d);
    }

    fn infer(&mut self, e: &Expr) -> Option<Dim> {
        match &e.kind {
            ExprKind::Number(_) | ExprKind::Pi => Some(Dim::NONE),
            ExprKind::Quantity(_, u) => match parse_unit(&u.text) {
                Ok(u) => Some(u.dim),
                Err(err) => {
                    self.diags.push(unit_error(u, err));
                    None
                }
            },
            ExprKind::Name(n) => {
                let Some(s) = self.syms.names.get(n) else {
                    self.unknown_name(n, e.span);
                    return None;
                };
                match s.kind {
                    SymbolKind::Output | SymbolKind::Energy => {
                        self.diags.push(
                            Diagnostic::error(
                                "plantc::not_a_value",
                                format!(
                                    "`{n}` is {} and cannot be used in an expression",
                                    s.kind.describe()
                                ),
                                e.span,
                                "used here",
                            )
                            .with_label(s.span, "declared here")
                            .with_help("define shared quantities with `let` and use that name"),
                        );
                        None
                    }
                    SymbolKind::Parameter => s.dim,
                    SymbolKind::Input if self.ctx == Ctx::Controller => {
                        self.diags.push(
                            Diagnostic::error(
                                "plantc::not_a_state",
                                format!("`{n}` is an input; a switch condition depends on the state"),
                                e.span,
                                "an input",
                            )
                            .with_label(s.span, "declared here")
                            .with_help("compare coordinates, their derivatives, `energy(q)`, parameters and numbers"),
                        );
                        None
                    }
                    _ if self.ctx == Ctx::Recorded && !recorded::readable_in_recorded(s) => {
                        self.diags.push(
                            Diagnostic::error(
                                "plantc::not_measured",
                                format!(
                                    "`{n}` is {}; a recorded controller computes inputs, it cannot read them",
                                    s.kind.describe()
                                ),
                                e.span,
                                "not a measurement",
                            )
                            .with_label(s.span, "declared here")
                            .with_help("the law may read coordinates, its `signal` columns, gains and parameters"),
                        );
                        None
                    }
                    _ if self.ctx == Ctx::Constant => {
                        self.diags.push(
                            Diagnostic::error(
                                "plantc::not_constant",
                                format!(
                                    "`{n}` is {}; only parameters and numbers are allowed here",
                                    s.kind.describe()
                                ),
                                e.span,
                                "not a constant",
                            )
                            .with_label(s.span, "declared here"),
                        );
                        None
                    }
                    _ => s.dim,
                }
            }
            ExprKind::Deriv(n, k) => {
                let Some(s) = self.syms.names.get(n) else {
                    self.unknown_name(n, Span::new(e.span.start, e.span.start + n.len()));
                    return None;
                };
                match s.kind {
                    SymbolKind::Coordinate(_) if self.ctx == Ctx::Recorded => {
                        self.diags.push(
                            Diagnostic::error(
                                "plantc::not_measured",
                                format!("a recorded controller does not see `{n}{}`: it reads measured positions", "'".repeat(*k as usize)),
                                e.span,
                                "not measured",
                            )
                            .with_help(format!("use the filtered difference the rig computed, e.g. `derivative({n}, 50 [rad/s])`")),
                        );
                        None
                    }
                    SymbolKind::Coordinate(kind) if self.ctx != Ctx::Constant => {
                        Some(coord_dim(kind).div(Dim::time().powi(*k as i64)))
                    }
                    _ => {
                        self.diags.push(
                            Diagnostic::error(
                                "plantc::bad_derivative",
                                format!(
                                    "`{n}` is {}; only coordinates have time derivatives",
                                    s.kind.describe()
                                ),
                                e.span,
                                "derivative of a non-coordinate",
                            )
                            .with_label(s.span, format!("`{n}` declared here"))
                            .with_help(
                                "`'` marks a time derivative of a coordinate, e.g. `theta'`",
                            ),
                        );
                        None
                    }
                }
            }
            ExprKind::Neg(a) => self.infer(a),
            ExprKind::Binary(op, a, b) => {
                let da = self.infer(a);
                let db = self.infer(b);
                match op {
                    BinOp::Add | BinOp::Sub => {
                        let (da, db) = (da?, db?);
                        if da != db {
                            let verb = if *op == BinOp::Add { "add" } else { "subtract" };
                            self.diags.push(
                                Diagnostic::error(
                                    "plantc::unit_mismatch",
                                    format!("cannot {verb} {da} and {db}"),
                                    b.span,
                                    format!("this is {db}"),
                                )
                                .with_label(a.span, format!("this is {da}"))
                                .with_help(format!(
                                    "both sides of `{}` must have the same unit",
                                    op.symbol()
                                )),
                            );
                            return None;
                        }
                        Some(da)
                    }
                    BinOp::Mul => Some(da?.mul(db?)),
                    BinOp::Div => Some(da?.div(db?)),
                    BinOp::Pow => {
                        if let Some(db) = db {
                            if !db.is_none() {
                                self.diags.push(Diagnostic::error(
                                    "plantc::unit_mismatch",
                                    format!("an exponent must be dimensionless, found {db}"),
                                    b.span,
                                    format!("this is {db}"),
                                ));
                                return None;
                            }
                        }
                        let da = da?;
                        if da.is_none() {
                            return db.map(|_| Dim::NONE);
                        }
                        match const_ratio(b) {
                            Some(r) => Some(da.pow(r)),
                            None => {
                                self.diags.push(
                                    Diagnostic::error(
                                        "plantc::non_constant_exponent",
                                        format!("a quantity with unit {da} can only be raised to a constant power"),
                                        b.span,
                                        "not a constant number",
                                    )
                                    .with_label(a.span, format!("this is {da}"))
                                    .with_help("use a number exponent like `^2` or `^(1/2)`, or make the base dimensionless"),
                                );
                                None
                            }
                        }
                    }
                }
            }
            ExprKind::Call(f, args) => self.call(e, f, args),
        }
    }

    fn call(&mut self, e: &Expr, f: &Ident, args: &[Expr]) -> Option<Dim> {
        if self.ctx == Ctx::Controller {
            if let Some(d) = self.controller_call(e, f, args) {
                return d;
            }
        }
        if self.ctx == Ctx::Recorded && f.name == "derivative" {
            return self.derivative_call(e, args);
        }
        if let Some(eff) = effects::lookup(&f.name) {
            let kw = eff.kind.keyword();
            let help = match eff.kind {
                EffectKind::Force => format!(
                    "an effect is the force on the coordinate of its line, e.g. `force theta = tau + {}`",
                    eff.signature()
                ),
                EffectKind::Sensor => format!(
                    "a sensor effect is written on its own line, e.g. `sensor theta = {}`",
                    eff.signature()
                ),
                EffectKind::Actuator => format!(
                    "an actuator effect is written on its own line, e.g. `actuator Vm = {}`",
                    eff.signature()
                ),
                EffectKind::Inertia => format!(
                    "an inertia effect is written on its own line, e.g. `inertia theta = {}`",
                    eff.signature()
                ),
            };
            self.diags.push(
                Diagnostic::error(
                    "plantc::effect_outside_force",
                    format!(
                        "effect `{}` can only be used in {} `{kw}` line",
                        f.name,
                        article(kw)
                    ),
                    e.span,
                    format!("not in {} {kw} line", article(kw)),
                )
                .with_help(help),
            );
            for a in args {
                self.infer(a);
            }
            return None;
        }
        let Some(&(_, arity)) = BUILTINS.iter().find(|(n, _)| *n == f.name) else {
            let cands: Vec<&str> = BUILTINS
                .iter()
                .map(|(n, _)| *n)
                .chain(effects::EFFECTS.iter().map(|e| e.name))
                .collect();
            let mut d = Diagnostic::error(
                "plantc::unknown_function",
                format!("unknown function `{}`", f.name),
                f.span,
                "not a built-in function or effect",
            );
            d.help = did_you_mean(&suggest(&f.name, cands)).or(Some(format!(
                "built-in functions: {}",
                BUILTINS
                    .iter()
                    .map(|(n, _)| *n)
                    .collect::<Vec<_>>()
                    .join(" ")
            )));
            self.diags.push(d);
            for a in args {
                self.infer(a);
            }
            return None;
        };
        let dims: Vec<Option<Dim>> = args.iter().map(|a| self.infer(a)).collect();
        if args.len() != arity {
            self.diags
                .push(wrong_arity(&f.name, arity, args.len(), e.span));
            return None;
        }
        let d0 = dims[0]?;
        match f.name.as_str() {
            "sqrt" => Some(d0.pow(Ratio::new(1, 2))),
            "abs" => Some(d0),
            "sign" => Some(Dim::NONE),
            "atan2" => {
                let d1 = dims[1]?;
                if d0 != d1 {
                    self.diags.push(
                        Diagnostic::error(
                            "plantc::unit_mismatch",
                            format!(
                                "`atan2` needs two arguments of the same unit, found {d0} and {d1}"
                            ),
                            args[1].span,
                            format!("this is {d1}"),
                        )
                        .with_label(args[0].span, format!("this is {d0}")),
                    );
                    return None;
                }
                Some(Dim::NONE)
            }
            _ => {
                if !d0.is_none() {
                    self.diags.push(
                        Diagnostic::error(
                            "plantc::unit_mismatch",
                            format!("`{}` needs a dimensionless argument, found {d0}", f.name),
                            args[0].span,
                            format!("expected 1 (dimensionless), found {d0}"),
                        )
                        .with_help("angles are in rad (dimensionless); make the argument a ratio, e.g. `x/L`"),
                    );
                    return None;
                }
                Some(Dim::NONE)
            }
        }
    }
}

fn negative(kind: &str, name: &str, span: Span) -> Diagnostic {
    Diagnostic::warning(
        "plantc::negative_value",
        format!("`{name}` is a {kind} and is negative"),
        span,
        "negative",
    )
    .with_help(format!(
        "a {kind} is positive; a negative one makes the mass matrix indefinite and the simulation meaningless"
    ))
}

fn unit_error(u: &UnitExpr, err: super::units::UnitError) -> Diagnostic {
    let s = u.span.start + err.start.min(u.text.len());
    let e = (u.span.start + err.end.min(u.text.len())).max(s);
    Diagnostic::error(
        "plantc::unknown_unit",
        err.message,
        Span::new(s, e),
        "in this unit",
    )
    .with_help(err.help)
}

/// `a` or `an` before a word.
fn article(word: &str) -> &'static str {
    if word.starts_with(['a', 'e', 'i', 'o', 'u']) {
        "an"
    } else {
        "a"
    }
}

/// `a` -> `A`, `an` -> `An`.
fn capital(article: &str) -> &'static str {
    if article == "an" {
        "An"
    } else {
        "A"
    }
}

/// The unit an effect argument must have on `target` (of unit `target_dim`,
/// a coordinate of kind `coord_kind`) and how to say it; None when the
/// target is unknown.
fn arg_expectation(
    unit: ArgUnit,
    target: &Ident,
    target_dim: Option<Dim>,
    coord_kind: Option<CoordKind>,
) -> Option<(Dim, String)> {
    let t = &target.name;
    let on = |k: CoordKind| match k {
        CoordKind::Angle => format!("`{t}` is an angle"),
        CoordKind::Length => format!("`{t}` is a length"),
    };
    let by_kind = |angle: (Dim, &str), length: (Dim, &str)| -> Option<(Dim, String)> {
        let k = coord_kind?;
        let (d, what) = match k {
            CoordKind::Angle => angle,
            CoordKind::Length => length,
        };
        Some((d, format!("{what} ({})", on(k))))
    };
    let force_dim = |k: CoordKind| match k {
        CoordKind::Angle => Dim::energy(),
        CoordKind::Length => Dim::force(),
    };
    match unit {
        ArgUnit::Time => Some((Dim::time(), "a time".to_string())),
        ArgUnit::Dimensionless => Some((Dim::NONE, "dimensionless".to_string())),
        ArgUnit::Target | ArgUnit::TargetNonNegative | ArgUnit::TargetPositive => {
            target_dim.map(|td| (td, format!("in the unit of `{t}`")))
        }
        ArgUnit::Inertia => by_kind(
            (Dim::mass() * Dim::length().powi(2), "an inertia, kg*m^2"),
            (Dim::mass(), "a mass, kg"),
        ),
        ArgUnit::Force => by_kind(
            (force_dim(CoordKind::Angle), "a torque, N*m"),
            (force_dim(CoordKind::Length), "a force, N"),
        ),
        ArgUnit::PerTarget => by_kind(
            (Dim::NONE, "dimensionless, periods per revolution"),
            (Dim::length().powi(-1), "a spatial frequency, 1/m"),
        ),
        ArgUnit::TargetRate => by_kind(
            (Dim::time().powi(-1), "a rate, rad/s"),
            (Dim::length() / Dim::time(), "a speed, m/s"),
        ),
        ArgUnit::Damping => by_kind(
            (
                force_dim(CoordKind::Angle) * Dim::time(),
                "a damping, N*m*s/rad",
            ),
            (
                force_dim(CoordKind::Length) * Dim::time() / Dim::length(),
                "a damping, N*s/m",
            ),
        ),
    }
}

/// A number 0 standing in for an effect call that was reported as an error.
fn zero_at(span: Span) -> Expr {
    Expr::new(
        ExprKind::Number(NumLit {
            text: "0".into(),
            span,
        }),
        span,
    )
}

/// The sign a signal effect's argument must have (checked once its unit is right).
struct SignRule {
    code: &'static str,
    /// What the argument is (`delay`).
    what: &'static str,
    /// What is wrong with it (`negative`).
    wrong: &'static str,
    /// After the value in the label.
    unit: &'static str,
    help: &'static str,
    /// `> 0` rather than `>= 0`.
    positive: bool,
}

impl SignRule {
    fn violated_by(&self, v: f64) -> bool {
        if self.positive {
            v.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
        } else {
            v.is_nan() || v < 0.0
        }
    }
}

fn sign_rule(unit: ArgUnit) -> Option<SignRule> {
    Some(match unit {
        ArgUnit::Time => SignRule {
            code: "plantc::negative_delay",
            what: "delay",
            wrong: "negative",
            unit: " s",
            help: "a delay is a time >= 0 s by which the plant receives the input late",
            positive: false,
        },
        ArgUnit::TargetNonNegative => SignRule {
            code: "plantc::negative_width",
            what: "deadzone width",
            wrong: "negative",
            unit: " (SI)",
            help: "a deadzone half-width w >= 0: inputs with |u| <= w do not reach the plant",
            positive: false,
        },
        ArgUnit::TargetPositive => SignRule {
            code: "plantc::nonpositive_level",
            what: "saturation level",
            wrong: "not positive",
            unit: " (SI)",
            help: "a saturation level L > 0: the plant receives the input clipped to [-L, L]",
            positive: true,
        },
        ArgUnit::Inertia => SignRule {
            code: "plantc::negative_inertia",
            what: "added inertia",
            wrong: "negative",
            unit: " (SI)",
            help: "an added inertia J >= 0 adds 1/2*J*q'^2 to the kinetic energy; to lower an inertia, change the parameter that holds it",
            positive: false,
        },
        _ => return None,
    })
}

/// `effect` (of kind `is`) written in a line of kind `line`, on `target`.
fn wrong_kind(
    call: &Expr,
    effect: &str,
    is: EffectKind,
    line: EffectKind,
    target: &Ident,
) -> Diagnostic {
    let (is_kw, line_kw) = (is.keyword(), line.keyword());
    let args = match &call.kind {
        ExprKind::Call(_, a) => a
            .iter()
            .map(|x| x.to_string())
            .collect::<Vec<_>>()
            .join(", "),
        _ => String::new(),
    };
    let elsewhere = match is {
        EffectKind::Force => format!(
            "force effects go into a force line: `force {} = ... + {effect}({args})`",
            target.name
        ),
        EffectKind::Sensor => format!(
            "sensor effects act on a measured coordinate: `sensor <coordinate> = {effect}({args})`"
        ),
        EffectKind::Actuator => {
            format!("actuator effects act on an input: `actuator <input> = {effect}({args})`")
        }
        EffectKind::Inertia => format!(
            "inertia effects add kinetic energy to a coordinate: `inertia {} = {effect}({args})`",
            target.name
        ),
    };
    Diagnostic::error(
        "plantc::effect_kind",
        format!(
            "`{effect}` is {} {is_kw} effect and cannot be used in {} `{line_kw}` line",
            article(is_kw),
            article(line_kw)
        ),
        call.span,
        format!("{} {is_kw} effect", article(is_kw)),
    )
    .with_help(format!(
        "effects valid in {} `{line_kw}` line: {}; {elsewhere}",
        article(line_kw),
        effects::signatures(line)
    ))
}

struct Checker {
    syms: Symbols,
    diags: Vec<Diagnostic>,
    lets: HashMap<String, usize>,
}

impl Checker {
    fn infer(&mut self, e: &Expr, ctx: Ctx) -> Option<Dim> {
        Infer {
            syms: &self.syms,
            diags: &mut self.diags,
            ctx,
        }
        .infer(e)
    }

    fn resolve_unit(&mut self, u: &Option<UnitExpr>) -> Option<Unit> {
        match u {
            None => Some(Unit::ONE),
            Some(u) => match parse_unit(&u.text) {
                Ok(x) => Some(x),
                Err(err) => {
                    self.diags.push(unit_error(u, err));
                    None
                }
            },
        }
    }

    /// A coordinate whose velocity appears nowhere in the kinetic energy
    /// (directly or through a `let`) and that no `inertia` line targets has
    /// no inertia: its row of the mass matrix is zero, so `M` is singular in
    /// every state and the equations of motion do not exist (derive used to
    /// print `det M = 0` and `f` with `inf`).
    fn check_inertia(&mut self, file: &ModelFile) {
        let [t] = file.kinetic.as_slice() else {
            return;
        };
        let lets: HashMap<&str, &Expr> = file
            .lets
            .iter()
            .map(|l| (l.name.name.as_str(), &l.expr))
            .collect();
        let mut moving = std::collections::BTreeSet::new();
        let mut seen_lets = std::collections::BTreeSet::new();
        let mut todo = vec![&t.expr];
        while let Some(e) = todo.pop() {
            e.walk(&mut |x| match &x.kind {
                ExprKind::Deriv(n, _) => {
                    moving.insert(n.clone());
                }
                ExprKind::Name(n) => {
                    if let Some(&l) = lets.get(n.as_str()) {
                        if seen_lets.insert(n.clone()) {
                            todo.push(l);
                        }
                    }
                }
                _ => {}
            });
        }
        // a velocity of no coordinate (a misspelling) is reported already;
        // the missing inertia would only follow from it
        if moving
            .iter()
            .any(|m| !file.coordinates.iter().any(|c| &c.name.name == m))
        {
            return;
        }
        for c in &file.coordinates {
            let name = &c.name.name;
            let added = file.inertias.iter().any(|i| &i.target.name == name);
            if !moving.contains(name) && !added {
                self.diags.push(
                    Diagnostic::error(
                        "plantc::no_inertia",
                        format!("coordinate `{name}` has no inertia"),
                        c.name.span,
                        format!("`{name}'` appears nowhere in the kinetic energy"),
                    )
                    .with_label(t.span, "the kinetic energy")
                    .with_help(format!(
                        "without a term in `{name}'` the mass matrix is singular for every state \
                         (no equation of motion gives `{name}''`): add its kinetic energy, e.g. \
                         `1/2*m*{name}'^2`, or an `inertia {name} = added_inertia(J)` line"
                    )),
                );
            }
        }
    }

    /// Refuses, where they are declared, the names the generated Rust code
    /// cannot spell even as raw identifiers ([`RUST_RESERVED`]).
    fn check_rust_reserved(&mut self, file: &ModelFile) {
        use super::visit::{occurrences, Role, SymbolRef};
        let mut seen = std::collections::BTreeSet::new();
        let model = file
            .model
            .iter()
            .map(|m| (m.name.name.as_str(), m.name.span));
        let declared = occurrences(file)
            .into_iter()
            .filter(|o| o.role == Role::Declaration)
            .filter_map(|o| {
                let name = match o.symbol {
                    SymbolRef::Model(n)
                    | SymbolRef::Gain(_, n)
                    | SymbolRef::Block(n)
                    | SymbolRef::Surface(_, n)
                    | SymbolRef::Mode(_, n) => n,
                    _ => return None,
                };
                Some((name, o.span))
            })
            .collect::<Vec<_>>();
        let all = model.map(|(n, s)| (n.to_string(), s)).chain(declared);
        for (name, span) in all {
            if RUST_RESERVED.contains(&name.as_str()) && seen.insert(span.start) {
                self.diags.push(
                    Diagnostic::error(
                        "plantc::reserved_name",
                        format!("`{name}` cannot be a name in a model"),
                        span,
                        "reserved in the generated Rust code",
                    )
                    .with_help(format!(
                        "Rust cannot name anything `{}` (not even as a raw identifier), and plantc \
                         generates Rust from the model: choose another name, e.g. `{}`",
                        name,
                        if name == "_" { "x_".to_string() } else { format!("{}_", name.to_lowercase()) }
                    )),
                );
            }
        }
    }

    fn declare(&mut self, name: &Ident, kind: SymbolKind, dim: Option<Dim>) {
        if BUILTINS.iter().any(|(n, _)| *n == name.name) || name.name == "pi" {
            self.diags.push(
                Diagnostic::error(
                    "plantc::reserved_name",
                    format!("`{}` is a built-in name", name.name),
                    name.span,
                    "reserved",
                )
                .with_help("choose another name"),
            );
            return;
        }
        if let Some(prev) = self.syms.names.get(&name.name) {
            self.diags.push(
                Diagnostic::error(
                    "plantc::duplicate_definition",
                    format!("`{}` is declared twice", name.name),
                    name.span,
                    format!("declared again here as {}", kind.describe()),
                )
                .with_label(
                    prev.span,
                    format!("first declared here as {}", prev.kind.describe()),
                )
                .with_help("every name must be declared once; rename one of them"),
            );
            return;
        }
        self.syms.names.insert(
            name.name.clone(),
            Symbol {
                kind,
                span: name.span,
                dim,
            },
        );
    }

    fn bounds_ok(&mut self, b: &Bounds, what: &str) -> bool {
        let (lo, hi) = (b.lo.value(), b.hi.value());
        if lo.partial_cmp(&hi) != Some(std::cmp::Ordering::Less) {
            self.diags.push(
                Diagnostic::error(
                    "plantc::bad_bounds",
                    format!(
                        "{what} must satisfy lo < hi, found [{}, {}]",
                        b.lo.text, b.hi.text
                    ),
                    b.span,
                    "empty or reversed interval",
                )
                .with_help("write the lower bound first, e.g. `[1e-4, 5e-3]`"),
            );
            return false;
        }
        true
    }

    fn check(&mut self, mut file: ModelFile) -> ModelFile {
        self.check_rust_reserved(&file);
        if file.model.is_none() {
            self.diags.push(
                Diagnostic::error(
                    "plantc::missing_model",
                    "missing `model` declaration",
                    Span::new(0, 0),
                    "expected here",
                )
                .with_help("start the file with `model my_model \"description\"`"),
            );
        }
        if let (true, Some(decl)) = (file.coordinates.is_empty(), &file.model) {
            // nothing could be derived, linearized or simulated
            let at = decl.name.span;
            self.diags.push(
                Diagnostic::error(
                    "plantc::no_coordinates",
                    "the model declares no coordinate",
                    at,
                    "a model needs at least one generalised coordinate",
                )
                .with_help(
                    "declare one, e.g. `coordinate theta : angle` or `coordinate x : length`",
                ),
            );
        }
        // declarations
        for c in &file.coordinates {
            self.declare(
                &c.name,
                SymbolKind::Coordinate(c.kind),
                Some(coord_dim(c.kind)),
            );
        }
        for i in &file.inputs {
            let u = self.resolve_unit(&i.unit);
            if let Some(u) = u {
                self.syms.inputs.insert(i.name.name.clone(), u);
            }
            self.declare(&i.name, SymbolKind::Input, u.map(|u| u.dim));
            if let Some(l) = &i.limits {
                self.bounds_ok(l, "limits");
            }
        }
        for p in &file.parameters {
            let u = self.resolve_unit(&p.unit);
            self.declare(&p.name, SymbolKind::Parameter, u.map(|u| u.dim));
            if let Some(u) = u {
                self.syms.parameters.insert(
                    p.name.name.clone(),
                    ParamValue {
                        unit: u,
                        si_value: p.value.value() * u.scale.to_f64(),
                    },
                );
            }
            if let Some(b) = &p.estimate {
                if self.bounds_ok(b, "estimate bounds") {
                    let v = p.value.value();
                    if !(b.lo.value() <= v && v <= b.hi.value()) {
                        self.diags.push(
                            Diagnostic::warning(
                                "plantc::value_outside_estimate",
                                format!(
                                    "value {} of `{}` is outside its estimate bounds",
                                    p.value.text, p.name.name
                                ),
                                p.value.span,
                                "outside the bounds",
                            )
                            .with_label(b.span, "estimate bounds")
                            .with_help("widen the bounds or change the nominal value"),
                        );
                    }
                }
            }
        }
        for (i, l) in file.lets.iter().enumerate() {
            self.declare(&l.name, SymbolKind::Let, None);
            self.lets.entry(l.name.name.clone()).or_insert(i);
        }
        for o in &file.outputs {
            if o.expr.is_some() {
                self.declare(&o.name, SymbolKind::Output, None);
            }
        }
        for e in file.kinetic.iter().chain(file.potential.iter()) {
            self.declare(&e.name, SymbolKind::Energy, Some(Dim::energy()));
        }
        self.check_lets(&file);
        self.check_inertia(&file);
        // outputs
        let mut output_names: BTreeMap<String, Span> = BTreeMap::new();
        for o in &file.outputs {
            if let Some(prev) = output_names.get(&o.name.name) {
                self.diags.push(
                    Diagnostic::error(
                        "plantc::duplicate_definition",
                        format!("output `{}` is declared twice", o.name.name),
                        o.name.span,
                        "declared again here",
                    )
                    .with_label(*prev, "first declared here"),
                );
                continue;
            }
            output_names.insert(o.name.name.clone(), o.name.span);
            match &o.expr {
                Some(e) => {
                    let d = self.infer(e, Ctx::Model);
                    if let Some(s) = self.syms.names.get_mut(&o.name.name) {
                        if s.kind == SymbolKind::Output {
                            s.dim = d;
                        }
                    }
                }
                None => match self.syms.names.get(&o.name.name).map(|s| s.kind) {
                    Some(SymbolKind::Coordinate(_)) | Some(SymbolKind::Let) => {}
                    other => {
                        let cands: Vec<&str> = self
                            .syms
                            .names
                            .iter()
                            .filter(|(_, s)| {
                                matches!(s.kind, SymbolKind::Coordinate(_) | SymbolKind::Let)
                            })
                            .map(|(n, _)| n.as_str())
                            .collect();
                        let mut d = Diagnostic::error(
                            "plantc::bad_output",
                            match other {
                                None => format!("unknown name `{}`", o.name.name),
                                Some(k) => format!(
                                    "`{}` is {}, not a coordinate or a `let`",
                                    o.name.name,
                                    k.describe()
                                ),
                            },
                            o.name.span,
                            "an output must be a coordinate or a `let` name",
                        );
                        d.help = did_you_mean(&suggest(&o.name.name, cands)).or(Some(format!(
                            "or give it a definition: `output {} = ...`",
                            o.name.name
                        )));
                        self.diags.push(d);
                    }
                },
            }
        }
        // energies
        match file.kinetic.as_slice() {
            [] => self.diags.push(
                Diagnostic::error(
                    "plantc::missing_kinetic",
                    "the model has no kinetic energy",
                    file.model.as_ref().map_or(Span::new(0, 0), |m| m.name.span),
                    "in this model",
                )
                .with_help("add a line like `kinetic T = 1/2*m*x'^2`; the equations of motion come from T - V"),
            ),
            [_, rest @ ..] => {
                for r in rest {
                    self.diags.push(
                        Diagnostic::error(
                            "plantc::duplicate_definition",
                            "kinetic energy is declared twice",
                            r.span,
                            "second `kinetic` line",
                        )
                        .with_label(file.kinetic[0].span, "first declared here")
                        .with_help("write the whole kinetic energy in one `kinetic` statement"),
                    );
                }
            }
        }
        if file.potential.is_empty() && !file.kinetic.is_empty() {
            self.diags.push(
                Diagnostic::note(
                    "plantc::no_potential",
                    "no potential energy declared; V = 0 is assumed",
                    file.kinetic[0].span,
                    "only kinetic energy",
                )
                .with_help("add `potential V = ...` if gravity or springs act on the system"),
            );
        }
        for r in file.potential.iter().skip(1) {
            self.diags.push(
                Diagnostic::error(
                    "plantc::duplicate_definition",
                    "potential energy is declared twice",
                    r.span,
                    "second `potential` line",
                )
                .with_label(file.potential[0].span, "first declared here"),
            );
        }
        for (e, which) in file
            .kinetic
            .iter()
            .map(|e| (e, "kinetic"))
            .chain(file.potential.iter().map(|e| (e, "potential")))
        {
            if let Some(d) = self.infer(&e.expr, Ctx::Model) {
                if d != Dim::energy() {
                    self.diags.push(
                        Diagnostic::error(
                            "plantc::not_an_energy",
                            format!("{which} energy `{}` is not an energy", e.name.name),
                            e.expr.span,
                            format!("expected {}, found {d}", Dim::energy()),
                        )
                        .with_help("check the units of the parameters in this expression (e.g. mass kg, inertia kg*m^2)"),
                    );
                }
            }
        }
        // forces
        let mut forced: BTreeMap<String, Span> = BTreeMap::new();
        let estimated: std::collections::HashSet<String> = file
            .parameters
            .iter()
            .filter(|p| p.estimate.is_some())
            .map(|p| p.name.name.clone())
            .collect();
        for f in file.forces.iter_mut() {
            let q = f.coordinate.clone();
            let kind = match self.syms.names.get(&q.name) {
                Some(Symbol {
                    kind: SymbolKind::Coordinate(k),
                    ..
                }) => Some(*k),
                other => {
                    let cands: Vec<&str> = self
                        .syms
                        .names
                        .iter()
                        .filter(|(_, s)| matches!(s.kind, SymbolKind::Coordinate(_)))
                        .map(|(n, _)| n.as_str())
                        .collect();
                    let mut d = Diagnostic::error(
                        "plantc::bad_force",
                        match other {
                            None => format!("unknown coordinate `{}`", q.name),
                            Some(s) => {
                                format!("`{}` is {}, not a coordinate", q.name, s.kind.describe())
                            }
                        },
                        q.span,
                        "a force acts on a coordinate",
                    );
                    d.help = did_you_mean(&suggest(&q.name, cands));
                    self.diags.push(d);
                    None
                }
            };
            if kind.is_some() {
                if let Some(prev) = forced.get(&q.name) {
                    self.diags.push(
                        Diagnostic::error(
                            "plantc::duplicate_force",
                            format!("coordinate `{}` has two `force` lines", q.name),
                            f.span,
                            "second force line",
                        )
                        .with_label(*prev, "first force line")
                        .with_help("add all terms in one line: `force q = a + b`"),
                    );
                } else {
                    forced.insert(q.name.clone(), f.span);
                }
            }
            // only the diagnostics of this line are looked at (counting all
            // of them per line made many force lines quadratic)
            let diags_before = self.diags.len();
            f.expr = self.expand_effects(&f.written, &q);
            let effect_error = self.diags[diags_before..].iter().any(|d| d.is_error());
            if kind == Some(CoordKind::Angle) {
                self.check_cogging_periods(&f.written, &q, &estimated);
            }
            let dim = if effect_error {
                None
            } else {
                self.infer(&f.expr, Ctx::Force)
            };
            if let (Some(k), Some(d)) = (kind, dim) {
                let expected = match k {
                    CoordKind::Angle => Dim::energy(),
                    CoordKind::Length => Dim::force(),
                };
                if d != expected {
                    let what = match k {
                        CoordKind::Angle => "a torque",
                        CoordKind::Length => "a force",
                    };
                    self.diags.push(
                        Diagnostic::error(
                            "plantc::force_dimension",
                            format!("the force on `{}` must be {what}", q.name),
                            f.written.span,
                            format!("expected {expected}, found {d}"),
                        )
                        .with_label(q.span, format!("`{}` is {}", q.name, if k == CoordKind::Angle { "an angle" } else { "a length" }))
                        .with_help("a generalised force on an angle is a torque (N*m); on a length it is a force (N)"),
                    );
                }
            }
        }
        for line in file
            .sensors
            .iter()
            .chain(file.actuators.iter())
            .chain(file.inertias.iter())
        {
            self.check_signal_effect(line);
        }
        self.check_saturations(&file);
        self.check_sets(&file);
        self.check_controllers(&file);
        self.check_recorded(&file);
        self.check_finite(&file);
        file
    }

    /// `cogging(A, N[, phase])` on an angle is periodic over a revolution
    /// only with an integer `N`: a warning when `N` evaluates to another
    /// number (unless `N` is a parameter being estimated, whose fitted value
    /// is a real number near the integer).
    fn check_cogging_periods(
        &mut self,
        written: &Expr,
        q: &Ident,
        estimated: &std::collections::HashSet<String>,
    ) {
        let mut found = Vec::new();
        written.walk(&mut |x| {
            if let ExprKind::Call(f, args) = &x.kind {
                if f.name == "cogging" && args.len() >= 2 {
                    found.push(args[1].clone());
                }
            }
        });
        for n in found {
            if matches!(&n.kind, ExprKind::Name(p) if estimated.contains(p)) {
                continue;
            }
            let Some(v) = eval_si(&n, &self.syms) else {
                continue;
            };
            if v.is_finite() && (v - v.round()).abs() > 1e-9 * v.abs().max(1.0) {
                self.diags.push(
                    Diagnostic::warning(
                        "plantc::cogging_period",
                        format!(
                            "the cogging torque on `{}` is not periodic over a revolution",
                            q.name
                        ),
                        n.span,
                        format!("N = {} is not an integer", fmt_num(v)),
                    )
                    .with_help(
                        "N is the number of detent periods per revolution (teeth, poles or slots seen at this coordinate)",
                    ),
                );
            }
        }
    }

    /// At most one `saturation` line per input (two limits in a row are the
    /// smaller one: write that one).
    fn check_saturations(&mut self, file: &ModelFile) {
        let mut seen: HashMap<&str, Span> = HashMap::new();
        for line in &file.actuators {
            if line.effect_name() != Some("saturation") {
                continue;
            }
            match seen.get(line.target.name.as_str()) {
                Some(first) => self.diags.push(
                    Diagnostic::error(
                        "plantc::duplicate_saturation",
                        format!("input `{}` has two `saturation` lines", line.target.name),
                        line.span,
                        "second saturation",
                    )
                    .with_label(*first, "first saturation")
                    .with_help("two limits in a row act as the smaller one: keep one line with it"),
                ),
                None => {
                    seen.insert(&line.target.name, line.span);
                }
            }
        }
    }

    /// A `sensor`, `actuator` or `inertia` line: its target, its one effect
    /// call (of the line's kind, right arity) and the units of the arguments.
    fn check_signal_effect(&mut self, line: &SignalEffect) {
        let kind = line.kind;
        let kw = kind.keyword();
        let t = &line.target;
        // the target's kind (coordinates) and unit
        let mut coord_kind = None;
        let target_dim = match (kind, self.syms.names.get(&t.name)) {
            (
                EffectKind::Sensor | EffectKind::Inertia,
                Some(Symbol {
                    kind: SymbolKind::Coordinate(k),
                    ..
                }),
            ) => {
                coord_kind = Some(*k);
                Some(coord_dim(*k))
            }
            (EffectKind::Actuator, Some(s)) if s.kind == SymbolKind::Input => {
                Some(s.dim.unwrap_or(Dim::NONE))
            }
            (_, other) => {
                let wanted = |s: &Symbol| match kind {
                    EffectKind::Actuator => s.kind == SymbolKind::Input,
                    _ => matches!(s.kind, SymbolKind::Coordinate(_)),
                };
                let cands: Vec<&str> = self
                    .syms
                    .names
                    .iter()
                    .filter(|(_, s)| wanted(s))
                    .map(|(n, _)| n.as_str())
                    .collect();
                let what = kind.target();
                let mut d = Diagnostic::error(
                    "plantc::bad_target",
                    match other {
                        None => format!(
                            "unknown {} `{}`",
                            if kind == EffectKind::Actuator {
                                "input"
                            } else {
                                "coordinate"
                            },
                            t.name
                        ),
                        Some(s) => format!("`{}` is {}, not {what}", t.name, s.kind.describe()),
                    },
                    t.span,
                    format!("{} `{kw}` line acts on {what}", capital(article(kw))),
                );
                if let Some(s) = other {
                    d = d.with_label(s.span, format!("`{}` declared here", t.name));
                }
                d.help = did_you_mean(&suggest(&t.name, cands.iter().copied())).or(Some(
                    if cands.is_empty() {
                        format!(
                            "the model declares no {}",
                            if kind == EffectKind::Actuator {
                                "input"
                            } else {
                                "coordinate"
                            }
                        )
                    } else {
                        format!(
                            "{} of this model: {}",
                            if kind == EffectKind::Actuator {
                                "inputs"
                            } else {
                                "coordinates"
                            },
                            cands.join(", ")
                        )
                    },
                ));
                self.diags.push(d);
                None
            }
        };
        // the call
        let valid = effects::signatures(kind);
        let ExprKind::Call(f, args) = &line.call.kind else {
            self.diags.push(
                Diagnostic::error(
                    "plantc::not_an_effect",
                    format!("a `{kw}` line holds one effect call"),
                    line.call.span,
                    "not an effect call",
                )
                .with_help(format!(
                    "effects valid in {} `{kw}` line: {valid}",
                    article(kw)
                )),
            );
            return;
        };
        let Some(effect) = effects::lookup(&f.name) else {
            let cands: Vec<&str> = effects::of_kind(kind).map(|e| e.name).collect();
            let mut d = Diagnostic::error(
                "plantc::not_an_effect",
                format!("`{}` is not {} {kw} effect", f.name, article(kw)),
                f.span,
                "unknown effect",
            );
            d.help = Some(match did_you_mean(&suggest(&f.name, cands)) {
                Some(m) => format!("{m} effects valid in {} `{kw}` line: {valid}", article(kw)),
                None => format!("effects valid in {} `{kw}` line: {valid}", article(kw)),
            });
            self.diags.push(d);
            for a in args {
                self.infer(a, Ctx::Constant);
            }
            return;
        };
        if effect.kind != kind {
            self.diags
                .push(wrong_kind(&line.call, &f.name, effect.kind, kind, t));
            return;
        }
        if let Err(d) = effects::resolve_call(&line.call) {
            self.diags.push(d);
            return;
        }
        for (a, unit) in args.iter().zip(effect.arg_units.iter()) {
            let Some(d) = self.infer(a, Ctx::Constant) else {
                continue;
            };
            let Some((expected, what)) = arg_expectation(*unit, t, target_dim, coord_kind) else {
                continue;
            };
            if d != expected {
                let mut diag = Diagnostic::error(
                    "plantc::unit_mismatch",
                    format!("the argument of `{}` must be {what}", f.name),
                    a.span,
                    format!("expected {expected}, found {d}"),
                )
                .with_help(format!("{}: {}", effect.signature(), effect.doc));
                if matches!(
                    unit,
                    ArgUnit::Target | ArgUnit::TargetNonNegative | ArgUnit::TargetPositive
                ) {
                    diag = diag.with_label(t.span, format!("`{}` is {expected}", t.name));
                }
                self.diags.push(diag);
            } else if let Some(rule) = sign_rule(*unit) {
                if let Some(v) = eval_si(a, &self.syms).filter(|v| rule.violated_by(*v)) {
                    self.diags.push(
                        Diagnostic::error(
                            rule.code,
                            format!("the {} of `{}` is {}", rule.what, t.name, rule.wrong),
                            a.span,
                            format!("= {}{}", fmt_num(v), rule.unit),
                        )
                        .with_help(rule.help),
                    );
                }
            }
        }
    }

    /// The arguments of a force effect that lists their units, each checked
    /// on its own (so a wrong unit is reported once, naming the argument);
    /// false (with the errors pushed) when one is wrong. Arguments whose
    /// dimension cannot be inferred are left to the check of the whole force.
    fn force_effect_args_ok(&mut self, call: &Expr, q: &Ident) -> bool {
        let ExprKind::Call(f, args) = &call.kind else {
            return true;
        };
        let Some(effect) = effects::lookup(&f.name) else {
            return true;
        };
        let coord_kind = match self.syms.names.get(&q.name) {
            Some(Symbol {
                kind: SymbolKind::Coordinate(k),
                ..
            }) => Some(*k),
            _ => None,
        };
        let target_dim = coord_kind.map(coord_dim);
        let names: Vec<&str> = effect
            .params
            .iter()
            .chain(effect.optional.iter())
            .copied()
            .collect();
        let mut ok = true;
        for (i, (a, unit)) in args.iter().zip(effect.arg_units.iter()).enumerate() {
            let Ok(d) = dimension_of(a, &self.syms) else {
                continue;
            };
            let Some((expected, what)) = arg_expectation(*unit, q, target_dim, coord_kind) else {
                continue;
            };
            if d != expected {
                ok = false;
                self.diags.push(
                    Diagnostic::error(
                        "plantc::unit_mismatch",
                        format!(
                            "`{}` of `{}` must be {what}",
                            names.get(i).copied().unwrap_or("the argument"),
                            f.name
                        ),
                        a.span,
                        format!("expected {expected}, found {d}"),
                    )
                    .with_label(q.span, format!("the force acts on `{}`", q.name))
                    .with_help(format!(
                        "{}: {}",
                        effect.signature(),
                        effect.doc
                    )),
                );
            }
        }
        ok
    }

    fn expand_effects(&mut self, e: &Expr, q: &Ident) -> Expr {
        let kind = match &e.kind {
            ExprKind::Call(f, _) if effects::lookup(&f.name).is_some() => {
                let eff = effects::lookup(&f.name).map(|x| x.kind);
                if let Some(
                    kind @ (EffectKind::Sensor | EffectKind::Actuator | EffectKind::Inertia),
                ) = eff
                {
                    self.diags
                        .push(wrong_kind(e, &f.name, kind, EffectKind::Force, q));
                    return zero_at(e.span);
                }
                if !self.force_effect_args_ok(e, q) {
                    return zero_at(e.span);
                }
                return match effects::expand(e, q) {
                    Ok(x) => x,
                    Err(d) => {
                        self.diags.push(d);
                        zero_at(e.span)
                    }
                };
            }
            ExprKind::Neg(a) => ExprKind::Neg(Box::new(self.expand_effects(a, q))),
            ExprKind::Binary(op, a, b) => ExprKind::Binary(
                *op,
                Box::new(self.expand_effects(a, q)),
                Box::new(self.expand_effects(b, q)),
            ),
            other => other.clone(),
        };
        Expr::new(kind, e.span)
    }

    fn check_lets(&mut self, file: &ModelFile) {
        // dependency graph among lets
        let n = file.lets.len();
        let mut deps: Vec<Vec<(usize, Span)>> = vec![Vec::new(); n];
        for (i, l) in file.lets.iter().enumerate() {
            if self.lets.get(&l.name.name) != Some(&i) {
                continue;
            }
            l.expr.walk(&mut |x| {
                if let ExprKind::Name(name) = &x.kind {
                    if let Some(&j) = self.lets.get(name) {
                        deps[i].push((j, x.span));
                    }
                }
            });
        }
        // iterative DFS: 0 = new, 1 = on stack, 2 = done
        let mut state = vec![0u8; n];
        let mut in_cycle = vec![false; n];
        let mut order = Vec::new();
        for root in 0..n {
            if state[root] != 0 || self.lets.get(&file.lets[root].name.name) != Some(&root) {
                continue;
            }
            let mut stack: Vec<(usize, usize)> = vec![(root, 0)];
            state[root] = 1;
            while let Some(&mut (v, ref mut k)) = stack.last_mut() {
                if *k < deps[v].len() {
                    let (w, sp) = deps[v][*k];
                    *k += 1;
                    if state[w] == 0 {
                        state[w] = 1;
                        stack.push((w, 0));
                    } else if state[w] == 1 {
                        // cycle: from w along the stack to v, back to w
                        let pos = stack.iter().position(|(x, _)| *x == w).unwrap_or(0);
                        let members: Vec<usize> = stack[pos..].iter().map(|(x, _)| *x).collect();
                        for &m in &members {
                            in_cycle[m] = true;
                        }
                        let path: Vec<&str> = members
                            .iter()
                            .map(|&m| file.lets[m].name.name.as_str())
                            .chain(std::iter::once(file.lets[w].name.name.as_str()))
                            .collect();
                        let mut d = Diagnostic::error(
                            "plantc::let_cycle",
                            format!("`let` definitions depend on each other in a cycle: {}", path.join(" -> ")),
                            sp,
                            format!("`{}` uses `{}`", file.lets[v].name.name, file.lets[w].name.name),
                        )
                        .with_help("a `let` may use other lets in any order, but not itself, directly or indirectly");
                        for &m in &members {
                            if m != v {
                                d = d.with_label(
                                    file.lets[m].name.span,
                                    format!("`{}` is defined here", file.lets[m].name.name),
                                );
                            }
                        }
                        self.diags.push(d);
                    }
                } else {
                    state[v] = 2;
                    order.push(v);
                    stack.pop();
                }
            }
        }
        for v in order {
            let l = &file.lets[v];
            let depends_on_cycle = in_cycle[v] || deps[v].iter().any(|(w, _)| in_cycle[*w]);
            if depends_on_cycle {
                in_cycle[v] = true;
                continue;
            }
            let d = self.infer(&l.expr, Ctx::Model);
            if let Some(s) = self.syms.names.get_mut(&l.name.name) {
                if s.kind == SymbolKind::Let {
                    s.dim = d;
                }
            }
            self.syms.let_order.push(l.name.name.clone());
        }
    }

    fn check_sets(&mut self, file: &ModelFile) {
        let mut seen: BTreeMap<String, (Span, &str)> = BTreeMap::new();
        let blocks = file
            .sets
            .iter()
            .map(|s| (&s.name, "set"))
            .chain(file.controllers.iter().map(|c| (&c.name, "controller")));
        for (name, what) in blocks {
            if let Some((prev, pw)) = seen.get(&name.name) {
                self.diags.push(
                    Diagnostic::error(
                        "plantc::duplicate_definition",
                        format!("{what} `{}` is declared twice", name.name),
                        name.span,
                        "declared again here",
                    )
                    .with_label(*prev, format!("first declared here as a {pw}"))
                    .with_help("sets and controllers need distinct names"),
                );
            } else {
                seen.insert(name.name.clone(), (name.span, what));
            }
        }
        for set in &file.sets {
            let mut entries: BTreeMap<&str, Span> = BTreeMap::new();
            for e in &set.entries {
                let param = file.parameters.iter().find(|p| p.name.name == e.name.name);
                let Some(param) = param else {
                    let cands: Vec<&str> = file
                        .parameters
                        .iter()
                        .map(|p| p.name.name.as_str())
                        .collect();
                    let mut d = Diagnostic::error(
                        "plantc::unknown_parameter",
                        format!(
                            "set `{}` gives a value to `{}`, which is not a parameter",
                            set.name.name, e.name.name
                        ),
                        e.name.span,
                        "not a parameter",
                    );
                    d.help = did_you_mean(&suggest(&e.name.name, cands)).or(Some(
                        "a set can only change the values of declared parameters".into(),
                    ));
                    self.diags.push(d);
                    self.infer(&e.value, Ctx::Constant);
                    continue;
                };
                if let Some(prev) = entries.get(e.name.name.as_str()) {
                    self.diags.push(
                        Diagnostic::error(
                            "plantc::duplicate_entry",
                            format!("`{}` is set twice in set `{}`", e.name.name, set.name.name),
                            e.name.span,
                            "set again here",
                        )
                        .with_label(*prev, "first set here"),
                    );
                    continue;
                }
                entries.insert(&e.name.name, e.name.span);
                let Some(pv) = self.syms.parameters.get(&e.name.name).copied() else {
                    continue;
                };
                let Some(d) = self.infer(&e.value, Ctx::Constant) else {
                    continue;
                };
                if d != pv.unit.dim {
                    let unit = param
                        .unit
                        .as_ref()
                        .map_or("1".to_string(), |u| u.text.clone());
                    self.diags.push(
                        Diagnostic::error(
                            "plantc::unit_mismatch",
                            format!("value for `{}` has the wrong unit", e.name.name),
                            e.value.span,
                            format!("expected {}, found {d}", pv.unit.dim),
                        )
                        .with_label(
                            param.name.span,
                            format!("`{}` is declared in [{unit}]", e.name.name),
                        )
                        .with_help(format!(
                            "write quantities with their unit in brackets, e.g. `1.0 [{unit}]`"
                        )),
                    );
                    continue;
                }
                if let (Some(b), Some(v)) = (&param.estimate, eval_si(&e.value, &self.syms)) {
                    let s = pv.unit.scale.to_f64();
                    let (lo, hi) = (b.lo.value() * s, b.hi.value() * s);
                    let tol = 1e-12 * lo.abs().max(hi.abs());
                    if v < lo - tol || v > hi + tol {
                        self.diags.push(
                            Diagnostic::warning(
                                "plantc::value_outside_estimate",
                                format!(
                                    "value for `{}` in set `{}` is outside its estimate bounds",
                                    e.name.name, set.name.name
                                ),
                                e.value.span,
                                format!(
                                    "= {} {} in SI, bounds [{}, {}]",
                                    fmt_num(v),
                                    pv.unit.dim.base_form(),
                                    fmt_num(lo),
                                    fmt_num(hi)
                                ),
                            )
                            .with_label(b.span, "estimate bounds"),
                        );
                    }
                }
            }
        }
    }

    fn check_finite(&mut self, file: &ModelFile) {
        let none = Symbols::default();
        let mut exprs: Vec<&Expr> = Vec::new();
        exprs.extend(file.lets.iter().map(|l| &l.expr));
        exprs.extend(file.outputs.iter().filter_map(|o| o.expr.as_ref()));
        exprs.extend(file.kinetic.iter().chain(&file.potential).map(|e| &e.expr));
        exprs.extend(file.forces.iter().map(|f| &f.written));
        exprs.extend(file.sensors.iter().chain(&file.actuators).map(|s| &s.call));
        exprs.extend(
            file.sets
                .iter()
                .flat_map(|s| s.entries.iter().map(|e| &e.value)),
        );
        for c in &file.controllers {
            for s in &c.body {
                match s {
                    ControllerStmt::Gain { value, .. } => exprs.push(value),
                    ControllerStmt::Law { expr, .. } => exprs.push(expr),
                    _ => {}
                }
            }
        }
        let mut found = Vec::new();
        for e in &exprs {
            e.walk(&mut |x| {
                if let ExprKind::Binary(BinOp::Div, _, b) = &x.kind {
                    if eval_si(b, &none) == Some(0.0) {
                        found.push(
                            Diagnostic::error(
                                "plantc::division_by_zero",
                                "division by zero",
                                b.span,
                                "this is 0",
                            )
                            .with_label(x.span, "not a finite number")
                            .with_help("every value of a model must be finite"),
                        );
                    }
                }
            });
        }
        // parameter-only parts of every expression, at the nominal values:
        // the first operation that turns finite operands into a value that
        // is not (an overflow, a logarithm of 0, a square root of -1, ...)
        // (set entries and gains: below, named by their set or controller)
        let literal_divisions: Vec<Span> = found.iter().map(|d| d.primary).collect();
        let mut model_exprs: Vec<&Expr> = Vec::new();
        model_exprs.extend(file.lets.iter().map(|l| &l.expr));
        model_exprs.extend(file.outputs.iter().filter_map(|o| o.expr.as_ref()));
        model_exprs.extend(file.kinetic.iter().chain(&file.potential).map(|e| &e.expr));
        model_exprs.extend(file.forces.iter().map(|f| &f.written));
        model_exprs.extend(file.sensors.iter().chain(&file.actuators).map(|s| &s.call));
        for c in &file.controllers {
            for s in &c.body {
                if let ControllerStmt::Law { expr, .. } = s {
                    model_exprs.push(expr);
                }
            }
        }
        for e in &model_exprs {
            let mut first = None;
            let _ = eval_reporting(e, &self.syms, &mut first);
            let Some((x, v)) = first else {
                continue;
            };
            let near = |s: &Span| x.span.start <= s.start && s.end <= x.span.end;
            if literal_divisions.iter().any(near) {
                continue;
            }
            found.push(
                Diagnostic::error(
                    "plantc::not_finite",
                    format!("this expression is not a finite number ({v})"),
                    x.span,
                    format!("evaluates to {v} (parameters at their nominal values)"),
                )
                .with_help(
                    "every value of a model must be finite: check the numbers here and the \
                     values of the parameters it uses",
                ),
            );
        }
        // constant values: set entries and gains, with the nominal values
        let mut constants: Vec<(&Expr, String)> = Vec::new();
        for s in &file.sets {
            for e in &s.entries {
                constants.push((
                    &e.value,
                    format!("`{}` in set `{}`", e.name.name, s.name.name),
                ));
            }
        }
        for c in &file.controllers {
            for s in &c.body {
                if let ControllerStmt::Gain { name, value, .. } = s {
                    constants.push((value, format!("gain `{}` of `{}`", name.name, c.name.name)));
                }
            }
        }
        let reported: Vec<Span> = found.iter().map(|d| d.primary).collect();
        for (e, what) in constants {
            let Some(v) = eval_si(e, &self.syms) else {
                continue;
            };
            let inside = |s: &Span| e.span.start <= s.start && s.end <= e.span.end;
            if !v.is_finite() && !reported.iter().any(inside) {
                found.push(
                    Diagnostic::error(
                        "plantc::not_finite",
                        format!("the value of {what} is not finite ({v})"),
                        e.span,
                        format!("evaluates to {v}"),
                    )
                    .with_help("every value of a model must be finite"),
                );
            }
        }
        // negative masses and inertias
        let physical = |d: Dim| {
            if d == Dim::mass() {
                Some("mass")
            } else if d == Dim::mass().mul(Dim::length().powi(2)) {
                Some("moment of inertia")
            } else {
                None
            }
        };
        for p in &file.parameters {
            let Some(pv) = self.syms.parameters.get(&p.name.name) else {
                continue;
            };
            if let Some(kind) = physical(pv.unit.dim) {
                if pv.si_value < 0.0 {
                    found.push(negative(kind, &p.name.name, p.value.span));
                }
                for s in &file.sets {
                    for e in s.entries.iter().filter(|e| e.name.name == p.name.name) {
                        if eval_si(&e.value, &self.syms).is_some_and(|v| v < 0.0) {
                            found.push(negative(kind, &p.name.name, e.value.span));
                        }
                    }
                }
            }
        }
        self.diags.extend(found);
    }
}
