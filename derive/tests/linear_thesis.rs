//! Acceptance tests of `plantc_derive::linear` against the rotary pendulum
//! thesis numbers, as restated in `/work/shared/reference/rotary-pendulum.md`
//! ("Published numbers to reproduce"), plus error cases.

use nalgebra::DMatrix;
use plantc_derive::linear::*;

/// Thesis Eq. 3-4 (the Quanser manual's linearization), as printed.
fn thesis_model() -> LinearModel {
    LinearModel::from_json(
        r#"{
        "state": ["theta", "alpha", "theta_dot", "alpha_dot"],
        "inputs": ["Vm"],
        "A": [[0, 0, 1, 0],
              [0, 0, 0, 1],
              [0, 81.4033, -45.8259, -0.9319],
              [0, 122.0545, -44.0966, -1.3972]],
        "B": [[0], [0], [83.4659], [80.3162]]
    }"#,
    )
    .expect("thesis model parses")
}

fn assert_rel(got: f64, want: f64, rel: f64, what: &str) {
    let err = (got - want).abs() / want.abs();
    assert!(
        err <= rel,
        "{what}: got {got}, want {want} (rel err {err:e} > {rel:e})"
    );
}

#[test]
fn open_loop_poles_and_controllability() {
    let m = thesis_model();
    let report = analyze(&m).unwrap();
    // Reference doc: open-loop poles -48.4156, -5.8644, 0, 7.0569; rank 4.
    let p = &report.poles;
    assert_eq!(p.len(), 4);
    assert!(p.iter().all(|z| z.im == 0.0), "{p:?}");
    assert_rel(p[0].re, -48.4156, 2e-3, "pole 1");
    assert_rel(p[1].re, -5.8644, 2e-3, "pole 2");
    assert!(p[2].re.abs() < 1e-6, "pole 3 = {}", p[2].re);
    assert_rel(p[3].re, 7.0569, 2e-3, "pole 4");
    assert!(report.controllable);
    assert_eq!(report.controllability_rank, 4);

    let c = controllability(&m.a, &m.b).unwrap();
    assert_eq!(c.singular_values.len(), 4);
    assert!(c.singular_values[3] > c.tolerance);
    assert_rel(
        c.tolerance,
        4.0 * f64::EPSILON * c.singular_values[0],
        1e-12,
        "tolerance",
    );

    let json: serde_json::Value = serde_json::from_str(&to_json(&report)).unwrap();
    assert_eq!(json["controllability_rank"], 4);
    assert_eq!(json["controllable"], true);
    assert!(json["poles"][0]["re"].is_f64() && json["poles"][0]["im"].is_f64());
}

#[test]
fn place_thesis_eq12() {
    let m = thesis_model();
    let desired = parse_poles("-2+3.464i, -2-3.464i, -40, -45").unwrap();
    let pl = place(&m.a, &m.b, &desired).unwrap();
    // Reference doc (thesis Eq. 12, sign flipped for u = -Kx, recomputed on the printed A, B).
    let want = [-7.8914, 37.8313, -2.9850, 3.6222];
    for (j, w) in want.iter().enumerate() {
        assert_rel(pl.k[(0, j)], *w, 1e-3, "K Eq. 12");
    }
    println!(
        "Eq. 12 K = {:?}, pole error {:e}",
        pl.k.as_slice(),
        pl.max_pole_error
    );
    assert!(pl.max_pole_error < 1e-9, "{}", pl.max_pole_error);
    let r = PlaceReport::from(&pl);
    let json: serde_json::Value = serde_json::from_str(&to_json(&r)).unwrap();
    assert_eq!(json["K"][0].as_array().unwrap().len(), 4);
    assert_eq!(json["closed_loop_poles"].as_array().unwrap().len(), 4);
    // Conjugate pair is exactly conjugate in the output.
    let cl = &pl.closed_loop_poles;
    let pair: Vec<_> = cl.iter().filter(|z| z.im != 0.0).collect();
    assert_eq!(pair.len(), 2);
    assert_eq!(pair[0].re, pair[1].re);
    assert_eq!(pair[0].im, -pair[1].im);
}

