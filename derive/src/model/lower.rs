//! Lowering a checked `.plant` AST into the symbolic [`Model`].

use std::collections::{HashMap, HashSet};
use std::fmt;
use std::path::Path;

use super::{
    ActuatorEffect, ActuatorEffectKind, ControllerSpec, Coordinate, CoordinateKind,
    DerivativeFilter, Derived, Guard, Input, ModeSpec, Model, Output, Parameter, ParameterSet,
    RecordedController, RecordedSignal, SensorEffect, SensorEffectKind, SurfaceSpec, SwitchSpec,
};
use crate::lang::ast::{self, BinOp, ExprKind};
use crate::lang::effects;
use crate::lang::units::parse_unit;
use crate::lang::{eval_si, parse_and_check, Diagnostic, SourceFile, Symbols};
use crate::sym::subst::substitute_symbols;
use crate::sym::{CoordinateSymbols, Expr, Func, Rational, Symbol};

/// A model loaded from a file, with the warnings and notes its checking produced.
#[derive(Clone, Debug)]
pub struct LoadedModel {
    /// The symbolic model.
    pub model: Model,
    /// The source it came from (for rendering diagnostics and for editing).
    pub source: SourceFile,
    /// Warnings and notes (never errors).
    pub diagnostics: Vec<Diagnostic>,
}

impl LoadedModel {
    /// Warnings, one per `sensor_offset`, `input_delay`, `deadzone` and
    /// `saturation` line, for a
    /// consumer (`consumer`, e.g. "`plantc sim`") that works on the plant
    /// equations and so ignores them (see [`Model`]'s docs). Empty for most
    /// models. Render them with [`crate::lang::render`] and `self.source`.
    pub fn ignored_signal_effects(&self, consumer: &str) -> Vec<Diagnostic> {
        let (file, _) = crate::lang::parser::parse(&self.source.text);
        let sensors = file.sensors.iter();
        let delays = file.actuators.iter().filter(|a| {
            matches!(
                a.effect_name(),
                Some("input_delay" | "deadzone" | "saturation")
            )
        });
        let mut lines: Vec<&ast::SignalEffect> = sensors.chain(delays).collect();
        lines.sort_by_key(|l| l.span.start);
        lines
            .into_iter()
            .map(|line| {
                let what = if line.kind == effects::EffectKind::Sensor {
                    "measurement effect"
                } else if line.effect_name() == Some("deadzone") {
                    "actuator deadzone"
                } else if line.effect_name() == Some("saturation") {
                    "actuator saturation"
                } else {
                    "input delay"
                };
                Diagnostic::warning(
                    "plantc::effect_ignored",
                    format!("{consumer} ignores this {what}"),
                    line.span,
                    "not part of the plant equations",
                )
                .with_help(
                    "sensor offsets, input delays, deadzones and saturations are honoured when comparing with measurements (compare, fit, diagnose); simulation, linearization and generated code describe the plant itself",
                )
            })
            .collect()
    }
}

/// Why a model could not be loaded.
#[derive(Clone, Debug)]
pub enum LoadError {
    /// The file could not be read.
    Io {
        /// Path as given.
        path: String,
        /// The operating system's message.
        message: String,
    },
    /// The file has errors (the diagnostics include any warnings too).
    Invalid {
        /// The source.
        source: SourceFile,
        /// All diagnostics, errors first in file order.
        diagnostics: Vec<Diagnostic>,
    },
}

impl LoadError {
    /// The diagnostics rendered as text with file:line:col and carets.
    pub fn render(&self) -> String {
        match self {
            LoadError::Io { path, message } => format!("error: cannot read `{path}`: {message}\n"),
            LoadError::Invalid {
                source,
                diagnostics,
            } => crate::lang::diagnostic::render(source, diagnostics),
        }
    }
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.render())
    }
}

impl std::error::Error for LoadError {}

