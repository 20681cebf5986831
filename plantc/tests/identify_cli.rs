//! End-to-end tests of `plantc compare`, `plantc fit` and `plantc diagnose`
//! on data made by `plantc synth` (short experiments: debug tests are slow).

use std::path::Path;

mod common;

use common::{model, plantc, s, tmp};

/// Synthesises `experiments` into `dir` with extra synth arguments.
fn synth(dir: &Path, extra: &[&str], experiments: &[&str]) -> Vec<String> {
    let m = model();
    let d = s(dir);
    let mut args = vec!["synth", m.as_str(), "-o", d.as_str()];
    args.extend_from_slice(extra);
    for e in experiments {
        args.push("--experiment");
        args.push(e);
    }
    let (code, out, err) = plantc(&args);
    assert_eq!(code, 0, "{out}{err}");
    let mut files: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| s(&e.unwrap().path()))
        .filter(|p| p.ends_with(".csv"))
        .collect();
    files.sort();
    files
}

#[test]
fn compare_json_shape_table_findings_and_plots() {
    let dir = tmp("compare");
    let files = synth(
        &dir,
        &["--set", "l2=0.165", "--set", "b2=1e-3"],
        &[
            "free_swing:alpha0=120deg,duration=2",
            "driven:alpha0=180deg,duration=2",
        ],
    );
    let m = model();
    let mut args = vec!["compare", m.as_str()];
    for f in &files {
        args.push(f);
    }
    let mut j = args.clone();
    j.push("--json");
    let (code, out, err) = plantc(&j);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let top: Vec<&String> = v.as_object().unwrap().keys().collect();
    assert_eq!(top, ["experiments", "rmse", "validation"]);
    let exps = v["experiments"].as_array().unwrap();
    assert_eq!(exps.len(), 2);
    // The pooled RMSE is over all samples of all channels and experiments:
    // every channel here has 1000 samples, so rmse^2 = mean of the rmse_ch^2.
    let mut sum = 0.0;
    for (e, f) in exps.iter().zip(&files) {
        assert_eq!(e["file"].as_str().unwrap(), f);
        let ch = e["channels"].as_object().unwrap();
        assert_eq!(ch.keys().collect::<Vec<_>>(), ["alpha", "theta"]);
        for c in ch.values() {
            let o = c.as_object().unwrap();
            assert_eq!(
                o.keys().collect::<Vec<_>>(),
                ["diverged", "fit_percent", "rmse"]
            );
            sum += c["rmse"].as_f64().unwrap().powi(2);
        }
    }
    let pooled = (sum / 4.0).sqrt();
    assert!((v["rmse"].as_f64().unwrap() / pooled - 1.0).abs() < 1e-12);

    let plots = dir.join("plots");
    let ps = s(&plots);
    let mut t = args.clone();
    t.extend(["--plots", ps.as_str()]);
    let (code, out, err) = plantc(&t);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("experiment") && out.contains("fit %"), "{out}");
    assert!(
        out.contains("RMSE over all experiments and channels"),
        "{out}"
    );
    assert!(out.contains("where it fails"), "{out}");
    for name in ["driven", "free_swing"] {
        let svg = std::fs::read_to_string(plots.join(format!("{name}.svg"))).unwrap();
        assert!(svg.starts_with("<svg"), "{name}.svg");
        // units on the axes, fit % in the legend, the input's own panel
        for label in [
            "t [s]",
            "alpha [rad]",
            "residual [rad]",
            "simulated, fit ",
            "Vm [V]",
        ] {
            assert!(svg.contains(label), "{name}.svg lacks `{label}`");
        }
    }
}

