//! Whether the data determine the fitted parameters, and what to do when
//! they do not.
//!
//! From the information matrix of the parameters at the optimum (`J'J` with
//! the nuisance unknowns, initial states and offsets, marginalised), scaled
//! to a unit diagonal (a correlation-like matrix `C`):
//! - a **dead** parameter changes the cost by less than 1e-6 of the most
//!   sensitive one when moved across its whole box;
//! - a **flat direction** is an eigenvector of `C` whose eigenvalue is below
//!   [`FLAT_RATIO`] of the largest: a combination the data do not fix (two
//!   parameters with `|corr| = 1.000`, or several together); it names the
//!   parameters with large components;
//! - **correlated** pairs have `|corr|` above the fit's threshold (0.95);
//! - a **wide** estimate has a standard error larger than its box;
//! - an estimate **at a bound** sits within 0.1 % of the box of it.
//!
//! Acted on: dead parameters, the parameter that moves most along each flat
//! direction and wide ones are fixed at their start values and the fit is
//! repeated without them ([`crate::fit`]); the result says which were fixed
//! and why. Correlated pairs and bounds are reported, not acted on (a
//! friction at its zero bound is a physical answer).

use nalgebra::{DMatrix, SymmetricEigen};
use serde::Serialize;

/// Eigenvalue ratio (smallest / largest of the unit-diagonal information)
/// below which a direction counts as flat: a condition number of 1e8, i.e.
/// a combination known 1e4 times worse than the best-known one.
pub const FLAT_RATIO: f64 = 1e-8;

/// A combination of parameters the data do not determine.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FlatDirection {
    /// The parameters involved with their (unit-scaled) components.
    pub parameters: Vec<(String, f64)>,
    /// Eigenvalue ratio to the best-determined direction.
    pub ratio: f64,
}

/// A parameter fixed because the data could not determine it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Fixed {
    /// Parameter name.
    pub name: String,
    /// The value it was fixed at (its start).
    pub value: f64,
    /// Why.
    pub reason: String,
}

/// The identifiability of a fit's parameters.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Identifiability {
    /// Parameters the data do not see.
    pub dead: Vec<String>,
    /// Combinations the data do not determine.
    pub flat: Vec<FlatDirection>,
    /// Strongly correlated pairs `(a, b, corr)`.
    pub correlated: Vec<(String, String, f64)>,
    /// Parameters whose standard error is wider than their box.
    pub wide: Vec<String>,
    /// Parameters at a bound of their box.
    pub at_bound: Vec<String>,
    /// Parameters fixed at their start by the fit (acted on).
    pub fixed: Vec<Fixed>,
    /// Parameters the analysis flagged that the fit tried fixing and kept
    /// free, with the cost rise fixing them caused (fraction): the data do
    /// determine them, jointly with the others, away from their start.
    pub kept_free: Vec<(String, f64)>,
}

impl Identifiability {
    /// True when every estimated parameter is determined by the data (no
    /// dead, flat or wide parameter left free).
    pub fn is_identifiable(&self) -> bool {
        self.dead.is_empty() && self.flat.is_empty() && self.wide.is_empty()
    }

    /// The findings in words, one line each.
    pub fn messages(&self) -> Vec<String> {
        let mut v = Vec::new();
        for f in &self.fixed {
            v.push(format!(
                "`{}` fixed at its start value {:.4e}: {}",
                f.name, f.value, f.reason
            ));
        }
        for d in &self.dead {
            v.push(format!(
                "`{d}` is not identifiable: the data do not depend on it (fix it, or add an experiment that excites it)"
            ));
        }
        for f in &self.flat {
            let names: Vec<String> = f
                .parameters
                .iter()
                .map(|(n, c)| format!("{c:+.2}*{n}"))
                .collect();
            let kept: Vec<String> = self
                .kept_free
                .iter()
                .filter(|(n, _)| f.parameters.iter().any(|(m, _)| m == n))
                .map(|(n, rise)| format!("`{n}` raised the cost by {:.0} %", 100.0 * rise))
                .collect();
            if kept.is_empty() {
                v.push(format!(
                    "not identifiable: the combination {} is undetermined (information ratio {:.1e}); fix one of them or add an experiment that separates them",
                    names.join(" "),
                    f.ratio
                ));
            } else {
                v.push(format!(
                    "the combination {} is poorly determined at the optimum (information ratio {:.1e}), but fixing {} at its start: the data place them away from their starts jointly, so they were kept free; their standard errors are not to be trusted",
                    names.join(" "),
                    f.ratio,
                    kept.join(", ")
                ));
            }
        }
        for w in &self.wide {
            v.push(format!(
                "`{w}`: its standard error is wider than its `estimate` box: the data hardly constrain it"
            ));
        }
        for (a, b, c) in &self.correlated {
            v.push(format!(
                "`{a}` and `{b}` are strongly correlated (corr {c:+.3}): the data barely separate them"
            ));
        }
        for b in &self.at_bound {
            v.push(format!(
                "`{b}` ended at a bound of its `estimate` box: the optimum may lie beyond it, or the effect is absent"
            ));
        }
        v
    }
}

