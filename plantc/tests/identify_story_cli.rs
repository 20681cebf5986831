//! `plantc identify`: the whole story (compare -> diagnose -> apply -> fit ->
//! compare) on short synthetic data with a hidden pendulum-joint dry friction
//! made by `plantc synth`; the truth is the synth command's own value.

mod common;

use common::{model_path, plantc_bin, repo, tmp};

#[test]
fn identify_finds_the_hidden_friction_and_the_error_falls() {
    let dir = tmp("coulomb");
    let data = dir.join("data");
    let model = model_path();
    let m = model.to_str().unwrap();
    let d = data.to_str().unwrap();
    // True rig: J1 and b2 off nominal, dry friction 1e-3 N m in the pendulum joint.
    let (code, _, err) = plantc_bin(&[
        "synth",
        m,
        "--effect",
        "coulomb_friction:alpha=1e-3",
        "--set",
        "J1=1.3e-3",
        "--set",
        "b2=1e-3",
        "--experiment",
        "free_swing:alpha0=130deg,duration=4,name=swing",
        "--experiment",
        "driven:alpha0=180deg,duration=4,seed=2,name=driven",
        "-o",
        d,
    ]);
    assert_eq!(code, 0, "{err}");
    let original = std::fs::read_to_string(&model).unwrap();
    let out = dir.join("out");
    let o = out.to_str().unwrap();
    let swing = data.join("swing.csv");
    let driven = data.join("driven.csv");
    let args = [
        "identify",
        m,
        swing.to_str().unwrap(),
        driven.to_str().unwrap(),
        "-o",
        o,
        "--json",
    ];
    let (code, stdout, err) = plantc_bin(&args);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("JSON");
    assert_eq!(v["verdict"], "missing_effect", "{stdout}");
    assert_eq!(v["effect"]["effect"], "coulomb_friction", "{stdout}");
    assert_eq!(v["effect"]["target"], "alpha", "{stdout}");
    let fc = v["fit"]["parameters"]["Fc_alpha"]["value"]
        .as_f64()
        .unwrap();
    assert!(
        (fc / 1e-3 - 1.0).abs() < 0.1,
        "Fc_alpha = {fc} (truth 1e-3)"
    );
    let stages = v["stages"].as_array().unwrap();
    assert_eq!(stages.len(), 3);
    let rmse = |i: usize| stages[i]["report"]["rmse"].as_f64().unwrap();
    // the bar: the error falls at least 5x from the refitted nominal
    assert!(rmse(1) / rmse(2) >= 5.0, "{} -> {}", rmse(1), rmse(2));
    for f in [
        "fitted.plant",
        "with_effect.plant",
        "report.json",
        "1-nominal/swing.svg",
        "3-fitted/driven.svg",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let fitted = std::fs::read_to_string(out.join("fitted.plant")).unwrap();
    assert!(fitted.contains("coulomb_friction(Fc_alpha)"));
    // the input model is untouched
    assert_eq!(std::fs::read_to_string(&model).unwrap(), original);
    // its own output directory may be replaced; a foreign one may not.
    // The re-run replaces the directory as a whole: a stale figure of an
    // earlier run (other data) does not survive (reliability reproducer 07)
    std::fs::write(out.join("3-fitted/old_data.svg"), "<svg/>").unwrap();
    let (code, _, err) = plantc_bin(&args);
    assert_eq!(code, 0, "{err}");
    assert!(!out.join("3-fitted/old_data.svg").exists());
    assert!(out.join("3-fitted/driven.svg").is_file());
    // refining the fitted model into the same directory would replace the
    // input model: refused without --force, nothing touched (reproducer 01)
    let fitted_in_out = out.join("fitted.plant");
    std::fs::write(&fitted_in_out, format!("{fitted}# my notes\n")).unwrap();
    let report_before = std::fs::read(out.join("report.json")).unwrap();
    let (code, _, err) = plantc_bin(&[
        "identify",
        fitted_in_out.to_str().unwrap(),
        swing.to_str().unwrap(),
        "-o",
        o,
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("lies inside the output directory"), "{err}");
    assert!(std::fs::read_to_string(&fitted_in_out)
        .unwrap()
        .ends_with("# my notes\n"));
    assert_eq!(
        std::fs::read(out.join("report.json")).unwrap(),
        report_before
    );
    let foreign = dir.join("foreign");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
    let (code, _, err) = plantc_bin(&[
        "identify",
        m,
        swing.to_str().unwrap(),
        "-o",
        foreign.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not written by `plantc identify`"), "{err}");
    assert_eq!(
        std::fs::read_to_string(foreign.join("notes.txt")).unwrap(),
        "mine"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The README's main job: the bundled `data/demo_two_effects` (3 x 10,000
/// samples) hides a pendulum-joint dry friction and a 4 ms input delay
/// (the synth command in its README is the truth: Fc 6e-4 N m, Td 4 ms).
/// `identify` names them in turn, the friction first (the free swings show
/// it; only the driven run shows the delay), and the error ends near the
/// encoder's quantisation floor, 2 pi / 4096 / sqrt(12) = 4.43e-4 rad.
#[test]
fn identify_names_the_two_bundled_effects_in_turn() {
    let data = repo().join("data/demo_two_effects");
    let model = model_path();
    let dir = tmp("two_effects");
    let out = dir.join("out");
    let files: Vec<String> = ["free_swing_large", "free_swing_small", "driven"]
        .iter()
        .map(|n| data.join(format!("{n}.csv")).display().to_string())
        .collect();
    let mut args = vec!["identify", model.to_str().unwrap()];
    args.extend(files.iter().map(String::as_str));
    args.extend(["-o", out.to_str().unwrap(), "--json"]);
    let (code, stdout, err) = plantc_bin(&args);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("JSON");
    let rounds = v["rounds"].as_array().expect("rounds");
    let named: Vec<(String, String)> = rounds
        .iter()
        .map(|r| {
            (
                r["effect"].as_str().unwrap_or("-").to_string(),
                r["target"].as_str().unwrap_or("-").to_string(),
            )
        })
        .collect();
    eprintln!("rounds: {named:?}; stop: {}; {} s", v["stop"], v["seconds"]);
    assert_eq!(
        named,
        [
            ("coulomb_friction".to_string(), "alpha".to_string()),
            ("input_delay".to_string(), "Vm".to_string())
        ],
        "{stdout}"
    );
    let p = |name: &str| v["fit"]["parameters"][name]["value"].as_f64().unwrap();
    let (fc, td) = (p("Fc_alpha"), p("Td_Vm"));
    eprintln!("Fc_alpha {fc:.4e} (6e-4), Td_Vm {td:.4e} (4e-3)");
    assert!((fc / 6e-4 - 1.0).abs() < 0.05, "Fc_alpha = {fc}");
    assert!((td / 4e-3 - 1.0).abs() < 0.1, "Td_Vm = {td}");
    let stages = v["stages"].as_array().unwrap();
    let last = stages.last().unwrap()["report"]["rmse"].as_f64().unwrap();
    let floor = 2.0 * std::f64::consts::PI / 4096.0 / 12f64.sqrt();
    eprintln!("RMSE at the end {last:.3e}, floor {floor:.3e}");
    assert!(last < 1.5 * floor, "RMSE {last}");
    let fitted = std::fs::read_to_string(out.join("fitted.plant")).unwrap();
    assert!(fitted.contains("coulomb_friction(Fc_alpha)") && fitted.contains("input_delay(Td_Vm)"));
    let _ = std::fs::remove_dir_all(&dir);
}
