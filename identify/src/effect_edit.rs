//! Adding a physical effect to a model text: the shared step of `diagnose`
//! (candidates, `--apply`) and `synth` (hidden effects in generated data).
//!
//! An [`EffectInstance`] is one effect of the language's effect table on one
//! target (a coordinate for force and sensor effects, an input for actuator
//! effects), with its new parameters named `<base>_<target>` (e.g.
//! `Fc_alpha`, `d_alpha`, `Td_Vm`). [`EffectInstance::apply`] edits the
//! model text losslessly (`lang::edit`): it appends the parameter
//! declarations and the effect call (a force term, or a `sensor`,
//! `actuator` or `inertia` line), and touches nothing else. Each new
//! parameter's description is the instance's label (`cogging@theta`), which
//! [`label_of`] reads back from a model (the equation-error ranking uses it
//! to recognise effects whose columns need a scan).
//!
//! The parameter templates (units, start values, bounds) live in
//! [`templates`]; an effect without a template cannot be instantiated.

use std::fmt;

use plantc_derive::lang::edit;
use plantc_derive::lang::effects as lang_effects;
use plantc_derive::model::{CoordinateKind, Model};

/// Where an effect acts.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum EffectKind {
    /// On a coordinate through the equations of motion: a generalised force
    /// (`force q = ... + effect(..)`) or, for `added_inertia`, a
    /// kinetic-energy term (`inertia q = added_inertia(..)`, see
    /// [`EffectInstance::line`]). Both add parameters to the equations.
    Force,
    /// A measurement effect on a coordinate (`sensor q = effect(..)`).
    Sensor,
    /// An effect on an input (`actuator u = effect(..)`).
    Actuator,
}

/// The unit of an effect parameter.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum TemplateUnit {
    /// Depends on the target coordinate's kind.
    Coordinate {
        /// Unit when the target is an angle coordinate.
        angle: &'static str,
        /// Unit when the target is a length coordinate.
        length: &'static str,
    },
    /// The target input's own unit (start value and bounds in that unit).
    Input,
    /// A fixed unit.
    Fixed(&'static str),
}

/// One parameter of an effect: base name, unit, start value and bounds.
/// Start values matter for effects whose equation-error columns are a
/// Gauss-Newton step from them; effects whose columns come from a scan
/// (cogging's period count, a saturation level, a speed limit: see
/// [`crate::equation_error::Regressor`]) get their start from the data.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ParamTemplate {
    /// Base name; the model parameter is `<base>_<target>`.
    pub base: &'static str,
    /// Its unit.
    pub unit: TemplateUnit,
    /// Start value of a fit (in the unit above).
    pub start: f64,
    /// Lower bound of the `estimate` box.
    pub lo: f64,
    /// Upper bound of the `estimate` box.
    pub hi: f64,
}

/// How much larger a level (a generalised force, a force per unit of
/// speed or position, an inertia) is on a length coordinate than the
/// template's, which is an angle's, in m^-2: the boxes span the same
/// decelerations, decay rates and natural frequencies (`F/M`, `b/M`,
/// `k/M`) for a cart of up to 10 kg as for a link of up to 0.1 kg m^2 about
/// its joint (a spring box of 1 N m/rad reaches 0.5 Hz on that link; read
/// as 1 N/m it reached 0.15 Hz on a 1.2 kg cart, and a cart's 2 N/m spring
/// ended at the box's edge while a cogging of period 2.9 m took its
/// place).
pub const LENGTH_LEVEL_SCALE: f64 = 100.0;

/// Is a parameter in angle unit `unit` a level ([`LENGTH_LEVEL_SCALE`]):
/// a torque or a torque per unit of speed or angle (`N*m...`), or an
/// inertia (`kg*m^2`)? Speeds, counts and phases are not.
fn is_level(unit: &str) -> bool {
    unit.starts_with("N*m") || unit.starts_with("kg*m^2")
}

