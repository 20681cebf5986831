//! Dry friction in the equations of motion: each coordinate's generalised
//! force split into a smooth part and `-D_i(x, p) * sign(q_i')`.
//!
//! `coulomb_friction(Fc)` is `-Fc*sign(q')`, `stribeck_friction(Fc, Fs, vs)`
//! is `-(Fc + (Fs - Fc)*exp(-(q'/vs)^2))*sign(q')`, and a hand-written
//! `-F*sign(theta')` is the same shape: a factor `sign(q_i')` on the force of
//! coordinate `i` itself. [`decompose`] collects every term of `Q0_i` that
//! carries that factor (once, with a cofactor free of it) into the level
//! `D_i` (the sum of the cofactors, negated), so that
//!
//! ```text
//! Q0_i = smooth_i - D_i * sign(q_i')
//! ```
//!
//! `D_i` is the magnitude of the dry friction while the joint slides; at
//! `q_i' = 0` it is the static level (`Fs` of a Stribeck friction), which
//! decides whether a joint at rest sticks (see [`super::stick_slip`]).
//!
//! Any other `sign()` (of another expression, on another coordinate's force,
//! in the mass matrix or the input matrix, or left in a level) is not a dry
//! friction of one joint: it keeps the smooth law `tanh(v / width)` and is
//! reported in [`DryFriction::notes`]. Every consumer (identification's
//! experiment simulation, `plantc sim`, the runtime's simulated plant, the
//! generated plant) takes its split from here.

use std::collections::HashMap;

use super::Equations;
use crate::sym::{substitute, Expr, Func, Node};

/// The equations split into a smooth part and per-coordinate dry-friction
/// levels.
#[derive(Clone, Debug)]
pub struct DryFriction {
    /// The equations without the dry-friction terms: `forces[i]` is the
    /// smooth part of `Q0_i`, and every `sign()` that is not a dry friction
    /// is replaced by `tanh(v / width)` (the fallback of [`decompose`]).
    pub smooth: Equations,
    /// `D_i(x, p)` per coordinate (`Expr::zero()` for a coordinate without
    /// dry friction): `Q0_i = smooth_i - D_i sign(q_i')`.
    pub levels: Vec<Expr>,
    /// One sentence per `sign()` kept smooth, naming where it is.
    pub notes: Vec<String>,
}

impl DryFriction {
    /// Whether coordinate `i` has a dry-friction level.
    pub fn has(&self, i: usize) -> bool {
        !self.levels[i].is_zero()
    }

    /// Whether any coordinate has a dry-friction level.
    pub fn any(&self) -> bool {
        self.levels.iter().any(|d| !d.is_zero())
    }

    /// The coordinates with a dry-friction level, in order.
    pub fn coordinates(&self) -> Vec<usize> {
        (0..self.levels.len()).filter(|&i| self.has(i)).collect()
    }
}

/// The additive terms of `e`.
fn terms(e: Expr) -> Vec<Expr> {
    match e.node() {
        Node::Add(ts) => ts.to_vec(),
        _ => vec![e],
    }
}

/// The factors of `e`.
fn factors(e: Expr) -> Vec<Expr> {
    match e.node() {
        Node::Mul(fs) => fs.to_vec(),
        _ => vec![e],
    }
}

/// Whether `f` is `sign(c * v)` with `c > 0` a constant (so equal to
/// `sign(v)`).
fn is_sign_of(f: Expr, v: Expr) -> bool {
    let Node::Func(Func::Sign, arg) = f.node() else {
        return false;
    };
    if *arg == v {
        return true;
    }
    let (c, rest) = arg.coeff_and_rest();
    rest == v && !c.is_negative() && !c.is_zero()
}

/// Whether `e` contains any `sign()`.
fn contains_sign(e: Expr) -> bool {
    let mut found = Vec::new();
    signs_in(e, &mut found);
    !found.is_empty()
}