#[test]
fn fit_json_lossless_out_and_no_clobber() {
    let dir = tmp("fit");
    // True l2 = 0.165 and b2 = 1e-3 (nominal 0.156 and 2.4e-3); 3 s runs.
    let files = synth(
        &dir,
        &["--set", "l2=0.165", "--set", "b2=1e-3"],
        &[
            "free_swing:alpha0=120deg,duration=3",
            "driven:alpha0=180deg,duration=3",
        ],
    );
    let out_model = dir.join("fitted.plant");
    let m = model();
    let o = s(&out_model);
    let mut args = vec![
        "fit",
        m.as_str(),
        "--free",
        "l2,b2",
        "-o",
        o.as_str(),
        "--json",
    ];
    for f in &files {
        args.push(f);
    }
    let (code, out, err) = plantc(&args);
    assert_eq!(code, 0, "{out}{err}");
    // the fitted model is written in the canonical layout (`plantc fmt`)
    let written = std::fs::read_to_string(&out_model).unwrap();
    assert_eq!(
        plantc_derive::lang::format::format(&written).unwrap(),
        written
    );
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    for key in ["parameters", "before", "after"] {
        assert!(v.get(key).is_some(), "{key} in {out}");
    }
    let l2 = v["parameters"]["l2"]["value"].as_f64().unwrap();
    let b2 = v["parameters"]["b2"]["value"].as_f64().unwrap();
    assert!(v["parameters"]["l2"]["std_error"].as_f64().unwrap() > 0.0);
    // Noise-free data from the same model structure: the fit recovers the
    // true values (synth's --set above) to well within 1 %.
    assert!((l2 / 0.165 - 1.0).abs() < 0.01, "l2 = {l2}");
    assert!((b2 / 1e-3 - 1.0).abs() < 0.01, "b2 = {b2}");
    let before = v["before"]["rmse"].as_f64().unwrap();
    let after = v["after"]["rmse"].as_f64().unwrap();
    assert!(after < before / 5.0, "before {before}, after {after}");
    assert!(err.contains("fitting 2 parameter(s)"), "{err}");

    // OUT differs from the model only on the two parameter lines, but for
    // the blanks of the realigned parameter table (canonical layout).
    let original = std::fs::read_to_string(model()).unwrap();
    let fitted = std::fs::read_to_string(&out_model).unwrap();
    fn words(l: &str) -> Vec<&str> {
        l.split_whitespace().collect()
    }
    let diff: Vec<(&str, &str)> = original
        .lines()
        .zip(fitted.lines())
        .filter(|(a, b)| words(a) != words(b))
        .collect();
    assert_eq!(original.lines().count(), fitted.lines().count());
    assert_eq!(diff.len(), 2, "{diff:?}");
    assert!(
        diff[0].1.starts_with(&format!("parameter l2 = {l2} [m] ")),
        "{diff:?}"
    );
    assert!(diff[1].1.starts_with("parameter b2 = "), "{diff:?}");

    // Never overwrite OUT or the input model without --force.
    let (code, _, err) = plantc(&args);
    assert_eq!(code, 2);
    assert!(err.contains("already exists"), "{err}");
    let mut into_model = args.clone();
    into_model[5] = m.as_str();
    let (code, _, err) = plantc(&into_model);
    assert_eq!(code, 2);
    assert!(err.contains("is the input model"), "{err}");
    assert_eq!(std::fs::read_to_string(model()).unwrap(), original);

    // Text mode and bad --free.
    let mut t = vec!["fit", m.as_str(), "--free", "l2"];
    t.extend(files.iter().map(String::as_str));
    let (code, out, err) = plantc(&t);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("parameter") && out.contains("RMSE before"),
        "{out}"
    );
    let mut t = vec!["fit", m.as_str(), "--free", "l9"];
    t.extend(files.iter().map(String::as_str));
    let (code, _, err) = plantc(&t);
    assert_eq!(code, 2);
    assert!(err.contains("no parameter `l9`"), "{err}");
}