/// One analysed parameter.
pub(crate) struct ParamInfo<'a> {
    pub name: &'a str,
    pub value: f64,
    pub lo: f64,
    pub hi: f64,
    pub std_error: f64,
}

/// Whether `v` sits at a bound of `[lo, hi]`: within a thousandth of the
/// smaller of the box's width and the value's own magnitude (itself at
/// least a thousandth of the box). A box is often far wider than the value
/// (dry friction of 6e-4 N m in `[0, 10]` is not at its bound; 1e-9 is).
pub(crate) fn at_bound(v: f64, lo: f64, hi: f64) -> bool {
    let w = hi - lo;
    if !(w.is_finite() && w > 0.0) {
        return v <= lo || v >= hi;
    }
    let scale = w.min(v.abs().max(1e-3 * w));
    (v - lo).min(hi - v) <= 1e-3 * scale
}

/// Analyse the information `info` (`np x np`, row-major, the parameters'
/// block with nuisance marginalised) and covariance `cov` of the
/// parameters, at a point where the (weighted) SSR is `ssr`.
pub(crate) fn analyse(
    params: &[ParamInfo<'_>],
    info: &[f64],
    cov: &[f64],
    ssr: f64,
    corr_threshold: f64,
) -> Identifiability {
    let np = params.len();
    let mut out = Identifiability::default();
    if np == 0 {
        return out;
    }
    let width = |p: &ParamInfo<'_>| {
        let w = p.hi - p.lo;
        if w.is_finite() && w > 0.0 {
            w
        } else {
            p.value.abs().max(1e-12)
        }
    };
    // change of the SSR when each parameter moves across its box: dead
    // when below a millionth of the SSR itself (judged against the cost,
    // not against the other parameters: a wide box, e.g. dry friction up to
    // 10 N m, would make every other parameter look dead)
    let sens: Vec<f64> = params
        .iter()
        .enumerate()
        .map(|(j, p)| info[j * np + j].max(0.0) * width(p).powi(2))
        .collect();
    let top = sens.iter().copied().fold(0.0f64, f64::max);
    let dead: Vec<bool> = sens
        .iter()
        .map(|&s| s.is_nan() || s <= 1e-6 * ssr.max(0.0) || top == 0.0)
        .collect();
    for (j, p) in params.iter().enumerate() {
        if dead[j] {
            out.dead.push(p.name.to_string());
        }
    }
    // flat directions among the live parameters
    let live: Vec<usize> = (0..np).filter(|&j| !dead[j]).collect();
    if live.len() > 1 {
        let nl = live.len();
        let d: Vec<f64> = live.iter().map(|&j| info[j * np + j].sqrt()).collect();
        let c = DMatrix::from_fn(nl, nl, |a, b| info[live[a] * np + live[b]] / (d[a] * d[b]));
        let eig = SymmetricEigen::new(c);
        let lmax = eig.eigenvalues.iter().copied().fold(0.0f64, f64::max);
        for k in 0..nl {
            let ratio = eig.eigenvalues[k] / lmax;
            if ratio < FLAT_RATIO {
                let v = eig.eigenvectors.column(k);
                let mut parts: Vec<(String, f64)> = (0..nl)
                    .filter(|&a| v[a].abs() > 0.3)
                    .map(|a| (params[live[a]].name.to_string(), v[a]))
                    .collect();
                parts.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
                // sign convention: the largest component positive
                if parts.first().is_some_and(|p| p.1 < 0.0) {
                    parts.iter_mut().for_each(|p| p.1 = -p.1);
                }
                out.flat.push(FlatDirection {
                    parameters: parts,
                    ratio: ratio.max(0.0),
                });
            }
        }
    }
    for j in 0..np {
        for l in j + 1..np {
            let c = cov[j * np + l] / (cov[j * np + j] * cov[l * np + l]).sqrt();
            if c.abs() > corr_threshold {
                out.correlated
                    .push((params[j].name.to_string(), params[l].name.to_string(), c));
            }
        }
    }
    for (j, p) in params.iter().enumerate() {
        let w = p.hi - p.lo;
        if !dead[j] && w.is_finite() && p.std_error.is_finite() && p.std_error > w {
            out.wide.push(p.name.to_string());
        }
        if w.is_finite() && at_bound(p.value, p.lo, p.hi) {
            out.at_bound.push(p.name.to_string());
        }
    }
    out
}