#[test]
fn place_thesis_eq13() {
    let m = thesis_model();
    let desired = parse_poles("-2.1467,-7.4533,-40,-45").unwrap();
    let pl = place(&m.a, &m.b, &desired).unwrap();
    // Reference doc (thesis Eq. 13): K = [-7.8917, 45.1949, -5.7471, 6.5623].
    let want = [-7.8917, 45.1949, -5.7471, 6.5623];
    for (j, w) in want.iter().enumerate() {
        assert_rel(pl.k[(0, j)], *w, 1e-3, "K Eq. 13");
    }
    println!(
        "Eq. 13 K = {:?}, pole error {:e}",
        pl.k.as_slice(),
        pl.max_pole_error
    );
    assert!(pl.max_pole_error < 1e-9, "{}", pl.max_pole_error);
}

#[test]
fn lqr_thesis_identity_weights() {
    let m = thesis_model();
    let q = DMatrix::<f64>::identity(4, 4);
    let r = DMatrix::from_element(1, 1, 1.0);
    let l = lqr(&m.a, &m.b, &q, &r).unwrap();
    // Reference: bench/lqr_reference.py, numpy 2.4.6 / scipy 1.17.1,
    // P = scipy.linalg.solve_continuous_are(A, B, np.eye(4), np.array([[1.0]])),
    // K = np.linalg.solve(R, B.T @ P). scipy's own residual norm: 3.7e-12.
    let k_ref = [
        -0.9999999999999835,
        22.198209789803105,
        -2.0361952156044443,
        3.238694515465337,
    ];
    let p_ref = [
        [
            1.487156333430333,
            -3.4927830960280257,
            0.4550962344729007,
            -0.48539418942743395,
        ],
        [
            -3.4927830960280257,
            41.172580004504674,
            -4.668944713960396,
            5.128428416567893,
        ],
        [
            0.4550962344729007,
            -4.668944713960396,
            0.5815672173404168,
            -0.629726336921044,
        ],
        [
            -0.48539418942743395,
            5.128428416567893,
            -0.629726336921044,
            0.6947461406326931,
        ],
    ];
    for (j, w) in k_ref.iter().enumerate() {
        assert_rel(l.k[(0, j)], *w, 1e-9, "LQR K");
    }
    for (i, row) in p_ref.iter().enumerate() {
        for (j, w) in row.iter().enumerate() {
            assert_rel(l.p[(i, j)], *w, 1e-9, "LQR P");
        }
    }
    assert!(l.care_residual < 1e-8, "residual {}", l.care_residual);
    assert!(l.closed_loop_poles.iter().all(|z| z.re < 0.0));
    // scipy closed-loop poles: -125.67197354, -5.42049968 +/- 1.93229758i, -0.87689731.
    assert_rel(l.closed_loop_poles[0].re, -125.67197354, 1e-8, "cl pole");
    assert_rel(l.closed_loop_poles[3].re, -0.87689731, 1e-7, "cl pole");
    println!(
        "LQR K = {:?}, residual = {:e}",
        l.k.as_slice(),
        l.care_residual
    );

    let json: serde_json::Value = serde_json::from_str(&to_json(&LqrReport::from(&l))).unwrap();
    for key in ["K", "P", "closed_loop_poles", "care_residual"] {
        assert!(json.get(key).is_some(), "missing {key}");
    }
}

