//! End-to-end tests of `plantc sim` through `plantc::run`.

mod common;

use common::{model, plantc, tmp};

#[test]
fn feedback_linearization_csv_plot_and_summary() {
    let dir = tmp("fl");
    let csv = dir.join("out.csv");
    let svg = dir.join("out.svg");
    let (code, out, err) = plantc(&[
        "sim",
        &model(),
        "--set",
        "thesis",
        "--controller",
        "feedback_linearization",
        "--x0",
        "alpha=10deg",
        "--duration",
        "5",
        "-o",
        csv.to_str().unwrap(),
        "--plot",
        svg.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("final state: theta = "), "{out}");
    assert!(out.contains("max |Vm| = "), "{out}");
    assert!(out.contains("saturated 0.0 %"), "{out}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "t,theta,alpha,theta_dot,alpha_dot,Vm,y_alpha"
    );
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 5001);
    let r = &rows[726];
    assert!((r[0] - 0.726).abs() < 1e-12);
    assert!(
        r[2].abs().to_degrees() <= 0.5,
        "alpha(0.726) = {} deg",
        r[2].to_degrees()
    );
    let last = rows.last().unwrap();
    assert!((last[3] + 3.1).abs() < 0.15, "steady rate {}", last[3]);
    assert_eq!(last[6], last[2]);
    let svg_text = std::fs::read_to_string(&svg).unwrap();
    assert!(svg_text.starts_with("<svg") && svg_text.contains("alpha [deg]"));

    // Refuses to overwrite, then overwrites with --force.
    let (code, _, err) = plantc(&[
        "sim",
        &model(),
        "--set",
        "thesis",
        "--controller",
        "feedback_linearization",
        "--x0",
        "alpha=10deg",
        "--duration",
        "0.1",
        "-o",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(code, 2);
    assert!(
        err.contains("already exists") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), text);
    let (code, out, err) = plantc(&[
        "sim",
        &model(),
        "--set",
        "thesis",
        "--controller",
        "feedback_linearization",
        "--x0",
        "alpha=10deg",
        "--duration",
        "0.1",
        "-o",
        csv.to_str().unwrap(),
        "--force",
        "--sample-rate",
        "1000",
        "--output-rate",
        "100",
    ]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("zero-order hold"), "{out}");
    assert_eq!(std::fs::read_to_string(&csv).unwrap().lines().count(), 12);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_x0_name_lists_known_states() {
    let dir = tmp("x0");
    let csv = dir.join("out.csv");
    let (code, _, err) = plantc(&[
        "sim",
        &model(),
        "--controller",
        "feedback_linearization",
        "--x0",
        "beta=10deg",
        "-o",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("`beta`") && err.contains("theta, alpha, theta_dot, alpha_dot"),
        "{err}"
    );
    assert!(!csv.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn gains_override_and_errors() {
    let dir = tmp("gain");
    let csv = dir.join("out.csv");
    let (code, _, err) = plantc(&[
        "sim",
        &model(),
        "--set",
        "thesis",
        "--controller",
        "fl_arm",
        "--gain",
        "c=1",
        "--x0",
        "alpha=10deg",
        "-o",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("no gain `c`") && err.contains("known: wn, zeta, a, b"),
        "{err}"
    );
    let (code, out, err) = plantc(&[
        "sim",
        &model(),
        "--set",
        "thesis",
        "--controller",
        "fl_arm",
        "--gain",
        "a=0.5,b=0.5",
        "--x0",
        "alpha=10deg",
        "--duration",
        "2",
        "-o",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let (code, _, err) = plantc(&[
        "sim",
        &model(),
        "--controller",
        "nope",
        "-o",
        dir.join("x.csv").to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("unknown controller `nope`"), "{err}");
    // Nominal model (gear friction Fg1 = 0.01 N m) with regularised friction.
    let (code, out, err) = plantc(&[
        "sim",
        &model(),
        "--controller",
        "pole_placement",
        "--smooth-sign",
        "1e-3",
        "--x0",
        "alpha=5deg",
        "--duration",
        "2",
        "-o",
        dir.join("friction.csv").to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Dry friction sticks by default: the DFKI double pendulum under its LQR
/// law from an offset stops its shoulder within the joint's friction and
/// holds it there exactly (speed 0 and the same angle to the bit over the
/// last second); `--smooth-sign` keeps the smooth law, whose joints never
/// come to rest exactly.
#[test]
fn dry_friction_sticks_unless_smoothed() {
    let dir = tmp("stick");
    let model = common::repo().join("models/double_pendulum.plant");
    let run = |extra: &[&str], name: &str| -> Vec<Vec<f64>> {
        let csv = dir.join(name);
        let mut args = vec![
            "sim",
            model.to_str().unwrap(),
            "--controller",
            "lqr_hanging",
            "--x0",
            "q1=0.3,q2=-0.2",
            "--duration",
            "5",
            "-o",
            csv.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let (code, out, err) = plantc(&args);
        assert_eq!(code, 0, "{out}{err}");
        let text = std::fs::read_to_string(&csv).unwrap();
        text.lines()
            .skip(1)
            .map(|l| l.split(',').map(|c| c.parse().unwrap()).collect())
            .collect()
    };
    let rows = run(&[], "stick.csv");
    let last = &rows[rows.len() - 1000..];
    assert!(
        last.iter().all(|r| r[3] == 0.0 && r[1] == last[0][1]),
        "the shoulder should be held"
    );
    let rows = run(&["--smooth-sign", "1e-3"], "smooth.csv");
    assert!(rows[rows.len() - 1000..].iter().all(|r| r[3] != 0.0));
    let _ = std::fs::remove_dir_all(&dir);
}