const fn pt(
    base: &'static str,
    unit_angle: &'static str,
    unit_length: &'static str,
    start: f64,
    lo: f64,
    hi: f64,
) -> ParamTemplate {
    pt_unit(
        base,
        TemplateUnit::Coordinate {
            angle: unit_angle,
            length: unit_length,
        },
        start,
        lo,
        hi,
    )
}

const fn pt_unit(
    base: &'static str,
    unit: TemplateUnit,
    start: f64,
    lo: f64,
    hi: f64,
) -> ParamTemplate {
    ParamTemplate {
        base,
        unit,
        start,
        lo,
        hi,
    }
}

/// The effects `diagnose` and `synth` know, with their kind and parameters
/// (in the effect's call order).
///
/// The boxes are wide enough for a lab rig, not only the bundled pendulum:
/// dry friction up to 10 N m (the DFKI double pendulum's joints have 0.12 to
/// 0.15 N m; a box of 0.1 N m held the refit at its edge, 1.68x instead of
/// the Stribeck candidate's 3.08x, and the diagnosis named the wrong one).
pub const TEMPLATES: &[(&str, EffectKind, &[ParamTemplate])] = &[
    (
        "coulomb_friction",
        EffectKind::Force,
        &[pt("Fc", "N*m", "N", 1e-4, 0.0, 10.0)],
    ),
    (
        "viscous_friction",
        EffectKind::Force,
        &[pt("bx", "N*m*s/rad", "N*s/m", 1e-4, 0.0, 0.1)],
    ),
    (
        "quadratic_drag",
        EffectKind::Force,
        &[pt("cd", "N*m*s^2/rad^2", "N*s^2/m^2", 1e-5, 0.0, 0.1)],
    ),
    (
        "stribeck_friction",
        EffectKind::Force,
        &[
            pt("Fc", "N*m", "N", 1e-4, 0.0, 10.0),
            pt("Fs", "N*m", "N", 2e-4, 0.0, 20.0),
            pt("vs", "rad/s", "m/s", 0.1, 1e-3, 10.0),
        ],
    ),
    (
        "spring",
        EffectKind::Force,
        &[pt("k", "N*m/rad", "N/m", 1e-3, 0.0, 1.0)],
    ),
    (
        // the period count N is found by a scan in the equation-error
        // ranking and refined by the fit; the phase is relative to the
        // encoder's zero, so it is estimated too
        "cogging",
        EffectKind::Force,
        &[
            pt("A", "N*m", "N", 1e-4, 0.0, 1.0),
            pt("N", "1", "1/m", 12.0, 1.0, 1000.0),
            pt("phi", "1", "1", 0.0, -7.0, 7.0),
        ],
    ),
    (
        // vmax found by a scan in the equation-error ranking
        "speed_limit",
        EffectKind::Force,
        &[
            pt("vmax", "rad/s", "m/s", 10.0, 0.0, 1000.0),
            pt("c", "N*m*s/rad", "N*s/m", 1e-2, 0.0, 100.0),
        ],
    ),
    (
        // a kinetic-energy term (`inertia` line), in the equations like a
        // force; a start above 0 so the first sensitivity is not at the
        // box edge
        "added_inertia",
        EffectKind::Force,
        &[pt("J", "kg*m^2", "kg", 1e-5, 0.0, 1.0)],
    ),
    (
        // an encoder offset is small but may have either sign
        "sensor_offset",
        EffectKind::Sensor,
        &[pt("d", "rad", "m", 0.0, -0.2, 0.2)],
    ),
    (
        "input_offset",
        EffectKind::Actuator,
        &[pt_unit("V0", TemplateUnit::Input, 0.0, -1.0, 1.0)],
    ),
    (
        // a start above 0 so the first sensitivity is not at the box edge
        "input_delay",
        EffectKind::Actuator,
        &[pt_unit("Td", TemplateUnit::Fixed("s"), 1e-3, 0.0, 0.05)],
    ),
    (
        // a start above 0 so the first sensitivity is not at the box edge
        "deadzone",
        EffectKind::Actuator,
        &[pt_unit("w", TemplateUnit::Input, 0.05, 0.0, 2.0)],
    ),
    (
        // the level found by a scan in the equation-error ranking
        "saturation",
        EffectKind::Actuator,
        &[pt_unit("L", TemplateUnit::Input, 5.0, 1e-3, 1e3)],
    ),
];