#[test]
fn model_json_roundtrip_and_default_names() {
    let m = LinearModel::from_json(r#"{"A": [[0, 1], [-2, -3]], "B": [[0], [1]]}"#).unwrap();
    assert_eq!(m.state, ["x1", "x2"]);
    assert_eq!(m.inputs, ["u1"]);
    assert_eq!(m.a[(1, 0)], -2.0);
    let back = LinearModel::from_json(&m.to_json()).unwrap();
    assert_eq!(back, m);
    let t = thesis_model();
    assert_eq!(LinearModel::from_json(&t.to_json()).unwrap(), t);
}

#[test]
fn model_json_errors() {
    let e = |s: &str| LinearModel::from_json(s).unwrap_err();
    assert!(matches!(e("{"), LinearError::Json { .. }));
    assert!(matches!(e(r#"{"A": [[1]]}"#), LinearError::Json { .. }));
    assert!(matches!(
        e(r#"{"A": [[1, "x"]], "B": [[1]]}"#),
        LinearError::Json { .. }
    ));
    assert_eq!(
        e(r#"{"A": [[1, 2], [3]], "B": [[1], [1]]}"#),
        LinearError::RaggedRows {
            matrix: "A",
            row: 1,
            expected: 2,
            found: 1
        }
    );
    assert_eq!(
        e(r#"{"A": [[1, 2]], "B": [[1]]}"#),
        LinearError::NotSquare {
            matrix: "A",
            rows: 1,
            cols: 2
        }
    );
    assert_eq!(
        e(r#"{"A": [[1, 2], [3, 4]], "B": [[1]]}"#),
        LinearError::DimensionMismatch {
            matrix: "B",
            expected: (2, 1),
            found: (1, 1)
        }
    );
    assert_eq!(
        e(r#"{"A": [], "B": [[1]]}"#),
        LinearError::EmptyMatrix { matrix: "A" }
    );
    assert_eq!(
        e(r#"{"A": [[1]], "B": [[]]}"#),
        LinearError::EmptyMatrix { matrix: "B" }
    );
    assert_eq!(
        e(r#"{"A": [[1]], "B": [[1]], "state": ["a", "b"]}"#),
        LinearError::NameCountMismatch {
            names: "state",
            expected: 1,
            found: 2
        }
    );
    // serde_json rejects 1e999 (out of range); non-finite values built in code are caught.
    assert!(matches!(
        e(r#"{"A": [[1e999]], "B": [[1]]}"#),
        LinearError::Json { .. }
    ));
    let nan = DMatrix::from_element(1, 1, f64::NAN);
    assert_eq!(
        LinearModel::new(nan, DMatrix::from_element(1, 1, 1.0)).unwrap_err(),
        LinearError::NonFinite {
            matrix: "A",
            row: 0,
            col: 0
        }
    );
}

#[test]
fn pole_parser() {
    let p = parse_poles("-2+3.464i, -2-3.464j,3.464i , -40, -1e-3-2E+1i, -i, +2").unwrap();
    assert_eq!(
        p,
        vec![
            Pole::new(-2.0, 3.464),
            Pole::new(-2.0, -3.464),
            Pole::new(0.0, 3.464),
            Pole::real(-40.0),
            Pole::new(-1e-3, -20.0),
            Pole::new(0.0, -1.0),
            Pole::real(2.0),
        ]
    );
    assert_eq!(
        parse_poles(" - 2 + 3 i").unwrap(),
        vec![Pole::new(-2.0, 3.0)]
    );
    let bad = |s: &str| match parse_poles(s).unwrap_err() {
        LinearError::InvalidPole { index, item, .. } => (index, item),
        other => panic!("unexpected {other:?}"),
    };
    assert_eq!(bad("-1, -2x, -3"), (1, "-2x".to_string()));
    assert_eq!(bad("-1,,-3"), (1, String::new()));
    assert_eq!(bad("-1, inf"), (1, "inf".to_string()));
    assert_eq!(bad("-1, nan"), (1, "nan".to_string()));
    assert_eq!(bad("1+2"), (0, "1+2".to_string()));
    assert_eq!(bad("-1, 2ii"), (1, "2ii".to_string()));
    assert_eq!(parse_poles("  ").unwrap_err(), LinearError::NoPoles);
    for z in &p {
        assert_eq!(parse_poles(&format_pole(*z)).unwrap(), vec![*z]);
    }
}

#[test]
fn place_errors() {
    let m = thesis_model();
    let three = parse_poles("-1,-2,-3").unwrap();
    assert_eq!(
        place(&m.a, &m.b, &three).unwrap_err(),
        LinearError::PoleCountMismatch {
            expected: 4,
            found: 3
        }
    );
    let unpaired = parse_poles("-2+3i,-2-3.1i,-40,-45").unwrap();
    assert_eq!(
        place(&m.a, &m.b, &unpaired).unwrap_err(),
        LinearError::ComplexPolesNotConjugate {
            pole: Pole::new(-2.0, 3.0)
        }
    );
    // Uncontrollable: the second state is decoupled from the input.
    let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 2.0]);
    let b = DMatrix::from_row_slice(2, 1, &[1.0, 0.0]);
    match place(&a, &b, &parse_poles("-1,-2").unwrap()).unwrap_err() {
        LinearError::NotControllable { rank, n, tolerance } => {
            assert_eq!((rank, n), (1, 2));
            assert!(tolerance > 0.0);
        }
        other => panic!("unexpected {other:?}"),
    }
    let b2 = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 1.0]);
    assert_eq!(
        place(&a, &b2, &parse_poles("-1,-2").unwrap()).unwrap_err(),
        LinearError::MultiInputUnsupported { inputs: 2 }
    );
    let bad_b = DMatrix::from_row_slice(3, 1, &[1.0, 0.0, 0.0]);
    assert!(matches!(
        place(&a, &bad_b, &parse_poles("-1,-2").unwrap()).unwrap_err(),
        LinearError::DimensionMismatch { .. }
    ));
}

#[test]
fn lqr_errors() {
    let m = thesis_model();
    let q = DMatrix::<f64>::identity(4, 4);
    let r_neg = DMatrix::from_element(1, 1, -1.0);
    assert!(matches!(
        lqr(&m.a, &m.b, &q, &r_neg).unwrap_err(),
        LinearError::RNotPositiveDefinite { .. }
    ));
    let r_zero = DMatrix::from_element(1, 1, 0.0);
    assert!(matches!(
        lqr(&m.a, &m.b, &q, &r_zero).unwrap_err(),
        LinearError::RNotPositiveDefinite { .. }
    ));
    let r = DMatrix::from_element(1, 1, 1.0);
    let mut q_neg = q.clone();
    q_neg[(2, 2)] = -0.5;
    assert!(matches!(
        lqr(&m.a, &m.b, &q_neg, &r).unwrap_err(),
        LinearError::QNotPositiveSemidefinite { .. }
    ));
    let mut q_asym = q.clone();
    q_asym[(0, 1)] = 0.5;
    assert!(matches!(
        lqr(&m.a, &m.b, &q_asym, &r).unwrap_err(),
        LinearError::NotSymmetric { .. }
    ));
    assert!(matches!(
        lqr(&m.a, &m.b, &DMatrix::identity(3, 3), &r).unwrap_err(),
        LinearError::DimensionMismatch { matrix: "Q", .. }
    ));
    // Unstabilizable: unstable mode at +1 not reached by the input.
    let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]);
    let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
    assert_eq!(
        lqr(&a, &b, &DMatrix::identity(2, 2), &r).unwrap_err(),
        LinearError::NotStabilizable {
            eigenvalue: Pole::real(1.0)
        }
    );
    // No stabilizing solution: integrator with zero state weight (mode on the axis unobservable).
    let a1 = DMatrix::from_element(1, 1, 0.0);
    let b1 = DMatrix::from_element(1, 1, 1.0);
    assert!(matches!(
        lqr(&a1, &b1, &DMatrix::zeros(1, 1), &r).unwrap_err(),
        LinearError::CareFailed { .. }
    ));
}
