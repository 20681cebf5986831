//! Nothing the user has is lost (reliability reproducers 08, 09, 16):
//! outputs that would collide are refused, existing files are kept without
//! `--force`, an unwritable output fails before the work, a regenerated crate
//! keeps its build cache, and no temporary is left behind.

mod common;

use std::path::Path;

use common::{model, plantc, repo, s, tmp};

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn sim_refuses_the_same_file_for_trajectory_and_figure() {
    let dir = tmp("sim_same");
    let x = dir.join("x.csv");
    std::fs::write(&x, "my trajectory\n").unwrap();
    for (o, plot) in [
        (s(&x), s(&x)),
        (s(&x), format!("{}/./x.csv", dir.display())),
        (s(&dir.join("y.csv")), s(&dir.join("y.csv"))),
    ] {
        let (code, _, err) = plantc(&[
            "sim",
            &model(),
            "--set",
            "thesis",
            "--controller",
            "pole_placement",
            "--x0",
            "alpha=5deg",
            "--duration",
            "0.1",
            "-o",
            &o,
            "--plot",
            &plot,
            "--force",
        ]);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains("would both go to"), "{err}");
    }
    assert_eq!(std::fs::read_to_string(&x).unwrap(), "my trajectory\n");
    assert_eq!(names(&dir), ["x.csv"]);
}