/// Read, check and lower the model file at `path`.
pub fn load_model(path: &Path) -> Result<LoadedModel, LoadError> {
    let text = read_source(path)?;
    load_model_text(&path.display().to_string(), &text)
}

/// The bytes of a regular file (a symbolic link to one is followed). A FIFO,
/// a device or a directory is refused before it is opened: opening a FIFO
/// blocks until a writer appears, and reading `/dev/zero` never ends.
pub fn read_regular_file(path: &Path) -> std::io::Result<Vec<u8>> {
    let m = std::fs::metadata(path)?;
    if !m.is_file() {
        let kind = if m.is_dir() {
            "a directory"
        } else {
            "not a regular file (a FIFO, socket or device)"
        };
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{kind}: plantc reads model files only"),
        ));
    }
    std::fs::read(path)
}

/// The text of a model file. A file that is not UTF-8 is an error at the
/// line and column of its first bad byte (UTF-16 files are named as such).
pub fn read_source(path: &Path) -> Result<String, LoadError> {
    let bytes = read_regular_file(path).map_err(|e| LoadError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    match String::from_utf8(bytes) {
        Ok(text) => Ok(text),
        Err(e) => {
            let bytes = e.as_bytes();
            let at = e.utf8_error().valid_up_to();
            let utf16 = bytes.starts_with(&[0xff, 0xfe]) || bytes.starts_with(&[0xfe, 0xff]);
            let text = String::from_utf8_lossy(bytes).into_owned();
            // the valid prefix is the same in the lossy text; the bad byte
            // became U+FFFD (3 bytes)
            let d = Diagnostic::error(
                "plantc::invalid_utf8",
                if utf16 {
                    "the file is UTF-16, not UTF-8".to_string()
                } else {
                    format!("the file is not valid UTF-8 (byte 0x{:02X})", bytes[at])
                },
                crate::lang::Span::new(at, at + '\u{fffd}'.len_utf8()),
                "this byte is not UTF-8",
            )
            .with_help("save the model file as UTF-8 (plain text; names and numbers are ASCII)");
            Err(LoadError::Invalid {
                source: SourceFile::new(path.display().to_string(), text),
                diagnostics: vec![d],
            })
        }
    }
}

/// Check and lower model text (`name` is used in diagnostics).
pub fn load_model_text(name: &str, text: &str) -> Result<LoadedModel, LoadError> {
    let source = SourceFile::new(name, text);
    let checked = parse_and_check(name, text);
    let has_errors = checked.diagnostics.iter().any(|d| d.is_error());
    match checked.model {
        Some(file) if !has_errors => Ok(LoadedModel {
            model: lower(&file, checked.symbols.as_ref()),
            source,
            diagnostics: checked.diagnostics,
        }),
        _ => Err(LoadError::Invalid {
            source,
            diagnostics: checked.diagnostics,
        }),
    }
}

fn number(text: &str) -> Expr {
    match Rational::from_decimal_str(text) {
        Some(r) => Expr::rational(r),
        None => Expr::float(text.parse().unwrap_or(f64::NAN)),
    }
}

fn scale_of(unit: Option<&ast::UnitExpr>) -> f64 {
    unit.and_then(|u| parse_unit(&u.text).ok())
        .map_or(1.0, |u| u.scale.to_f64())
}

fn scale_expr(unit: &ast::UnitExpr) -> Expr {
    match parse_unit(&unit.text) {
        Ok(u) => {
            let r = Rational::new(u.scale.ratio.num as i128, u.scale.ratio.den as i128)
                .map_or(Expr::float(u.scale.ratio.to_f64()), Expr::rational);
            if u.scale.pi_power == 0 {
                r
            } else {
                r * Expr::float(std::f64::consts::PI).powi(u.scale.pi_power as i64)
            }
        }
        Err(_) => Expr::one(),
    }
}

struct Lowerer<'a> {
    lets: HashMap<&'a str, &'a ast::Let>,
    let_values: HashMap<String, Expr>,
    params: HashSet<String>,
    derived: Vec<Derived>,
    derived_names: HashSet<String>,
    in_progress: HashSet<String>,
    /// `energy(q)` of each coordinate (filled once T and V are lowered).
    energies: HashMap<String, Expr>,
}