/// Kind and parameter templates of an effect, if it has templates.
pub fn templates(effect: &str) -> Option<(EffectKind, &'static [ParamTemplate])> {
    TEMPLATES
        .iter()
        .find(|(n, _, _)| *n == effect)
        .map(|(_, k, t)| (*k, *t))
}

/// Why an effect cannot be instantiated or applied.
#[derive(Clone, Debug, PartialEq)]
pub enum EffectEditError {
    /// The effect has no template here.
    UnknownEffect {
        /// The name given.
        effect: String,
        /// Effects that do exist.
        known: Vec<String>,
    },
    /// The target is not a coordinate (force and sensor effects) or an input
    /// (actuator effects) of the model.
    UnknownTarget {
        /// The effect.
        effect: String,
        /// The target given.
        target: String,
        /// Valid targets for this effect.
        valid: Vec<String>,
    },
    /// A value was given for a parameter the effect does not have.
    UnknownParameter {
        /// The effect.
        effect: String,
        /// The parameter given.
        name: String,
        /// The effect's parameters.
        valid: Vec<String>,
    },
    /// The value is not finite.
    BadValue {
        /// Parameter base name.
        name: String,
    },
    /// A new parameter name already exists in the model.
    NameTaken {
        /// The name.
        name: String,
    },
    /// The lossless edit failed.
    Edit(String),
}

impl fmt::Display for EffectEditError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EffectEditError::UnknownEffect { effect, known } => write!(
                f,
                "unknown effect `{effect}`; known effects: {}",
                known.join(", ")
            ),
            EffectEditError::UnknownTarget {
                effect,
                target,
                valid,
            } => write!(
                f,
                "`{effect}` cannot act on `{target}`; valid targets: {}",
                valid.join(", ")
            ),
            EffectEditError::UnknownParameter {
                effect,
                name,
                valid,
            } => write!(
                f,
                "`{effect}` has no parameter `{name}`; its parameters: {}",
                valid.join(", ")
            ),
            EffectEditError::BadValue { name } => {
                write!(f, "the value of `{name}` must be a finite number")
            }
            EffectEditError::NameTaken { name } => write!(
                f,
                "the model already has a parameter `{name}` (is the effect already there?)"
            ),
            EffectEditError::Edit(m) => write!(f, "editing the model text: {m}"),
        }
    }
}

impl std::error::Error for EffectEditError {}

/// A parameter an effect adds to the model.
#[derive(Clone, Debug, PartialEq)]
pub struct NewParameter {
    /// Effect parameter base name (`Fc`).
    pub base: String,
    /// Model parameter name (`Fc_alpha`).
    pub name: String,
    /// Unit text (`N*m`).
    pub unit: String,
    /// Value in that unit.
    pub value: f64,
    /// `estimate [lo, hi]` bounds, if the parameter is to be fitted.
    pub estimate: Option<(f64, f64)>,
}

/// What a threshold effect's level is compared with
/// ([`EffectInstance::threshold`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reach {
    /// The magnitude of the target input as recorded.
    InputMagnitude,
    /// The speed of the target coordinate.
    Speed,
}

/// One effect on one target with its new parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct EffectInstance {
    /// Effect name (`coulomb_friction`).
    pub effect: String,
    /// Kind of the effect.
    pub kind: EffectKind,
    /// Target: a coordinate for force and sensor effects, an input for
    /// actuator effects.
    pub target: String,
    /// New parameters, in the effect's call order.
    pub parameters: Vec<NewParameter>,
}

impl EffectInstance {
    /// The effect as a fit candidate: parameters at their template start
    /// values, marked `estimate` with the template bounds.
    pub fn candidate(model: &Model, effect: &str, target: &str) -> Result<Self, EffectEditError> {
        Self::build(model, effect, target, &[], true)
    }

