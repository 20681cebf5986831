//! Lossless editing of model files.
//!
//! Each function changes one thing in the source text and leaves every other
//! byte untouched (comments, alignment, line endings). The result is parsed
//! and checked again; an edit that would introduce an error is refused.

use super::ast::ModelFile;
use super::check::{parse_and_check, suggest};
use super::diagnostic::Diagnostic;
use super::effects;
use super::lexer::{lex, Tok};
use super::span::Span;
use super::visit::{occurrences, SymbolRef};
use std::collections::BTreeSet;
use std::fmt;

/// Why an edit was refused.
#[derive(Debug, Clone, PartialEq)]
pub enum EditError {
    /// The original text does not parse; the diagnostics say why.
    InvalidSource(Vec<Diagnostic>),
    /// No parameter of that name.
    UnknownParameter {
        /// The name asked for.
        name: String,
        /// Close names that exist.
        suggestions: Vec<String>,
    },
    /// No coordinate of that name.
    UnknownCoordinate {
        /// The name asked for.
        name: String,
        /// Close names that exist.
        suggestions: Vec<String>,
    },
    /// No input of that name.
    UnknownInput {
        /// The name asked for.
        name: String,
        /// Close names that exist.
        suggestions: Vec<String>,
    },
    /// The given text is not a single effect call on one line.
    NotAnEffectCall(String),
    /// The given text is not a plain number literal (optionally negative).
    NotANumber(String),
    /// The given declaration is not a single `parameter` line.
    NotAParameterDeclaration(String),
    /// The edited file would have these new errors.
    WouldBreak(Vec<Diagnostic>),
    /// The new name is not a name of the model language.
    NotAName(String),
    /// The new name is already used by another symbol in the same scope.
    NameTaken(String),
    /// This symbol cannot be renamed (a built-in function or an effect).
    NotRenamable(String),
}

impl fmt::Display for EditError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EditError::InvalidSource(d) => {
                write!(f, "the model file has {} syntax error(s)", d.len())
            }
            EditError::UnknownParameter { name, suggestions } => {
                write!(f, "no parameter `{name}`")?;
                if !suggestions.is_empty() {
                    write!(f, " (did you mean {}?)", suggestions.join(", "))?;
                }
                Ok(())
            }
            EditError::UnknownCoordinate { name, suggestions } => {
                write!(f, "no coordinate `{name}`")?;
                if !suggestions.is_empty() {
                    write!(f, " (did you mean {}?)", suggestions.join(", "))?;
                }
                Ok(())
            }
            EditError::UnknownInput { name, suggestions } => {
                write!(f, "no input `{name}`")?;
                if !suggestions.is_empty() {
                    write!(f, " (did you mean {}?)", suggestions.join(", "))?;
                }
                Ok(())
            }
            EditError::NotAnEffectCall(t) => write!(f, "`{t}` is not a single effect call"),
            EditError::NotANumber(t) => write!(f, "`{t}` is not a number literal"),
            EditError::NotAParameterDeclaration(t) => {
                write!(f, "`{t}` is not a single `parameter` declaration")
            }
            EditError::NotAName(t) => write!(
                f,
                "`{t}` is not a name (ASCII letters, digits and `_`, not starting with a digit; not a keyword, `pi` or a built-in function)"
            ),
            EditError::NameTaken(t) => write!(f, "`{t}` is already used by another name"),
            EditError::NotRenamable(t) => write!(f, "`{t}` is built into the language and cannot be renamed"),
            EditError::WouldBreak(d) => {
                write!(f, "the edit would make the model invalid: ")?;
                let msgs: Vec<&str> = d.iter().map(|d| d.message.as_str()).collect();
                f.write_str(&msgs.join("; "))
            }
        }
    }
}

impl std::error::Error for EditError {}

/// Formats a float as a number literal of the model language (shortest
/// round-trip text, exponent form for very small or large magnitudes).
pub fn number_text(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-4..1e6).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