impl<'a> Lowerer<'a> {
    fn expr(&mut self, e: &ast::Expr) -> Expr {
        match &e.kind {
            ExprKind::Number(n) => number(&n.text),
            ExprKind::Quantity(n, u) => number(&n.text) * scale_expr(u),
            ExprKind::Pi => Expr::float(std::f64::consts::PI),
            ExprKind::Name(name) => self.name(name),
            ExprKind::Deriv(name, k) => Expr::sym(&format!("{name}{}", "'".repeat(*k as usize))),
            ExprKind::Neg(a) => -self.expr(a),
            ExprKind::Binary(op, a, b) => {
                let (x, y) = (self.expr(a), self.expr(b));
                match op {
                    BinOp::Add => x + y,
                    BinOp::Sub => x - y,
                    BinOp::Mul => x * y,
                    BinOp::Div => x / y,
                    BinOp::Pow => x.pow(y),
                }
            }
            ExprKind::Call(f, args) if f.name == "energy" => match args.first().map(|a| &a.kind) {
                Some(ExprKind::Name(q)) if args.len() == 1 => self
                    .energies
                    .get(q)
                    .copied()
                    .unwrap_or_else(|| Expr::float(f64::NAN)),
                _ => Expr::float(f64::NAN),
            },
            ExprKind::Call(f, args) if f.name == "sat" && args.len() == 1 => {
                // x clamped to [-1, 1], in functions the symbolic core has
                let x = self.expr(&args[0]);
                let one = Expr::one();
                ((x + one).abs() - (x - one).abs()) * Expr::frac(1, 2)
            }
            ExprKind::Call(f, args) => {
                let a: Vec<Expr> = args.iter().map(|x| self.expr(x)).collect();
                match (f.name.as_str(), a.as_slice()) {
                    ("sqrt", [x]) => x.sqrt(),
                    ("atan2", [y, x]) => Expr::atan2(*y, *x),
                    (name, [x]) => match Func::from_name(name) {
                        Some(func) => Expr::apply(func, *x),
                        None => Expr::float(f64::NAN),
                    },
                    _ => Expr::float(f64::NAN),
                }
            }
        }
    }

    fn name(&mut self, name: &str) -> Expr {
        if self.params.contains(name) || self.derived_names.contains(name) {
            return Expr::sym(name);
        }
        if let Some(v) = self.let_values.get(name) {
            return *v;
        }
        if let Some(l) = self.lets.get(name).copied() {
            if !self.in_progress.insert(name.to_string()) {
                return Expr::float(f64::NAN); // cycle: the checker reports it
            }
            let def = self.expr(&l.expr);
            self.in_progress.remove(name);
            let only_params = def
                .symbols()
                .iter()
                .all(|s| self.params.contains(s.name()) || self.derived_names.contains(s.name()));
            let value = if only_params && !def.is_constant() {
                let sym = Symbol::new(name);
                self.derived.push(Derived {
                    name: name.to_string(),
                    symbol: sym,
                    expr: def,
                });
                self.derived_names.insert(name.to_string());
                Expr::symbol(sym)
            } else {
                def
            };
            self.let_values.insert(name.to_string(), value);
            return value;
        }
        Expr::sym(name)
    }
}

