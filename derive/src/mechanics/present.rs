//! The equations of motion as printed by `plantc derive`: `M`, `bias`, `Q0`,
//! `B` in readable form ([`crate::sym::present`]), and the control-affine
//! `f = (q', M^-1 (Q0 - bias))`, `g = (0, M^-1 B)` expanded only when asked
//! for or when small, with `D = det M` named. Every budget that stops a
//! computation is reported in [`PresentedEquations::notes`], never hidden.

use super::{adjugate, determinant, Equations};
use crate::sym::{Canonicalizer, Expr, Name};

/// Largest number of coordinates whose control-affine form is expanded by
/// default.
pub const EXPAND_MAX_COORDINATES: usize = 3;

/// Term budget of the presentation of one entry.
pub const PRESENT_MAX_TERMS: usize = 40_000;

/// Term budget when the expansion is asked for explicitly.
pub const EXPAND_MAX_TERMS: usize = 200_000;

/// When to expand `M^-1` in the control-affine form.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Expand {
    /// Up to [`EXPAND_MAX_COORDINATES`] coordinates.
    Auto,
    /// Always (within [`EXPAND_MAX_TERMS`]).
    Always,
    /// Never: `f` and `g` are given by their structure.
    Never,
}

/// The presented equations.
#[derive(Clone, Debug)]
pub struct PresentedEquations {
    /// `M[i][j]`.
    pub mass_matrix: Vec<Vec<Expr>>,
    /// `bias[i]`.
    pub bias: Vec<Expr>,
    /// `Q0[i]`.
    pub forces: Vec<Expr>,
    /// `B[i][j]`.
    pub input_matrix: Vec<Vec<Expr>>,
    /// `det M` when the expansion was done.
    pub det_mass: Option<Expr>,
    /// The lower half of `f`, `(M^-1 (Q0 - bias))_i`, with `D = det M` named.
    pub f: Option<Vec<Expr>>,
    /// The lower half of `g`, `(M^-1 B)_ij`, with `D` named.
    pub g: Option<Vec<Vec<Expr>>>,
    /// Why something is not simplified or not expanded.
    pub notes: Vec<String>,
    /// The equations in the angles they were derived in (models with
    /// [`Equations::angles`]): then `mass_matrix` and `bias` are their
    /// named sums `S^T M_theta S`, `S^T bias_theta`, not expanded.
    pub angles: Option<PresentedAngles>,
}

/// The equations in the angle coordinates `theta = S q`, as printed: the
/// angles, then `M_theta` and `bias_theta` by the separable structure
/// (generators, diagonal, potential gradient: `O(n)` expressions, each a
/// sum over the links below one link) or, without it, entry by entry.
#[derive(Clone, Debug)]
pub struct PresentedAngles {
    /// `theta_k` (display symbol) and its definition in `q`.
    pub theta: Vec<(Expr, Expr)>,
    /// The separable structure, when `M_theta` has it.
    pub separable: Option<PresentedSeparable>,
    /// `M_theta[a][b]`, `b <= a` (without the separable structure).
    pub mass_matrix: Vec<Vec<Expr>>,
    /// `bias_theta[a]` (without the separable structure).
    pub bias: Vec<Expr>,
}

/// `M_theta[a][a] = D_a`, `M_theta[a][b] = sum_r alpha^r_a f_r(theta_a)
/// beta^r_b g_r(theta_b)` (`a < b`), `bias_theta[a] = D_a'/2 theta_a'^2 +
/// U_a . sum_(b>a) V_b' theta_b'^2 + V_a . sum_(b<a) U_b' theta_b'^2 +
/// dV/dtheta_a` (see [`super::SeparableMass`]).
#[derive(Clone, Debug)]
pub struct PresentedSeparable {
    /// `D_a`.
    pub diag: Vec<Expr>,
    /// `(f_r, g_r)` as text (`1`, `cos`, `sin`).
    pub factors: Vec<(String, String)>,
    /// `alpha^r_a`, `[r][a]`.
    pub alpha: Vec<Vec<Expr>>,
    /// `beta^r_b`, `[r][b]`.
    pub beta: Vec<Vec<Expr>>,
    /// `dV/dtheta_a`.
    pub potential_gradient: Vec<Expr>,
}

