//! The decoupling analysis of square multi-input systems: vector relative
//! degree, decoupling matrix `A(x)`, `b(x)`, the law `u = A^-1 (v - b)`,
//! normal form and zero dynamics.
//!
//! The two-input two-wheeled robot (`models/twip_yaw.plant`) is checked against
//! an independent computation: `bench/twip_yaw_decoupling_sympy.py` derives
//! the Euler-Lagrange equations, `x' = f + g u`, the Lie derivatives and the
//! zero dynamics (in a chart of its own) with SymPy from the physics as the
//! model file states it. Its numbers below were produced by
//!
//! ```sh
//! bash -c '. bench/sympy_venv.sh; "$VENV/bin/python" bench/twip_yaw_decoupling_sympy.py'
//! ```
//!
//! (SymPy 1.14.0) and are compared to 1e-9 relative. A second, linear check
//! needs no reference numbers: the zero dynamics linearized at the
//! equilibrium are the restriction of `A_lin - B_lin (C A B)^-1 C A^2` to the
//! kernel of `[C; C A]` (that subspace is invariant under it), computed here
//! from plantc's linearization (another code path). A four-link chain with
//! two torques exercises the structured (unexpanded) path the same way.

use std::collections::HashMap;

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use plantc_derive::analysis::{
    analyze_outputs, decoupling, hadamard_ratio, linearize, AnalysisError, DecouplingReport,
    OperatingPoint, OutputAnalysisError,
};
use plantc_derive::control::{output_expr, Derivation};
use plantc_derive::model::{load_model_text, LoadedModel, ParameterValues};
use plantc_derive::sym::{eval_jacobian, Evaluator, Expr, Symbol};

fn models() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models")
}

/// `models/<file>` edited by `edit`, with `extra` lines inserted after its
/// last `output` line.
fn model_with(file: &str, extra: &str, edit: &dyn Fn(&str) -> String) -> LoadedModel {
    let text = std::fs::read_to_string(models().join(file)).expect("model file");
    let text = edit(&text);
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let last = lines
        .iter()
        .rposition(|l| l.starts_with("output "))
        .expect("an output line");
    lines.insert(last + 1, extra.to_string());
    let text = lines.join("\n") + "\n";
    load_model_text(file, &text).unwrap_or_else(|e| panic!("{file}: {}", e.render()))
}

/// twip_yaw with two more outputs: the forward position of the axle and of
/// the body's centre of mass (pitch-compensated).
fn twip() -> LoadedModel {
    model_with(
        "twip_yaw.plant",
        "output x = R*theta \"forward position of the axle\"\n\
         output xc = R*theta + L*sin(psi) \"forward position of the body's centre of mass\"\n\
         output drop = L*(1 - cos(psi)) \"how far the centre of mass is below its top position\"",
        &|t| t.to_string(),
    )
}

/// The random states of the SymPy script (`random.Random(30)`, 6 decimals):
/// theta, psi, phi, theta', psi', phi'.
const STATES: [[f64; 6]; 3] = [
    [
        0.093796, -0.505929, -1.127911, 0.368726, -0.695979, -0.582535,
    ],
    [-0.246724, 0.339788, 1.173147, -0.092321, 1.184364, 1.182173],
    [-0.617579, -1.025652, -0.816238, 0.820567, 0.238931, 1.00191],
];