/// Lower a checked model file. The file must have passed
/// [`crate::lang::parse_and_check`] without errors.
pub fn lower(file: &ast::ModelFile, symbols: Option<&Symbols>) -> Model {
    let mut lw = Lowerer {
        lets: file
            .lets
            .iter()
            .map(|l| (l.name.name.as_str(), l))
            .collect(),
        let_values: HashMap::new(),
        params: file
            .parameters
            .iter()
            .map(|p| p.name.name.clone())
            .collect(),
        derived: Vec::new(),
        derived_names: HashSet::new(),
        in_progress: HashSet::new(),
        energies: HashMap::new(),
    };
    // Lower lets in file order so derived quantities are in dependency order.
    for l in &file.lets {
        lw.name(&l.name.name);
    }
    let coordinates: Vec<Coordinate> = file
        .coordinates
        .iter()
        .map(|c| Coordinate {
            name: c.name.name.clone(),
            kind: match c.kind {
                ast::CoordKind::Angle => CoordinateKind::Angle,
                ast::CoordKind::Length => CoordinateKind::Length,
            },
            symbols: CoordinateSymbols::new(&c.name.name),
            description: c.doc.as_ref().map(|d| d.value.clone()),
        })
        .collect();
    let inputs: Vec<Input> = file
        .inputs
        .iter()
        .map(|i| {
            let s = scale_of(i.unit.as_ref());
            Input {
                name: i.name.name.clone(),
                symbol: Symbol::new(&i.name.name),
                unit: i.unit.as_ref().map(|u| u.text.clone()).unwrap_or_default(),
                limits: i
                    .limits
                    .as_ref()
                    .map(|b| (b.lo.value() * s, b.hi.value() * s)),
                description: i.doc.as_ref().map(|d| d.value.clone()),
            }
        })
        .collect();
    let parameters: Vec<Parameter> = file
        .parameters
        .iter()
        .map(|p| {
            let s = scale_of(p.unit.as_ref());
            Parameter {
                name: p.name.name.clone(),
                symbol: Symbol::new(&p.name.name),
                value: p.value.value() * s,
                unit: p.unit.as_ref().map(|u| u.text.clone()).unwrap_or_default(),
                description: p.doc.as_ref().map(|d| d.value.clone()),
                estimate: p
                    .estimate
                    .as_ref()
                    .map(|b| (b.lo.value() * s, b.hi.value() * s)),
            }
        })
        .collect();
    let outputs = file
        .outputs
        .iter()
        .map(|o| Output {
            name: o.name.name.clone(),
            expr: match &o.expr {
                Some(e) => lw.expr(e),
                None => lw.name(&o.name.name),
            },
        })
        .collect();
    let mut kinetic = file
        .kinetic
        .first()
        .map_or(Expr::zero(), |k| lw.expr(&k.expr));
    // `inertia q = added_inertia(J)`: `1/2*J*q'^2` added to T
    for line in &file.inertias {
        if let Ok(term) = effects::expand(&line.call, &line.target) {
            kinetic += lw.expr(&term);
        }
    }
    let potential = file
        .potential
        .first()
        .map_or(Expr::zero(), |v| lw.expr(&v.expr));
    let mut forces: Vec<Expr> = coordinates
        .iter()
        .map(|c| {
            file.forces
                .iter()
                .filter(|f| f.coordinate.name == c.name)
                .map(|f| lw.expr(&f.expr))
                .sum()
        })
        .collect();
    let (sensors, actuators) = lower_signal_effects(&mut lw, file, &coordinates, &inputs);
    // Algebraic actuator effects are folded into the forces: every input
    // symbol becomes what the plant receives (`u` -> `u + V0`), line by line
    // in file order.
    for line in &file.actuators {
        let Some(j) = inputs.iter().position(|i| i.name == line.target.name) else {
            continue;
        };
        let algebraic = effects::lookup(line.effect_name().unwrap_or(""))
            .is_some_and(|e| !e.formula.is_empty());
        if !algebraic {
            continue;
        }
        let Ok(received) = effects::expand(&line.call, &line.target) else {
            continue;
        };
        let map: HashMap<Symbol, Expr> = [(inputs[j].symbol, lw.expr(&received))].into();
        for f in forces.iter_mut() {
            *f = crate::sym::substitute_symbols(*f, &map);
        }
    }
    // Parameter sets: entries evaluated against the nominal values.
    let nominal: HashMap<Symbol, f64> = parameters.iter().map(|p| (p.symbol, p.value)).collect();
    let sets = file
        .sets
        .iter()
        .map(|s| ParameterSet {
            name: s.name.name.clone(),
            description: s.title.as_ref().map(|t| t.value.clone()),
            values: s
                .entries
                .iter()
                .map(|e| {
                    // Values in SI, against the parameters' declared values.
                    let v = symbols
                        .and_then(|s| eval_si(&e.value, s))
                        .unwrap_or_else(|| lw.expr(&e.value).eval_map(&nominal));
                    (e.name.name.clone(), v)
                })
                .collect(),
        })
        .collect();
    lw.energies = coordinates
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let others: HashMap<Symbol, Expr> = coordinates
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, o)| (o.symbols.qd, Expr::zero()))
                .collect();
            let at_zero: HashMap<Symbol, Expr> = [(c.symbols.q, Expr::zero())].into();
            let t = crate::sym::substitute_symbols(kinetic, &others);
            let v = potential - crate::sym::substitute_symbols(potential, &at_zero);
            (c.name.clone(), t + v)
        })
        .collect();
    let controllers = file
        .controllers
        .iter()
        .map(|c| lower_controller(&mut lw, c, &coordinates, &inputs))
        .collect();
    let recorded = file
        .recorded
        .iter()
        .map(|r| lower_recorded(&mut lw, r, &inputs, &nominal))
        .collect();
    Model {
        name: file
            .model
            .as_ref()
            .map_or("model".to_string(), |m| m.name.name.clone()),
        description: file
            .model
            .as_ref()
            .and_then(|m| m.title.as_ref().map(|t| t.value.clone())),
        coordinates,
        inputs,
        outputs,
        parameters,
        derived: lw.derived,
        sets,
        kinetic,
        potential,
        forces,
        sensors,
        actuators,
        controllers,
        recorded,
    }
}