/// The `sign(..)` nodes of `e`, in a deterministic order (first seen,
/// depth first from the last child).
fn signs_in(e: Expr, out: &mut Vec<Expr>) {
    let mut stack = vec![e];
    let mut seen = std::collections::HashSet::new();
    while let Some(x) = stack.pop() {
        if !seen.insert(x) {
            continue;
        }
        if let Node::Func(Func::Sign, _) = x.node() {
            if !out.contains(&x) {
                out.push(x);
            }
        }
        stack.extend(x.children());
    }
}

/// Split the dry friction out of `eqs` (see the module docs); every `sign()`
/// that is not a dry friction of one coordinate becomes `tanh(v / width)`
/// with a note.
pub fn decompose(eqs: &Equations, width: f64) -> DryFriction {
    let n = eqs.coords.len();
    let mut forces = Vec::with_capacity(n);
    let mut levels = Vec::with_capacity(n);
    for (i, c) in eqs.coords.iter().enumerate() {
        let v = Expr::symbol(c.qd);
        let mut keep = Vec::new();
        let mut cof = Vec::new();
        for t in terms(eqs.forces[i]) {
            let fs = factors(t);
            let hits: Vec<usize> = (0..fs.len()).filter(|&k| is_sign_of(fs[k], v)).collect();
            if hits.len() == 1 {
                let rest = Expr::mul_all(
                    fs.iter()
                        .enumerate()
                        .filter(|(k, _)| *k != hits[0])
                        .map(|(_, f)| *f),
                );
                if !contains_sign(rest) {
                    cof.push(rest);
                    continue;
                }
            }
            keep.push(t);
        }
        forces.push(Expr::add_all(keep));
        levels.push(-Expr::add_all(cof));
    }
    let mut smooth = Equations {
        coords: eqs.coords.clone(),
        inputs: eqs.inputs.clone(),
        mass_matrix: eqs.mass_matrix.clone(),
        bias: eqs.bias.clone(),
        forces,
        input_matrix: eqs.input_matrix.clone(),
        // the angle frame holds M and bias (from T and V), unchanged here
        angles: eqs.angles.clone(),
    };
    // what is left: smoothed, each with a note on where it is
    let mut notes = Vec::new();
    let mut map: HashMap<Expr, Expr> = HashMap::new();
    let name = |i: usize| eqs.coords[i].q.name().to_string();
    let mut note = |sign: Expr, place: String, map: &mut HashMap<Expr, Expr>| {
        if let Node::Func(Func::Sign, arg) = sign.node() {
            map.entry(sign)
                .or_insert_with(|| (*arg * Expr::float(1.0 / width)).tanh());
            notes.push(format!(
                "`{sign}` in {place} is not a dry friction `-D*sign(q')` on its own coordinate's force: it is smoothed as tanh(({arg})/{width:e})"
            ));
        }
    };
    for (i, level) in levels.iter().enumerate() {
        let mut found = Vec::new();
        signs_in(smooth.forces[i], &mut found);
        for s in found {
            note(s, format!("the force on `{}`", name(i)), &mut map);
        }
        let mut found = Vec::new();
        signs_in(*level, &mut found);
        for s in found {
            note(
                s,
                format!("the dry-friction level of `{}`", name(i)),
                &mut map,
            );
        }
        let mut found = Vec::new();
        signs_in(smooth.bias[i], &mut found);
        for e in smooth.mass_matrix[i].iter().chain(&smooth.input_matrix[i]) {
            signs_in(*e, &mut found);
        }
        for s in found {
            note(
                s,
                format!(
                    "the equation of `{}` (mass matrix, bias or input matrix)",
                    name(i)
                ),
                &mut map,
            );
        }
    }
    if !map.is_empty() {
        let s = |e: &Expr| substitute(*e, &map);
        smooth = Equations {
            coords: smooth.coords.clone(),
            inputs: smooth.inputs.clone(),
            mass_matrix: smooth
                .mass_matrix
                .iter()
                .map(|r| r.iter().map(s).collect())
                .collect(),
            bias: smooth.bias.iter().map(s).collect(),
            forces: smooth.forces.iter().map(s).collect(),
            input_matrix: smooth
                .input_matrix
                .iter()
                .map(|r| r.iter().map(s).collect())
                .collect(),
            // kept unless a sign was smoothed in the frame's M or bias
            angles: smooth
                .angles
                .clone()
                .filter(|ac| !crate::mechanics::numeric::has_sign(&ac.equations)),
        };
        levels = levels.iter().map(s).collect();
    }
    DryFriction {
        smooth,
        levels,
        notes,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mechanics::derive_equations;
    use crate::model::load_model_text;
    use crate::sym::Symbol;

    fn equations(force_theta: &str, force_alpha: &str, extra: &str) -> (Equations, Vec<Symbol>) {
        let text = format!(
            "model m\ncoordinate theta : angle\ncoordinate alpha : angle\ninput u [N*m]\n\
             parameter J = 0.01 [kg*m^2]\nparameter Fc = 0.1 [N*m]\nparameter Fs = 0.15 [N*m]\n\
             parameter vs = 0.1 [rad/s]\nparameter b = 0.01 [N*m*s/rad]\n{extra}\n\
             kinetic T = 1/2*J*theta'^2 + 1/2*J*alpha'^2\n\
             force theta = {force_theta}\nforce alpha = {force_alpha}\n"
        );
        let model = load_model_text("m", &text).expect("model").model;
        let eqs = derive_equations(&model).expect("equations");
        (eqs, model.parameter_symbols())
    }

    fn value(e: Expr, v: &[(&str, f64)]) -> f64 {
        e.eval_with(&mut |s| {
            v.iter()
                .find(|(n, _)| *n == s.name())
                .map(|(_, x)| *x)
                .unwrap_or_else(|| panic!("no value for {}", s.name()))
        })
    }

    /// A Coulomb and a Stribeck friction come out as their levels (the
    /// Stribeck level is `Fs` at rest and tends to `Fc` at speed), with the
    /// rest of the force kept and no note.
    #[test]
    fn coulomb_and_stribeck_levels() {
        let (eqs, _) = equations(
            "u + viscous_friction(b) + coulomb_friction(Fc)",
            "stribeck_friction(Fc, Fs, vs)",
            "",
        );
        let d = decompose(&eqs, 1e-3);
        assert!(d.notes.is_empty(), "{:?}", d.notes);
        assert!(d.has(0) && d.has(1));
        let at = |v: f64| {
            [
                ("Fc", 0.1),
                ("Fs", 0.15),
                ("vs", 0.1),
                ("b", 0.01),
                ("alpha'", v),
                ("theta'", 2.0),
            ]
        };
        assert_eq!(value(d.levels[0], &at(0.0)), 0.1);
        assert!((value(d.levels[1], &at(0.0)) - 0.15).abs() < 1e-15);
        assert!((value(d.levels[1], &at(1.0)) - 0.1).abs() < 1e-12);
        // the smooth force of theta keeps the viscous term only
        assert_eq!(value(d.smooth.forces[0], &at(0.0)), -0.01 * 2.0);
        assert!(d.smooth.forces[1].is_zero());
        // smooth - D sign(v) is the original force
        for v in [-0.3, 0.2] {
            let vals = at(v);
            let orig = value(eqs.forces[1], &vals);
            let split = value(d.smooth.forces[1], &vals) - value(d.levels[1], &vals) * v.signum();
            assert!((orig - split).abs() < 1e-15, "{orig} {split}");
        }
    }

    /// A hand-written friction with a scaled argument is a dry friction too;
    /// the sign of another coordinate's velocity, or of a difference, is
    /// not: it is smoothed and named.
    #[test]
    fn other_signs_are_smoothed_with_a_note() {
        let (eqs, _) = equations(
            "-Fc*sign(2*theta') - Fc*sign(alpha')",
            "-Fc*sign(alpha' - theta')",
            "",
        );
        let d = decompose(&eqs, 1e-3);
        assert!(d.has(0) && !d.has(1));
        assert_eq!(d.notes.len(), 2, "{:?}", d.notes);
        assert!(d.notes[0].contains("the force on `theta`"), "{:?}", d.notes);
        assert!(d.notes[1].contains("the force on `alpha`"), "{:?}", d.notes);
        let mut signs = Vec::new();
        for f in &d.smooth.forces {
            signs_in(*f, &mut signs);
        }
        assert!(signs.is_empty());
    }
}
