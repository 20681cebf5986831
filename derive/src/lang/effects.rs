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
//!   `u` (`deadzone`, `saturation`): such effects stay out of the forces,
//!   which must be linear in the inputs.
//! - **inertia** effects (`inertia theta = added_inertia(J)`): a term added
//!   to the kinetic energy `T` (in `q'`), so the mass matrix gains it and
//!   every consumer of the equations sees it.
//!
//! Sensor, actuator and inertia effect arguments are expressions of
//! parameters whose units are given by [`ArgUnit`]. To add an effect, add a
//! row to [`EFFECTS`].

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
    /// A kinetic-energy term in an `inertia q = ...` line (`q` a
    /// coordinate): the formula is added to `T`.
    Inertia,
}

impl EffectKind {
    /// The keyword of the line that holds effects of this kind.
    pub fn keyword(self) -> &'static str {
        match self {
            EffectKind::Force => "force",
            EffectKind::Sensor => "sensor",
            EffectKind::Actuator => "actuator",
            EffectKind::Inertia => "inertia",
        }
    }

    /// What the target of such a line is (`a coordinate`, `an input`).
    pub fn target(self) -> &'static str {
        match self {
            EffectKind::Force | EffectKind::Sensor | EffectKind::Inertia => "a coordinate",
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
    /// The unit of the target, and `> 0` (a saturation level).
    TargetPositive,
    /// An inertia of the target coordinate, `>= 0`: kg*m^2 on an angle, kg
    /// on a length (so that `1/2*J*q'^2` is an energy).
    Inertia,
    /// A generalised force on the target coordinate: N*m on an angle, N on
    /// a length.
    Force,
    /// The inverse of the target's unit (dimensionless on an angle, 1/m on
    /// a length): a spatial frequency.
    PerTarget,
    /// Dimensionless (an angle in rad).
    Dimensionless,
    /// The unit of the target's rate (1/s on an angle, m/s on a length).
    TargetRate,
    /// A generalised force per rate of the target: N*m*s/rad on an angle,
    /// N*s/m on a length (a viscous coefficient).
    Damping,
}

/// One effect: name, kind, parameters, documentation and formula.
#[derive(Debug, Clone, Copy)]
pub struct Effect {
    /// Name as called in a force, sensor or actuator line.
    pub name: &'static str,
    /// Which line may hold it.
    pub kind: EffectKind,
    /// Units of the arguments, in call order. Sensor, actuator and inertia
    /// effects list all of theirs; a force effect may list them (each
    /// argument is then checked on its own, with a message naming it) or
    /// leave this empty (its units are checked on the whole force).
    pub arg_units: &'static [ArgUnit],
    /// Required parameter names, in call order.
    pub params: &'static [&'static str],
    /// Optional trailing parameters (may be omitted), in call order.
    pub optional: &'static [&'static str],
    /// Formula used when the optional parameters are omitted: the force (in
    /// `q`, `q'`), the measurement (in `q`), the received input (in `u`) or
    /// the kinetic-energy term (in `q'`); empty for an effect that is not
    /// algebraic (`input_delay`, `deadzone`, `saturation`).
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
        name: "cogging",
        kind: EffectKind::Force,
        arg_units: &[ArgUnit::Force, ArgUnit::PerTarget, ArgUnit::Dimensionless],
        params: &["A", "N"],
        optional: &["phase"],
        formula: "-A*sin(N*q)",
        formula_full: "-A*sin(N*q + phase)",
        doc: "detent/cogging torque: -A*sin(N*q + phase), periodic in q with N periods per revolution (an integer on an angle; 1/m on a length)",
    },
    Effect {
        name: "speed_limit",
        kind: EffectKind::Force,
        arg_units: &[ArgUnit::TargetRate, ArgUnit::Damping],
        params: &["vmax", "c"],
        optional: &[],
        // -c*dz(q', vmax) with the kinks rounded over vmax/50: odd, smooth,
        // zero at q' = 0, -c*(q' - vmax) well above vmax
        formula: "-c/2*(2*q' + sqrt((q' - vmax)^2 + (vmax/50)^2) - sqrt((q' + vmax)^2 + (vmax/50)^2))",
        formula_full: "-c/2*(2*q' + sqrt((q' - vmax)^2 + (vmax/50)^2) - sqrt((q' + vmax)^2 + (vmax/50)^2))",
        doc: "a drive's speed limit: a steep viscous force -c*(q' - vmax) above vmax (and -c*(q' + vmax) below -vmax), zero in between, the kinks rounded over vmax/50",
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
    Effect {
        name: "saturation",
        kind: EffectKind::Actuator,
        arg_units: &[ArgUnit::TargetPositive],
        params: &["L"],
        optional: &[],
        formula: "",
        formula_full: "",
        doc: "actuator saturation (a drive's voltage or current limit): the plant receives min(max(u, -L), L) (L > 0 in the input's unit)",
    },
    Effect {
        name: "added_inertia",
        kind: EffectKind::Inertia,
        arg_units: &[ArgUnit::Inertia],
        params: &["J"],
        optional: &[],
        formula: "1/2*J*q'^2",
        formula_full: "1/2*J*q'^2",
        doc: "added inertia (e.g. a rotor's reflected inertia Kg^2*Jm): adds 1/2*J*q'^2 to the kinetic energy (J >= 0, kg*m^2 on an angle, kg on a length)",
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
/// receives, for an inertia effect the kinetic-energy term; an effect without
/// a formula (`input_delay`) expands to the target itself.
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
        return Err(
            super::check::wrong_arity(effect.name, expected, args.len(), call.span)
                .with_help(format!("{}: {}", effect.signature(), effect.doc)),
        );
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