/// SymPy's numbers for one output pair (see the module docs).
struct Reference {
    outputs: [&'static str; 2],
    /// `A` at each of [`STATES`].
    a: [[[f64; 2]; 2]; 3],
    /// `b` at each of [`STATES`].
    b: [[f64; 2]; 3],
    /// Zero-dynamics eigenvalues at the upright equilibrium, `(re, im)`,
    /// sorted by real part.
    eigenvalues: [(f64, f64); 2],
}

const REFERENCES: [Reference; 3] = [
    Reference {
        outputs: ["psi", "phi"],
        a: [
            [
                [-50.39441604575764, -50.39441604575764],
                [-36.167188962231975, 36.167188962231975],
            ],
            [
                [-61.83652102938906, -61.83652102938906],
                [-43.465905567663356, 43.465905567663356],
            ],
            [
                [-24.19775367134465, -24.19775367134465],
                [-21.61511699639048, 21.61511699639048],
            ],
        ],
        b: [
            [-38.62153332116762, 38.40046033801281],
            [-5.3101175677517025, -93.95199917137263],
            [-89.89362819166284, -38.82027412921566],
        ],
        eigenvalues: [(0.0, 0.0), (0.0, 0.0)],
    },
    Reference {
        outputs: ["x", "phi"],
        a: [
            [
                [4.361161757871806, 4.361161757871806],
                [-36.167188962231975, 36.167188962231975],
            ],
            [
                [5.227459813178386, 5.227459813178386],
                [-43.465905567663356, 43.465905567663356],
            ],
            [
                [2.440652979852762, 2.440652979852762],
                [-21.61511699639048, 21.61511699639048],
            ],
        ],
        b: [
            [0.18837273618505204, 38.40046033801281],
            [2.547804419896778, -93.95199917137263],
            [1.7904046766855437, -38.82027412921566],
        ],
        eigenvalues: [(-8.493076765293981, 0.0), (8.493076765293981, 0.0)],
    },
    Reference {
        outputs: ["xc", "phi"],
        a: [
            [
                [1.1873126636547824, 1.1873126636547824],
                [-36.167188962231975, 36.167188962231975],
            ],
            [
                [1.0297849917202155, 1.0297849917202155],
                [-43.465905567663356, 43.465905567663356],
            ],
            [
                [1.5372301318783799, 1.5372301318783799],
                [-21.61511699639048, 21.61511699639048],
            ],
        ],
        b: [
            [-2.227116612351719, 38.40046033801281],
            [2.153674876781802, -93.95199917137263],
            [-1.5622583174940974, -38.82027412921566],
        ],
        eigenvalues: [(-23.345235059857504, 0.0), (23.345235059857504, 0.0)],
    },
];

/// `|got - want| <= 1e-9 |want|`, or `<= 1e-9` for `want = 0` (the
/// eigenvalues are in 1/s and the nonzero ones are 8.5 and 23.3, so an
/// absolute floor of 1e-9 is as strict as the relative test there).
fn close(got: f64, want: f64) -> bool {
    (got - want).abs() <= 1e-9 * want.abs().max(1.0)
}

fn point(
    model: &plantc_derive::model::Model,
    values: &ParameterValues,
    x: &[f64],
) -> HashMap<Symbol, f64> {
    let mut p = values.symbol_map(model);
    for (s, v) in model.state_symbols().iter().zip(x) {
        p.insert(*s, *v);
    }
    p
}

fn analyse(
    loaded: &LoadedModel,
    outputs: &[&str],
) -> (Derivation, ParameterValues, DecouplingReport) {
    let model = &loaded.model;
    let values = ParameterValues::new(model, None, &[]).expect("values");
    let d = Derivation::new(model).expect("derivation");
    let rep =
        analyze_outputs(model, &d, outputs, &values).unwrap_or_else(|e| panic!("{outputs:?}: {e}"));
    (d, values, rep)
}

/// `M q'' = Q0 - bias + B u` solved numerically at `p` (with `u`): `q''`.
fn accelerations(d: &Derivation, p: &HashMap<Symbol, f64>, u: &[f64]) -> DVector<f64> {
    let eqs = &d.equations;
    let n = eqs.coords.len();
    let mut ev = Evaluator::new(p);
    let m = DMatrix::from_fn(n, n, |i, j| ev.eval(eqs.mass_matrix[i][j]));
    let r = DVector::from_fn(n, |i, _| {
        ev.eval(eqs.forces[i]) - ev.eval(eqs.bias[i])
            + (0..u.len())
                .map(|j| ev.eval(eqs.input_matrix[i][j]) * u[j])
                .sum::<f64>()
    });
    m.lu().solve(&r).expect("M nonsingular")
}

/// The zero dynamics' eigenvalues from the linearization (module docs),
/// sorted by real part; the outputs' relative degrees must be 2.
fn linear_zero_dynamics(loaded: &LoadedModel, outputs: &[&str]) -> Vec<(f64, f64)> {
    let model = &loaded.model;
    let values = ParameterValues::new(model, None, &[]).expect("values");
    let d = Derivation::new(model).expect("derivation");
    let lin = linearize(model, &d.equations, &values, &OperatingPoint::zero(model)).expect("lin");
    let nx = lin.a.nrows();
    let state = model.state_symbols();
    let hs: Vec<Expr> = outputs
        .iter()
        .map(|o| output_expr(model, o).unwrap())
        .collect();
    let (_, jac) = eval_jacobian(&hs, &state, &point(model, &values, &vec![0.0; nx]));
    let c = DMatrix::from_fn(outputs.len(), nx, |i, j| jac[i][j]);
    let ca = &c * &lin.a;
    let cab = &ca * &lin.b;
    let k = -cab.lu().solve(&(&ca * &lin.a)).expect("C A B nonsingular");
    let closed = &lin.a + &lin.b * k;
    // kernel of [C; C A]: eigenvectors of G^T G with eigenvalue ~ 0
    let g = DMatrix::from_fn(2 * outputs.len(), nx, |i, j| {
        if i < outputs.len() {
            c[(i, j)]
        } else {
            ca[(i - outputs.len(), j)]
        }
    });
    let eig = SymmetricEigen::new(g.transpose() * &g);
    let scale = eig.eigenvalues.amax();
    let basis: Vec<usize> = (0..nx)
        .filter(|i| eig.eigenvalues[*i] <= 1e-12 * scale)
        .collect();
    let n = DMatrix::from_fn(nx, basis.len(), |i, j| eig.eigenvectors[(i, basis[j])]);
    let restricted = n.transpose() * closed * &n;
    let mut out: Vec<(f64, f64)> = restricted
        .complex_eigenvalues()
        .iter()
        .map(|z| (z.re, z.im))
        .collect();
    out.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    out
}

fn sorted_eigenvalues(rep: &DecouplingReport) -> Vec<(f64, f64)> {
    let mut v: Vec<(f64, f64)> = rep
        .zero_dynamics
        .eigenvalues
        .iter()
        .map(|p| (p.re, p.im))
        .collect();
    v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    v
}

#[test]
fn twip_yaw_decoupling_matches_sympy() {
    let loaded = twip();
    let model = &loaded.model;
    for r in &REFERENCES {
        let (d, values, rep) = analyse(&loaded, &r.outputs);
        let dec = &rep.decoupling;
        assert_eq!(dec.vector_relative_degree(), vec![2, 2], "{:?}", r.outputs);
        assert!(dec.expanded(), "{:?}: {:?}", r.outputs, dec.not_expanded);
        for (k, x) in STATES.iter().enumerate() {
            let p = point(model, &values, x);
            let a = dec.matrix_at(&p);
            let b = dec.drift_at(&p);
            for i in 0..2 {
                for j in 0..2 {
                    assert!(
                        close(a[(i, j)], r.a[k][i][j]),
                        "{:?} state {k}: A[{i}][{j}] = {} (SymPy {})",
                        r.outputs,
                        a[(i, j)],
                        r.a[k][i][j]
                    );
                }
                assert!(
                    close(b[i], r.b[k][i]),
                    "{:?} state {k}: b[{i}] = {} (SymPy {})",
                    r.outputs,
                    b[i],
                    r.b[k][i]
                );
            }
            // the law makes y_i'' = v_i on the numerically solved equations
            let v = [0.7, -1.3];
            let u = dec.law_at(&p, &v).expect("A nonsingular here");
            let qdd = accelerations(&d, &p, &u);
            let hs: Vec<Expr> = r
                .outputs
                .iter()
                .map(|o| output_expr(model, o).unwrap())
                .collect();
            for (i, h) in hs.iter().enumerate() {
                // y'' = J q'' + q'^T H q': with the state at p, from the chain
                let lf = &dec.outputs[i].lf;
                let state = model.state_symbols();
                let nq = model.coordinates.len();
                let (_, jl) = eval_jacobian(&[lf[1]], &state, &p);
                let ydd: f64 = (0..nq).map(|c| jl[0][c] * x[nq + c]).sum::<f64>()
                    + (0..nq).map(|c| jl[0][nq + c] * qdd[c]).sum::<f64>();
                assert!(
                    (ydd - v[i]).abs() <= 1e-9 * v[i].abs(),
                    "{:?} state {k}: {h}'' = {ydd}, v = {}",
                    r.outputs,
                    v[i]
                );
            }
        }
        let got = sorted_eigenvalues(&rep);
        assert_eq!(got.len(), 2, "{:?}", r.outputs);
        for (g, w) in got.iter().zip(&r.eigenvalues) {
            assert!(
                close(g.0, w.0) && close(g.1, w.1),
                "{:?}: zero-dynamics eigenvalue {g:?} (SymPy {w:?})",
                r.outputs
            );
        }
        let lin = linear_zero_dynamics(&loaded, &r.outputs);
        for (g, w) in got.iter().zip(&lin) {
            assert!(
                (g.0 - w.0).abs() <= 1e-7 * w.0.abs().max(1.0) && (g.1 - w.1).abs() <= 1e-7,
                "{:?}: {g:?} against the linear zero dynamics {w:?}",
                r.outputs
            );
        }
        assert!(rep.zero_dynamics.equilibrium_residual < 1e-12);
    }
}

/// An output of the velocities goes through the expanded control-affine
/// form: the axle speed `v = R theta'` (relative degree 1) with the yaw
/// (2). Holding the speed at 0 holds the axle still up to a constant
/// position, so the zero dynamics are the pitch about a fixed axle (SymPy's
/// `(x, phi)` pair: +-8.493) and the free position (a zero eigenvalue).
#[test]
fn twip_yaw_speed_output() {
    let loaded = model_with(
        "twip_yaw.plant",
        "output v = R*theta' \"forward speed of the axle\"",
        &|t| t.to_string(),
    );
    let model = &loaded.model;
    let (d, values, rep) = analyse(&loaded, &["v", "phi"]);
    let dec = &rep.decoupling;
    assert_eq!(dec.vector_relative_degree(), vec![1, 2]);
    assert!(dec.outputs[0].curvature.is_none());
    assert_eq!(rep.normal_form.xi.len(), 3);
    assert_eq!(rep.normal_form.eta.len(), 3);
    // the speed row is R (M^-1 B)[theta]: against a numeric solve
    let eqs = &d.equations;
    for x in &STATES {
        let p = point(model, &values, x);
        let mut ev = Evaluator::new(&p);
        let m = DMatrix::from_fn(3, 3, |i, j| ev.eval(eqs.mass_matrix[i][j]));
        let b = DMatrix::from_fn(3, 2, |i, j| ev.eval(eqs.input_matrix[i][j]));
        let want = m.lu().solve(&b).unwrap() * values.get(model, "R").unwrap();
        let got = dec.matrix_at(&p);
        for j in 0..2 {
            assert!(
                (got[(0, j)] - want[(0, j)]).abs() <= 1e-12 * want[(0, j)].abs(),
                "{got} vs {want}"
            );
        }
    }
    let got = sorted_eigenvalues(&rep);
    let pitch = REFERENCES[1].eigenvalues;
    let want = [pitch[0], (0.0, 0.0), pitch[1]];
    assert_eq!(got.len(), 3);
    for (g, w) in got.iter().zip(&want) {
        assert!(
            close(g.0, w.0) && close(g.1, w.1),
            "zero-dynamics eigenvalue {g:?} (want {w:?})"
        );
    }
}

/// The normal form's `eta` have `L_g eta = 0` and `eta' = L_f eta`: checked
/// on the expanded control-affine form at the random states.
#[test]
fn twip_yaw_normal_form_is_input_free() {
    let loaded = twip();
    let model = &loaded.model;
    for r in &REFERENCES {
        let (d, values, rep) = analyse(&loaded, &r.outputs);
        let ca = d.affine().expect("control-affine form");
        let nf = &rep.normal_form;
        assert_eq!(nf.xi.len(), 4);
        assert_eq!(nf.eta.len(), 2, "{:?}", r.outputs);
        for x in &STATES {
            let p = point(model, &values, x);
            let mut ev = Evaluator::new(&p);
            let f: Vec<f64> = ca.f.iter().map(|e| ev.eval(*e)).collect();
            let g: Vec<Vec<f64>> =
                ca.g.iter()
                    .map(|row| row.iter().map(|e| ev.eval(*e)).collect())
                    .collect();
            let (vals, _) = eval_jacobian(&nf.eta_dot, &ca.state, &p);
            let (_, deta) = eval_jacobian(&nf.eta, &ca.state, &p);
            for (k, row) in deta.iter().enumerate() {
                for j in 0..2 {
                    let terms: Vec<f64> = row.iter().zip(&g).map(|(d, gs)| d * gs[j]).collect();
                    let lg: f64 = terms.iter().sum();
                    let scale: f64 = terms.iter().map(|t| t.abs()).sum();
                    assert!(
                        lg.abs() <= 1e-9 * scale,
                        "{:?}: L_g{j} eta{k} = {lg} ({scale})",
                        r.outputs
                    );
                }
                let lf: f64 = (0..row.len()).map(|s| row[s] * f[s]).sum();
                assert!(
                    (lf - vals[k]).abs() <= 1e-9 * lf.abs().max(1.0),
                    "{:?}: L_f eta{k} = {lf}, eta{k}' = {}",
                    r.outputs,
                    vals[k]
                );
            }
        }
    }
}

/// With the pitch and yaw as outputs, `A` is singular exactly where
/// `2 Jw + (2 m + M) R^2 + M R L cos(psi) = 0`. By hand: the kinetic energy
/// of the model file gives a block-diagonal `M` (`vbx^2 + vby^2 = (R theta' +
/// L cos(psi) psi')^2 + (L sin(psi) phi')^2`: yaw does not couple with
/// theta, psi), with `M_tt = (2 m + M) R^2 + 2 Jw + 2 Jm`,
/// `M_tp = M R L cos(psi) - 2 Jm`; `B` has rows `a (1, 1)`, `-a (1, 1)`,
/// `k (-1, 1)`. The pitch row of `A` is `(M^-1)[psi] B = a (-M_tp - M_tt) /
/// det M[theta, psi] (1, 1)`, the yaw row `k / M_pp (-1, 1)`, so
/// `det A = -2 a k (M_tt + M_tp) / (det M[theta, psi] M_pp)`, zero where
/// `M_tt + M_tp = (2 m + M) R^2 + 2 Jw + M R L cos(psi) = 0`: at the model's
/// values `cos(psi) = -0.639` (the body below the axle). There the numeric
/// `A` is singular, 0.1 rad away it is not.
#[test]
fn twip_yaw_singular_set() {
    let loaded = twip();
    let model = &loaded.model;
    let (_, values, rep) = analyse(&loaded, &["psi", "phi"]);
    let dec = &rep.decoupling;
    assert_eq!(dec.singular_factors.len(), 1, "{}", rep.singular_set);
    let get = |name: &str| values.get(model, name).unwrap();
    let (m, r, mb, jw, l) = (get("m"), get("R"), get("M"), get("Jw"), get("L"));
    let cos_psi = -(2.0 * jw + (2.0 * m + mb) * r * r) / (mb * r * l);
    assert!((cos_psi + 0.639).abs() < 1e-3, "{cos_psi}");
    let psi = cos_psi.acos();
    let mut x = point(model, &values, &[0.3, psi, 0.2, 0.1, -0.2, 0.4]);
    // the pitch row vanishes (Hadamard's ratio alone cannot see that)
    let s = dec.singularity_at(&x);
    assert!(s < 1e-12, "{s}");
    // the reported factor vanishes there, and is of order 1e-3 elsewhere
    let factor = dec.singular_factors[0];
    assert!(factor.eval_map(&x).abs() < 1e-15, "{}", factor.eval_map(&x));
    x.insert(Symbol::new("psi"), psi - 0.1);
    assert!(factor.eval_map(&x).abs() > 1e-5, "{}", factor.eval_map(&x));
    assert!(dec.singularity_at(&x) > 1e-3, "{}", dec.singularity_at(&x));
    assert!(hadamard_ratio(&dec.matrix_at(&x)) > 1e-3);
}

/// Axle position and pitch both see only `vl + vr`: `A`'s rows are
/// proportional everywhere and the analysis says so; an output whose row
/// vanishes at the operating point is refused there; a wrong count or name
/// is an error.
#[test]
fn singular_decoupling_is_reported() {
    let loaded = twip();
    let model = &loaded.model;
    let d = Derivation::new(model).expect("derivation");
    match decoupling(model, &d, &["x", "psi"]) {
        Err(AnalysisError::SingularDecoupling { reason }) => {
            assert!(reason.contains("identically"), "{reason}")
        }
        other => panic!("{other:?}"),
    }
    match decoupling(model, &d, &["psi"]) {
        Err(AnalysisError::NotSquare {
            outputs: 1,
            inputs: 2,
        }) => {}
        other => panic!("{other:?}"),
    }
    let values = ParameterValues::new(model, None, &[]).unwrap();
    // d(drop)/dpsi = L sin(psi) = 0 upright: A's first row vanishes there
    // (not identically: the decoupling matrix exists, the operating point is
    // in its singular set)
    let dec = decoupling(model, &d, &["drop", "phi"]).expect("defined away from psi = 0");
    assert_eq!(dec.vector_relative_degree(), vec![2, 2]);
    match analyze_outputs(model, &d, &["drop", "phi"], &values) {
        Err(OutputAnalysisError::Lie(AnalysisError::SingularDecoupling { reason })) => {
            assert!(reason.contains("operating point"), "{reason}")
        }
        other => panic!("{:?}", other.err()),
    }
    match analyze_outputs(model, &d, &["psi", "nope"], &values) {
        Err(OutputAnalysisError::Lie(AnalysisError::UnknownOutput { name, .. })) => {
            assert_eq!(name, "nope")
        }
        other => panic!("{:?}", other.err()),
    }
}

/// The fully actuated double pendulum (two torques, outputs q1, q2): `A =
/// M^-1 B`, no zero dynamics.
#[test]
fn fully_actuated_double_pendulum() {
    let text = std::fs::read_to_string(models().join("double_pendulum.plant")).unwrap();
    let loaded = load_model_text("double_pendulum.plant", &text).unwrap();
    let model = &loaded.model;
    let (d, values, rep) = analyse(&loaded, &["q1", "q2"]);
    assert_eq!(rep.decoupling.vector_relative_degree(), vec![2, 2]);
    assert!(rep.normal_form.eta.is_empty());
    assert!(rep.zero_dynamics.eigenvalues.is_empty());
    let eqs = &d.equations;
    for x in &[[0.3, -0.7, 0.2, 0.5], [1.1, 0.4, -0.9, 0.0]] {
        let p = point(model, &values, x);
        let mut ev = Evaluator::new(&p);
        let m = DMatrix::from_fn(2, 2, |i, j| ev.eval(eqs.mass_matrix[i][j]));
        let b = DMatrix::from_fn(2, 2, |i, j| ev.eval(eqs.input_matrix[i][j]));
        let want = m.lu().solve(&b).unwrap();
        let got = rep.decoupling.matrix_at(&p);
        assert!(
            (&got - &want).amax() <= 1e-12 * want.amax(),
            "{got} vs {want}"
        );
    }
}

/// A four-link chain with torques at joints 1 and 3 (more than
/// `EXPLICIT_MAX_COORDINATES` coordinates: `A` and `b` stay structured, the
/// zero dynamics are linearized numerically): `A = J M^-1 B` against a
/// numeric solve, the zero dynamics against the linear ones.
#[test]
fn two_torque_chain_structured() {
    let loaded = model_with("chain4.plant", "", &|t| {
        let mut out = String::new();
        for line in t.lines() {
            if line.starts_with("controller") {
                break;
            }
            let line = line.replace(
                "force q3 = viscous_friction(b3)",
                "force q3 = tau3 + viscous_friction(b3)",
            );
            out.push_str(&line);
            out.push('\n');
            if line.starts_with("input tau ") {
                out.push_str("input tau3 [N*m] limits [-20, 20] \"torque at joint 3\"\n");
            }
        }
        out
    });
    let model = &loaded.model;
    let outputs = ["q1", "tip"];
    let (d, values, rep) = analyse(&loaded, &outputs);
    let dec = &rep.decoupling;
    assert!(!dec.expanded());
    assert!(dec.det.is_none());
    assert!(
        rep.notes
            .iter()
            .any(|n| n.contains("checked nonsingular numerically")),
        "{:?}",
        rep.notes
    );
    assert_eq!(dec.vector_relative_degree(), vec![2, 2]);
    let eqs = &d.equations;
    let x = [0.3, -0.2, 0.5, 0.1, 0.4, -0.6, 0.2, 0.9];
    let p = point(model, &values, &x);
    let mut ev = Evaluator::new(&p);
    let m = DMatrix::from_fn(4, 4, |i, j| ev.eval(eqs.mass_matrix[i][j]));
    let b = DMatrix::from_fn(4, 2, |i, j| ev.eval(eqs.input_matrix[i][j]));
    let j = DMatrix::from_row_slice(2, 4, &[1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]);
    let want = &j * m.lu().solve(&b).unwrap();
    let got = dec.matrix_at(&p);
    assert!(
        (&got - &want).amax() <= 1e-12 * want.amax(),
        "{got} vs {want}"
    );
    let zd = sorted_eigenvalues(&rep);
    let lin = linear_zero_dynamics(&loaded, &outputs);
    assert_eq!(zd.len(), 4);
    assert_eq!(lin.len(), 4);
    for (g, w) in zd.iter().zip(&lin) {
        assert!(
            (g.0 - w.0).abs() <= 1e-7 * w.0.abs().max(1.0) && (g.1 - w.1).abs() <= 1e-7,
            "{g:?} against the linear zero dynamics {w:?}"
        );
    }
}
