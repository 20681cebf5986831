//! JSON shape of `plantc analyze` and `plantc stability`, run in process.

mod common;

use common::{model_file, plantc};

#[test]
fn analyze_json_shape() {
    let m = model_file("rotary_pendulum.plant");
    let (code, out, err) = plantc(&[
        "analyze", &m, "--output", "alpha", "--set", "thesis", "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("json");
    assert_eq!(v["relative_degree"], 2);
    for key in ["h", "L_f h", "L_g h", "L_f^2 h", "L_g L_f h"] {
        assert!(v["lie_derivatives"][key].is_string(), "missing {key}");
    }
    assert_eq!(v["lie_derivatives"]["L_g h"], "0");
    assert!(v["control_law"].as_str().unwrap().starts_with("u = "));
    assert_eq!(v["singular_set"], "cos(alpha) = 0");
    assert_eq!(
        v["normal_form"]["xi"],
        serde_json::json!(["alpha", "alpha'"])
    );
    assert_eq!(v["normal_form"]["eta"].as_array().unwrap().len(), 2);
    let zd = &v["zero_dynamics"];
    assert_eq!(zd["equations"].as_array().unwrap().len(), 2);
    let eig = zd["eigenvalues"].as_array().unwrap();
    assert_eq!(eig.len(), 2);
    for e in eig {
        assert!(e["re"].as_f64().unwrap().abs() < 1e-9 && e["im"].as_f64().unwrap().abs() < 1e-9);
    }
    assert_eq!(zd["asymptotically_stable"], false);
    assert_eq!(zd["minimum_phase"], false);
    assert!(zd["classification"]
        .as_str()
        .unwrap()
        .starts_with("not asymptotically stable"));
}

#[test]
fn analyze_text_and_pendubot() {
    let (code, out, err) = plantc(&["analyze", &model_file("pendubot.plant")]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("relative degree 2"), "{out}");
    assert!(out.contains("unstable (non-minimum phase)"), "{out}");
}

#[test]
fn analyze_unknown_output_is_bad_input() {
    let (code, _, err) = plantc(&[
        "analyze",
        &model_file("rotary_pendulum.plant"),
        "--output",
        "nope",
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("unknown output"), "{err}");
}

#[test]
fn stability_json_interval() {
    let m = model_file("rotary_pendulum.plant");
    let (code, out, err) = plantc(&[
        "stability",
        &m,
        "--controller",
        "fl_arm",
        "--vary",
        "a,b",
        "--set",
        "thesis",
        "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("json");
    let iv = v["intervals"].as_array().unwrap();
    assert_eq!(iv.len(), 1, "{out}");
    let lo = iv[0][0].as_f64().unwrap();
    let hi = iv[0][1].as_f64().unwrap();
    assert!(lo.abs() < 1e-9, "{lo}");
    assert!((hi - 1.002).abs() < 5e-4, "{hi}");
}

#[test]
fn stability_text_and_unbounded_null() {
    let m = model_file("rotary_pendulum.plant");
    let (code, out, err) = plantc(&[
        "stability",
        &m,
        "--controller",
        "fl_arm",
        "--vary",
        "a,b",
        "--set",
        "thesis",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("0 < k < 1.00"), "{out}");
    assert!(out.contains("method:"), "{out}");
    let (code, _, err) = plantc(&[
        "stability",
        &m,
        "--controller",
        "pole_placement",
        "--vary",
        "a",
    ]);
    assert_eq!(code, 2, "{err}");
}