    /// The effect with given values (by base name, e.g. `("Fc", 8e-4)`; the
    /// others at their start values), not marked `estimate`: a hidden effect
    /// for synthetic data.
    pub fn with_values(
        model: &Model,
        effect: &str,
        target: &str,
        values: &[(String, f64)],
    ) -> Result<Self, EffectEditError> {
        Self::build(model, effect, target, values, false)
    }

    fn build(
        model: &Model,
        effect: &str,
        target: &str,
        values: &[(String, f64)],
        estimate: bool,
    ) -> Result<Self, EffectEditError> {
        let Some((kind, temps)) = templates(effect) else {
            return Err(EffectEditError::UnknownEffect {
                effect: effect.to_string(),
                known: TEMPLATES.iter().map(|(n, _, _)| n.to_string()).collect(),
            });
        };
        let unknown_target = |valid: Vec<String>| EffectEditError::UnknownTarget {
            effect: effect.to_string(),
            target: target.to_string(),
            valid,
        };
        // (coordinate kind, input unit) of the target
        let (coordinate_kind, input_unit) = match kind {
            EffectKind::Force | EffectKind::Sensor => {
                match model.coordinates.iter().find(|c| c.name == target) {
                    Some(c) => (Some(c.kind), None),
                    None => {
                        return Err(unknown_target(
                            model.coordinates.iter().map(|c| c.name.clone()).collect(),
                        ))
                    }
                }
            }
            EffectKind::Actuator => match model.inputs.iter().find(|i| i.name == target) {
                Some(i) => (None, Some(i.unit.clone())),
                None => {
                    return Err(unknown_target(
                        model.inputs.iter().map(|i| i.name.clone()).collect(),
                    ))
                }
            },
        };
        for (name, v) in values {
            if !temps.iter().any(|t| t.base == name) {
                return Err(EffectEditError::UnknownParameter {
                    effect: effect.to_string(),
                    name: name.clone(),
                    valid: temps.iter().map(|t| t.base.to_string()).collect(),
                });
            }
            if !v.is_finite() {
                return Err(EffectEditError::BadValue { name: name.clone() });
            }
        }
        let mut parameters = Vec::new();
        for t in temps {
            let name = format!("{}_{}", t.base, target);
            if model.parameters.iter().any(|p| p.name == name) {
                return Err(EffectEditError::NameTaken { name });
            }
            // a level on a length coordinate: its start and box scaled
            // ([`LENGTH_LEVEL_SCALE`])
            let scale = match (t.unit, coordinate_kind) {
                (TemplateUnit::Coordinate { angle, .. }, Some(CoordinateKind::Length))
                    if is_level(angle) =>
                {
                    LENGTH_LEVEL_SCALE
                }
                _ => 1.0,
            };
            let value = values
                .iter()
                .rev()
                .find(|(n, _)| n == t.base)
                .map(|(_, v)| *v)
                .unwrap_or(scale * t.start);
            let unit = match (t.unit, coordinate_kind) {
                (TemplateUnit::Coordinate { length, .. }, Some(CoordinateKind::Length)) => {
                    length.to_string()
                }
                (TemplateUnit::Coordinate { angle, .. }, _) => angle.to_string(),
                (TemplateUnit::Fixed(u), _) => u.to_string(),
                (TemplateUnit::Input, _) => match input_unit.as_deref() {
                    Some(u) if !u.trim().is_empty() => u.to_string(),
                    _ => "1".to_string(),
                },
            };
            parameters.push(NewParameter {
                base: t.base.to_string(),
                name,
                unit,
                value,
                estimate: estimate.then_some((scale * t.lo, scale * t.hi)),
            });
        }
        Ok(EffectInstance {
            effect: effect.to_string(),
            kind,
            target: target.to_string(),
            parameters,
        })
    }

