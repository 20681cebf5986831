//! The `.plant` model language: lexer, parser, AST with spans, name
//! resolution, dimensional analysis, diagnostics, lossless editing
//! ([`edit`], incl. rename), the canonical layout ([`mod@format`]) and where each
//! name is declared and used ([`visit`]).
//!
//! Entry point: [`parse_and_check`]; render its diagnostics with [`render`].
//!
//! # Language reference
//!
//! ```text
//! # comment to end of line
//! model rotary_pendulum "Rotary inverted pendulum"
//!
//! coordinate theta : angle  "arm angle"        # angle (rad) | length (m)
//! input Vm [V] limits [-10, 10] "motor voltage" # unit, limits, doc all optional
//! output alpha                                  # a coordinate or a let name
//! output tip = L1*theta "tip position"          # or a named expression
//!
//! parameter J1 = 9.98e-4 [kg*m^2] "arm inertia" estimate [1e-5, 5e-3]
//! parameter Kg = 70 "gear ratio"                # no unit = dimensionless
//!
//! let J0h = J1 + m1*l1^2 + m2*L1^2              # lets may use lets defined later
//! kinetic T = 1/2*J0h*theta'^2 - c*cos(alpha)*theta'*alpha'
//!           + 1/2*J2h*alpha'^2
//! potential V = m2*g*l2*cos(alpha)              # optional, 0 if absent
//! force theta = tau + viscous_friction(b1) + coulomb_friction(Fg1)
//! sensor alpha = sensor_offset(d_alpha)         # the encoder reads alpha + d_alpha
//! actuator Vm = input_offset(V0)                # the plant receives Vm + V0
//! actuator Vm = input_delay(Td)                 # the plant receives Vm(t - Td)
//! actuator Vm = deadzone(w)                     # sign(Vm)*max(|Vm| - w, 0)
//!
//! set quanser_manual "manual values" { l2 = 0.1685 [m]
//!     J1 = 9.98e-4 [kg*m^2] - m1*l1^2 }
//!
//! controller pp { place poles [-2+3.464i, -2-3.464i, -40, -45] }
//! controller q  { lqr Q [1, 1, 1, 1] R [1] }
//! controller k  { gains K [-7.89, 37.8, -2.98, 3.62] }
//! controller fl { linearize output alpha
//!                 gain wn = 4
//!                 v = -wn^2*y - 2*0.7*wn*y' }
//! ```
//!
//! ## Lines
//! A statement ends at the end of its line, except
//! - inside open `(` or `[`,
//! - when the line ends with a binary operator (`+ - * / ^`), `,` or `=`
//!   (but if the next line starts with a declaration keyword in column 1,
//!   that is reported as an expression ending with an operator),
//! - in `output`, `let`, `kinetic`, `potential`, `force` and controller laws:
//!   a following line that starts with `+` or `-` continues the expression
//!   when it is indented more than the statement's first line.
//!
//! Inside `{ }` of `set` and `controller` blocks each entry is on its own line;
//! the closing `}` may follow the last entry on the same line.
//!
//! ## Declarations
//! - Every name (coordinate, input, parameter, let, named output, the energy
//!   names) is declared once. `pi` and the built-in function names are reserved.
//! - Optional trailing parts (`limits [..]`, `estimate [..]`, a doc string) may
//!   come in any order after the unit.
//! - A parameter's value is a number literal (optionally negative) with an
//!   optional unit; it is stored in SI ([`check::ParamValue`]), the exact
//!   scale is kept in [`units::Scale`]. Estimate bounds and input limits are
//!   in the declared unit.
//! - Set and controller names share one namespace, separate from the model's.
//!
//! ## Expressions
//! Precedence from loosest: `+ -`, `* /`, unary `-`, `^` (right-associative),
//! so `-x^2` is `-(x^2)` and `a^b^c` is `a^(b^c)`. `q'` and `q''` are the first
//! and second time derivatives of a coordinate. Numbers are decimal with an
//! optional exponent (`9.98e-4`); their source text is kept. A number may be
//! followed by a unit in brackets (`0.1685 [m]`, a quantity literal). Complex
//! literals (`-2+3.464i`) exist only in `place poles [...]`.
//!
//! Built-in functions: `sin cos tan sqrt exp ln abs sign tanh atan2(y, x)`,
//! constant `pi`. Effects (only in `force` lines, see [`effects::EFFECTS`]):
//! `viscous_friction(b)`, `coulomb_friction(Fc)`, `stribeck_friction(Fc, Fs, vs)`,
//! `quadratic_drag(cd)`, `spring(k)`, `spring(k, q0)`; each is the force on the
//! coordinate of its line and already carries the minus sign.
//!
//! ## Sensor and actuator effects
//! `sensor q = effect(..)` (q a coordinate) and `actuator u = effect(..)` (u an
//! input) hold exactly one effect call of their kind; several lines may target
//! the same name and compose (offsets add, delays add, deadzone widths add;
//! whatever the line order, the deadzone acts on the commanded value, the
//! delay shifts the result in time and the offset is added last). Sensor
//! effects: `sensor_offset(d)` (d in the coordinate's unit). Actuator
//! effects: `input_offset(V0)` (the input's unit), `input_delay(Td)` (s),
//! `deadzone(w)` (the input's unit, `w >= 0`). Arguments are expressions of parameters and numbers. An effect of the
//! wrong kind for its line is an error that lists the effects valid there.
//! See [`crate::model::Model`] for which consumers honour them.
//!
//! ## Units
//! Known units are listed in [`units::UNITS`]; combine with `*`, `/`, `^n`,
//! `^(p/q)`: `kg*m^2`, `N*m*s/rad`, `m/s^2`, `1/s`; `1` or no unit means
//! dimensionless. rad is dimensionless, so the force on an angle is a torque
//! (N*m, an energy) and on a length a force (N). `T` and `V` must be energies.
//! Arguments of `sin cos tan exp ln tanh` are dimensionless; `sqrt` halves
//! exponents; `abs` keeps the unit; `sign` is dimensionless; `atan2` needs two
//! arguments of equal unit; a dimensional base needs a constant exponent.
//!
//! ## Sets and controllers
//! A set gives alternative values to parameters; values are expressions of
//! numbers, quantity literals and the parameters' declared values, and must
//! have the parameter's unit. Values outside estimate bounds are warnings.
//! A controller has exactly one design statement: `place poles` (2 per
//! coordinate; complex poles in conjugate pairs), `lqr Q [..] R [..]`
//! (diagonals: 2 per coordinate, 1 per input), `gains K [..]`
//! (2 per coordinate per input), or `linearize output y` with `gain` lines and
//! a law `v = ...` using the gains, `y`, `y'`, coordinates (and derivatives)
//! and parameters.

pub mod ast;
pub mod check;
pub mod diagnostic;
pub mod edit;
pub mod effects;
pub mod format;
pub mod lexer;
pub mod parser;
pub mod source;
pub mod span;
pub mod units;
pub mod visit;

pub use check::{dimension_of, eval_si, parse_and_check, Checked, Symbols};
pub use diagnostic::{render, Diagnostic, Severity};
pub use source::SourceFile;
pub use span::Span;

#[cfg(test)]
mod tests;
