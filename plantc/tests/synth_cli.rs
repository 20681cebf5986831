//! End-to-end tests of `plantc synth` (and its round trip through
//! `plantc compare`) via `plantc::run`.

use std::path::{Path, PathBuf};

mod common;

use common::{model, plantc, s, tmp};

/// Synthesises the model's own (nominal) values, no hidden effect, no noise.
/// `alpha0 = 135deg` is exactly 1536 counts of 4096 and `alpha0 = 180deg`
/// exactly 2048, so the recorded initial state equals the true one and the
/// only difference left between the data and a simulation of the same model
/// is the encoder rounding (plus the 2 ms vs 0.1 ms RK4 step, far smaller).
fn clean_round_trip_data(dir: &Path) {
    let (code, out, err) = plantc(&[
        "synth",
        &model(),
        "--experiment",
        "free_swing:alpha0=135deg,duration=3",
        "--experiment",
        "driven:alpha0=180deg,duration=3",
        "-o",
        &s(dir),
    ]);
    assert_eq!(code, 0, "{out}{err}");
}

#[test]
fn round_trip_compare_is_at_the_quantisation_floor() {
    let dir = tmp("roundtrip");
    clean_round_trip_data(&dir);
    let header = std::fs::read_to_string(dir.join("free_swing.csv")).unwrap();
    assert!(header.starts_with("t,theta,alpha,Vm\n0.0000,0.000000000,2.356194490,0.000000\n"));
    let (code, out, err) = plantc(&[
        "compare",
        &model(),
        &s(&dir.join("free_swing.csv")),
        &s(&dir.join("driven.csv")),
        "--json",
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    // Rounding to the nearest count q = 2 pi / 4096 leaves an error uniform on
    // [-q/2, q/2]: RMS q / sqrt(12) = 1.5340e-3 / 3.4641 = 4.428e-4 rad.
    let floor = 2.0 * std::f64::consts::PI / 4096.0 / 12f64.sqrt();
    let exps = v["experiments"].as_array().unwrap();
    assert_eq!(exps.len(), 2);
    for e in exps {
        // alpha sweeps many counts in both runs, so its error is uniform
        let a = e["channels"]["alpha"]["rmse"].as_f64().unwrap();
        assert!(
            (a / floor - 1.0).abs() < 0.1,
            "{}: alpha RMSE {a} vs floor {floor}",
            e["file"]
        );
        assert!(e["channels"]["theta"]["fit_percent"].is_number());
    }
    // theta barely moves in the free swing (its error is then the sub-count
    // motion, below the floor), so the pooled RMSE is at most the floor.
    let rmse = v["rmse"].as_f64().unwrap();
    assert!(rmse <= 1.05 * floor && rmse > 0.5 * floor, "rmse {rmse}");
}

#[test]
fn same_seed_same_bytes_and_no_overwrite() {
    let a = tmp("det_a");
    let b = tmp("det_b");
    let args = |dir: &Path| {
        vec![
            "synth".to_string(),
            model(),
            "--effect".into(),
            "stribeck_friction:alpha:Fc=6e-4,Fs=1e-3,vs=0.2".into(),
            "--set".into(),
            "l2=0.16".into(),
            "--experiment".into(),
            "driven:alpha0=180deg,band=0.5-4,rms=1,duration=1".into(),
            "--experiment".into(),
            "free_swing:alpha0=60deg,duration=1,name=swing".into(),
            "--noise".into(),
            "2e-4".into(),
            "--seed".into(),
            "7".into(),
            "--case".into(),
            "same".into(),
            "-o".into(),
            s(dir),
        ]
    };
    for dir in [&a, &b] {
        let v = args(dir);
        let r: Vec<&str> = v.iter().map(String::as_str).collect();
        let (code, out, err) = plantc(&r);
        assert_eq!(code, 0, "{out}{err}");
    }
    for f in ["driven.csv", "swing.csv", "truth.json"] {
        let x = std::fs::read(a.join(f)).unwrap();
        let y = std::fs::read(b.join(f)).unwrap();
        assert!(x == y, "{f} differs between two runs with the same seed");
    }
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(a.join("truth.json")).unwrap()).unwrap();
    assert_eq!(truth["case"], "same");
    assert_eq!(truth["effect"], "stribeck_friction");
    assert_eq!(truth["coordinate"], "alpha");
    assert_eq!(truth["effect_parameters"]["Fs"], 1e-3);
    assert_eq!(truth["true_parameters"]["l2"], 0.16);
    assert_eq!(truth["nominal_parameters"]["l2"], 0.156);
    assert_eq!(truth["experiments"], serde_json::json!(["driven", "swing"]));
    // The same shape as the shared data's truth.json, when it is there.
    let shared =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/clean/truth.json");
    match std::fs::read_to_string(&shared) {
        Ok(text) => {
            let v: serde_json::Value = serde_json::from_str(&text).unwrap();
            for key in v.as_object().unwrap().keys() {
                assert!(truth.get(key).is_some(), "truth.json lacks `{key}`");
            }
        }
        Err(_) => eprintln!("skipped the shape check: {} is absent", shared.display()),
    }
    // A different seed changes the noise.
    let c = tmp("det_c");
    let mut v = args(&c);
    let i = v.iter().position(|x| x == "7").unwrap();
    v[i] = "8".into();
    let r: Vec<&str> = v.iter().map(String::as_str).collect();
    assert_eq!(plantc(&r).0, 0);
    assert_ne!(
        std::fs::read(a.join("swing.csv")).unwrap(),
        std::fs::read(c.join("swing.csv")).unwrap()
    );
    // Existing files are kept unless --force.
    let before = std::fs::read(a.join("swing.csv")).unwrap();
    let v = args(&a);
    let r: Vec<&str> = v.iter().map(String::as_str).collect();
    let (code, _, err) = plantc(&r);
    assert_eq!(code, 2);
    assert!(
        err.contains("already exists") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read(a.join("swing.csv")).unwrap(), before);
    let mut v = args(&a);
    v.push("--force".into());
    let r: Vec<&str> = v.iter().map(String::as_str).collect();
    assert_eq!(plantc(&r).0, 0);
}

#[test]
fn hidden_effect_raises_the_error_of_the_nominal_model() {
    // Dry friction on the pendulum (8e-4 N m, the shared data's level) must
    // leave a clear trace: the nominal model's RMSE on a 3 s free swing from
    // 60 deg is well above the quantisation floor (4.4e-4 rad).
    let dir = tmp("hidden");
    let (code, out, err) = plantc(&[
        "synth",
        &model(),
        "--effect",
        "coulomb_friction:alpha=8e-4",
        "--experiment",
        "free_swing:alpha0=120deg,duration=3",
        "-o",
        &s(&dir),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let (code, out, err) = plantc(&[
        "compare",
        &model(),
        &s(&dir.join("free_swing.csv")),
        "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let rmse = v["rmse"].as_f64().unwrap();
    assert!(rmse > 5.0 * 4.43e-4, "rmse {rmse}");
}

#[test]
fn bad_specs_exit_2_naming_the_token() {
    let dir = tmp("bad");
    let o = s(&dir.join("out"));
    let cases: &[(&[&str], &[&str])] = &[
        (
            &["--effect", "dry_friction:alpha=1e-3"],
            &["dry_friction", "known effects", "coulomb_friction"],
        ),
        (
            &["--effect", "coulomb_friction:beta=1e-3"],
            &["beta", "valid targets", "theta, alpha"],
        ),
        (
            &["--effect", "stribeck_friction:alpha=1e-3"],
            &["stribeck_friction", "Fc, Fs, vs"],
        ),
        (
            &["--effect", "stribeck_friction:alpha:Fc=1e-3,Fx=2"],
            &["no parameter `Fx`", "Fc, Fs, vs"],
        ),
        (
            &["--effect", "stribeck_friction:alpha:Fc=1e-3"],
            &["missing value(s) for Fs, vs"],
        ),
        (
            &["--effect", "spring:theta=abc"],
            &["`abc` is not a number"],
        ),
        (&["--effect", "spring"], &["`spring`", "no target"]),
        (&["--set", "J9=1"], &["J9", "no parameter"]),
        (&["--set", "J1=x"], &["`--set J1=x`", "not a number"]),
    ];
    for (extra, needles) in cases {
        let mut args = vec![
            "synth",
            &model(),
            "--experiment",
            "free_swing:alpha0=10deg,duration=1",
            "-o",
            &o,
        ]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>();
        args.extend(extra.iter().map(|x| x.to_string()));
        let r: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, out, err) = plantc(&r);
        assert_eq!(code, 2, "{extra:?}: {out}{err}");
        for n in *needles {
            assert!(err.contains(n), "{extra:?}: `{n}` not in: {err}");
        }
        assert!(!err.contains("panicked"), "{err}");
    }
    let experiments: &[(&str, &[&str])] = &[
        ("wiggle:duration=1", &["wiggle", "free_swing, driven, step"]),
        (
            "free_swing:beta0=1",
            &["beta0", "no coordinate `beta`", "theta0, alpha0"],
        ),
        (
            "free_swing:speed=3",
            &["no setting `speed`", "duration, name"],
        ),
        ("free_swing:duration=-1", &["duration -1 must be positive"]),
        ("driven:band=6-1", &["band `6-1`"]),
        (
            "driven:rms=20,duration=2",
            &["outside its limits [-10, 10]"],
        ),
        ("free_swing:alpha0", &["`alpha0` is not KEY=VALUE"]),
        // issue 31 (r08): refused before anything is allocated
        (
            "free_swing:alpha0=120deg,duration=1e9",
            &["5.000e11 samples", "at most 1e7 per experiment"],
        ),
    ];
    for (e, needles) in experiments {
        let (code, out, err) = plantc(&["synth", &model(), "--experiment", e, "-o", &o]);
        assert_eq!(code, 2, "{e}: {out}{err}");
        for n in *needles {
            assert!(err.contains(n), "{e}: `{n}` not in: {err}");
        }
    }
    assert!(!dir.join("out").exists(), "nothing is written on bad input");
}

#[test]
fn reproduces_the_shared_clean_free_swings() {
    // ../shared/data/clean was made by an independent simulator (fine-step
    // RK4, ZOH, 500 Hz, 4096 counts/rev, dry friction as tanh(v / 1e-3))
    // from the true values in its truth.json; synth with those values, that
    // law and the same releases (60 and 12 deg from hanging) must record the
    // same counts. (With sticking friction the held arm parts from the
    // creeping one by 2 counts at 6.5 s.)
    let shared = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/clean");
    if !shared.join("free_swing_large.csv").is_file() {
        eprintln!("skipped: {} is absent", shared.display());
        return;
    }
    let dir = tmp("shared");
    let (code, out, err) = plantc(&[
        "synth",
        &model(),
        "--set",
        "J1=0.0016",
        "--set",
        "l2=0.162",
        "--set",
        "b1=0.003",
        "--set",
        "b2=0.0008",
        "--set",
        "Fg1=0.015",
        "--experiment",
        "free_swing:alpha0=120deg,duration=20,name=free_swing_large",
        "--experiment",
        "free_swing:alpha0=168deg,duration=20,name=free_swing_small",
        "--friction",
        "smooth:1e-3",
        "-o",
        &s(&dir),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let q = 2.0 * std::f64::consts::PI / 4096.0;
    for name in ["free_swing_large.csv", "free_swing_small.csv"] {
        let read = |p: PathBuf| -> Vec<Vec<f64>> {
            std::fs::read_to_string(p)
                .unwrap()
                .lines()
                .skip(1)
                .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
                .collect()
        };
        let ours = read(dir.join(name));
        let theirs = read(shared.join(name));
        assert_eq!(ours.len(), theirs.len(), "{name}: sample count");
        let mut differ = 0;
        for (a, b) in ours.iter().zip(&theirs) {
            assert_eq!(a[0], b[0], "{name}: time");
            for c in 1..=2 {
                let d = ((a[c] - b[c]) / q).abs();
                assert!(d < 1.0 + 1e-6, "{name}: {} counts apart at t = {}", d, a[0]);
                if d > 0.5 {
                    differ += 1;
                }
            }
        }
        // a count boundary crossed a hair earlier or later may flip a sample
        assert!(
            differ * 1000 <= ours.len(),
            "{name}: {differ} samples differ"
        );
    }
}

#[test]
fn every_effect_of_the_vocabulary_round_trips_through_its_true_model() {
    // For every effect effect_edit knows, on every target it accepts, synth
    // data and compare them with the true model (the text synth built: effect
    // added, values written). Only the encoder rounding should remain:
    // RMSE about q / sqrt(12) = 4.43e-4 rad (see the round-trip test above);
    // 1.1x allows for the initial state read from the rounded first sample
    // (a sensor offset moves it off the count grid).
    use plantc_identify::effect_edit::{EffectInstance, TEMPLATES};
    use plantc_identify::synth::{parse_experiment_spec, synthesize, SynthSpec};
    let text = std::fs::read_to_string(model()).unwrap();
    let nominal = plantc_derive::model::load_model_text("m", &text)
        .unwrap()
        .model;
    let targets: Vec<String> = nominal
        .coordinates
        .iter()
        .map(|c| c.name.clone())
        .chain(nominal.inputs.iter().map(|i| i.name.clone()))
        .collect();
    let floor = 2.0 * std::f64::consts::PI / 4096.0 / 12f64.sqrt();
    let dir = tmp("vocabulary");
    let mut cases = 0;
    for (effect, _, temps) in TEMPLATES {
        // a clear but moderate value: the template start, or a tenth of the
        // upper bound when the start is 0 (offsets)
        let values: Vec<(String, f64)> = temps
            .iter()
            .map(|t| {
                let v = if t.start != 0.0 { t.start } else { 0.1 * t.hi };
                (t.base.to_string(), v)
            })
            .collect();
        for target in &targets {
            if EffectInstance::with_values(&nominal, effect, target, &values).is_err() {
                continue;
            }
            let token = format!(
                "{effect}:{target}:{}",
                values
                    .iter()
                    .map(|(n, v)| format!("{n}={v}"))
                    .collect::<Vec<_>>()
                    .join(",")
            );
            let spec = SynthSpec {
                case: token.clone(),
                model_name: "rotary_pendulum.plant".into(),
                effects: vec![plantc_identify::synth::parse_effect_spec(&token).unwrap()],
                experiments: vec![
                    parse_experiment_spec("free_swing:alpha0=135deg,duration=2").unwrap(),
                    parse_experiment_spec("driven:alpha0=180deg,duration=2").unwrap(),
                ],
                ..SynthSpec::default()
            };
            let made = synthesize(&text, &spec).unwrap_or_else(|e| panic!("{token}: {e}"));
            let case = dir.join(format!("{effect}_{target}"));
            std::fs::create_dir_all(&case).unwrap();
            let true_model = case.join("true.plant");
            std::fs::write(&true_model, &made.true_model).unwrap();
            let mut args = vec!["compare".to_string(), s(&true_model), "--json".into()];
            for f in &made.files {
                std::fs::write(case.join(&f.file_name), &f.text).unwrap();
                args.push(s(&case.join(&f.file_name)));
            }
            let r: Vec<&str> = args.iter().map(String::as_str).collect();
            let (code, out, err) = plantc(&r);
            assert_eq!(code, 0, "{token}: {err}");
            let v: serde_json::Value = serde_json::from_str(&out).unwrap();
            let rmse = v["rmse"].as_f64().unwrap();
            assert!(rmse < 1.1 * floor, "{token}: RMSE {rmse} vs floor {floor}");
            cases += 1;
        }
    }
    // 5 force effects on 2 coordinates at least (more once sensor and
    // actuator effects are in the table)
    assert!(cases >= 10, "{cases} cases");
}

/// `--friction` chooses the true model's dry-friction law (sticking by
/// default) and truth.json records it; a bad law is an input error naming
/// the token.
#[test]
fn friction_law_is_chosen_and_recorded() {
    let dir = tmp("friction");
    for (law, want) in [(None, "sticking"), (Some("smooth:1e-3"), "smooth:1e-3")] {
        let out_dir = dir.join(want.replace(':', "_"));
        let mut args = vec![
            "synth".to_string(),
            model(),
            "--experiment".into(),
            "free_swing:alpha0=135deg,duration=1".into(),
            "-o".into(),
            s(&out_dir),
        ];
        if let Some(l) = law {
            args.extend(["--friction".to_string(), l.to_string()]);
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, out, err) = plantc(&args);
        assert_eq!(code, 0, "{out}{err}");
        let truth: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out_dir.join("truth.json")).unwrap())
                .unwrap();
        assert_eq!(truth["dry_friction"], want);
    }
    let (code, _, err) = plantc(&[
        "synth",
        &model(),
        "--experiment",
        "free_swing:alpha0=135deg,duration=1",
        "--friction",
        "smooth:-1",
        "-o",
        &s(&dir.join("bad")),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("smooth:-1") && err.contains("positive"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