/// The parameters to fix, with the reason: every dead one, the one with
/// the largest component of each flat direction (not fixed yet), every
/// wide one.
pub(crate) fn to_fix(id: &Identifiability) -> Vec<(String, String)> {
    let mut v: Vec<(String, String)> = id
        .dead
        .iter()
        .map(|d| (d.clone(), "the data do not depend on it".to_string()))
        .collect();
    for f in &id.flat {
        if let Some((name, _)) = f
            .parameters
            .iter()
            .find(|(n, _)| !v.iter().any(|(m, _)| m == n))
        {
            let others: Vec<&str> = f
                .parameters
                .iter()
                .filter(|(n, _)| n != name)
                .map(|(n, _)| n.as_str())
                .collect();
            v.push((
                name.clone(),
                if others.is_empty() {
                    "undetermined by the data".to_string()
                } else {
                    format!("the data do not separate it from {}", others.join(", "))
                },
            ));
        }
    }
    for w in &id.wide {
        if !v.iter().any(|(m, _)| m == w) {
            v.push((
                w.clone(),
                "its standard error was wider than its box".to_string(),
            ));
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(name: &str) -> ParamInfo<'_> {
        ParamInfo {
            name,
            value: 0.5,
            lo: 0.0,
            hi: 1.0,
            std_error: 0.01,
        }
    }

    /// Two parameters that enter only as a sum give a flat direction (the
    /// difference); a zero column is dead; the fix list names one of the
    /// pair and the dead one.
    #[test]
    fn flat_and_dead() {
        // J columns: a, b, c = a (b entering like a), d dead
        // J'J of columns [1,1,0.5? ] built from rows
        let rows = [
            [1.0, 0.2, 1.0, 0.0],
            [0.3, 1.0, 0.3, 0.0],
            [2.0, -0.5, 2.0, 0.0],
        ];
        let np = 4;
        let mut info = vec![0.0; np * np];
        for r in &rows {
            for i in 0..np {
                for j in 0..np {
                    info[i * np + j] += r[i] * r[j];
                }
            }
        }
        let cov = vec![f64::NAN; np * np];
        let params = [p("a"), p("b"), p("c"), p("d")];
        let id = analyse(&params, &info, &cov, 1.0, 0.95);
        assert_eq!(id.dead, vec!["d".to_string()]);
        assert_eq!(id.flat.len(), 1, "{id:?}");
        let names: Vec<&str> = id.flat[0].parameters.iter().map(|x| x.0.as_str()).collect();
        assert!(names.contains(&"a") && names.contains(&"c"), "{names:?}");
        let fix = to_fix(&id);
        assert_eq!(fix.len(), 2);
        assert!(fix.iter().any(|f| f.0 == "d"));
        assert!(fix.iter().any(|f| f.0 == "a" || f.0 == "c"));
        assert!(!id.is_identifiable());
    }

    /// A parameter in a box far wider than its value (dry friction of
    /// 6e-4 N m in [0, 10]) neither makes the others look dead nor sits
    /// at its bound (identify's report said "J1, b1, l2: the data do not
    /// depend on it" with such a box).
    #[test]
    fn a_wide_box_does_not_kill_the_others() {
        // the cost is very sensitive to Fc per unit (the old rule, relative
        // to the most sensitive parameter across its box, called J1 dead)
        let info = [1.0, 0.0, 0.0, 1e6];
        let cov = [1.0, 0.0, 0.0, 1e-6];
        let mut wide = p("Fc");
        wide.value = 6e-4;
        wide.hi = 10.0;
        let params = [p("J1"), wide];
        let id = analyse(&params, &info, &cov, 1e-2, 0.95);
        assert!(id.dead.is_empty(), "{id:?}");
        assert!(id.at_bound.is_empty(), "{id:?}");
        assert!(at_bound(1e-9, 0.0, 10.0));
        assert!(at_bound(10.0, 0.0, 10.0));
        assert!(!at_bound(0.5, 0.0, 1.0));
    }
}
