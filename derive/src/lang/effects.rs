//! Named physical effects (`viscous_friction(b)`, `sensor_offset(d)`, ...),
//! defined as data.
//!
//! Every effect has a kind ([`EffectKind`]) that says which line may hold it:
//! - **force** effects (`force q = ... + coulomb_friction(Fc)`): the formula is
//!   the generalised force exerted on the coordinate `q` of the line, written
//!   in the model language with the placeholders `q`, `q'` and the effect's
//!   parameter names. [`expand`] parses the formula with the model parser and
//!   substitutes the coordinate and the call's arguments, so later stages only
//!   see plain expressions.
//! - **sensor** effects (`sensor alpha = sensor_offset(d)`): what the encoder
//!   of the coordinate reads; the formula is the measurement in terms of `q`.
//! - **actuator** effects (`actuator Vm = input_offset(V0)`): what the plant
//!   receives for the commanded input; the formula is in terms of `u`, or
//!   empty when the effect is not algebraic (`input_delay`) or not linear in
//!   `u` (`deadzone`): such effects stay out of the forces, which must be
//!   linear in the inputs.
//!
//! Sensor and actuator effect arguments are expressions of parameters whose
//! units are given by [`ArgUnit`]. To add an effect, add a row to [`EFFECTS`].

use super::ast::{Expr, ExprKind, Ident};
use super::diagnostic::Diagnostic;
use super::parser::parse_expr;
use super::span::Span;

/// Which kind of line may hold an effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EffectKind {
    /// A generalised force term in a `force q = ...` line.
    Force,
    /// A measurement effect in a `sensor q = ...` line (`q` a coordinate).
    Sensor,
    /// An input effect in an `actuator u = ...` line (`u` an input).
    Actuator,
}

impl EffectKind {
    /// The keyword of the line that holds effects of this kind.
    pub fn keyword(self) -> &'static str {
        match self {
            EffectKind::Force => "force",
            EffectKind::Sensor => "sensor",
            EffectKind::Actuator => "actuator",
        }
    }

    /// What the target of such a line is (`a coordinate`, `an input`).
    pub fn target(self) -> &'static str {
        match self {
            EffectKind::Force | EffectKind::Sensor => "a coordinate",
            EffectKind::Actuator => "an input",
        }
    }
}

/// The unit an argument of a sensor or actuator effect must have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArgUnit {
    /// The unit of the target (rad or m for a coordinate, the input's unit).
    Target,
    /// Seconds.
    Time,
    /// The unit of the target, and `>= 0` (a deadzone half-width).
    TargetNonNegative,
}

/// One effect: name, kind, parameters, documentation and formula.
#[derive(Debug, Clone, Copy)]
pub struct Effect {
    /// Name as called in a force, sensor or actuator line.
    pub name: &'static str,
    /// Which line may hold it.
    pub kind: EffectKind,
    /// Units of the arguments of sensor and actuator effects, in call order
    /// (empty for force effects, whose units are checked on the whole force).
    pub arg_units: &'static [ArgUnit],
    /// Required parameter names, in call order.
    pub params: &'static [&'static str],
    /// Optional trailing parameters (may be omitted), in call order.
    pub optional: &'static [&'static str],
    /// Formula used when the optional parameters are omitted: the force (in
    /// `q`, `q'`), the measurement (in `q`) or the received input (in `u`);
    /// empty for an effect that is not algebraic (`input_delay`).
    pub formula: &'static str,
    /// Formula used when all optional parameters are given.
    pub formula_full: &'static str,
    /// One-line description.
    pub doc: &'static str,
}

impl Effect {
    /// Number of accepted arguments (min, max).
    pub fn arity(&self) -> (usize, usize) {
        (self.params.len(), self.params.len() + self.optional.len())
    }

    /// A call template for help texts, e.g. `spring(k[, q0])`.
    pub fn signature(&self) -> String {
        let mut s = format!("{}({}", self.name, self.params.join(", "));
        for o in self.optional {
            s.push_str(&format!("[, {o}]"));
        }
        s.push(')');
        s
    }
}

