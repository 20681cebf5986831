//! Bad measurement files through the command line (`plantc compare`, `fit`,
//! `diagnose` share the reader): exit code 2, a message naming
//! file:line:column, no panic; a degrees-looking column is only a warning.

use std::path::Path;

mod common;

use common::{model, plantc, tmp};

/// A valid file body: 20 samples at 500 Hz, pendulum hanging, no input.
fn rows(n: usize) -> Vec<String> {
    (0..n)
        .map(|k| format!("{:.4},0.000000000,3.141592654,0.000000", k as f64 * 0.002))
        .collect()
}

fn write(dir: &Path, name: &str, header: &str, rows: &[String]) -> String {
    let p = dir.join(name);
    let mut text = format!("{header}\n");
    for r in rows {
        text.push_str(r);
        text.push('\n');
    }
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

/// Runs every identification command on `file`; each must exit 2 with
/// `needle` (a `file:line:col` location or a message) in its error.
fn assert_rejected(file: &str, needles: &[&str]) {
    // one output directory per file: the tests run in parallel
    let stem = Path::new(file).file_stem().unwrap().to_string_lossy();
    let dir = tmp(&format!("out-{stem}"));
    let out_model = dir.join("fitted.plant").display().to_string();
    for cmd in [
        vec!["compare", &model(), file],
        vec!["fit", &model(), file, "-o", &out_model],
        vec!["diagnose", &model(), file],
    ] {
        let (code, out, err) = plantc(&cmd);
        assert_eq!(code, 2, "{cmd:?}: {out}{err}");
        for n in needles {
            assert!(err.contains(n), "{cmd:?}: `{n}` not in: {err}");
        }
        assert!(!err.contains("panicked"), "{err}");
        assert!(out.is_empty(), "nothing on stdout: {out}");
    }
    assert!(!Path::new(&out_model).exists(), "no model written");
}

#[test]
fn nan_cell() {
    let dir = tmp("nan");
    let mut r = rows(20);
    r[3] = "0.0060,0.000000000,NaN,0.000000".into();
    let f = write(&dir, "nan.csv", "t,theta,alpha,Vm", &r);
    // header = line 1, so data row 4 is line 5; alpha is column 3
    assert_rejected(
        &f,
        &[
            &format!("{f}:5:3:"),
            "non-finite value `NaN` in column `alpha`",
        ],
    );
}

#[test]
fn empty_cell() {
    let dir = tmp("empty");
    let mut r = rows(20);
    r[9] = "0.0180,,3.141592654,0.000000".into();
    let f = write(&dir, "empty.csv", "t,theta,alpha,Vm", &r);
    assert_rejected(&f, &[&format!("{f}:11:2:"), "empty cell in column `theta`"]);
}

#[test]
fn missing_column() {
    let dir = tmp("missing");
    let r: Vec<String> = rows(20)
        .iter()
        .map(|l| l.rsplit_once(',').unwrap().0.to_string())
        .collect();
    let f = write(&dir, "missing.csv", "t,theta,alpha", &r);
    assert_rejected(
        &f,
        &[
            &format!("{f}:1: missing column `Vm`"),
            "expected: t, theta, alpha, Vm",
        ],
    );
}

#[test]
fn time_going_backwards_and_duplicate_time() {
    let dir = tmp("time");
    let mut r = rows(20);
    r[6] = "0.0100,0.000000000,3.141592654,0.000000".into(); // after 0.0100 at row 5
    let f = write(&dir, "dup.csv", "t,theta,alpha,Vm", &r);
    assert_rejected(&f, &[&format!("{f}:8:1:"), "duplicate time 0.01 s"]);
    let mut r = rows(20);
    r[12] = "0.0100,0.000000000,3.141592654,0.000000".into();
    let f = write(&dir, "back.csv", "t,theta,alpha,Vm", &r);
    assert_rejected(
        &f,
        &[
            &format!("{f}:14:1:"),
            "time goes backwards: 0.01 s after 0.022 s",
        ],
    );
}

#[test]
fn file_too_short() {
    let dir = tmp("short");
    let f = write(&dir, "short.csv", "t,theta,alpha,Vm", &rows(4));
    // the reader's minimum is identify::data::MIN_SAMPLES = 10
    // the error points at the last sample line (header + 4 samples)
    assert_rejected(
        &f,
        &[&format!(
            "{f}:5: file too short: 4 samples, at least 10 needed"
        )],
    );
}

#[test]
fn degrees_without_suffix_is_a_warning() {
    let dir = tmp("deg");
    // a hanging pendulum logged in degrees: 180, read as radians (> 40 pi)
    let r: Vec<String> = (0..20)
        .map(|k| format!("{:.4},0.0,180.0,0.0", k as f64 * 0.002))
        .collect();
    let f = write(&dir, "deg.csv", "t,theta,alpha,Vm", &r);
    let (code, out, err) = plantc(&["compare", &model(), &f]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(
        err.contains(&format!("{f}: warning: angle column `alpha`"))
            && err.contains("write `alpha[deg]`"),
        "{err}"
    );
    // with the suffix the same file is read in degrees, silently
    let f2 = write(&dir, "deg2.csv", "t,theta,alpha[deg],Vm", &r);
    let (code, out, err) = plantc(&["compare", &model(), &f2, "--json"]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(!err.contains("warning"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(v["rmse"].as_f64().unwrap() < 1e-6, "hanging at rest: {out}");
}

#[test]
fn missing_file_and_unknown_unit() {
    let dir = tmp("misc");
    let f = dir.join("nope.csv").display().to_string();
    assert_rejected(&f, &[&f, "cannot read file"]);
    let f = write(&dir, "unit.csv", "t,theta,alpha[grad],Vm", &rows(20));
    assert_rejected(&f, &[&format!("{f}:1:3:"), "unknown unit suffix `[grad]`"]);
}

/// An unknown `--inputs` reading is refused before anything is fitted, by
/// every command that reads records.
#[test]
fn unknown_inputs_reading() {
    let dir = tmp("inputs-reading");
    let file = write(&dir, "run.csv", "t,theta,alpha,Vm", &rows(20));
    let out_dir = dir.join("identify-out").display().to_string();
    for cmd in [
        vec!["compare", &model(), &file, "--inputs", "zoh"],
        vec!["fit", &model(), &file, "--inputs", "zoh"],
        vec!["diagnose", &model(), &file, "--inputs", "zoh"],
        vec![
            "identify",
            &model(),
            &file,
            "--inputs",
            "zoh",
            "-o",
            &out_dir,
        ],
    ] {
        let (code, out, err) = plantc(&cmd);
        assert_eq!(code, 2, "{cmd:?}: {out}{err}");
        assert!(
            err.contains("--inputs: expected `held`, `continuous` or `auto`, got `zoh`"),
            "{cmd:?}: {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
    }
    assert!(!Path::new(&out_dir).exists(), "nothing written");
}