#[test]
fn compare_keeps_existing_figures_and_separates_same_named_files() {
    let dir = tmp("compare_figs");
    let figs = dir.join("figs");
    std::fs::create_dir_all(&figs).unwrap();
    std::fs::write(figs.join("driven.svg"), "my own figure").unwrap();
    let driven = repo().join("data/demo_coulomb/driven.csv");
    let (code, _, err) = plantc(&["compare", &model(), &s(&driven), "--plots", &s(&figs)]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("already exists; pass --force"), "{err}");
    assert_eq!(
        std::fs::read_to_string(figs.join("driven.svg")).unwrap(),
        "my own figure"
    );
    // two files named exp.csv in different folders: two rows, two figures
    for (sub, src) in [("a", "driven.csv"), ("b", "free_swing_large.csv")] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
        let text = std::fs::read_to_string(repo().join("data/demo_coulomb").join(src)).unwrap();
        // the first 2 s are enough
        let short: String = text.lines().take(1001).map(|l| format!("{l}\n")).collect();
        std::fs::write(dir.join(sub).join("exp.csv"), short).unwrap();
    }
    let figs2 = dir.join("figs2");
    let (code, out, err) = plantc(&[
        "compare",
        &model(),
        &s(&dir.join("a/exp.csv")),
        &s(&dir.join("b/exp.csv")),
        "--plots",
        &s(&figs2),
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        names(&figs2),
        [
            "a-exp-residual-tests.svg",
            "a-exp.svg",
            "b-exp-residual-tests.svg",
            "b-exp.svg"
        ]
    );
    assert!(out.contains("a-exp ") && out.contains("b-exp "), "{out}");
    // --force replaces them
    let (code, _, err) = plantc(&[
        "compare",
        &model(),
        &s(&dir.join("a/exp.csv")),
        &s(&dir.join("b/exp.csv")),
        "--plots",
        &s(&figs2),
        "--force",
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        names(&figs2),
        [
            "a-exp-residual-tests.svg",
            "a-exp.svg",
            "b-exp-residual-tests.svg",
            "b-exp.svg"
        ]
    );
}

#[test]
fn fit_to_an_unwritable_path_fails_before_fitting() {
    let dir = tmp("fit_unwritable");
    std::fs::write(dir.join("a_file"), "").unwrap();
    let driven = repo().join("data/demo_coulomb/driven.csv");
    for bad in [
        dir.join("missing/fitted.plant"),
        dir.join("a_file/fitted.plant"),
    ] {
        let started = std::time::Instant::now();
        let (code, _, err) = plantc(&["fit", &model(), &s(&driven), "-o", &s(&bad)]);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains("cannot write"), "{err}");
        assert!(!err.contains("fitting"), "the fit ran first: {err}");
        // (not a timing assertion: the message above shows no fit started)
        let _ = started;
    }
    let (code, _, err) = plantc(&[
        "diagnose",
        &model(),
        &s(&driven),
        "--apply",
        "-o",
        &s(&dir.join("missing/x.plant")),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(!err.contains("refitting"), "{err}");
    assert_eq!(names(&dir), ["a_file"]);
}

#[test]
fn regenerating_a_crate_keeps_its_build_cache_and_unchanged_files() {
    let dir = tmp("gen_keep");
    let krate = dir.join("rotpen");
    let gen = |set: &str| {
        plantc(&[
            "gen",
            &model(),
            "--controller",
            "pole_placement",
            "--set",
            set,
            "-o",
            &s(&krate),
        ])
    };
    let (code, _, err) = gen("thesis");
    assert_eq!(code, 0, "{err}");
    std::fs::create_dir_all(krate.join("target/debug")).unwrap();
    std::fs::write(krate.join("target/debug/cache"), "built").unwrap();
    std::fs::write(krate.join("Cargo.lock"), "lock").unwrap();
    std::fs::write(krate.join("src/extra.rs"), "// mine").unwrap();
    let mtime = |p: &str| {
        std::fs::metadata(krate.join(p))
            .unwrap()
            .modified()
            .unwrap()
    };
    let toml_time = mtime("Cargo.toml");
    let lib_before = std::fs::read_to_string(krate.join("src/lib.rs")).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(30));
    // other parameter values: lib.rs changes, Cargo.toml does not
    let (code, _, err) = gen("quanser_manual");
    assert_eq!(code, 0, "{err}");
    assert_ne!(
        std::fs::read_to_string(krate.join("src/lib.rs")).unwrap(),
        lib_before
    );
    assert_eq!(mtime("Cargo.toml"), toml_time, "unchanged file rewritten");
    assert_eq!(
        std::fs::read_to_string(krate.join("target/debug/cache")).unwrap(),
        "built"
    );
    assert_eq!(
        std::fs::read_to_string(krate.join("Cargo.lock")).unwrap(),
        "lock"
    );
    assert_eq!(
        std::fs::read_to_string(krate.join("src/extra.rs")).unwrap(),
        "// mine"
    );
    assert_eq!(names(&dir), ["rotpen"], "no temporaries left");
}

/// Issue 31 (r18): an output directory given as a symbolic link is refused
/// with a message; the link and the directory it names are left as they were.
#[cfg(unix)]
#[test]
fn an_output_directory_that_is_a_symbolic_link_is_refused() {
    let dir = tmp("gen_link");
    let real = dir.join("real");
    let gen = |out: &Path| {
        plantc(&[
            "gen",
            &model(),
            "--controller",
            "pole_placement",
            "-o",
            &s(out),
        ])
    };
    let (code, _, err) = gen(&real);
    assert_eq!(code, 0, "{err}");
    std::fs::write(real.join("notes.txt"), "mine").unwrap();
    let before = names(&real);
    std::os::unix::fs::symlink("real", dir.join("out")).unwrap();
    let (code, _, err) = gen(&dir.join("out"));
    assert_ne!(code, 0, "{err}");
    assert!(
        err.contains("symbolic link") && err.contains("real"),
        "{err}"
    );
    let out_meta = std::fs::symlink_metadata(dir.join("out")).unwrap();
    assert!(
        out_meta.file_type().is_symlink(),
        "the link is still a link"
    );
    assert_eq!(names(&real), before);
}

/// Issue 31 (r02, r09): a crate directory holds the user's files next to
/// plantc's; regenerating (and switching to the rig layout) replaces and
/// removes only the files plantc listed in its manifest, whatever they are
/// named.
#[test]
fn regenerating_touches_only_the_files_plantc_listed() {
    let dir = tmp("gen_manifest");
    let krate = dir.join("rotpen");
    let gen = |extra: &[&str]| {
        let mut args = vec![
            "gen".to_string(),
            model(),
            "--controller".into(),
            "pole_placement".into(),
            "-o".into(),
            s(&krate),
        ];
        args.extend(extra.iter().map(|a| a.to_string()));
        plantc(&args)
    };
    let (code, _, err) = gen(&[]);
    assert_eq!(code, 0, "{err}");
    let mine = [
        ("src/lib2.rs", "// mine"),
        ("examples/mine.rs", "fn main() {}"),
        ("2024-06-01-notes.txt", "notes"),
    ];
    for (rel, text) in mine {
        std::fs::write(krate.join(rel), text).unwrap();
    }
    // the rig layout: lib.rs and examples/simulate.rs were plantc's, so go
    let (code, _, err) = gen(&["--rig"]);
    assert_eq!(code, 0, "{err}");
    assert!(!krate.join("src/lib.rs").exists());
    assert!(!krate.join("examples/simulate.rs").exists());
    assert!(krate.join("src/main.rs").exists());
    for (rel, text) in mine {
        assert_eq!(
            std::fs::read_to_string(krate.join(rel)).unwrap(),
            text,
            "{rel}"
        );
    }
    let listed = plantc_fsio::manifest(&krate, "gen").unwrap();
    assert!(listed.contains(Path::new("src/main.rs")), "{listed:?}");
    assert!(!listed.iter().any(|p| p.ends_with("lib2.rs")), "{listed:?}");
    assert!(
        !names(&krate)
            .iter()
            .any(|n| n.contains("plantc-new") || n.contains("plantc-commit")),
        "{:?}",
        names(&krate)
    );
}

/// Issue 31 (r09): a `gen` killed half-way through its commit (journaled,
/// `Cargo.toml` moved in, `src/lib.rs` still staged, the manifest not yet
/// written) does not make the next `gen` (without --force) refuse the
/// directory as not plantc's: the commit is finished first. The state is
/// the one fsio's journal format describes (`fresh_dir.rs`), built by hand
/// with a process id that is not running.
#[test]
fn a_gen_killed_during_its_commit_does_not_lock_the_next_one_out() {
    const DEAD: u32 = 999_999_999;
    let dir = tmp("gen_half_committed");
    let krate = dir.join("rotpen");
    let gen = || {
        plantc(&[
            "gen".to_string(),
            model(),
            "--controller".into(),
            "pole_placement".into(),
            "-o".into(),
            s(&krate),
        ])
    };
    let (code, _, err) = gen();
    assert_eq!(code, 0, "{err}");
    std::fs::write(krate.join("notes.txt"), "mine").unwrap();
    let listed = plantc_fsio::manifest(&krate, "gen").unwrap();
    let lib = std::fs::read_to_string(krate.join("src/lib.rs")).unwrap();
    // the killed run: lib.rs staged, journal written, manifest not yet
    let staging = krate.join(format!(".plantc-new-{DEAD}-4"));
    std::fs::create_dir_all(staging.join("src")).unwrap();
    std::fs::rename(krate.join("src/lib.rs"), staging.join("src/lib.rs")).unwrap();
    std::fs::remove_file(krate.join(".plantc-manifest-gen")).unwrap();
    let mut journal = "owner gen\n+ src/lib.rs\n".to_string();
    for p in &listed {
        journal.push_str(&format!("= {}\n", p.display()));
    }
    std::fs::write(krate.join(format!(".plantc-commit-{DEAD}-4")), journal).unwrap();
    let (code, _, err) = gen();
    assert_eq!(code, 0, "{err}");
    assert_eq!(
        std::fs::read_to_string(krate.join("src/lib.rs")).unwrap(),
        lib
    );
    assert_eq!(
        std::fs::read_to_string(krate.join("notes.txt")).unwrap(),
        "mine"
    );
    assert_eq!(plantc_fsio::manifest(&krate, "gen").unwrap(), listed);
    assert!(
        !names(&krate)
            .iter()
            .any(|n| n.contains("plantc-new") || n.contains("plantc-commit")),
        "{:?}",
        names(&krate)
    );
}