#[test]
fn diagnose_names_a_hidden_spring_and_applies_it() {
    // A torsion spring on the arm (0.03 N m/rad, the shared spring_arm level)
    // hidden in 2 s runs; every candidate is refitted, so keep it short.
    let dir = tmp("diagnose");
    let files = synth(
        &dir,
        &["--effect", "spring:theta=0.03"],
        &[
            "free_swing:alpha0=120deg,duration=2",
            "driven:alpha0=180deg,duration=2",
        ],
    );
    let m = model();
    let o = s(&dir.join("with_effect.plant"));
    let mut args = vec![
        "diagnose",
        m.as_str(),
        "--json",
        "--apply",
        "-o",
        o.as_str(),
    ];
    args.extend(files.iter().map(String::as_str));
    let (code, out, err) = plantc(&args);
    assert_eq!(code, 0, "{out}{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["verdict"], "missing_effect", "{out}");
    let top = &v["findings"][0];
    assert_eq!(top["effect"], "spring");
    assert_eq!(top["target"], "theta");
    let k = top["parameters"]["k"]["value"].as_f64().unwrap();
    assert_eq!(top["parameters"]["k"]["name"], "k_theta");
    assert!((k / 0.03 - 1.0).abs() < 0.05, "k = {k}");
    assert!(top["evidence"].is_object());
    let snippet = top["snippet"].as_str().unwrap();
    assert!(snippet.contains("spring(k_theta)"), "{snippet}");
    // The written model is the original plus the effect, parameter to estimate.
    let text = std::fs::read_to_string(&o).unwrap();
    assert!(
        text.contains("spring(k_theta)") && text.contains("estimate [0, 1]"),
        "{text}"
    );
    let original = std::fs::read_to_string(model()).unwrap();
    assert!(text.len() > original.len());
    // in the canonical layout (`plantc fmt`)
    assert_eq!(plantc_derive::lang::format::format(&text).unwrap(), text);
    // Refuses to overwrite it.
    let (code, _, err) = plantc(&args);
    assert_eq!(code, 2);
    assert!(err.contains("already exists"), "{err}");
}

/// Validation as MATLAB's compare/resid: k-step-ahead prediction, residual
/// whiteness and input cross-correlation with 99 % bands (2.576 / sqrt(N),
/// the normal quantile), in JSON and in figures.
#[test]
fn compare_prediction_and_residual_tests_in_json_and_figures() {
    let dir = tmp("compare_validation");
    let files = synth(
        &dir,
        &["--set", "l2=0.165"],
        &["driven:alpha0=180deg,duration=3"],
    );
    let m = model();
    let plots = dir.join("plots");
    let ps = s(&plots);
    let args = vec![
        "compare",
        m.as_str(),
        files[0].as_str(),
        "--horizon",
        "0.5",
        "--plots",
        ps.as_str(),
        "--json",
    ];
    let (code, out, err) = plantc(&args);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let e = &v["validation"]["experiments"][0];
    let pred = e["prediction"].as_array().expect("prediction per channel");
    assert_eq!(pred.len(), 2);
    for c in pred {
        let f = c["fit_percent"].as_f64().expect("fit %");
        // 0.5 s ahead from the measured state cannot be worse than the
        // whole-record simulation of a model with l2 off by 3 %
        assert!(f > 50.0, "prediction fit {f}");
    }
    let tests = e["residual_tests"].as_array().expect("residual tests");
    assert_eq!(tests.len(), 2);
    for t in tests {
        let n = t["samples"].as_f64().unwrap();
        let band = t["band"].as_f64().unwrap();
        assert!(
            (band - 2.576 / n.sqrt()).abs() < 1e-3,
            "band {band} for {n}"
        );
        assert!(t["autocorrelation"].as_array().unwrap().len() > 1);
        assert!(!t["cross"].as_array().unwrap().is_empty());
    }
    let name = std::path::Path::new(&files[0])
        .file_stem()
        .unwrap()
        .to_str()
        .unwrap()
        .to_string();
    for f in [
        format!("{name}.svg"),
        format!("{name}-predicted.svg"),
        format!("{name}-residual-tests.svg"),
    ] {
        let svg = std::fs::read_to_string(plots.join(&f)).unwrap_or_default();
        assert!(svg.starts_with("<svg"), "{f} missing");
    }
}
