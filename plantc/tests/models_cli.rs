//! The models added for the symbolic pipeline at scale (issue 16) through
//! every command that applies: check, derive, linearize, lqr, analyze, gen
//! and sim (with the model's `lqr_unit` controller from a tilted start).
//! Data-driven: one row per model, with its outputs to analyse and the state
//! to tilt. `twip_yaw` has two inputs: analyze reports the decoupling of its
//! two declared outputs (pitch and yaw: vector relative degree, decoupling
//! matrix and law, zero dynamics).

mod common;

use common::{model_file, plantc, s, tmp};

struct Case {
    file: &'static str,
    /// Outputs for `analyze` (`a,b`: one decoupling analysis of both).
    outputs: &'static [&'static str],
    /// `--x0` of the simulation and the state that must come back near 0.
    tilt: (&'static str, &'static str),
}

const CASES: &[Case] = &[
    Case {
        file: "chain4.plant",
        outputs: &["q1", "tip"],
        tilt: ("q2=2deg", "q2"),
    },
    Case {
        file: "double_pendulum_cart.plant",
        outputs: &["th1", "tip"],
        tilt: ("th2=3deg", "th2"),
    },
    Case {
        file: "twip_planar.plant",
        outputs: &["psi"],
        tilt: ("psi=5deg", "psi"),
    },
    Case {
        file: "twip_yaw.plant",
        outputs: &["psi,phi"],
        tilt: ("psi=5deg", "psi"),
    },
];

fn ok(args: &[&str]) -> String {
    let (code, out, err) = plantc(args);
    assert_eq!(code, 0, "plantc {}: {err}", args.join(" "));
    out
}

#[test]
fn new_models_through_every_command() {
    for case in CASES {
        let m = model_file(case.file);
        ok(&["check", &m]);
        let derive = ok(&["derive", &m]);
        // M entry by entry, or (chains of 4 links and more) in the angle frame
        assert!(
            derive.contains("M[0][0] =") || derive.contains("M_theta"),
            "{}: {derive}",
            case.file
        );

        let lin: serde_json::Value =
            serde_json::from_str(&ok(&["linearize", &m, "--json"])).unwrap();
        assert_eq!(lin["controllable"], true, "{}", case.file);
        let nx = lin["state"].as_array().unwrap().len();
        let nu = lin["inputs"].as_array().unwrap().len();
        let ones = |k: usize| vec!["1"; k].join(",");
        let lqr: serde_json::Value = serde_json::from_str(&ok(&[
            "lqr",
            &m,
            "--q",
            &ones(nx),
            "--r",
            &ones(nu),
            "--json",
        ]))
        .unwrap();
        let res = lqr["care_residual"].as_f64().unwrap();
        assert!(res < 1e-8, "{}: CARE residual {res}", case.file);
        for p in lqr["closed_loop_poles"].as_array().unwrap() {
            assert!(p["re"].as_f64().unwrap() < 0.0, "{}: {p}", case.file);
        }

        for output in case.outputs {
            let out = ok(&["analyze", &m, "--output", output]);
            assert!(
                out.contains("relative degree"),
                "{} {output}: {out}",
                case.file
            );
            assert!(
                out.contains("linearizing law"),
                "{} {output}: {out}",
                case.file
            );
            assert!(
                out.contains("eigenvalues at eta = 0"),
                "{} {output}: {out}",
                case.file
            );
        }
        if nu > 1 {
            // the declared outputs by default, as many as the inputs
            let out = ok(&["analyze", &m]);
            assert!(out.contains("vector relative degree (2, 2)"), "{out}");
            assert!(out.contains("decoupling matrix A(x)"), "{out}");
        }

        let dir = tmp(case.file);
        ok(&["gen", &m, "-o", &s(&dir.join("crate"))]);
        let lib = std::fs::read_to_string(dir.join("crate/src/lib.rs")).unwrap();
        assert!(lib.contains("pub fn dynamics"), "{}", case.file);

        let csv = dir.join("sim.csv");
        ok(&[
            "sim",
            &m,
            "--controller",
            "lqr_unit",
            "--x0",
            case.tilt.0,
            "--duration",
            "10",
            "--output-rate",
            "10",
            "-o",
            &s(&csv),
        ]);
        let text = std::fs::read_to_string(&csv).unwrap();
        let mut lines = text.lines().filter(|l| !l.starts_with('#'));
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let col = header
            .iter()
            .position(|h| h.split('[').next() == Some(case.tilt.1))
            .unwrap_or_else(|| panic!("{}: no column {} in {header:?}", case.file, case.tilt.1));
        let rows: Vec<Vec<f64>> = lines
            .map(|l| {
                l.split(',')
                    .map(|v| v.parse().unwrap_or(f64::NAN))
                    .collect()
            })
            .collect();
        let first = rows.first().unwrap()[col].abs();
        let last = rows.last().unwrap()[col].abs();
        assert!(first > 0.01, "{}: start {first}", case.file);
        assert!(
            last < 1e-2 * first,
            "{}: {} from {first} to {last}",
            case.file,
            case.tilt.1
        );
    }
}