/// The `sensor` and `actuator` lines with their parameter expressions.
fn lower_signal_effects(
    lw: &mut Lowerer<'_>,
    file: &ast::ModelFile,
    coordinates: &[Coordinate],
    inputs: &[Input],
) -> (Vec<SensorEffect>, Vec<ActuatorEffect>) {
    let arg = |lw: &mut Lowerer<'_>, line: &ast::SignalEffect| {
        line.args().first().map_or(Expr::zero(), |a| lw.expr(a))
    };
    let mut sensors = Vec::new();
    for line in &file.sensors {
        let Some(i) = coordinates.iter().position(|c| c.name == line.target.name) else {
            continue;
        };
        if line.effect_name() == Some("sensor_offset") {
            sensors.push(SensorEffect {
                coordinate: i,
                effect: SensorEffectKind::Offset(arg(lw, line)),
            });
        }
    }
    let mut actuators = Vec::new();
    for line in &file.actuators {
        let Some(j) = inputs.iter().position(|u| u.name == line.target.name) else {
            continue;
        };
        let effect = match line.effect_name() {
            Some("input_offset") => ActuatorEffectKind::Offset(arg(lw, line)),
            Some("input_delay") => ActuatorEffectKind::Delay(arg(lw, line)),
            Some("deadzone") => ActuatorEffectKind::Deadzone(arg(lw, line)),
            Some("saturation") => ActuatorEffectKind::Saturation(arg(lw, line)),
            _ => continue,
        };
        actuators.push(ActuatorEffect { input: j, effect });
    }
    (sensors, actuators)
}

fn lower_gain(
    lw: &mut Lowerer<'_>,
    gains: &mut Vec<(String, f64)>,
    g: &ast::Ident,
    value: &ast::Expr,
) {
    let env: HashMap<Symbol, f64> = gains.iter().map(|(n, v)| (Symbol::new(n), *v)).collect();
    let v = lw.expr(value).eval_map(&env);
    gains.push((g.name.clone(), v));
}

