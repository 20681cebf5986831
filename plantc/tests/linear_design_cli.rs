//! End-to-end acceptance of the linear analysis and design commands, driving
//! the CLI in process. Reference numbers: the thesis (Eq. 3-4, 12, 13) as
//! restated in `shared/reference/rotary-pendulum.md`; the LQR gain from scipy.

use std::path::PathBuf;

use serde_json::Value;

mod common;

use common::{model, model_file, plantc, tmp};

fn json(args: &[&str]) -> Value {
    let (code, out, err) = plantc(args);
    assert_eq!(code, 0, "plantc {args:?} failed: {err}");
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("not JSON ({e}): {out}"))
}

fn matrix(v: &Value) -> Vec<Vec<f64>> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|r| {
            r.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        })
        .collect()
}

/// Thesis Eq. 3-4.
const A_THESIS: [[f64; 4]; 4] = [
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
    [0.0, 81.4033, -45.8259, -0.9319],
    [0.0, 122.0545, -44.0966, -1.3972],
];
const B_THESIS: [f64; 4] = [0.0, 0.0, 83.4659, 80.3162];

#[test]
fn linearize_reproduces_thesis_eq_3_4() {
    let v = json(&["linearize", &model(), "--set", "quanser_manual", "--json"]);
    assert_eq!(
        v["state"],
        serde_json::json!(["theta", "alpha", "theta_dot", "alpha_dot"])
    );
    assert_eq!(v["inputs"], serde_json::json!(["Vm"]));
    let a = matrix(&v["A"]);
    let b = matrix(&v["B"]);
    for i in 0..4 {
        for j in 0..4 {
            let want = A_THESIS[i][j];
            if want == 0.0 {
                assert_eq!(a[i][j], 0.0, "A[{i}][{j}] must be exactly 0");
            } else {
                let rel = (a[i][j] - want).abs() / want.abs();
                assert!(
                    rel < 2e-3,
                    "A[{i}][{j}] = {} vs thesis {want} ({:.3} %)",
                    a[i][j],
                    rel * 100.0
                );
            }
        }
        let want = B_THESIS[i];
        if want == 0.0 {
            assert_eq!(b[i][0], 0.0);
        } else {
            assert!(
                (b[i][0] - want).abs() / want < 2e-3,
                "B[{i}] = {} vs {want}",
                b[i][0]
            );
        }
    }
    let mut poles: Vec<f64> = v["poles"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["re"].as_f64().unwrap())
        .collect();
    poles.sort_by(f64::total_cmp);
    for (got, want) in poles.iter().zip([-48.4156, -5.8644, 0.0, 7.0569]) {
        if want == 0.0 {
            assert!(got.abs() < 1e-9, "pole {got} should be 0");
        } else {
            assert!(
                (got - want).abs() / want.abs() < 2e-3,
                "pole {got} vs thesis {want}"
            );
        }
    }
    assert!(v["poles"]
        .as_array()
        .unwrap()
        .iter()
        .all(|p| p["im"].as_f64().unwrap() == 0.0));
    assert_eq!(v["controllable"], true);
    assert_eq!(v["controllability_rank"], 4);
}

fn thesis_linear_file(name: &str) -> PathBuf {
    let dir = tmp(name);
    let path = dir.join("thesis.json");
    let v = serde_json::json!({
        "A": A_THESIS,
        "B": B_THESIS.iter().map(|b| vec![*b]).collect::<Vec<_>>(),
    });
    std::fs::write(&path, v.to_string()).unwrap();
    path
}

fn assert_gain(k: &[f64], want: &[f64], tol: f64) {
    for (g, w) in k.iter().zip(want) {
        assert!(
            (g - w).abs() / w.abs() < tol,
            "K = {k:?}, expected {want:?}"
        );
    }
}

#[test]
fn place_reproduces_thesis_eq_12_and_13() {
    let f = thesis_linear_file("place");
    let f = f.to_str().unwrap();
    let v = json(&[
        "place",
        "--linear",
        f,
        "--poles",
        "-2+3.464i,-2-3.464i,-40,-45",
        "--json",
    ]);
    assert_gain(
        &matrix(&v["K"])[0],
        &[-7.8914, 37.8313, -2.9850, 3.6222],
        1e-3,
    );
    let cl = v["closed_loop_poles"].as_array().unwrap();
    assert_eq!(cl.len(), 4);
    let v = json(&[
        "place",
        "--linear",
        f,
        "--poles",
        "-2.1467,-7.4533,-40,-45",
        "--json",
    ]);
    assert_gain(
        &matrix(&v["K"])[0],
        &[-7.8917, 45.1949, -5.7471, 6.5623],
        1e-3,
    );
}

