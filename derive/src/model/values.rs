//! Numeric parameter values: nominal, a named set, command-line overrides, and
//! the derived quantities computed from them.

use std::collections::HashMap;
use std::fmt;

use super::Model;
use crate::lang::check::edit_distance_within;
use crate::sym::Symbol;

/// Why a parameter selection failed.
#[derive(Clone, Debug, PartialEq)]
pub enum ValuesError {
    /// `--set NAME` names no set of the model.
    UnknownSet {
        /// The name asked for.
        name: String,
        /// The sets the model has.
        known: Vec<String>,
    },
    /// `--param NAME=VALUE` names no parameter.
    UnknownParameter {
        /// The name asked for.
        name: String,
        /// Closest known names.
        suggestions: Vec<String>,
    },
    /// A value is not a finite number.
    NotFinite {
        /// Parameter name.
        name: String,
    },
}

impl fmt::Display for ValuesError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ValuesError::UnknownSet { name, known } => {
                write!(f, "unknown parameter set `{name}`")?;
                if known.is_empty() {
                    write!(f, " (the model defines no sets)")
                } else {
                    write!(f, " (known sets: {})", known.join(", "))
                }
            }
            ValuesError::UnknownParameter { name, suggestions } => {
                write!(f, "unknown parameter `{name}`")?;
                if !suggestions.is_empty() {
                    write!(f, " (did you mean {}?)", suggestions.join(", "))?;
                }
                Ok(())
            }
            ValuesError::NotFinite { name } => write!(f, "parameter `{name}` is not finite"),
        }
    }
}

impl std::error::Error for ValuesError {}

/// Parameter values in model order, followed by derived quantities.
#[derive(Clone, Debug, PartialEq)]
pub struct ParameterValues {
    /// Values of [`Model::parameters`] in SI units.
    pub base: Vec<f64>,
    /// `base` followed by the values of [`Model::derived`]: the order of
    /// [`Model::parameter_symbols`].
    pub full: Vec<f64>,
}

/// Up to three names close to `name` (edit distance at most 2, or a prefix).
pub(crate) fn nearest<'a>(name: &str, known: impl Iterator<Item = &'a str>) -> Vec<String> {
    let mut v: Vec<(usize, &str)> = known
        .filter_map(|k| match edit_distance_within(name, k, 2) {
            Some(d) => Some((d, k)),
            // a prefix: the distance is the length difference
            None => k
                .starts_with(name)
                .then(|| (k.chars().count() - name.chars().count(), k)),
        })
        .collect();
    v.sort();
    v.into_iter()
        .take(3)
        .map(|(_, k)| format!("`{k}`"))
        .collect()
}

impl ParameterValues {
    /// Nominal values, then the set `set` (if any), then `overrides` in order.
    pub fn new(
        model: &Model,
        set: Option<&str>,
        overrides: &[(String, f64)],
    ) -> Result<ParameterValues, ValuesError> {
        let mut base: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
        let index = |name: &str| model.parameters.iter().position(|p| p.name == name);
        if let Some(s) = set {
            let Some(ps) = model.sets.iter().find(|x| x.name == s) else {
                return Err(ValuesError::UnknownSet {
                    name: s.to_string(),
                    known: model.sets.iter().map(|x| x.name.clone()).collect(),
                });
            };
            for (n, v) in &ps.values {
                if let Some(i) = index(n) {
                    base[i] = *v;
                }
            }
        }
        for (n, v) in overrides {
            let Some(i) = index(n) else {
                return Err(ValuesError::UnknownParameter {
                    name: n.clone(),
                    suggestions: nearest(n, model.parameters.iter().map(|p| p.name.as_str())),
                });
            };
            if !v.is_finite() {
                return Err(ValuesError::NotFinite { name: n.clone() });
            }
            base[i] = *v;
        }
        Ok(Self::from_base(model, base))
    }

    /// Values from a base vector (model order); derived quantities recomputed.
    pub fn from_base(model: &Model, base: Vec<f64>) -> ParameterValues {
        let mut map: HashMap<Symbol, f64> = model
            .parameters
            .iter()
            .zip(&base)
            .map(|(p, v)| (p.symbol, *v))
            .collect();
        let mut full = base.clone();
        for d in &model.derived {
            let v = d.expr.eval_map(&map);
            map.insert(d.symbol, v);
            full.push(v);
        }
        ParameterValues { base, full }
    }

    /// Symbol -> value for every parameter and derived quantity.
    pub fn symbol_map(&self, model: &Model) -> HashMap<Symbol, f64> {
        model
            .parameter_symbols()
            .into_iter()
            .zip(self.full.iter().copied())
            .collect()
    }

    /// Value of a parameter or derived quantity by name.
    pub fn get(&self, model: &Model, name: &str) -> Option<f64> {
        let names = model
            .parameters
            .iter()
            .map(|p| p.name.as_str())
            .chain(model.derived.iter().map(|d| d.name.as_str()));
        names
            .zip(self.full.iter())
            .find(|(n, _)| *n == name)
            .map(|(_, v)| *v)
    }
}