/// The effect table.
pub const EFFECTS: &[Effect] = &[
    Effect {
        name: "viscous_friction",
        kind: EffectKind::Force,
        arg_units: &[],
        params: &["b"],
        optional: &[],
        formula: "-b*q'",
        formula_full: "-b*q'",
        doc: "viscous friction: -b*q'",
    },
    Effect {
        name: "coulomb_friction",
        kind: EffectKind::Force,
        arg_units: &[],
        params: &["Fc"],
        optional: &[],
        formula: "-Fc*sign(q')",
        formula_full: "-Fc*sign(q')",
        doc: "dry (Coulomb) friction: -Fc*sign(q')",
    },
    Effect {
        name: "stribeck_friction",
        kind: EffectKind::Force,
        arg_units: &[],
        params: &["Fc", "Fs", "vs"],
        optional: &[],
        formula: "-(Fc + (Fs - Fc)*exp(-(q'/vs)^2))*sign(q')",
        formula_full: "-(Fc + (Fs - Fc)*exp(-(q'/vs)^2))*sign(q')",
        doc: "Stribeck friction: Coulomb level Fc, static level Fs, Stribeck velocity vs",
    },
    Effect {
        name: "quadratic_drag",
        kind: EffectKind::Force,
        arg_units: &[],
        params: &["cd"],
        optional: &[],
        formula: "-cd*q'*abs(q')",
        formula_full: "-cd*q'*abs(q')",
        doc: "quadratic drag: -cd*q'*|q'|",
    },
    Effect {
        name: "spring",
        kind: EffectKind::Force,
        arg_units: &[],
        params: &["k"],
        optional: &["q0"],
        formula: "-k*q",
        formula_full: "-k*(q - q0)",
        doc: "linear spring: -k*q, or -k*(q - q0) with rest position q0",
    },
    Effect {
        name: "sensor_offset",
        kind: EffectKind::Sensor,
        arg_units: &[ArgUnit::Target],
        params: &["d"],
        optional: &[],
        formula: "q + d",
        formula_full: "q + d",
        doc: "encoder offset: the sensor of q reads q + d (d in the coordinate's unit)",
    },
    Effect {
        name: "input_offset",
        kind: EffectKind::Actuator,
        arg_units: &[ArgUnit::Target],
        params: &["V0"],
        optional: &[],
        formula: "u + V0",
        formula_full: "u + V0",
        doc: "input offset: the plant receives u + V0 (V0 in the input's unit)",
    },
    Effect {
        name: "input_delay",
        kind: EffectKind::Actuator,
        arg_units: &[ArgUnit::Time],
        params: &["Td"],
        optional: &[],
        formula: "",
        formula_full: "",
        doc: "input delay: the plant receives u(t - Td) (Td in s)",
    },
    Effect {
        name: "deadzone",
        kind: EffectKind::Actuator,
        arg_units: &[ArgUnit::TargetNonNegative],
        params: &["w"],
        optional: &[],
        formula: "",
        formula_full: "",
        doc: "actuator deadzone: the plant receives sign(u)*max(|u| - w, 0) (w >= 0 in the input's unit)",
    },
];

/// The effects of one kind, in table order.
pub fn of_kind(kind: EffectKind) -> impl Iterator<Item = &'static Effect> {
    EFFECTS.iter().filter(move |e| e.kind == kind)
}

/// `name(args)` signatures of the effects of one kind, comma-separated (for
/// help texts).
pub fn signatures(kind: EffectKind) -> String {
    of_kind(kind)
        .map(Effect::signature)
        .collect::<Vec<_>>()
        .join(", ")
}

/// Looks up an effect by name.
pub fn lookup(name: &str) -> Option<&'static Effect> {
    EFFECTS.iter().find(|e| e.name == name)
}

