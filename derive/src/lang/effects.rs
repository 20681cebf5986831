//! Named force effects (`viscous_friction(b)`, ...), defined as data.
//!
//! Each effect is the generalised force it exerts on the coordinate `q` of the
//! enclosing `force q = ...` line, written in the model language with the
//! placeholders `q`, `q'` and the effect's parameter names. [`expand`] parses
//! the formula with the model parser and substitutes the coordinate and the
//! call's arguments, so later stages only see plain expressions. To add an
//! effect, add a row to [`EFFECTS`].

use super::ast::{Expr, ExprKind, Ident};
use super::diagnostic::Diagnostic;
use super::parser::parse_expr;
use super::span::Span;

/// One effect: name, parameters, documentation and formula.
#[derive(Debug, Clone, Copy)]
pub struct Effect {
    /// Name as called in a force line.
    pub name: &'static str,
    /// Required parameter names, in call order.
    pub params: &'static [&'static str],
    /// Optional trailing parameters (may be omitted), in call order.
    pub optional: &'static [&'static str],
    /// Formula used when the optional parameters are omitted.
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
        params: &["b"],
        optional: &[],
        formula: "-b*q'",
        formula_full: "-b*q'",
        doc: "viscous friction: -b*q'",
    },
    Effect {
        name: "coulomb_friction",
        params: &["Fc"],
        optional: &[],
        formula: "-Fc*sign(q')",
        formula_full: "-Fc*sign(q')",
        doc: "dry (Coulomb) friction: -Fc*sign(q')",
    },
    Effect {
        name: "stribeck_friction",
        params: &["Fc", "Fs", "vs"],
        optional: &[],
        formula: "-(Fc + (Fs - Fc)*exp(-(q'/vs)^2))*sign(q')",
        formula_full: "-(Fc + (Fs - Fc)*exp(-(q'/vs)^2))*sign(q')",
        doc: "Stribeck friction: Coulomb level Fc, static level Fs, Stribeck velocity vs",
    },
    Effect {
        name: "quadratic_drag",
        params: &["cd"],
        optional: &[],
        formula: "-cd*q'*abs(q')",
        formula_full: "-cd*q'*abs(q')",
        doc: "quadratic drag: -cd*q'*|q'|",
    },
    Effect {
        name: "spring",
        params: &["k"],
        optional: &["q0"],
        formula: "-k*q",
        formula_full: "-k*(q - q0)",
        doc: "linear spring: -k*q, or -k*(q - q0) with rest position q0",
    },
];

/// Looks up an effect by name.
pub fn lookup(name: &str) -> Option<&'static Effect> {
    EFFECTS.iter().find(|e| e.name == name)
}

/// Expands an effect call (`call` must be an [`ExprKind::Call`] of a known
/// effect) acting on `coordinate` into a plain expression. Every node of the
/// result gets the call's span, except substituted arguments, which keep theirs.
#[allow(clippy::result_large_err)] // cold path; Diagnostic is plain data
pub fn expand(call: &Expr, coordinate: &Ident) -> Result<Expr, Diagnostic> {
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
    let formula = if args.len() == hi {
        effect.formula_full
    } else {
        effect.formula
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
    Ok(substitute(&template, call.span, coordinate, &names, args))
}

fn substitute(t: &Expr, span: Span, q: &Ident, names: &[&str], args: &[Expr]) -> Expr {
    let kind = match &t.kind {
        ExprKind::Name(n) if n == "q" => ExprKind::Name(q.name.clone()),
        ExprKind::Deriv(n, k) if n == "q" => ExprKind::Deriv(q.name.clone(), *k),
        ExprKind::Name(n) => {
            if let Some(i) = names.iter().position(|p| p == n) {
                if let Some(a) = args.get(i) {
                    return a.clone();
                }
            }
            ExprKind::Name(n.clone())
        }
        ExprKind::Neg(a) => ExprKind::Neg(Box::new(substitute(a, span, q, names, args))),
        ExprKind::Binary(op, a, b) => ExprKind::Binary(
            *op,
            Box::new(substitute(a, span, q, names, args)),
            Box::new(substitute(b, span, q, names, args)),
        ),
        ExprKind::Call(f, xs) => ExprKind::Call(
            Ident {
                name: f.name.clone(),
                span,
            },
            xs.iter()
                .map(|x| substitute(x, span, q, names, args))
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
