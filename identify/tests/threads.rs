//! The diagnosis is the same on one and on two worker threads: the
//! candidate refits computed ahead on the second worker
//! (`identify/src/speculate.rs`) and the fit's blocks shared out
//! (`identify/src/parallel.rs`) change when things are computed, never what.
//!
//! The case is the bundled `data/demo_two_effects` (two hidden effects, far
//! above the noise floor: every candidate is refitted, in batches of two on
//! two threads), cut to its first 4 s so that the two diagnoses stay cheap
//! (about 7 s CPU for the two in the test profile, on a loaded machine).

mod common;

use std::path::{Path, PathBuf};

use plantc_identify::{diagnose, parallel, read_experiments, FitOptions, ReadOptions};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Everything of a diagnosis, floats printed exactly (Rust's `{:?}` of an
/// f64 round-trips), and the simulated samples of every fit as bits.
fn fingerprint(d: &plantc_identify::Diagnosis) -> (String, Vec<u64>) {
    let mut bits = Vec::new();
    let fits = std::iter::once(&d.baseline).chain(d.ranking.iter().filter_map(|r| r.fit.as_ref()));
    for f in fits {
        for e in &f.simulated {
            for c in e {
                bits.extend(c.iter().map(|v| v.to_bits()));
            }
        }
    }
    (format!("{d:?}"), bits)
}

#[test]
fn one_and_two_threads_give_the_same_diagnosis() {
    let text =
        std::fs::read_to_string(repo().join("models/rotary_pendulum.plant")).expect("model text");
    let dir = common::scratch("threads");
    let files: Vec<PathBuf> = ["driven", "free_swing_large", "free_swing_small"]
        .iter()
        .map(|n| {
            let src = repo().join(format!("data/demo_two_effects/{n}.csv"));
            let csv = std::fs::read_to_string(&src).expect("demo data");
            // header + 4 s at 500 Hz
            let cut: String = csv.lines().take(2001).map(|l| format!("{l}\n")).collect();
            let p = dir.join(format!("{n}.csv"));
            std::fs::write(&p, cut).expect("writes");
            p
        })
        .collect();
    let (exps, _) =
        read_experiments(&files, &common::pendulum_spec(), &ReadOptions::default()).expect("reads");
    parallel::set_threads(1);
    let one = diagnose(&text, &exps, &FitOptions::default()).expect("diagnoses on 1 thread");
    parallel::set_threads(2);
    let two = diagnose(&text, &exps, &FitOptions::default()).expect("diagnoses on 2 threads");
    parallel::set_threads(0);
    // the case must exercise the refits ahead: several candidates refitted
    let refitted = one.ranking.iter().filter(|r| r.fit.is_some()).count();
    assert!(refitted >= 2, "only {refitted} candidates refitted");
    let (a, b) = (fingerprint(&one), fingerprint(&two));
    assert_eq!(a.0, b.0, "the diagnosis differs between 1 and 2 threads");
    assert!(
        a.1 == b.1,
        "simulated samples differ between 1 and 2 threads"
    );
    eprintln!(
        "{refitted} candidates refitted; verdict {:?}",
        one.verdict.as_ref().map(|c| c.label())
    );
}