fn parse_ok(text: &str) -> Result<(ModelFile, BTreeSet<(String, String)>), EditError> {
    let c = parse_and_check("<edit>", text);
    let errors = c
        .diagnostics
        .iter()
        .filter(|d| d.is_error())
        .map(|d| (d.code.to_string(), d.message.clone()))
        .collect();
    match c.model {
        Some(m) => Ok((m, errors)),
        None => Err(EditError::InvalidSource(c.diagnostics)),
    }
}

/// Applies replacements (non-overlapping spans) and re-checks the result
/// against the errors the original already had.
fn apply(
    text: &str,
    before: &BTreeSet<(String, String)>,
    mut edits: Vec<(Span, String)>,
) -> Result<String, EditError> {
    edits.sort_by_key(|(s, _)| std::cmp::Reverse(s.start));
    let mut out = text.to_string();
    for (s, r) in edits {
        out.replace_range(s.start..s.end, &r);
    }
    let c = parse_and_check("<edit>", &out);
    let new: Vec<Diagnostic> = c
        .diagnostics
        .into_iter()
        .filter(|d| d.is_error() && !before.contains(&(d.code.to_string(), d.message.clone())))
        .collect();
    if new.is_empty() {
        Ok(out)
    } else {
        Err(EditError::WouldBreak(new))
    }
}

fn check_number(t: &str) -> Result<String, EditError> {
    let t = t.trim();
    let body = t.strip_prefix('-').unwrap_or(t);
    let mut d = Vec::new();
    let toks = lex(body, &mut d);
    let ok = d.is_empty()
        && toks.len() == 2
        && toks[0].tok == Tok::Number
        && toks[0].span == Span::new(0, body.len());
    if ok {
        Ok(t.to_string())
    } else {
        Err(EditError::NotANumber(t.to_string()))
    }
}

fn find_param<'m>(m: &'m ModelFile, name: &str) -> Result<&'m super::ast::Parameter, EditError> {
    m.parameters
        .iter()
        .find(|p| p.name.name == name)
        .ok_or_else(|| EditError::UnknownParameter {
            name: name.to_string(),
            suggestions: suggest(name, m.parameters.iter().map(|p| p.name.name.as_str())),
        })
}

/// Offset just after the end of the line containing `offset` (after its
/// `\n`, `\r\n` or lone `\r`).
fn after_line(text: &str, offset: usize) -> usize {
    let b = text.as_bytes();
    match text[offset..].find(['\n', '\r']) {
        None => text.len(),
        Some(i) if b[offset + i] == b'\r' && b.get(offset + i + 1) == Some(&b'\n') => {
            offset + i + 2
        }
        Some(i) => offset + i + 1,
    }
}

/// The file's line ending: `\r\n`, a lone `\r` (classic Mac) or `\n`.
fn line_ending(text: &str) -> &'static str {
    if text.contains("\r\n") {
        "\r\n"
    } else if text.contains('\r') && !text.contains('\n') {
        "\r"
    } else {
        "\n"
    }
}

/// Inserts a full line after the line containing `offset` (or at the end).
fn insert_line(text: &str, offset: usize, line: &str) -> (Span, String) {
    let nl = line_ending(text);
    let at = after_line(text, offset);
    if at == text.len() && !text.is_empty() && !text.ends_with(['\n', '\r']) {
        (Span::new(at, at), format!("{nl}{line}"))
    } else {
        (Span::new(at, at), format!("{line}{nl}"))
    }
}

/// Replaces the value literal of parameter `name` by `value_text` (a number
/// in the parameter's declared unit, e.g. `0.0031` or `-2e-3`).
pub fn set_parameter_value(text: &str, name: &str, value_text: &str) -> Result<String, EditError> {
    let value = check_number(value_text)?;
    let (m, before) = parse_ok(text)?;
    let p = find_param(&m, name)?;
    apply(text, &before, vec![(p.value.span, value)])
}