impl PresentedAngles {
    /// The lines `derive` prints, with `show` writing an expression.
    pub fn lines(&self, show: &dyn Fn(Expr) -> String) -> Vec<String> {
        let n = self.theta.len();
        let mut out =
            vec!["derived in the angles of its sines and cosines, theta = S q:".to_string()];
        for (t, d) in &self.theta {
            out.push(format!("  {} = {}", show(*t), show(*d)));
        }
        out.push(
            "M = S^T M_theta S, bias = S^T bias_theta, Q_theta = S^-T (Q0 + B u), q'' = S^-1 theta''"
                .into(),
        );
        let name = |k: usize| show(self.theta[k].0);
        match &self.separable {
            Some(s) => {
                let same = s.alpha.windows(2).all(|w| w[0] == w[1])
                    && s.beta.windows(2).all(|w| w[0] == w[1]);
                let gens: Vec<String> = s
                    .factors
                    .iter()
                    .enumerate()
                    .map(|(r, (f, g))| {
                        let k = if same {
                            String::new()
                        } else {
                            format!("{}", r + 1)
                        };
                        let ff = if f == "1" {
                            String::new()
                        } else {
                            format!("*{f}(theta_a)")
                        };
                        let gg = if g == "1" {
                            String::new()
                        } else {
                            format!("*{g}(theta_b)")
                        };
                        format!("alpha{k}_a{ff}*beta{k}_b{gg}")
                    })
                    .collect();
                let cos_diff = same
                    && s.factors
                        == [
                            ("cos".to_string(), "cos".to_string()),
                            ("sin".to_string(), "sin".to_string()),
                        ];
                let entry = if cos_diff {
                    "alpha_a*beta_b*cos(theta_a - theta_b)".to_string()
                } else {
                    gens.join(" + ")
                };
                out.push(format!(
                    "M_theta (separable): M_theta[a][a] = D_a, M_theta[a][b] = M_theta[b][a] = {entry} for a < b"
                ));
                out.push(
                    "bias_theta[a] = D_a'/2 theta_a'^2 + U_a . sum_(b > a) V_b' theta_b'^2 + V_a . sum_(b < a) U_b' theta_b'^2 + dV/dtheta_a,"
                        .into(),
                );
                out.push(
                    "  U_a, V_b the vectors of the alpha_a and beta_b terms above, ' the derivative in their own angle"
                        .into(),
                );
                for a in 0..n {
                    let mut parts = vec![format!("D_{} = {}", a + 1, show(s.diag[a]))];
                    let rows = if same { 1 } else { s.factors.len() };
                    for r in 0..rows {
                        let k = if same {
                            String::new()
                        } else {
                            format!("{}", r + 1)
                        };
                        parts.push(format!("alpha{k}_{} = {}", a + 1, show(s.alpha[r][a])));
                        parts.push(format!("beta{k}_{} = {}", a + 1, show(s.beta[r][a])));
                    }
                    parts.push(format!(
                        "dV/d{} = {}",
                        name(a),
                        show(s.potential_gradient[a])
                    ));
                    out.push(format!("  {}", parts.join(", ")));
                }
            }
            None => {
                for a in 0..n {
                    for b in 0..=a {
                        out.push(format!(
                            "  M_theta[{a}][{b}] = {}",
                            show(self.mass_matrix[a][b])
                        ));
                    }
                }
                for a in 0..n {
                    out.push(format!("  bias_theta[{a}] = {}", show(self.bias[a])));
                }
            }
        }
        out
    }
}

/// The angle-frame part of the presentation: display symbols `theta1`, ...
/// (or the internal names if those are taken), the separable structure
/// presented term by term, or the entries as derived (expanded already).
fn present_angles(
    ac: &super::AngleCoordinates,
    q: &[crate::sym::Symbol],
    canon: &mut Canonicalizer,
) -> PresentedAngles {
    let n = ac.coords.len();
    let taken = |s: &str| q.iter().any(|m| m.name() == s);
    let display: Vec<Expr> = (0..n)
        .map(|k| {
            let nice = format!("theta{}", k + 1);
            if taken(&nice) {
                Expr::symbol(ac.coords[k].q)
            } else {
                Expr::sym(&nice)
            }
        })
        .collect();
    let mut map = std::collections::HashMap::new();
    for (k, c) in ac.coords.iter().enumerate() {
        map.insert(c.q, display[k]);
        if let Some(s) = display[k].as_symbol() {
            map.insert(c.qd, Expr::sym(&format!("{}'", s.name())));
        }
    }
    let rename = |e: Expr| crate::sym::substitute_symbols(e, &map);
    let mut tidy = |e: Expr| rename(canon.try_present(e, &[]).unwrap_or(e));
    let theta = (0..n)
        .map(|k| {
            let def = Expr::add_all(
                (0..n)
                    .filter(|j| !ac.s[k][*j].is_zero())
                    .map(|j| Expr::rational(ac.s[k][j]) * Expr::symbol(q[j])),
            );
            (display[k], def)
        })
        .collect();
    let separable = super::separable_mass(ac).map(|sm| PresentedSeparable {
        diag: sm.diag.iter().map(|e| tidy(*e)).collect(),
        factors: sm
            .factors
            .iter()
            .map(|(f, g)| {
                let t = |x: &super::AngleFactor| match x {
                    super::AngleFactor::One => "1".to_string(),
                    super::AngleFactor::Cos => "cos".to_string(),
                    super::AngleFactor::Sin => "sin".to_string(),
                };
                (t(f), t(g))
            })
            .collect(),
        alpha: sm
            .alpha
            .iter()
            .map(|r| r.iter().map(|e| tidy(*e)).collect())
            .collect(),
        beta: sm
            .beta
            .iter()
            .map(|r| r.iter().map(|e| tidy(*e)).collect())
            .collect(),
        potential_gradient: sm.potential_gradient.iter().map(|e| tidy(*e)).collect(),
    });
    let (mass_matrix, bias) = if separable.is_some() {
        (Vec::new(), Vec::new())
    } else {
        (
            (0..n)
                .map(|a| {
                    (0..=a)
                        .map(|b| rename(ac.equations.mass_matrix[a][b]))
                        .collect()
                })
                .collect(),
            ac.equations.bias.iter().map(|e| rename(*e)).collect(),
        )
    };
    PresentedAngles {
        theta,
        separable,
        mass_matrix,
        bias,
    }
}