    /// The model name of the effect's parameter `base` (`Fc` -> `Fc_alpha`).
    pub fn parameter_name(&self, base: &str) -> Option<&str> {
        self.parameters
            .iter()
            .find(|p| p.base == base)
            .map(|p| p.name.as_str())
    }

    /// The values of the effect's parameters (by model name) at which it
    /// vanishes from the equations: every level, gain, width or delay at
    /// zero, a saturation level at the largest finite value (no clipping), a spring's rest
    /// position and a cogging phase or a Stribeck velocity as they are
    /// (with the level at zero they do nothing). `base` gives a parameter's
    /// current value by model name. With `nested`, the values that make
    /// it its nested simpler effect instead ([`EffectInstance::nested`]):
    /// a Stribeck friction's static level at its sliding level.
    pub fn null_values(&self, nested: bool, base: impl Fn(&str) -> f64) -> Vec<(String, f64)> {
        let name = |b: &str| self.parameter_name(b).map(str::to_string);
        if nested {
            if let ("stribeck_friction", Some(fs), Some(fc)) =
                (self.effect.as_str(), name("Fs"), name("Fc"))
            {
                let v = base(&fc);
                return vec![(fs, v)];
            }
            return Vec::new();
        }
        self.parameters
            .iter()
            .filter_map(|p| match (self.effect.as_str(), p.base.as_str()) {
                ("spring", "q0") | ("cogging", "N") | ("cogging", "phase") => None,
                ("stribeck_friction", "vs") | ("speed_limit", "vmax") => None,
                // (the largest finite level: no input is clipped)
                ("saturation", _) => Some((p.name.clone(), f64::MAX)),
                _ => Some((p.name.clone(), 0.0)),
            })
            .collect()
    }

    /// `base` (parameter values in `m`'s order) with the effect at its
    /// null value ([`EffectInstance::null_values`], `nested` as there; the
    /// current values read from `base`).
    pub fn nulled(&self, m: &Model, base: &[f64], nested: bool) -> Vec<f64> {
        let index = |name: &str| m.parameters.iter().position(|p| p.name == name);
        let mut out = base.to_vec();
        for (name, v) in self.null_values(nested, |n| index(n).map_or(f64::NAN, |i| base[i])) {
            if let Some(i) = index(&name) {
                out[i] = v;
            }
        }
        out
    }

    /// Whether fitted values (`value` by model name) describe the effect
    /// in its own form, the one its name claims. A Stribeck friction has
    /// its hump: a sliding level above zero, a static level above it (`0 <
    /// Fc + D < Fs + D`, `D` the dry friction the model already gives the
    /// joint, which `underneath` gives, asked only for a Stribeck
    /// friction; with `Fs <= Fc` the curve is a friction that falls at low
    /// speed, with no sliding level one that vanishes at
    /// speed; where the model has its own dry friction on the joint that
    /// level and `Fc` are one to the data, and the fit leaves `Fc` at its
    /// bound 0 with the sliding level in `D`), and the hump's
    /// width inside its box (a width at the box's edge says the data want
    /// a curve the form does not describe: in the main job's first round,
    /// before the input delay was in, `Fc = 0` and `vs` at its 10 rad/s
    /// edge took part of the delay's error). A cogging is a force periodic
    /// in its target: at least half its period, `pi / N`, lies within the
    /// largest range the target covers in a record, which `covered` gives
    /// (asked only for a cogging), so that the force swings through its
    /// whole amplitude, peak to trough, where the records show it; over
    /// less, its amplitude is an extrapolation of a smooth curve of the
    /// position that a spring or an offset draws as well (a cart on a
    /// spring, its travel 0.92 m: a cogging of period 2.9 m, a third of it
    /// seen, was named in the spring's place). The other effects' boxes
    /// already hold their forms.
    pub fn in_own_form(
        &self,
        value: impl Fn(&str) -> f64,
        underneath: impl FnOnce() -> f64,
        covered: impl FnOnce() -> f64,
    ) -> bool {
        if let ("cogging", Some(n)) = (self.effect.as_str(), self.parameter_name("N")) {
            return value(n).abs() * covered() >= std::f64::consts::PI;
        }
        match (
            self.effect.as_str(),
            self.parameter_name("Fs"),
            self.parameter_name("Fc"),
        ) {
            ("stribeck_friction", Some(fs), Some(fc)) => {
                let (fs, fc) = (value(fs), value(fc));
                let width_inside = self
                    .parameters
                    .iter()
                    .find(|p| p.base == "vs")
                    .and_then(|p| p.estimate.map(|(lo, hi)| (value(&p.name), lo, hi)))
                    .is_none_or(|(v, lo, hi)| {
                        // "at the edge" as the fit's bound warnings say it:
                        // within 1e-6 of the box's width
                        let tol = 1e-6 * (hi - lo);
                        v > lo + tol && v < hi - tol
                    });
                fc + underneath() > 0.0 && fs > fc && width_inside
            }
            _ => true,
        }
    }