/// Sets the estimate bounds of parameter `name` (in its declared unit),
/// replacing existing bounds or appending ` estimate [lo, hi]` to its line.
pub fn set_estimate(text: &str, name: &str, lo: &str, hi: &str) -> Result<String, EditError> {
    let lo = check_number(lo)?;
    let hi = check_number(hi)?;
    let (m, before) = parse_ok(text)?;
    let p = find_param(&m, name)?;
    let edits = match &p.estimate {
        Some(b) => vec![(b.lo.span, lo), (b.hi.span, hi)],
        None => vec![(
            Span::new(p.span.end, p.span.end),
            format!(" estimate [{lo}, {hi}]"),
        )],
    };
    apply(text, &before, edits)
}

/// Removes the ` estimate [lo, hi]` clause of parameter `name` (the
/// parameter is then fixed at its value); a parameter without one is left
/// as it is.
pub fn clear_estimate(text: &str, name: &str) -> Result<String, EditError> {
    let (m, before) = parse_ok(text)?;
    let p = find_param(&m, name)?;
    let Some(b) = &p.estimate else {
        return Ok(text.to_string());
    };
    let head = text[..b.span.start].trim_end();
    let Some(kw) = head.strip_suffix("estimate") else {
        return Ok(text.to_string());
    };
    let start = kw.trim_end().len();
    apply(
        text,
        &before,
        vec![(Span::new(start, b.span.end), String::new())],
    )
}

/// Adds a term such as `+ coulomb_friction(Fc_alpha)` to the force on
/// `coordinate` (a term without a leading sign gets `+ `). If the coordinate
/// has no `force` line, `force q = term` is added after the last force line
/// (or after the energies when there is none).
pub fn add_force_term(text: &str, coordinate: &str, term_text: &str) -> Result<String, EditError> {
    let term = term_text.trim();
    if term.contains('\n') || term.is_empty() {
        return Err(EditError::WouldBreak(Vec::new()));
    }
    let (m, before) = parse_ok(text)?;
    require_coordinate(&m, coordinate)?;
    let edit = match m.forces.iter().find(|f| f.coordinate.name == coordinate) {
        Some(f) => {
            let t = if term.starts_with('+') || term.starts_with('-') {
                format!(" {term}")
            } else {
                format!(" + {term}")
            };
            (Span::new(f.expr_end, f.expr_end), t)
        }
        None => {
            let body = term.strip_prefix('+').map_or(term, str::trim_start);
            let anchor = m
                .forces
                .iter()
                .map(|f| f.span.end)
                .max()
                .or_else(|| {
                    m.kinetic
                        .iter()
                        .chain(m.potential.iter())
                        .map(|e| e.span.end)
                        .max()
                })
                .unwrap_or(text.len());
            insert_line(text, anchor, &format!("force {coordinate} = {body}"))
        }
    };
    apply(text, &before, vec![edit])
}

/// Adds a parameter declaration line (e.g.
/// `parameter Fc_alpha = 0.001 [N*m] "pendulum dry friction" estimate [0, 0.01]`)
/// after the last parameter, or after the other declarations if there is none.
pub fn add_parameter(text: &str, decl_line: &str) -> Result<String, EditError> {
    let decl = decl_line.trim();
    let (single, _) = super::parser::parse(decl);
    let ok = !decl.contains('\n')
        && single.parameters.len() == 1
        && single.coordinates.is_empty()
        && single.lets.is_empty()
        && single.model.is_none()
        && decl.starts_with("parameter");
    if !ok {
        return Err(EditError::NotAParameterDeclaration(decl.to_string()));
    }
    let (m, before) = parse_ok(text)?;
    let anchor = m
        .parameters
        .iter()
        .map(|p| p.span.end)
        .max()
        .or_else(|| {
            m.coordinates
                .iter()
                .map(|c| c.span.end)
                .chain(m.inputs.iter().map(|i| i.span.end))
                .chain(m.outputs.iter().map(|o| o.span.end))
                .chain(m.model.iter().map(|d| d.span.end))
                .max()
        })
        .unwrap_or(text.len());
    apply(text, &before, vec![insert_line(text, anchor, decl)])
}