/// The symbol `D` used for `det M`.
pub fn det_name() -> Expr {
    Expr::sym("D")
}

/// Present `eqs` (see the module docs).
#[allow(clippy::needless_range_loop)] // row/column index loops over a matrix
pub fn present_equations(eqs: &Equations, expand: Expand) -> PresentedEquations {
    let n = eqs.coords.len();
    let mut notes = Vec::new();
    let (mut small, mut large) = (
        Canonicalizer::new(PRESENT_MAX_TERMS),
        Canonicalizer::new(EXPAND_MAX_TERMS),
    );
    // derived in the angle frame: M and bias stay the named sums
    // `S^T M_theta S`, `S^T bias_theta`, the angle frame is presented instead
    let mut mass_matrix = eqs.mass_matrix.clone();
    let mut bias = eqs.bias.clone();
    let angles = eqs.angles.as_ref().map(|ac| {
        let q: Vec<crate::sym::Symbol> = eqs.coords.iter().map(|c| c.q).collect();
        present_angles(ac, &q, &mut small)
    });
    let mut show = |e: Expr, what: String, names: &[Name], budget: usize| -> Option<Expr> {
        let c = if budget > PRESENT_MAX_TERMS {
            &mut large
        } else {
            &mut small
        };
        match c.try_present(e, names) {
            Ok(p) => Some(p),
            Err(x) => {
                notes.push(format!(
                    "{what} is not simplified: {x} (budget {budget} terms)"
                ));
                None
            }
        }
    };
    if angles.is_none() {
        for i in 0..n {
            for j in 0..n {
                let e = eqs.mass_matrix[i][j];
                mass_matrix[i][j] =
                    show(e, format!("M[{i}][{j}]"), &[], PRESENT_MAX_TERMS).unwrap_or(e);
            }
        }
        bias = (0..n)
            .map(|i| {
                show(eqs.bias[i], format!("bias[{i}]"), &[], PRESENT_MAX_TERMS)
                    .unwrap_or(eqs.bias[i])
            })
            .collect();
    }
    let forces = (0..n)
        .map(|i| {
            show(eqs.forces[i], format!("Q0[{i}]"), &[], PRESENT_MAX_TERMS).unwrap_or(eqs.forces[i])
        })
        .collect();
    let input_matrix = (0..n)
        .map(|i| {
            eqs.input_matrix[i]
                .iter()
                .enumerate()
                .map(|(j, e)| {
                    show(*e, format!("B[{i}][{j}]"), &[], PRESENT_MAX_TERMS).unwrap_or(*e)
                })
                .collect()
        })
        .collect();
    let (do_expand, budget) = match expand {
        Expand::Auto => (n <= EXPAND_MAX_COORDINATES, PRESENT_MAX_TERMS),
        Expand::Always => (true, EXPAND_MAX_TERMS),
        Expand::Never => (false, 0),
    };
    let mut det_mass = None;
    let mut f = None;
    let mut g = None;
    if !do_expand {
        if expand == Expand::Auto {
            notes.push(format!(
                "f and g are not expanded for {n} coordinates (more than {EXPAND_MAX_COORDINATES}): \
                 f = (q', M^-1 (Q0 - bias)), g = (0, M^-1 B) with M, bias, Q0, B above \
                 (`--expand` expands them)"
            ));
        }
    } else if let Some(det) = show(determinant(&eqs.mass_matrix), "det M".into(), &[], budget) {
        let names = [Name {
            symbol: det_name(),
            definition: det,
        }];
        let adj = adjugate(&eqs.mass_matrix);
        let mut fs = Vec::new();
        let mut gs = Vec::new();
        let mut complete = true;
        for i in 0..n {
            let num: Expr = (0..n)
                .map(|k| adj[i][k] * (eqs.forces[k] - eqs.bias[k]))
                .sum();
            match show(num / det, format!("f[{i}]"), &names, budget) {
                Some(e) => fs.push(e),
                None => complete = false,
            }
            let mut row = Vec::new();
            for j in 0..eqs.inputs.len() {
                let num: Expr = (0..n).map(|k| adj[i][k] * eqs.input_matrix[k][j]).sum();
                match show(num / det, format!("g[{i}][{j}]"), &names, budget) {
                    Some(e) => row.push(e),
                    None => complete = false,
                }
            }
            gs.push(row);
        }
        det_mass = Some(det);
        if complete {
            f = Some(fs);
            g = Some(gs);
        }
    }
    PresentedEquations {
        mass_matrix,
        bias,
        forces,
        input_matrix,
        det_mass,
        f,
        g,
        notes,
        angles,
    }
}