    /// The simpler effect this one contains on its target (Stribeck
    /// friction with `Fs = Fc` is Coulomb friction), if any.
    pub fn nested(&self) -> Option<&'static str> {
        match self.effect.as_str() {
            "stribeck_friction" => Some("coulomb_friction"),
            _ => None,
        }
    }

    /// Whether the effect enters the equations (or the measurement) linearly
    /// in each of its parameters: a level times a fixed function of the
    /// state or input (Coulomb and viscous friction, a drag, a spring, an
    /// added inertia, an input or sensor offset). Not an effect with a
    /// shape parameter: a Stribeck hump's width, cogging's period and
    /// phase, a speed limit, a delay, a deadzone or saturation level.
    pub fn linear_in_parameters(&self) -> bool {
        !SHAPED_EFFECTS.contains(&self.effect.as_str())
    }

    /// A threshold effect's level and what it is compared with: the effect
    /// acts only where its target's magnitude goes beyond the level (a
    /// saturation clips the input beyond `L`; a speed limit brakes the
    /// joint beyond `vmax`). The level's model parameter name; None for an
    /// effect that acts wherever its size is not null.
    pub fn threshold(&self) -> Option<(&str, Reach)> {
        let (base, reach) = match self.effect.as_str() {
            "saturation" => ("L", Reach::InputMagnitude),
            "speed_limit" => ("vmax", Reach::Speed),
            _ => return None,
        };
        self.parameters
            .iter()
            .find(|p| p.base == base)
            .map(|p| (p.name.as_str(), reach))
    }

    /// `effect@target`.
    pub fn label(&self) -> String {
        format!("{}@{}", self.effect, self.target)
    }

    /// The keyword of the line that holds the effect: `force`, `sensor`,
    /// `actuator` or `inertia` (an `added_inertia`, of kind
    /// [`EffectKind::Force`], is written on an `inertia` line).
    pub fn line(&self) -> &'static str {
        match lang_effects::lookup(&self.effect).map(|e| e.kind) {
            Some(k) => k.keyword(),
            None => match self.kind {
                EffectKind::Force => "force",
                EffectKind::Sensor => "sensor",
                EffectKind::Actuator => "actuator",
            },
        }
    }

    /// The effect call, e.g. `coulomb_friction(Fc_alpha)`.
    pub fn call(&self) -> String {
        let args: Vec<&str> = self.parameters.iter().map(|p| p.name.as_str()).collect();
        format!("{}({})", self.effect, args.join(", "))
    }

    /// The declaration line of one new parameter.
    pub fn declaration(&self, p: &NewParameter) -> String {
        let mut s = format!(
            "parameter {} = {} [{}] \"{}\"",
            p.name,
            edit::number_text(p.value),
            p.unit,
            self.label()
        );
        if let Some((lo, hi)) = p.estimate {
            s.push_str(&format!(
                " estimate [{}, {}]",
                edit::number_text(lo),
                edit::number_text(hi)
            ));
        }
        s
    }

    /// The text a user adds to the model file by hand: the parameter lines
    /// and the line that holds the effect (for force effects, the term to
    /// append to the `force <target> = ...` line; for the others, the whole
    /// `sensor`/`actuator`/`inertia` line).
    pub fn snippet(&self) -> String {
        let mut s = String::new();
        for p in &self.parameters {
            s.push_str(&self.declaration(p));
            s.push('\n');
        }
        match self.line() {
            "force" => s.push_str(&format!("force {} = ... + {}\n", self.target, self.call())),
            kw => s.push_str(&format!("{kw} {} = {}\n", self.target, self.call())),
        }
        s
    }

    /// The model text with this effect added (lossless: every other byte is
    /// kept).
    pub fn apply(&self, text: &str) -> Result<String, EffectEditError> {
        let err = |e: edit::EditError| EffectEditError::Edit(format!("{e:?}"));
        let mut t = text.to_string();
        for p in &self.parameters {
            t = edit::add_parameter(&t, &self.declaration(p)).map_err(err)?;
        }
        match self.line() {
            "inertia" => edit::add_inertia_effect(&t, &self.target, &self.call()).map_err(err),
            "sensor" => edit::add_sensor_effect(&t, &self.target, &self.call()).map_err(err),
            "actuator" => edit::add_actuator_effect(&t, &self.target, &self.call()).map_err(err),
            _ => edit::add_force_term(&t, &self.target, &self.call()).map_err(err),
        }
    }
}

