//! Where every name of a model file is declared and used.
//!
//! [`occurrences`] walks a parsed [`ModelFile`] and lists each written name
//! with the symbol it denotes: editors use it for go to definition, find
//! references, rename ([`super::edit::rename`]), hover and highlighting.
//! [`root_exprs`] lists every expression of the file with the scope its
//! names resolve in. New syntax that holds expressions or names needs a line
//! in these two functions (and nowhere else in this module).

use super::ast::*;
use super::check::BUILTINS;
use super::effects;
use super::span::Span;
use std::collections::BTreeMap;

/// What a written name denotes.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum SymbolRef {
    /// A model-level name: coordinate, input, parameter, let, named output or
    /// energy (declared or not: an undeclared name is still one symbol).
    Model(String),
    /// A `gain` of the controller with this index in [`ModelFile::controllers`].
    Gain(usize, String),
    /// The output `y` of a feedback-linearizing controller's law.
    LawOutput(usize),
    /// A set or controller name (one namespace).
    Block(String),
    /// A sliding surface of the controller with this index (usable in its law).
    Surface(usize, String),
    /// A mode of the hybrid controller with this index.
    Mode(usize, String),
    /// A built-in function (`sin`, `atan2`, ...).
    Builtin(String),
    /// An effect (`viscous_friction`, `sensor_offset`, ...).
    Effect(String),
    /// A call of a name that is neither a built-in nor an effect.
    UnknownFunction(String),
}

/// Declaration or use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Role {
    /// Where the name is declared.
    Declaration,
    /// Where it is used.
    Reference,
}

/// One written name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Occurrence {
    /// The symbol.
    pub symbol: SymbolRef,
    /// Span of the name only (without `'` of a derivative).
    pub span: Span,
    /// Declaration or use.
    pub role: Role,
}

/// Where the names of an expression resolve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExprScope {
    /// Model names (lets, energies, outputs, forces, sensor/actuator lines,
    /// set values, gain values).
    Model,
    /// The law of the controller with this index: its gains and `y` first,
    /// then model names.
    Law(usize),
}

/// Every expression of the file (the roots; walk them with [`Expr::walk`]),
/// with its scope, in source order.
pub fn root_exprs(file: &ModelFile) -> Vec<(&Expr, ExprScope)> {
    let mut v: Vec<(&Expr, ExprScope)> = Vec::new();
    let m = ExprScope::Model;
    v.extend(
        file.outputs
            .iter()
            .filter_map(|o| o.expr.as_ref())
            .map(|e| (e, m)),
    );
    v.extend(file.lets.iter().map(|l| (&l.expr, m)));
    v.extend(
        file.kinetic
            .iter()
            .chain(&file.potential)
            .map(|e| (&e.expr, m)),
    );
    v.extend(file.forces.iter().map(|f| (&f.written, m)));
    v.extend(
        file.sensors
            .iter()
            .chain(&file.actuators)
            .chain(&file.inertias)
            .map(|s| (&s.call, m)),
    );
    for s in &file.sets {
        v.extend(s.entries.iter().map(|e| (&e.value, m)));
    }
    for (i, c) in file.controllers.iter().enumerate() {
        for st in &c.body {
            match st {
                ControllerStmt::Gain { value, .. } => v.push((value, m)),
                ControllerStmt::Law { expr, .. } => v.push((expr, ExprScope::Law(i))),
                ControllerStmt::Surface {
                    def: SurfaceDef::Expr(e),
                    ..
                } => v.push((e, ExprScope::Law(i))),
                ControllerStmt::Switch { when, .. } => {
                    for (_, a, b) in when.comparisons() {
                        v.push((a, m));
                        v.push((b, m));
                    }
                }
                _ => {}
            }
        }
    }
    v.sort_by_key(|(e, _)| e.span.start);
    v
}