fn lower_guard(lw: &mut Lowerer<'_>, g: &ast::Guard) -> Guard {
    match &g.kind {
        ast::GuardKind::Cmp(op, a, b) => Guard::Cmp {
            op: *op,
            lhs: lw.expr(a),
            rhs: lw.expr(b),
        },
        ast::GuardKind::And(a, b) => {
            Guard::And(Box::new(lower_guard(lw, a)), Box::new(lower_guard(lw, b)))
        }
        ast::GuardKind::Or(a, b) => {
            Guard::Or(Box::new(lower_guard(lw, a)), Box::new(lower_guard(lw, b)))
        }
    }
}

fn lower_controller(
    lw: &mut Lowerer<'_>,
    c: &ast::Controller,
    coordinates: &[Coordinate],
    inputs: &[Input],
) -> ControllerSpec {
    let name = c.name.name.clone();
    let mut gains: Vec<(String, f64)> = Vec::new();
    let mut output = None;
    let mut law = None;
    let mut surface = None;
    let mut direct: Vec<Option<Expr>> = vec![None; inputs.len()];
    let mut modes: Vec<ModeSpec> = Vec::new();
    let mut switches = Vec::new();
    let mut wrap = Vec::new();
    for st in &c.body {
        match st {
            ast::ControllerStmt::Place { poles, .. } => {
                return ControllerSpec::Place {
                    name,
                    poles: poles.iter().map(|p| p.value()).collect(),
                }
            }
            ast::ControllerStmt::Lqr { q, r, .. } => {
                return ControllerSpec::Lqr {
                    name,
                    q: q.iter().map(|x| x.value()).collect(),
                    r: r.iter().map(|x| x.value()).collect(),
                }
            }
            ast::ControllerStmt::Gains { values, .. } => {
                return ControllerSpec::Gains {
                    name,
                    k: vec![values.iter().map(|x| x.value()).collect()],
                }
            }
            ast::ControllerStmt::Linearize { output: o, .. } => output = Some(o.name.clone()),
            ast::ControllerStmt::Gain { name: g, value, .. } => {
                lower_gain(lw, &mut gains, g, value)
            }
            ast::ControllerStmt::Law { target, expr, .. } => {
                match inputs.iter().position(|i| i.name == target.name) {
                    Some(j) => direct[j] = Some(lw.expr(expr)),
                    None => law = Some(lw.expr(expr)),
                }
            }
            ast::ControllerStmt::Surface { name: s, def, .. } => {
                let spec = match def {
                    ast::SurfaceDef::Expr(e) => SurfaceSpec::Expr(lw.expr(e)),
                    ast::SurfaceDef::Poles(p) => {
                        SurfaceSpec::Poles(p.iter().map(|p| p.value()).collect())
                    }
                };
                surface = Some((s.name.clone(), spec));
            }
            ast::ControllerStmt::Mode {
                name: m,
                controller,
                swing_up,
                ..
            } => modes.push(ModeSpec {
                name: m.name.clone(),
                controller: controller.name.clone(),
                swing_up: swing_up.is_some(),
            }),
            ast::ControllerStmt::Switch { from, to, when, .. } => {
                let index = |m: &ast::Ident| modes.iter().position(|k| k.name == m.name);
                if let (Some(f), Some(t)) = (index(from), index(to)) {
                    switches.push(SwitchSpec {
                        from: f,
                        to: t,
                        when: lower_guard(lw, when),
                        text: when.to_string(),
                    });
                }
            }
            ast::ControllerStmt::Wrap { coordinate, .. } => {
                if let Some(i) = coordinates.iter().position(|q| q.name == coordinate.name) {
                    wrap.push(i);
                }
            }
        }
    }
    if !modes.is_empty() {
        return ControllerSpec::Hybrid {
            name,
            modes,
            switches,
            wrap,
        };
    }
    if let Some((surface_name, surface)) = surface {
        return ControllerSpec::SlidingMode {
            name,
            surface_name,
            surface,
            gains,
            v: law.unwrap_or_else(Expr::zero),
        };
    }
    if output.is_none() && direct.iter().any(Option::is_some) {
        return ControllerSpec::Direct {
            name,
            gains,
            laws: direct
                .into_iter()
                .map(|l| l.unwrap_or_else(Expr::zero))
                .collect(),
        };
    }
    ControllerSpec::FeedbackLinearization {
        name,
        output: output.unwrap_or_default(),
        gains,
        v: law.unwrap_or_else(Expr::zero),
    }
}

