//! The separable recursion of a 10-link chain (`plantc gen` writes it from
//! `RECURSIVE_MIN_COORDINATES` = 10 coordinates on): the generated crate is
//! built and run, and its `dynamics`, `jacobian_x`, `jacobian_u` and
//! `rk4_step` are compared with numbers computed here independently of
//! code generation: the derived equations' `M q'' = Q0 - bias + B u` solved
//! by LU (`NumericDynamics`), central finite differences of it, and a
//! classical RK4 step over it. Skipped only if cargo is unavailable (about
//! 10 s: one small debug build).

use std::path::{Path, PathBuf};
use std::process::Command;

use plantc_derive::control::Derivation;
use plantc_derive::mechanics::NumericDynamics;
use plantc_derive::model::{load_model_text, n_link_chain_source, ParameterValues};

const N: usize = 10;

fn manifest() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Deterministic test states (`2N` entries each) and inputs.
fn states() -> Vec<(Vec<f64>, f64)> {
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
    let mut r = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    (0..5)
        .map(|_| {
            let x: Vec<f64> = (0..2 * N)
                .map(|i| if i < N { 1.5 * r() } else { 2.0 * r() })
                .collect();
            (x, 0.3 * r())
        })
        .collect()
}

fn write(path: &Path, text: &str) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, text).unwrap();
}

#[test]
fn recursive_chain_agrees_with_the_derived_equations() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    if Command::new(&cargo).arg("--version").output().is_err() {
        eprintln!("skipped: cargo not available");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let model_path = dir.path().join("chain10.plant");
    write(&model_path, &n_link_chain_source(N));
    let opts = plantc_codegen::CrateOptions {
        model: model_path.clone(),
        dir: dir.path().join("gen"),
        ..Default::default()
    };
    plantc_codegen::write_crate(&opts).unwrap();
    let lib = std::fs::read_to_string(opts.dir.join("src/lib.rs")).unwrap();
    assert!(
        lib.contains("while j < N_STATES"),
        "the 10-link chain is generated as the recursion (Jacobians in a loop)"
    );
    // a probe printing every function at the test states
    let probe = dir.path().join("probe");
    write(
        &probe.join("Cargo.toml"),
        "[package]\nname = \"probe\"\nversion = \"0.1.0\"\nedition = \"2021\"\npublish = false\n\
         [workspace]\n[dependencies]\nchain10 = { path = \"../gen\" }\n",
    );
    let mut main = String::from("use chain10::*;\nfn main() {\n    let p = Plant::default();\n");
    for (x, u) in states() {
        let xs: Vec<String> = x.iter().map(|v| format!("{v:e}")).collect();
        main.push_str(&format!(
            "    {{ let x = [{}]; let u = [{u:e}];\n\
             let d = p.dynamics(&x, &u); let jx = p.jacobian_x(&x, &u); let ju = p.jacobian_u(&x, &u);\n\
             let s = p.rk4_step(&x, &u, 1e-3);\n\
             let mut v: Vec<f64> = d.to_vec(); for r in jx {{ v.extend(r); }} for r in ju {{ v.extend(r); }} v.extend(s);\n\
             println!(\"{{}}\", v.iter().map(|a| format!(\"{{a:e}}\")).collect::<Vec<_>>().join(\" \")); }}\n",
            xs.join(", ")
        ));
    }
    main.push_str("}\n");
    write(&probe.join("src/main.rs"), &main);
    let target = manifest().join("../target/codegen-generated-crates");
    let out = Command::new(&cargo)
        .args(["run", "-q"])
        .current_dir(&probe)
        .env("CARGO_TARGET_DIR", &target)
        .env_remove("RUSTFLAGS")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "probe failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<Vec<f64>> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| l.split(' ').map(|v| v.parse().unwrap()).collect())
        .collect();

    // the reference: LU solves of the derived equations
    let loaded = load_model_text("chain10.plant", &n_link_chain_source(N)).unwrap();
    let model = &loaded.model;
    let values = ParameterValues::new(model, None, &[]).unwrap();
    let d = Derivation::new(model).unwrap();
    let num = NumericDynamics::new(model, &d.equations).unwrap();
    let mut ws = num.workspace();
    let mut f = |x: &[f64], u: f64| {
        let mut dx = vec![0.0; 2 * N];
        num.derivatives(x, &[u], &values.full, &mut dx, &mut ws)
            .unwrap();
        dx
    };
    let nx = 2 * N;
    for ((x, u), got) in states().iter().zip(&lines) {
        let (dy, rest) = got.split_at(nx);
        let (jx, rest) = rest.split_at(nx * nx);
        let (ju, step) = rest.split_at(nx);
        let want = f(x, *u);
        let scale = want.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        for i in 0..nx {
            assert!(
                (dy[i] - want[i]).abs() <= 1e-10 * scale,
                "dynamics[{i}]: {} vs {}",
                dy[i],
                want[i]
            );
        }
        // Jacobians against central differences (step 1e-6: error ~1e-7)
        let h = 1e-6;
        let jscale = jx.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        for k in 0..=nx {
            let (mut xp, mut xm, mut up, mut um) = (x.clone(), x.clone(), *u, *u);
            if k < nx {
                xp[k] += h;
                xm[k] -= h;
            } else {
                up += h;
                um -= h;
            }
            let (fp, fm) = (f(&xp, up), f(&xm, um));
            for i in 0..nx {
                let fd = (fp[i] - fm[i]) / (2.0 * h);
                let g = if k < nx { jx[i * nx + k] } else { ju[i] };
                assert!(
                    (g - fd).abs() <= 1e-6 * jscale,
                    "d f[{i}] / d x[{k}]: {g} vs {fd}"
                );
            }
        }
        // one classical RK4 step of 1 ms
        let hh = 1e-3;
        let k1 = f(x, *u);
        let y: Vec<f64> = (0..nx).map(|i| x[i] + 0.5 * hh * k1[i]).collect();
        let k2 = f(&y, *u);
        let y: Vec<f64> = (0..nx).map(|i| x[i] + 0.5 * hh * k2[i]).collect();
        let k3 = f(&y, *u);
        let y: Vec<f64> = (0..nx).map(|i| x[i] + hh * k3[i]).collect();
        let k4 = f(&y, *u);
        for i in 0..nx {
            let want = x[i] + hh / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
            assert!(
                (step[i] - want).abs() <= 1e-12 * (1.0 + want.abs()),
                "rk4_step[{i}]: {} vs {want}",
                step[i]
            );
        }
    }
}