/// Every written name of the file, in source order.
pub fn occurrences(file: &ModelFile) -> Vec<Occurrence> {
    let mut out = Vec::new();
    let mut push =
        |symbol: SymbolRef, span: Span, role: Role| out.push(Occurrence { symbol, span, role });
    let model = |i: &Ident| SymbolRef::Model(i.name.clone());
    let decl = Role::Declaration;
    let refr = Role::Reference;
    for c in &file.coordinates {
        push(model(&c.name), c.name.span, decl);
    }
    for i in &file.inputs {
        push(model(&i.name), i.name.span, decl);
    }
    for p in &file.parameters {
        push(model(&p.name), p.name.span, decl);
    }
    for l in &file.lets {
        push(model(&l.name), l.name.span, decl);
    }
    for o in &file.outputs {
        // `output alpha` names a coordinate or let; `output tip = ...` declares.
        let role = if o.expr.is_some() { decl } else { refr };
        push(model(&o.name), o.name.span, role);
    }
    for e in file.kinetic.iter().chain(&file.potential) {
        push(model(&e.name), e.name.span, decl);
    }
    for f in &file.forces {
        push(model(&f.coordinate), f.coordinate.span, refr);
    }
    for s in file
        .sensors
        .iter()
        .chain(&file.actuators)
        .chain(&file.inertias)
    {
        push(model(&s.target), s.target.span, refr);
    }
    for s in &file.sets {
        push(SymbolRef::Block(s.name.name.clone()), s.name.span, decl);
        for e in &s.entries {
            push(model(&e.name), e.name.span, refr);
        }
    }
    // a controller's own names in its law: gains and surfaces
    let mut gains: Vec<BTreeMap<&str, SymbolRef>> = Vec::new();
    for (ci, c) in file.controllers.iter().enumerate() {
        push(SymbolRef::Block(c.name.name.clone()), c.name.span, decl);
        let mut g = BTreeMap::new();
        for st in &c.body {
            match st {
                ControllerStmt::Gain { name, .. } => {
                    let sym = SymbolRef::Gain(ci, name.name.clone());
                    g.insert(name.name.as_str(), sym.clone());
                    push(sym, name.span, decl);
                }
                ControllerStmt::Surface { name, .. } => {
                    let sym = SymbolRef::Surface(ci, name.name.clone());
                    g.insert(name.name.as_str(), sym.clone());
                    push(sym, name.span, decl);
                }
                ControllerStmt::Linearize { output, .. } => {
                    push(model(output), output.span, refr);
                }
                // `Vm = ...`: a direct law names its input (`v` is the outer law)
                ControllerStmt::Law { target, .. } if target.name != "v" => {
                    push(model(target), target.span, refr);
                }
                ControllerStmt::Mode {
                    name, controller, ..
                } => {
                    push(SymbolRef::Mode(ci, name.name.clone()), name.span, decl);
                    push(
                        SymbolRef::Block(controller.name.clone()),
                        controller.span,
                        refr,
                    );
                }
                ControllerStmt::Switch { from, to, .. } => {
                    push(SymbolRef::Mode(ci, from.name.clone()), from.span, refr);
                    push(SymbolRef::Mode(ci, to.name.clone()), to.span, refr);
                }
                ControllerStmt::Wrap { coordinate, .. } => {
                    push(model(coordinate), coordinate.span, refr);
                }
                _ => {}
            }
        }
        gains.push(g);
    }
    for (root, scope) in root_exprs(file) {
        root.walk(&mut |e| {
            let (name, span) = match &e.kind {
                ExprKind::Name(n) => (n.as_str(), e.span),
                ExprKind::Deriv(n, _) => {
                    (n.as_str(), Span::new(e.span.start, e.span.start + n.len()))
                }
                ExprKind::Call(f, _) => {
                    let sym = if BUILTINS.iter().any(|(b, _)| *b == f.name) {
                        SymbolRef::Builtin(f.name.clone())
                    } else if effects::lookup(&f.name).is_some() {
                        SymbolRef::Effect(f.name.clone())
                    } else {
                        SymbolRef::UnknownFunction(f.name.clone())
                    };
                    push(sym, f.span, refr);
                    return;
                }
                _ => return,
            };
            let sym = match scope {
                ExprScope::Law(ci) if gains[ci].contains_key(name) => gains[ci][name].clone(),
                ExprScope::Law(ci) if name == "y" => SymbolRef::LawOutput(ci),
                _ => SymbolRef::Model(name.to_string()),
            };
            push(sym, span, refr);
        });
    }
    out.sort_by_key(|o| (o.span.start, o.span.end));
    out
}

/// The occurrence whose name span contains byte `offset` (a cursor just after
/// the last character still counts).
pub fn occurrence_at(occurrences: &[Occurrence], offset: usize) -> Option<&Occurrence> {
    occurrences
        .iter()
        .find(|o| o.span.start <= offset && offset < o.span.end)
        .or_else(|| occurrences.iter().find(|o| o.span.end == offset))
}