/// Expands an effect call (`call` must be an [`ExprKind::Call`] of a known
/// effect) acting on `coordinate` into a plain expression. Every node of the
/// result gets the call's span, except substituted arguments, which keep theirs.
/// For a sensor effect the result is the measurement of the coordinate, for an
/// actuator effect (with `coordinate` naming the input) the input the plant
/// receives; an effect without a formula (`input_delay`) expands to the
/// target itself.
#[allow(clippy::result_large_err)] // cold path; Diagnostic is plain data
pub fn expand(call: &Expr, coordinate: &Ident) -> Result<Expr, Diagnostic> {
    let (effect, args) = resolve_call(call)?;
    let hi = effect.arity().1;
    let formula = if args.len() == hi {
        effect.formula_full
    } else {
        effect.formula
    };
    let formula = if formula.is_empty() {
        match effect.kind {
            EffectKind::Actuator => "u",
            _ => "q",
        }
    } else {
        formula
    };
    let template = parse_expr(formula).map_err(|_| {
        Diagnostic::error(
            "plantc::internal",
            format!("effect `{}` has an invalid formula", effect.name),
            call.span,
            "here",
        )
    })?;
    let names: Vec<&str> = effect
        .params
        .iter()
        .chain(effect.optional.iter())
        .copied()
        .collect();
    let placeholder = match effect.kind {
        EffectKind::Actuator => "u",
        _ => "q",
    };
    Ok(substitute(
        &template,
        call.span,
        placeholder,
        coordinate,
        &names,
        args,
    ))
}

/// The effect and arguments of an effect call, with its arity checked.
#[allow(clippy::result_large_err)] // cold path; Diagnostic is plain data
pub fn resolve_call(call: &Expr) -> Result<(&'static Effect, &[Expr]), Diagnostic> {
    let ExprKind::Call(name, args) = &call.kind else {
        return Err(Diagnostic::error(
            "plantc::not_an_effect",
            "not an effect call",
            call.span,
            "expected an effect call",
        ));
    };
    let Some(effect) = lookup(&name.name) else {
        return Err(Diagnostic::error(
            "plantc::not_an_effect",
            format!("`{}` is not an effect", name.name),
            name.span,
            "unknown effect",
        ));
    };
    let (lo, hi) = effect.arity();
    if args.len() < lo || args.len() > hi {
        let expected = if lo == hi {
            format!("{lo}")
        } else {
            format!("{lo} or {hi}")
        };
        return Err(Diagnostic::error(
            "plantc::wrong_arity",
            format!(
                "`{}` takes {expected} argument(s), found {}",
                effect.name,
                args.len()
            ),
            call.span,
            "wrong number of arguments",
        )
        .with_help(format!("{}: {}", effect.signature(), effect.doc)));
    }
    Ok((effect, args))
}

fn substitute(t: &Expr, span: Span, ph: &str, q: &Ident, names: &[&str], args: &[Expr]) -> Expr {
    let kind = match &t.kind {
        ExprKind::Name(n) if n == ph => ExprKind::Name(q.name.clone()),
        ExprKind::Deriv(n, k) if n == ph => ExprKind::Deriv(q.name.clone(), *k),
        ExprKind::Name(n) => {
            if let Some(i) = names.iter().position(|p| p == n) {
                if let Some(a) = args.get(i) {
                    return a.clone();
                }
            }
            ExprKind::Name(n.clone())
        }
        ExprKind::Neg(a) => ExprKind::Neg(Box::new(substitute(a, span, ph, q, names, args))),
        ExprKind::Binary(op, a, b) => ExprKind::Binary(
            *op,
            Box::new(substitute(a, span, ph, q, names, args)),
            Box::new(substitute(b, span, ph, q, names, args)),
        ),
        ExprKind::Call(f, xs) => ExprKind::Call(
            Ident {
                name: f.name.clone(),
                span,
            },
            xs.iter()
                .map(|x| substitute(x, span, ph, q, names, args))
                .collect(),
        ),
        ExprKind::Number(n) => ExprKind::Number(super::ast::NumLit {
            text: n.text.clone(),
            span,
        }),
        other => other.clone(),
    };
    Expr::new(kind, span)
}