#[test]
fn place_on_the_printed_linearization_round_trips() {
    // The A, B printed by `linearize --json` feed `place --linear` directly.
    let (code, out, err) = plantc(&["linearize", &model(), "--set", "quanser_manual", "--json"]);
    assert_eq!(code, 0, "{err}");
    let dir = std::env::temp_dir().join(format!("plantc-test-{}-roundtrip", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let f = dir.join("lin.json");
    std::fs::write(&f, out).unwrap();
    let v = json(&[
        "place",
        "--linear",
        f.to_str().unwrap(),
        "--poles",
        "-2+3.464i,-2-3.464i,-40,-45",
        "--json",
    ]);
    // Our derived model differs from the printed thesis matrices by < 0.2 %;
    // the gain follows within 1 %.
    assert_gain(
        &matrix(&v["K"])[0],
        &[-7.8914, 37.8313, -2.9850, 3.6222],
        1e-2,
    );
    // Straight from the model file too.
    let w = json(&[
        "place",
        &model(),
        "--set",
        "quanser_manual",
        "--poles",
        "-2+3.464i,-2-3.464i,-40,-45",
        "--json",
    ]);
    let (k1, k2) = (matrix(&v["K"]), matrix(&w["K"]));
    assert_gain(&k1[0], &k2[0], 1e-9);
}

#[test]
fn lqr_matches_scipy_and_solves_the_care() {
    let f = thesis_linear_file("lqr");
    let v = json(&[
        "lqr",
        "--linear",
        f.to_str().unwrap(),
        "--q",
        "1,1,1,1",
        "--r",
        "1",
        "--json",
    ]);
    assert!(v["care_residual"].as_f64().unwrap() < 1e-8);
    for p in v["closed_loop_poles"].as_array().unwrap() {
        assert!(p["re"].as_f64().unwrap() < 0.0, "closed loop unstable: {v}");
    }
    // scipy 1.17.1: K = solve_continuous_are(A, B, eye(4), [[1]]) then B' P
    // (see bench/lqr_reference.py).
    assert_gain(
        &matrix(&v["K"])[0],
        &[
            -1.000000000000142,
            22.198209789804196,
            -2.0361952156045433,
            3.238694515465454,
        ],
        1e-8,
    );
    assert!(v.get("P").is_some());
}

#[test]
fn bad_inputs_give_clear_errors_with_exit_code_2() {
    let (code, _, err) = plantc(&["linearize", &model(), "--set", "nope"]);
    assert_eq!(code, 2);
    assert!(
        err.contains("unknown parameter set `nope`") && err.contains("quanser_manual"),
        "{err}"
    );
    let (code, _, err) = plantc(&["linearize", &model(), "--param", "l3=0.1"]);
    assert_eq!(code, 2);
    assert!(
        err.contains("unknown parameter `l3`") && err.contains("`l2`"),
        "{err}"
    );
    let (code, _, err) = plantc(&["linearize", &model(), "--at", "beta=1"]);
    assert_eq!(code, 2);
    assert!(err.contains("`beta`") && err.contains("alpha"), "{err}");
    let f = thesis_linear_file("bad");
    let (code, _, err) = plantc(&[
        "place",
        "--linear",
        f.to_str().unwrap(),
        "--poles",
        "-1,-2,-3",
    ]);
    assert_ne!(code, 0);
    assert!(err.contains("pole"), "{err}");
    let (code, _, err) = plantc(&["check", "does/not/exist.plant"]);
    assert_eq!(code, 2);
    assert!(err.contains("does/not/exist.plant"), "{err}");
}

#[test]
fn derive_json_has_the_documented_shape() {
    let v = json(&["derive", &model(), "--json"]);
    for key in [
        "coordinates",
        "mass_matrix",
        "bias",
        "input_matrix",
        "f",
        "g",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    assert_eq!(v["coordinates"], serde_json::json!(["theta", "alpha"]));
    assert_eq!(v["mass_matrix"][1][1], "J2h");
    assert_eq!(v["f"].as_array().unwrap().len(), 4);
}

#[test]
fn linearize_reports_the_dropped_dry_friction_term() {
    let (code, _, err) = plantc(&["linearize", &model()]);
    assert_eq!(code, 0);
    assert!(
        err.contains("sign(theta')") && err.contains("not differentiable"),
        "{err}"
    );
}

#[test]
fn other_models_linearize_and_are_controllable() {
    for m in ["cart_pole.plant", "pendubot.plant"] {
        let path = model_file(m);
        let v = json(&["linearize", &path, "--json"]);
        assert_eq!(v["controllable"], true, "{m}");
        // Both are open-loop unstable upright: one pole with positive real part.
        let unstable = v["poles"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|p| p["re"].as_f64().unwrap() > 1e-9)
            .count();
        assert!(unstable >= 1, "{m}: {v}");
    }
}