/// Checks that `call_text` is one call expression on one line.
fn check_call(call_text: &str) -> Result<String, EditError> {
    let call = call_text.trim();
    let ok = !call.contains('\n')
        && !call.contains('\r')
        && matches!(
            super::parser::parse_expr(call),
            Ok(super::ast::Expr {
                kind: super::ast::ExprKind::Call(..),
                ..
            })
        );
    if ok {
        Ok(call.to_string())
    } else {
        Err(EditError::NotAnEffectCall(call.to_string()))
    }
}

/// Where a new `force`/`sensor`/`actuator`/`inertia` line goes: after the
/// last of those lines, or after the energies when there is none.
fn effect_anchor(m: &ModelFile, text: &str) -> usize {
    m.forces
        .iter()
        .map(|f| f.span.end)
        .chain(m.sensors.iter().map(|s| s.span.end))
        .chain(m.actuators.iter().map(|a| a.span.end))
        .chain(m.inertias.iter().map(|a| a.span.end))
        .max()
        .or_else(|| {
            m.kinetic
                .iter()
                .chain(m.potential.iter())
                .map(|e| e.span.end)
                .max()
        })
        .unwrap_or(text.len())
}

/// Adds the line `sensor <coordinate> = <call>` (e.g. `sensor_offset(d_alpha)`)
/// after the last force, sensor or actuator line. The result must check:
/// the call must be a sensor effect whose arguments exist, with the right units.
pub fn add_sensor_effect(
    text: &str,
    coordinate: &str,
    call_text: &str,
) -> Result<String, EditError> {
    add_coordinate_effect(text, "sensor", coordinate, call_text)
}

/// Adds the line `<keyword> <coordinate> = <call>` after the last force,
/// sensor, actuator or inertia line (see [`add_sensor_effect`] and
/// [`add_inertia_effect`]).
fn add_coordinate_effect(
    text: &str,
    keyword: &str,
    coordinate: &str,
    call_text: &str,
) -> Result<String, EditError> {
    let call = check_call(call_text)?;
    let (m, before) = parse_ok(text)?;
    require_coordinate(&m, coordinate)?;
    let anchor = effect_anchor(&m, text);
    let edit = insert_line(text, anchor, &format!("{keyword} {coordinate} = {call}"));
    apply(text, &before, vec![edit])
}

/// The error when `coordinate` is not a coordinate of `m`.
fn require_coordinate(m: &ModelFile, coordinate: &str) -> Result<(), EditError> {
    if m.coordinates.iter().any(|c| c.name.name == coordinate) {
        return Ok(());
    }
    Err(EditError::UnknownCoordinate {
        name: coordinate.to_string(),
        suggestions: suggest(
            coordinate,
            m.coordinates.iter().map(|c| c.name.name.as_str()),
        ),
    })
}

/// Adds the line `actuator <input> = <call>` (e.g. `input_delay(Td_Vm)`)
/// after the last force, sensor or actuator line. The result must check:
/// the call must be an actuator effect whose arguments exist, with the right
/// units.
pub fn add_actuator_effect(text: &str, input: &str, call_text: &str) -> Result<String, EditError> {
    let call = check_call(call_text)?;
    let (m, before) = parse_ok(text)?;
    if !m.inputs.iter().any(|i| i.name.name == input) {
        return Err(EditError::UnknownInput {
            name: input.to_string(),
            suggestions: suggest(input, m.inputs.iter().map(|i| i.name.name.as_str())),
        });
    }
    let anchor = effect_anchor(&m, text);
    let edit = insert_line(text, anchor, &format!("actuator {input} = {call}"));
    apply(text, &before, vec![edit])
}

