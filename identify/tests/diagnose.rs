//! Candidate effects: text edits that load, and (slow, ignored by default)
//! the ranking on the shared `coulomb_pendulum` case, whose truth.json names
//! coulomb_friction on alpha.

mod common;

use std::path::{Path, PathBuf};

use plantc_identify::diagnose::model_from_text;
use plantc_identify::{candidates, diagnose, read_experiments, FitOptions, ReadOptions};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn pendulum_text() -> String {
    std::fs::read_to_string(repo().join("models/rotary_pendulum.plant")).expect("model text")
}

#[test]
fn every_candidate_edit_gives_a_valid_model() {
    let text = pendulum_text();
    let model = model_from_text("baseline", &text).expect("baseline checks");
    let cs = candidates(&model);
    // 5 force + 1 sensor effects on each of 2 coordinates, 2 actuator effects on Vm
    assert_eq!(cs.len(), 14);
    for c in &cs {
        let edited = c.apply(&text).expect("edit applies");
        let m = model_from_text(&c.label(), &edited).expect("edited model checks");
        assert!(m.parameters.len() > model.parameters.len(), "{}", c.label());
        assert!(m.parameters.iter().filter(|p| p.estimate.is_some()).count() > 5);
    }
    let coulomb = cs
        .iter()
        .find(|c| c.effect == "coulomb_friction" && c.target == "alpha")
        .expect("candidate exists");
    let edited = coulomb.apply(&text).expect("applies");
    assert!(edited.contains("coulomb_friction(Fc_alpha)"));
    assert!(edited.contains("parameter Fc_alpha"));
}

/// Ten refits of three 20 s experiments: run with
/// `cargo test -p plantc-identify --release --test diagnose -- --ignored`.
#[test]
#[ignore]
fn coulomb_on_alpha_ranks_first() {
    let dir = repo().join("../shared/data/coulomb_pendulum");
    if !dir.is_dir() {
        eprintln!("skipping: {} not present", dir.display());
        return;
    }
    let files: Vec<PathBuf> = ["free_swing_large", "free_swing_small", "driven"]
        .iter()
        .map(|n| dir.join(format!("{n}.csv")))
        .collect();
    let (exps, _) =
        read_experiments(&files, &common::pendulum_spec(), &ReadOptions::default()).expect("reads");
    let d = diagnose(&pendulum_text(), &exps, &FitOptions::default()).expect("diagnoses");
    eprintln!("baseline rmse {:.3e}", d.baseline.after_rmse);
    for r in &d.ranking {
        eprintln!(
            "{:28} gain {:8.2} {:?}",
            r.candidate.label(),
            r.gain,
            r.error
        );
    }
    let top = &d.ranking[0].candidate;
    assert_eq!(
        (top.effect.as_str(), top.target.as_str()),
        ("coulomb_friction", "alpha")
    );
    assert!(d.verdict.is_some());
}
