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
//! # a statement starts with one of: model coordinate input output parameter let
//! # kinetic potential force sensor actuator inertia set controller recorded
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
//! actuator Vm = saturation(Vmax)                # min(max(Vm, -Vmax), Vmax)
//! inertia theta = added_inertia(Jr)             # T gains 1/2*Jr*theta'^2
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
//! controller pump {                             # a direct law for an input
//!     gain kE = 200
//!     Vm = 10*sat((kE*(0 - energy(alpha))*sign(alpha'*cos(alpha)) - 2*theta)/10) }
//! controller smc {                              # sliding mode
//!     surface s poles [-3+2i, -3-2i, -6]        # or: surface s = alpha' + 8*alpha + ...
//!     gain k = 2
//!     gain phi = 0.05
//!     v = -k*sat(s/phi) }                       # s' = v
//! controller swing {                            # hybrid: modes and switches
//!     wrap alpha
//!     mode pump = pump swing_up
//!     mode catch = pp
//!     switch pump -> catch when abs(alpha) < 15 [deg]
//!     switch catch -> pump when abs(alpha) > 25 [deg] }
//!
//! recorded controller pd "the law that made the logged voltage" {
//!     signal target_alpha [rad] "reference column"  # a data column it reads
//!     gain kp = 30 [V/rad]
//!     gain kd = 2.5 [V*s/rad]
//!     let e = target_alpha - alpha
//!     Vm = kp*e + kd*derivative(e, 50 [rad/s]) }    # filtered derivative
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
//! constant `pi` (controllers add `sat` and `energy`, below). Effects (only
//! in `force` lines, see [`effects::EFFECTS`]):
//! `viscous_friction(b)`, `coulomb_friction(Fc)`, `stribeck_friction(Fc, Fs, vs)`,
//! `quadratic_drag(cd)`, `spring(k)`, `spring(k, q0)`, `cogging(A, N)`,
//! `cogging(A, N, phase)` (`-A*sin(N*q + phase)`, N periods per revolution:
//! a warning when a known N on an angle is not an integer), `speed_limit(vmax,
//! c)` (a drive's velocity limit: `-c*(q' - vmax)` above `vmax`, mirrored
//! below `-vmax`, zero between, kinks rounded over `vmax/50`); each is the
//! force on the coordinate of its line and already carries the minus sign.
//!
//! ## Sensor and actuator effects
//! `sensor q = effect(..)` (q a coordinate) and `actuator u = effect(..)` (u an
//! input) hold exactly one effect call of their kind; several lines may target
//! the same name and compose (offsets add, delays add, deadzone widths add;
//! one saturation per input; whatever the line order, the deadzone acts on
//! the commanded value, the saturation on its result, the delay shifts that
//! in time and the offset is added last). Sensor effects: `sensor_offset(d)`
//! (d in the coordinate's unit). Actuator effects: `input_offset(V0)` (the
//! input's unit), `input_delay(Td)` (s), `deadzone(w)` (the input's unit,
//! `w >= 0`), `saturation(L)` (the input's unit, `L > 0`). Arguments are
//! expressions of parameters and numbers. An effect of the wrong kind for its
//! line is an error that lists the effects valid there. See
//! [`crate::model::Model`] for which consumers honour them.
//!
//! ## Inertia lines
//! `inertia q = added_inertia(J)` (q a coordinate, `J >= 0` in kg*m^2 on an
//! angle, kg on a length) adds `1/2*J*q'^2` to the kinetic energy: an inertia
//! the written `T` lacks, e.g. a rotor's reflected inertia `Kg^2*Jm`. Unlike
//! sensor and actuator effects it is part of the plant equations, so every
//! consumer sees it.
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
//! (2 per coordinate per input), `linearize output y` with `gain` lines and
//! a law `v = ...` using the gains, `y`, `y'`, coordinates (and derivatives)
//! and parameters, or one of:
//! - a direct law per input, `Vm = expr` (the input's name on the left), with
//!   `gain` lines; the actuation level is the input itself (e.g. the motor
//!   voltage);
//! - `surface s = expr` (linear in the state, with a velocity the input
//!   reaches: relative degree 1) or `surface s poles [..]` (one fewer than
//!   the states: `s = c x` whose sliding dynamics linearized about 0 have
//!   these poles, by Ackermann and Utkin's formula), with `gain` lines and a
//!   reaching law `v = ...` using `s`: sliding mode `u = (v - L_f s)/L_g s`,
//!   the equivalent control plus `v / L_g s`. Two surfaces combined (Khanesar
//!   et al.) are one linear surface, e.g. `s = (alpha' + 8*alpha) - 0.1*(theta' + 2*theta)`;
//! - `mode name = controller` lines (another controller of the file, not
//!   itself hybrid; `swing_up` after it marks a mode that drives the input
//!   with the pendulum anywhere), `switch a -> b when condition` lines and
//!   optional `wrap q` lines (the modes and conditions see angle `q`
//!   wrapped into [-pi, pi)). The first mode is the initial one; at every
//!   sample the first switch from the current mode whose condition holds is
//!   taken (then again from the new mode). A condition compares two
//!   expressions (`<`, `<=`, `>`, `>=`, both sides of one unit) of
//!   coordinates, their derivatives, parameters, numbers and quantities,
//!   joined by `and` (binding tighter) and `or`; inputs are not allowed.
//!
//! Laws and conditions may also call `sat(x)` (`x` clamped to [-1, 1],
//! dimensionless) and `energy(q)`: the kinetic energy with the other
//! coordinates' velocities at 0 plus `V - V|q=0` (for the rotary pendulum,
//! `energy(alpha) = J2h*alpha'^2/2 + m2*g*l2*(cos(alpha) - 1)`, 0 upright at
//! rest).
//!
//! ## Recorded controllers
//! `recorded controller name "title" { ... }` describes the discrete-time law
//! that drove an input while data were recorded (closed-loop data), so
//! identification can replay it in the loop. Its lines: `signal name [unit]
//! "doc"` (a data column the law reads: a reference, a feedforward),
//! `gain name = value`, `let name = expr` and one law per driven input,
//! `Vm = expr`, with that input's unit. It sees the measured coordinates
//! (positions only), its signals, gains and lets, and the model's
//! parameters; velocities come from `derivative(x, wc)`, the filtered
//! difference of `x` with cutoff `wc` (a rate, e.g. `50 [rad/s]`) at the
//! record's sample rate, not nested. Names are local to the block but may
//! not shadow a model name; a recorded controller's name may not be a
//! controller's. See [`check`] (`check_recorded.rs`) and plantc-identify's
//! closed-loop replay.
//!
//! ## Contextual keywords
//! `surface`, `mode`, `switch`, `wrap` (in controllers) and `signal` (in
//! recorded controllers) are keywords only when a name follows them; `when`,
//! `and`, `or` only in switch conditions; `poles`, `Q`, `R`, `output` only after
//! `place`, `lqr`, `linearize`; `swing_up` only after a mode's controller.
//! Elsewhere they are ordinary names.

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