/// The replacements that rename `symbol` (see [`super::visit::occurrences`])
/// to `new_name` everywhere in the file, checked like every edit: the result
/// must parse and check with no new error, and the new name must not be
/// taken by another symbol it could be confused with (which would silently
/// change what a name means).
pub fn rename_edits(
    text: &str,
    symbol: &SymbolRef,
    new_name: &str,
) -> Result<Vec<(Span, String)>, EditError> {
    let new_name = new_name.trim();
    let mut d = Vec::new();
    let toks = lex(new_name, &mut d);
    let reserved = super::parser::KEYWORDS.contains(&new_name)
        || new_name == "pi"
        || super::check::BUILTINS.iter().any(|(b, _)| *b == new_name)
        || effects::lookup(new_name).is_some();
    if !d.is_empty() || toks.len() != 2 || toks[0].tok != Tok::Ident || reserved {
        return Err(EditError::NotAName(new_name.to_string()));
    }
    let (old, scope_names): (&str, Vec<String>) = {
        let (m, _) = super::parser::parse(text);
        let occ = occurrences(&m);
        let names_of = |f: &dyn Fn(&SymbolRef) -> Option<String>| -> Vec<String> {
            occ.iter().filter_map(|o| f(&o.symbol)).collect()
        };
        match symbol {
            SymbolRef::Model(n) => (
                n.as_str(),
                // model names, and gains/`y` that would shadow it in a law
                names_of(&|s| match s {
                    SymbolRef::Model(x) | SymbolRef::Gain(_, x) | SymbolRef::Surface(_, x) => {
                        Some(x.clone())
                    }
                    SymbolRef::LawOutput(_) => Some("y".into()),
                    _ => None,
                }),
            ),
            // a controller's gains and surfaces share its law's namespace
            SymbolRef::Gain(ci, n) | SymbolRef::Surface(ci, n) => (
                n.as_str(),
                names_of(&|s| match s {
                    SymbolRef::Model(x) => Some(x.clone()),
                    SymbolRef::Gain(c, x) | SymbolRef::Surface(c, x) if c == ci => Some(x.clone()),
                    SymbolRef::LawOutput(c) if c == ci => Some("y".into()),
                    _ => None,
                }),
            ),
            SymbolRef::Block(n) => (
                n.as_str(),
                names_of(&|s| match s {
                    SymbolRef::Block(x) => Some(x.clone()),
                    _ => None,
                }),
            ),
            SymbolRef::Mode(ci, n) => (
                n.as_str(),
                names_of(&|s| match s {
                    SymbolRef::Mode(c, x) if c == ci => Some(x.clone()),
                    _ => None,
                }),
            ),
            SymbolRef::LawOutput(_) => return Err(EditError::NotRenamable("y".into())),
            SymbolRef::Builtin(n) | SymbolRef::Effect(n) | SymbolRef::UnknownFunction(n) => {
                return Err(EditError::NotRenamable(n.clone()))
            }
        }
    };
    if new_name == old {
        return Ok(Vec::new());
    }
    if scope_names.iter().any(|n| n == new_name) {
        return Err(EditError::NameTaken(new_name.to_string()));
    }
    let (m, before) = parse_ok(text)?;
    let edits: Vec<(Span, String)> = occurrences(&m)
        .into_iter()
        .filter(|o| &o.symbol == symbol)
        .map(|o| (o.span, new_name.to_string()))
        .collect();
    if edits.is_empty() {
        return Ok(edits);
    }
    apply(text, &before, edits.clone())?;
    Ok(edits)
}

/// Renames `symbol` to `new_name` everywhere (see [`rename_edits`]); every
/// other byte of the file is kept.
pub fn rename(text: &str, symbol: &SymbolRef, new_name: &str) -> Result<String, EditError> {
    let mut edits = rename_edits(text, symbol, new_name)?;
    edits.sort_by_key(|(s, _)| std::cmp::Reverse(s.start));
    let mut out = text.to_string();
    for (s, r) in edits {
        out.replace_range(s.start..s.end, &r);
    }
    Ok(out)
}

/// Adds the line `inertia <coordinate> = <call>` (e.g.
/// `added_inertia(J_theta)`) after the last force, sensor, actuator or
/// inertia line. The result must check: the call must be an inertia effect
/// whose arguments exist, with the right units.
pub fn add_inertia_effect(
    text: &str,
    coordinate: &str,
    call_text: &str,
) -> Result<String, EditError> {
    add_coordinate_effect(text, "inertia", coordinate, call_text)
}
