//! Hover: what a name, an effect, a function or a unit is.

use crate::analysis::{short_dim, Analysis};
use lsp_types::{Hover, HoverContents, MarkupContent, MarkupKind};
use plantc_derive::lang::ast::CoordKind;
use plantc_derive::lang::check::SymbolKind;
use plantc_derive::lang::effects::{self, EffectKind};
use plantc_derive::lang::units::{self, parse_unit};
use plantc_derive::lang::visit::SymbolRef;
use plantc_derive::lang::Span;

/// Markdown for the thing at byte `offset`, with the range it applies to.
pub fn hover(a: &Analysis, offset: usize) -> Option<Hover> {
    let (text, span) = match a.occurrence_at(offset) {
        Some(o) => (symbol(a, &o.symbol, o.span)?, o.span),
        None => unit_at(a, offset)?,
    };
    Some(Hover {
        contents: HoverContents::Markup(MarkupContent {
            kind: MarkupKind::Markdown,
            value: text,
        }),
        range: Some(a.doc.range(span)),
    })
}

fn code(s: &str) -> String {
    format!("```plant\n{s}\n```")
}

fn symbol(a: &Analysis, s: &SymbolRef, at: Span) -> Option<String> {
    let f = &a.file;
    match s {
        SymbolRef::Model(name) => match a.kind_of(name) {
            Some(SymbolKind::Coordinate(k)) => {
                let c = f.coordinates.iter().find(|c| &c.name.name == name)?;
                let (kind, unit) = match k {
                    CoordKind::Angle => ("angle", "rad"),
                    CoordKind::Length => ("length", "m"),
                };
                let mut t = code(&format!("coordinate {name} : {kind}"));
                t.push_str(&format!(
                    "\n\nA generalised coordinate, an **{kind}** (unit {unit}); `{name}'` and `{name}''` are its velocity and acceleration."
                ));
                if let Some(d) = &c.doc {
                    t.push_str(&format!("\n\n{}", d.value));
                }
                Some(t)
            }
            Some(SymbolKind::Input) => {
                let i = f.inputs.iter().find(|i| &i.name.name == name)?;
                let mut t = code(a.slice(i.span));
                t.push_str("\n\nA control input");
                if let Some(u) = &i.unit {
                    t.push_str(&format!(", unit `{}`", u.text));
                }
                if let Some(l) = &i.limits {
                    t.push_str(&format!(", saturated to [{}, {}]", l.lo.text, l.hi.text));
                }
                t.push('.');
                if let Some(d) = &i.doc {
                    t.push_str(&format!("\n\n{}", d.value));
                }
                Some(t)
            }
            Some(SymbolKind::Parameter) => {
                let p = f.parameters.iter().find(|p| &p.name.name == name)?;
                let unit = p.unit.as_ref().map_or("1".to_string(), |u| u.text.clone());
                let mut t = match &p.unit {
                    Some(u) => code(&format!("parameter {name} = {} [{}]", p.value.text, u.text)),
                    None => {
                        code(&format!("parameter {name} = {}", p.value.text)) + "\n\nDimensionless."
                    }
                };
                if let Some(d) = &p.doc {
                    t.push_str(&format!("\n\n{}", d.value));
                }
                if let Some(pv) = a
                    .checked
                    .symbols
                    .as_ref()
                    .and_then(|s| s.parameters.get(name))
                {
                    if !pv.unit.scale.is_one() {
                        t.push_str(&format!(
                            "\n\n= {} {} in SI",
                            pv.si_value,
                            short_dim(pv.unit.dim)
                        ));
                    }
                }
                match &p.estimate {
                    Some(b) => t.push_str(&format!(
                        "\n\nEstimated by `plantc fit` within [{}, {}] {unit}.",
                        b.lo.text, b.hi.text
                    )),
                    None => t.push_str("\n\nNot estimated (no `estimate [lo, hi]`)."),
                }
                let sets: Vec<String> = f
                    .sets
                    .iter()
                    .flat_map(|s| {
                        s.entries
                            .iter()
                            .filter(|e| &e.name.name == name)
                            .map(move |e| {
                                format!("- set `{}`: `{}`", s.name.name, a.slice(e.value.span))
                            })
                    })
                    .collect();
                if !sets.is_empty() {
                    t.push_str(&format!("\n\nIn parameter sets:\n{}", sets.join("\n")));
                }
                Some(t)
            }
            Some(SymbolKind::Let) => {
                let l = f.lets.iter().find(|l| &l.name.name == name)?;
                let mut t = code(&format!("let {name} = {}", a.slice(l.expr.span)));
                if let Some(d) = a.dim_of_name(name) {
                    t.push_str(&format!("\n\nDerived unit: `{}`", short_dim(d)));
                    if !d.is_none() && d.common_name().is_some() {
                        t.push_str(&format!(" = {}", d.base_form()));
                    }
                }
                Some(t)
            }
            Some(SymbolKind::Output) => {
                let o = f.outputs.iter().find(|o| &o.name.name == name)?;
                let mut t = code(a.slice(o.span));
                if let Some(d) = o.expr.as_ref().and_then(|e| a.dim_of(e)) {
                    t.push_str(&format!("\n\nAn output, unit `{}`.", short_dim(d)));
                }
                Some(t)
            }
            Some(SymbolKind::Energy) => {
                let (e, what) = match f.kinetic.iter().find(|e| &e.name.name == name) {
                    Some(e) => (e, "kinetic"),
                    None => (
                        f.potential.iter().find(|e| &e.name.name == name)?,
                        "potential",
                    ),
                };
                let mut t = code(a.slice(e.span));
                t.push_str(&format!(
                    "\n\nThe {what} energy; the equations of motion come from T - V."
                ));
                if let Some(d) = a.dim_of(&e.expr) {
                    t.push_str(&format!(" Unit: `{}`.", short_dim(d)));
                }
                Some(t)
            }
            None => Some(format!("`{name}` is not declared")),
        },
        SymbolRef::Gain(ci, name) => {
            let c = f.controllers.get(*ci)?;
            Some(format!(
                "{}\n\nA gain of controller `{}`, usable in its law.",
                code(&format!("gain {name}")),
                c.name.name
            ))
        }
        SymbolRef::Surface(ci, name) => {
            let c = f.controllers.get(*ci)?;
            Some(format!(
                "{}\n\nThe sliding surface of controller `{}`, usable in its law.",
                code(&format!("surface {name}")),
                c.name.name
            ))
        }
        SymbolRef::Mode(ci, name) => {
            let c = f.controllers.get(*ci)?;
            let (drives, swing) = c.body.iter().find_map(|s| match s {
                plantc_derive::lang::ast::ControllerStmt::Mode {
                    name: n,
                    controller,
                    swing_up,
                    ..
                } if &n.name == name => Some((controller.name.clone(), swing_up.is_some())),
                _ => None,
            })?;
            Some(format!(
                "{}\n\nA mode of the hybrid controller `{}`, driven by `{drives}`{}.",
                code(&format!("mode {name}")),
                c.name.name,
                if swing {
                    " (swing-up: the pendulum anywhere)"
                } else {
                    ""
                }
            ))
        }
        SymbolRef::LawOutput(ci) => {
            let c = f.controllers.get(*ci)?;
            let out = c.body.iter().find_map(|s| match s {
                plantc_derive::lang::ast::ControllerStmt::Linearize { output, .. } => {
                    Some(output.name.clone())
                }
                _ => None,
            });
            Some(format!(
                "`y`: the linearized output{} of controller `{}`; `y'` is its derivative and the law sets `y'' = v`.",
                out.map_or(String::new(), |o| format!(" (`{o}`)")),
                c.name.name
            ))
        }
        SymbolRef::Block(name) => {
            if let Some(s) = f.sets.iter().find(|s| &s.name.name == name) {
                let title = s
                    .title
                    .as_ref()
                    .map_or(String::new(), |t| format!("\n\n{}", t.value));
                return Some(format!(
                    "{}{title}\n\nA parameter set ({} value(s)); use it with `--set {name}`.",
                    code(&format!("set {name}")),
                    s.entries.len()
                ));
            }
            let c = f.controllers.iter().find(|c| &c.name.name == name)?;
            let title = c
                .title
                .as_ref()
                .map_or(String::new(), |t| format!("\n\n{}", t.value));
            Some(format!(
                "{}{title}\n\nA controller; use it with `--controller {name}`.",
                code(&format!("controller {name}"))
            ))
        }
        SymbolRef::Effect(name) => {
            let e = effects::lookup(name)?;
            let mut t = code(&e.signature());
            let line = match e.kind {
                EffectKind::Force => "a force term, in `force q = ...` lines",
                EffectKind::Sensor => "a sensor effect, in `sensor q = ...` lines",
                EffectKind::Actuator => "an actuator effect, in `actuator u = ...` lines",
                EffectKind::Inertia => "a kinetic-energy term, in `inertia q = ...` lines",
            };
            t.push_str(&format!("\n\n{}\n\nEffect: {line}.", e.doc));
            if !e.formula.is_empty() {
                t.push_str(&format!(" Formula: `{}`", e.formula));
                if e.formula_full != e.formula {
                    t.push_str(&format!(", or `{}` with all arguments", e.formula_full));
                }
                t.push('.');
            }
            if let Some((_, args)) = a.call_at(at) {
                let names = e.params.iter().chain(e.optional.iter());
                let lines: Vec<String> = names
                    .zip(args.iter())
                    .map(|(p, x)| format!("- `{p}` = `{}`", a.slice(x.span)))
                    .collect();
                if !lines.is_empty() {
                    t.push_str(&format!("\n\nArguments:\n{}", lines.join("\n")));
                }
            }
            Some(t)
        }
        SymbolRef::Builtin(name) => Some(builtin_doc(name)),
        SymbolRef::UnknownFunction(name) => {
            Some(format!("`{name}` is not a built-in function or an effect"))
        }
    }
}