/// Effects of a drive (a motor's detent torque, a drive's speed limit):
/// [`all_candidates`] proposes them only on coordinates whose force depends
/// on an input (a detent on a free pendulum joint is not physical, and its
/// period scan would fit anything periodic there). They can be written on
/// any coordinate by hand.
pub const DRIVE_EFFECTS: &[&str] = &["cogging", "speed_limit"];

/// Effects with a parameter they are not linear in (see
/// [`EffectInstance::linear_in_parameters`]).
pub const SHAPED_EFFECTS: &[&str] = &[
    "stribeck_friction",
    "cogging",
    "speed_limit",
    "input_delay",
    "deadzone",
    "saturation",
];

/// Every template effect on every valid target of `model`, as fit
/// candidates (see [`EffectInstance::candidate`]): for each coordinate the
/// force and sensor effects in table order, then for each input the actuator
/// effects in table order.
/// Drive effects ([`DRIVE_EFFECTS`]) only on actuated coordinates.
pub fn all_candidates(model: &Model) -> Vec<EffectInstance> {
    let mut v = Vec::new();
    let targets = model
        .coordinates
        .iter()
        .map(|c| (&c.name, [EffectKind::Force, EffectKind::Sensor]))
        .chain(
            model
                .inputs
                .iter()
                .map(|i| (&i.name, [EffectKind::Actuator, EffectKind::Actuator])),
        );
    let inputs = model.input_symbols();
    let unactuated: Vec<&String> = model
        .coordinates
        .iter()
        .zip(&model.forces)
        .filter(|(_, f)| {
            let f = model.expand_derived(**f);
            !inputs.iter().any(|&u| f.contains(u))
        })
        .map(|(c, _)| &c.name)
        .collect();
    for (target, kinds) in targets {
        for (name, kind, _) in TEMPLATES {
            if DRIVE_EFFECTS.contains(name) && unactuated.contains(&target) {
                continue;
            }
            if kinds.contains(kind) {
                if let Ok(e) = EffectInstance::candidate(model, name, target) {
                    v.push(e);
                }
            }
        }
    }
    v
}

/// The `effect@target` label of an effect instance whose parameter `name`
/// was added by [`EffectInstance::apply`] (its description), split into
/// effect and target; None for any other parameter.
pub fn label_of(model: &Model, name: &str) -> Option<(String, String)> {
    let d = model.parameter(name)?.description.as_deref()?;
    let (effect, target) = d.split_once('@')?;
    templates(effect)?;
    Some((effect.to_string(), target.to_string()))
}