/// A `recorded controller` block: `derivative(x, wc)` calls become filter
/// symbols (named `derivative#k@block`, which no model name can be), gains
/// and local lets are inlined, signals become symbols of their own names.
fn lower_recorded(
    lw: &mut Lowerer<'_>,
    r: &ast::RecordedController,
    inputs: &[Input],
    nominal: &HashMap<Symbol, f64>,
) -> RecordedController {
    let mut env: HashMap<Symbol, Expr> = HashMap::new();
    let mut signals = Vec::new();
    let mut filters: Vec<DerivativeFilter> = Vec::new();
    let mut laws = Vec::new();
    let block = r.name.name.clone();
    // lower an expression, turning derivative calls into filters first
    let lower_expr = |lw: &mut Lowerer<'_>,
                      e: &ast::Expr,
                      env: &HashMap<Symbol, Expr>,
                      filters: &mut Vec<DerivativeFilter>|
     -> Expr {
        let mut e = e.clone();
        let mut found: Vec<(String, ast::Expr, ast::Expr)> = Vec::new();
        replace_derivatives(&mut e, &mut |args| {
            let name = format!("derivative#{}@{block}", filters.len() + found.len() + 1);
            found.push((name.clone(), args[0].clone(), args[1].clone()));
            name
        });
        for (name, x, wc) in found {
            let input = substitute_symbols(lw.expr(&x), env);
            let cutoff = substitute_symbols(lw.expr(&wc), env).eval_map(nominal);
            filters.push(DerivativeFilter {
                symbol: Symbol::new(&name),
                input,
                cutoff,
            });
        }
        substitute_symbols(lw.expr(&e), env)
    };
    for st in &r.body {
        match st {
            ast::RecordedStmt::Signal {
                name, unit, title, ..
            } => {
                let symbol = Symbol::new(&name.name);
                signals.push(RecordedSignal {
                    name: name.name.clone(),
                    symbol,
                    unit: unit.as_ref().map_or(String::new(), |u| u.text.clone()),
                    description: title.as_ref().map(|t| t.value.clone()),
                });
            }
            ast::RecordedStmt::Gain { name, value, .. }
            | ast::RecordedStmt::Let { name, value, .. } => {
                let v = lower_expr(lw, value, &env, &mut filters);
                env.insert(Symbol::new(&name.name), v);
            }
            ast::RecordedStmt::Law { target, expr, .. } => {
                let Some(j) = inputs.iter().position(|u| u.name == target.name) else {
                    continue;
                };
                let v = lower_expr(lw, expr, &env, &mut filters);
                laws.push((j, v));
            }
        }
    }
    RecordedController {
        name: r.name.name.clone(),
        description: r.title.as_ref().map(|t| t.value.clone()),
        signals,
        filters,
        laws,
    }
}

/// Replace every `derivative(a, b)` call in `e` by a name chosen by `name`
/// (given the call's arguments).
fn replace_derivatives(e: &mut ast::Expr, name: &mut dyn FnMut(&[ast::Expr]) -> String) {
    match &mut e.kind {
        ExprKind::Call(f, args) if f.name == "derivative" && args.len() == 2 => {
            let n = name(args);
            e.kind = ExprKind::Name(n);
        }
        ExprKind::Call(_, args) => args.iter_mut().for_each(|a| replace_derivatives(a, name)),
        ExprKind::Neg(a) => replace_derivatives(a, name),
        ExprKind::Binary(_, a, b) => {
            replace_derivatives(a, name);
            replace_derivatives(b, name);
        }
        _ => {}
    }
}