/// Documentation of a built-in function.
pub fn builtin_doc(name: &str) -> String {
    let (sig, doc) = match name {
        "sin" | "cos" | "tan" | "tanh" => {
            ("(x)", "of a dimensionless argument (angles are in rad)")
        }
        "exp" | "ln" => ("(x)", "of a dimensionless argument"),
        "sqrt" => ("(x)", "square root; halves the exponents of the unit"),
        "abs" => ("(x)", "absolute value; keeps the unit"),
        "sign" => ("(x)", "-1, 0 or 1; dimensionless"),
        "atan2" => ("(y, x)", "angle of (x, y); both arguments of the same unit"),
        _ => ("(..)", ""),
    };
    format!(
        "{}\n\nBuilt-in function: {doc}.",
        code(&format!("{name}{sig}"))
    )
}

/// A unit symbol inside `[ ]` under the cursor.
fn unit_at(a: &Analysis, offset: usize) -> Option<(String, Span)> {
    let spans = a.unit_spans();
    let us = spans
        .into_iter()
        .find(|s| s.start <= offset && offset <= s.end)?;
    let text = a.text().as_bytes();
    let word = |b: u8| b.is_ascii_alphanumeric() || b == b'_';
    let (mut s, mut e) = (offset, offset);
    while s > us.start && word(text[s - 1]) {
        s -= 1;
    }
    while e < us.end && word(text[e]) {
        e += 1;
    }
    let name = a.slice(Span::new(s, e));
    let def = units::lookup(name)?;
    let whole = a.slice(us);
    let mut t = format!("`{}`: {}", def.name, def.doc);
    if let Ok(u) = parse_unit(whole) {
        t.push_str(&format!("\n\n`[{whole}]` = {}", u.dim));
    }
    Some((t, Span::new(s, e)))
}
