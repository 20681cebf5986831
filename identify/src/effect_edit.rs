//! Adding a physical effect to a model text: the shared step of `diagnose`
//! (candidates, `--apply`) and `synth` (hidden effects in generated data).
//!
//! An [`EffectInstance`] is one effect of the language's effect table on one
//! target (a coordinate for force effects), with its new parameters named
//! `<base>_<target>` (e.g. `Fc_alpha`). [`EffectInstance::apply`] edits the
//! model text losslessly (`lang::edit`): it appends the parameter
//! declarations and the effect call, and touches nothing else.
//!
//! The parameter templates (units, start values, bounds) live in
//! [`templates`]; an effect without a template cannot be instantiated.

use std::fmt;

use plantc_derive::lang::edit;
use plantc_derive::model::{CoordinateKind, Model};

/// Where an effect acts.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum EffectKind {
    /// A generalised force on a coordinate (`force q = ... + effect(..)`).
    Force,
}

/// One parameter of an effect: base name, units, start value and bounds.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ParamTemplate {
    /// Base name; the model parameter is `<base>_<target>`.
    pub base: &'static str,
    /// Unit when the target is an angle coordinate.
    pub unit_angle: &'static str,
    /// Unit when the target is a length coordinate.
    pub unit_length: &'static str,
    /// Start value of a fit (in the unit above).
    pub start: f64,
    /// Lower bound of the `estimate` box.
    pub lo: f64,
    /// Upper bound of the `estimate` box.
    pub hi: f64,
}

const fn pt(
    base: &'static str,
    unit_angle: &'static str,
    unit_length: &'static str,
    start: f64,
    lo: f64,
    hi: f64,
) -> ParamTemplate {
    ParamTemplate {
        base,
        unit_angle,
        unit_length,
        start,
        lo,
        hi,
    }
}

/// The effects `diagnose` and `synth` know, with their kind and parameters
/// (in the effect's call order).
pub const TEMPLATES: &[(&str, EffectKind, &[ParamTemplate])] = &[
    (
        "coulomb_friction",
        EffectKind::Force,
        &[pt("Fc", "N*m", "N", 1e-4, 0.0, 0.1)],
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
            pt("Fc", "N*m", "N", 1e-4, 0.0, 0.1),
            pt("Fs", "N*m", "N", 2e-4, 0.0, 0.2),
            pt("vs", "rad/s", "m/s", 0.1, 1e-3, 10.0),
        ],
    ),
    (
        "spring",
        EffectKind::Force,
        &[pt("k", "N*m/rad", "N/m", 1e-3, 0.0, 1.0)],
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
    /// The target is not a coordinate (force effects) of the model.
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

/// One effect on one target with its new parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct EffectInstance {
    /// Effect name (`coulomb_friction`).
    pub effect: String,
    /// Kind of the effect.
    pub kind: EffectKind,
    /// Target: a coordinate for force effects.
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
        let coordinate_kind = match kind {
            EffectKind::Force => match model.coordinates.iter().find(|c| c.name == target) {
                Some(c) => c.kind,
                None => {
                    return Err(EffectEditError::UnknownTarget {
                        effect: effect.to_string(),
                        target: target.to_string(),
                        valid: model.coordinates.iter().map(|c| c.name.clone()).collect(),
                    })
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
            let value = values
                .iter()
                .rev()
                .find(|(n, _)| n == t.base)
                .map(|(_, v)| *v)
                .unwrap_or(t.start);
            let unit = match coordinate_kind {
                CoordinateKind::Angle => t.unit_angle,
                CoordinateKind::Length => t.unit_length,
            };
            parameters.push(NewParameter {
                base: t.base.to_string(),
                name,
                unit: unit.to_string(),
                value,
                estimate: estimate.then_some((t.lo, t.hi)),
            });
        }
        Ok(EffectInstance {
            effect: effect.to_string(),
            kind,
            target: target.to_string(),
            parameters,
        })
    }

    /// `effect@target`.
    pub fn label(&self) -> String {
        format!("{}@{}", self.effect, self.target)
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
    /// append to the `force <target> = ...` line).
    pub fn snippet(&self) -> String {
        let mut s = String::new();
        for p in &self.parameters {
            s.push_str(&self.declaration(p));
            s.push('\n');
        }
        match self.kind {
            EffectKind::Force => {
                s.push_str(&format!("force {} = ... + {}\n", self.target, self.call()))
            }
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
        match self.kind {
            EffectKind::Force => edit::add_force_term(&t, &self.target, &self.call()).map_err(err),
        }
    }
}

/// Every template effect on every valid target of `model`, as fit
/// candidates (see [`EffectInstance::candidate`]), in table order per target.
pub fn all_candidates(model: &Model) -> Vec<EffectInstance> {
    let mut v = Vec::new();
    for c in &model.coordinates {
        for (name, kind, _) in TEMPLATES {
            if *kind == EffectKind::Force {
                if let Ok(e) = EffectInstance::candidate(model, name, &c.name) {
                    v.push(e);
                }
            }
        }
    }
    v
}
