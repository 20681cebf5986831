//! JSON shape of `plantc analyze` and `plantc stability`, run in process;
//! the two-input robot's decoupling analysis as printed (its numbers are
//! checked against SymPy in `derive/tests/analysis_mimo.rs`).

mod common;

use common::{model_file, plantc, s, tmp};

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

#[test]
fn analyze_two_inputs_text() {
    let m = model_file("twip_yaw.plant");
    let (code, out, err) = plantc(&["analyze", &m]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("outputs y = (psi, phi), inputs u = (vl, vr): vector relative degree (2, 2)"),
        "{out}"
    );
    // by hand (derive/tests/analysis_mimo.rs): det A vanishes where
    // M_tt + M_tp = 0, the body below the axle
    assert!(
        out.contains("singular set (det A = 0): 2*Jw + 2*R^2*m + L*M*R*cos(psi) + M*R^2 = 0"),
        "{out}"
    );
    assert!(out.contains("D1 = det M[theta, psi] = "), "{out}");
    assert!(
        out.contains("linearizing law (decoupling): u = A(x)^-1 (v - b(x))"),
        "{out}"
    );
    // pitch and yaw held: the wheels roll freely, theta'' = 0
    assert!(out.contains("eta2' = 0"), "{out}");
    assert!(out.contains("eigenvalues at eta = 0: 0, 0"), "{out}");
    assert!(out.contains("not asymptotically stable"), "{out}");
    let (code, same, _) = plantc(&["analyze", &m, "--output", "psi,phi"]);
    assert_eq!(code, 0);
    assert_eq!(same, out);
    insta::with_settings!({description => "plantc analyze models/twip_yaw.plant (numbers checked against SymPy in derive/tests/analysis_mimo.rs)", omit_expression => true}, {
        insta::assert_snapshot!("twip_yaw_analyze", out);
    });
}

#[test]
fn analyze_two_inputs_json() {
    let m = model_file("twip_yaw.plant");
    let (code, out, err) = plantc(&["analyze", &m, "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("json");
    assert_eq!(v["outputs"], serde_json::json!(["psi", "phi"]));
    assert_eq!(v["inputs"], serde_json::json!(["vl", "vr"]));
    assert_eq!(v["vector_relative_degree"], serde_json::json!([2, 2]));
    for o in ["psi", "phi"] {
        for key in ["h", "L_f h", "L_f^2 h", "L_g h", "L_g L_f h"] {
            assert!(v["lie_derivatives"][o][key].is_string(), "{o}: {key}");
        }
        assert_eq!(v["lie_derivatives"][o]["L_g h"], "[0, 0]");
    }
    let a = v["decoupling_matrix"].as_array().unwrap();
    assert_eq!(a.len(), 2);
    assert!(a.iter().all(|r| r.as_array().unwrap().len() == 2));
    // both motors push the pitch alike and the yaw oppositely
    let a0 = &v["decoupling_matrix_at_operating_point"];
    let x = |i: usize, j: usize| a0[i][j].as_f64().unwrap();
    assert!(x(0, 0) < 0.0 && (x(0, 0) - x(0, 1)).abs() <= 1e-12 * x(0, 0).abs());
    assert!(x(1, 1) > 0.0 && (x(1, 0) + x(1, 1)).abs() <= 1e-12 * x(1, 1).abs());
    assert!(v["det_decoupling_matrix"].is_string());
    assert_eq!(v["b"].as_array().unwrap().len(), 2);
    assert!(v["control_law"]
        .as_str()
        .unwrap()
        .starts_with("u = A(x)^-1 (v - b(x))"));
    assert_eq!(
        v["normal_form"]["xi"],
        serde_json::json!(["psi", "psi'", "phi", "phi'"])
    );
    assert_eq!(v["normal_form"]["eta"][0], "theta");
    let zd = &v["zero_dynamics"];
    assert_eq!(zd["eigenvalues"].as_array().unwrap().len(), 2);
    assert_eq!(zd["minimum_phase"], false);
}

#[test]
fn analyze_two_inputs_bad_outputs() {
    let m = model_file("twip_yaw.plant");
    for (args, want) in [
        (vec!["--output", "psi"], "needs as many outputs as inputs"),
        (vec!["--output", "psi,nope"], "unknown output `nope`"),
        (vec!["--output", "psi,psi"], "twice"),
        (vec!["--output", "psi,"], "empty"),
    ] {
        let mut all = vec!["analyze", m.as_str()];
        all.extend(args.iter().copied());
        let (code, _, err) = plantc(&all);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
    // a single-input model asked for two outputs
    let (code, _, err) = plantc(&[
        "analyze",
        &model_file("rotary_pendulum.plant"),
        "--output",
        "alpha,alpha",
    ]);
    assert_eq!(code, 2, "{err}");
    // two inputs, one declared output: say what to pass
    let text = std::fs::read_to_string(&m)
        .unwrap()
        .replace("output phi\n", "");
    let dir = tmp("one_output");
    let file = dir.join("twip_one_output.plant");
    std::fs::write(&file, text).unwrap();
    let (code, _, err) = plantc(&["analyze", &s(&file)]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("pass --output NAME,NAME"), "{err}");
}
