//! The QUBE-Servo recordings (`../shared/data/real/qube_koopman_prbs`, MIT
//! licence, raw files): closed-loop identification with the recorded PD
//! law of `models/qube_servo.plant`. Skipped when the shared data are absent.

use std::path::{Path, PathBuf};

use plantc_derive::model::{load_model, Model};
use plantc_identify::{
    fit, read_experiments, validate, ChannelSpec, Experiment, FitOptions, Kind, LoopLaw,
    ReadOptions, ValidateOptions,
};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn qube_model() -> Model {
    load_model(&repo().join("models/qube_servo.plant"))
        .expect("qube model loads")
        .model
}

/// The three raw episodes, or None when the shared data are absent.
fn episodes() -> Option<Vec<Experiment>> {
    episodes_in(&["raw"])
}

/// The episodes of the session's folders `dirs` (file names sorted within
/// each), or None when the shared data are absent.
fn episodes_in(dirs: &[&str]) -> Option<Vec<Experiment>> {
    let mut files: Vec<PathBuf> = Vec::new();
    for d in dirs {
        let dir = repo().join("../shared/data/real/qube_koopman_prbs").join(d);
        if !dir.is_dir() {
            eprintln!("skipping: {} not present", dir.display());
            return None;
        }
        let mut here: Vec<PathBuf> = std::fs::read_dir(&dir)
            .expect("lists")
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "csv"))
            .collect();
        here.sort();
        files.extend(here);
    }
    let spec = ChannelSpec::new()
        .angle("theta")
        .angle("alpha")
        .optional("Vm", Kind::Voltage);
    let opts = ReadOptions {
        rename: vec![("Vm".into(), "plant_input".into())],
        ..ReadOptions::default()
    };
    let (exps, _) = read_experiments(&files, &spec, &opts).expect("reads");
    Some(exps)
}

/// Channel `c`'s fit % in `scores` (minus infinity when absent or
/// undefined).
fn fit_percent(scores: &[plantc_identify::ChannelScore], c: &str) -> f64 {
    scores
        .iter()
        .find(|x| x.channel == c)
        .and_then(|x| x.fit_percent)
        .unwrap_or(f64::NEG_INFINITY)
}

/// The recorded law replayed on the measured angles and references
/// reproduces the logged controller output (`control_output`, before the
/// feedforward is added... the law includes it: compare with plant_input)
/// to rounding: the filter discretisation, its zero initial state and the
/// signs of `models/qube_servo.plant` are those of the rig's code.
#[test]
fn replay_reproduces_the_logged_law() {
    let Some(exps) = episodes() else { return };
    let model = qube_model();
    let law = LoopLaw::new(&model, "qube_pd").expect("compiles");
    for e in &exps {
        let q = vec![
            e.values("theta").expect("theta").to_vec(),
            e.values("alpha").expect("alpha").to_vec(),
        ];
        let rep = law.replay(e, &q).expect("replays");
        let logged = e.values("Vm").expect("plant_input");
        let worst = rep.u[0]
            .iter()
            .zip(logged)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f64, f64::max);
        eprintln!("{}: largest |law - plant_input| = {worst:.2e} V", e.name);
        assert!(worst < 1e-9, "{}: {worst}", e.name);
    }
}

/// Leave-one-episode-out: fitted on two episodes in closed loop, the third
/// predicted in closed loop with the recorded PD law and references, and
/// 0.5 s ahead. Issue acceptance: mean fit % theta >= 85, alpha >= 75
/// (simulation) and theta >= 90, alpha >= 85 (0.5 s ahead); by-hand
/// workarounds reached theta 77-89 %, alpha 66-70 %.
#[test]
fn leave_one_episode_out() {
    let Some(exps) = episodes() else { return };
    let model = qube_model();
    let mut sim = (Vec::new(), Vec::new());
    let mut pred = (Vec::new(), Vec::new());
    for held in 0..exps.len() {
        let train: Vec<Experiment> = exps
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != held)
            .map(|(_, e)| e.clone())
            .collect();
        let t = std::time::Instant::now();
        let r = fit(&model, &train, &FitOptions::default()).expect("fits");
        let fit_time = t.elapsed();
        assert!(r.after_cost <= r.before_cost);
        let v = validate(
            &model,
            &r.base,
            &exps[held..held + 1],
            &ValidateOptions {
                horizon: Some(0.5),
                ..ValidateOptions::default()
            },
        )
        .expect("validates");
        let get = fit_percent;
        let e = &v.experiments[0];
        eprintln!(
            "held out {}: fit {:.1} s, {}; simulation theta {:.1} % alpha {:.1} %; 0.5 s ahead theta {:.1} % alpha {:.1} %",
            e.name,
            fit_time.as_secs_f64(),
            r.parameters
                .iter()
                .map(|p| format!("{} = {:.4e}", p.name, p.value))
                .collect::<Vec<_>>()
                .join(", "),
            get(&e.simulation, "theta"),
            get(&e.simulation, "alpha"),
            get(&e.prediction, "theta"),
            get(&e.prediction, "alpha"),
        );
        for n in &r.notes {
            eprintln!("   note: {n}");
        }
        for tst in &e.residual_tests {
            eprintln!("   residuals {}", tst.summary());
        }
        sim.0.push(get(&e.simulation, "theta"));
        sim.1.push(get(&e.simulation, "alpha"));
        pred.0.push(get(&e.prediction, "theta"));
        pred.1.push(get(&e.prediction, "alpha"));
    }
    let mean = |v: &Vec<f64>| v.iter().sum::<f64>() / v.len() as f64;
    eprintln!(
        "mean fit %: simulation theta {:.1} alpha {:.1}; 0.5 s ahead theta {:.1} alpha {:.1}",
        mean(&sim.0),
        mean(&sim.1),
        mean(&pred.0),
        mean(&pred.1)
    );
    assert!(mean(&sim.0) >= 85.0 && mean(&sim.1) >= 75.0);
    assert!(mean(&pred.0) >= 90.0 && mean(&pred.1) >= 85.0);
}

/// The trap: on closed-loop data the controller used to be absorbed
/// into the plant as a spring on alpha (k = 0.0107 N m/rad, "13x lower
/// RMSE"). With the recorded controller simulated in the loop, no effect
/// may be named that holds the pendulum upright by itself: a spring on alpha
/// stiffer than the gravity torque's slope mp g lp (0.0152 N m/rad at the
/// model's values).
#[test]
fn diagnosis_does_not_absorb_the_controller() {
    let Some(exps) = episodes() else { return };
    let text = std::fs::read_to_string(repo().join("models/qube_servo.plant")).expect("reads");
    let model = qube_model();
    let v = |n: &str| model.parameter(n).expect(n).value;
    let upright = v("mp") * v("g") * v("lp");
    let d = plantc_identify::diagnose(&text, &exps, &FitOptions::default()).expect("diagnoses");
    for r in d.ranking.iter().filter(|r| r.fit.is_some()) {
        eprintln!(
            "{:<20} {:<6} gain {:.2}x {}",
            r.candidate.effect,
            r.candidate.target,
            r.gain,
            r.parameters
                .iter()
                .map(|p| format!("{} = {:.4e}", p.name, p.value))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    eprintln!(
        "verdict: {}",
        d.verdict
            .as_ref()
            .map_or("adequate".to_string(), |c| c.label())
    );
    // the replay from the nominal values leaves the data (weighted RMS
    // about 600 against the baseline's 0.09): no candidate is refitted
    // from there (those refits ended 30-6000x above the baseline, 38 s)
    assert!(
        d.notes
            .iter()
            .any(|n| n.contains("no candidate refitted again from there")),
        "notes: {:?}",
        d.notes
    );
    if let Some(c) = &d.verdict {
        if c.effect == "spring" && c.target == "alpha" {
            let k = d.ranking[0].parameters[0].value;
            assert!(
                k < upright,
                "a spring on alpha of {k:.4e} N m/rad (gravity slope {upright:.4e}) was named"
            );
        }
    }
}

/// Issue 26's acceptance on the session's 16 episodes (raw/ and more/, 9 of
/// them start clipped at +-10 V): fitted on 8 with the defaults (the
/// README's `plantc fit` command), validated on the other 8, both ways
/// round (the first 8 of more/, then the other 8). Every held-out episode
/// 0.5 s ahead >= 90 % on the arm and >= 85 % on the pendulum, simulation
/// at least 85 % / 75 % (the numbers), no simulation diverges, and every
/// episode that starts clipped is followed only after its release transient
/// (the hand that still holds the pendulum when the controller starts,
/// `plantc_identify::fit::ExperimentEstimate::release`).
/// Measured 2026-11-28 (release build, both splits 42 s wall, 78 s CPU on 2
/// threads): simulation 90.5-96.3 % arm, 86.1-92.2 % pendulum; 0.5 s ahead
/// 92.2-96.5 % / 87.7-91.5 %; the 9 clipped episodes followed from t = 0.25
/// or 0.5 s, 5 of the 7 unclipped ones too (the hand holds them as well,
/// with a smaller kick). Before the
/// release rule (2026-11-27) the simulation was 62.3-88.2 % on the
/// pendulum (163847: 78.4 / 62.3), all of it lost in the first second.
/// Ignored in CI for its cost: run with
/// `cargo test --release -p plantc-identify --test real_qube -- --ignored`.
#[test]
#[ignore = "16 real episodes, about 75 s CPU in release, minutes in debug"]
fn eight_fitted_eight_held_out() {
    let Some(all) = episodes_in(&["more", "raw"]) else {
        return;
    };
    let model = qube_model();
    let mut bad = Vec::new();
    for (train, held) in [all.split_at(8), {
        let (a, b) = all.split_at(8);
        (b, a)
    }] {
        let r = fit(&model, train, &FitOptions::default()).expect("fits");
        let v = validate(
            &model,
            &r.base,
            held,
            &ValidateOptions {
                horizon: Some(0.5),
                ..ValidateOptions::default()
            },
        )
        .expect("validates");
        let get = fit_percent;
        for (e, exp) in v.experiments.iter().zip(held) {
            let (st, sa) = (get(&e.simulation, "theta"), get(&e.simulation, "alpha"));
            let (pt, pa) = (get(&e.prediction, "theta"), get(&e.prediction, "alpha"));
            let clipped = exp
                .values("Vm")
                .is_some_and(|u| u.iter().take(20).any(|v| v.abs() >= 10.0));
            eprintln!(
                "{}: simulation theta {st:.1} % alpha {sa:.1} %; 0.5 s ahead theta {pt:.1} % alpha {pa:.1} %; clipped {clipped}, followed from {:?} s",
                e.name, e.nuisance.release
            );
            if !(pt >= 90.0 && pa >= 85.0 && st >= 85.0 && sa >= 75.0) {
                bad.push(e.name.clone());
            }
            if clipped && e.nuisance.release.is_none() {
                bad.push(format!("{}: clipped start followed from t = 0", e.name));
            }
        }
    }
    assert!(bad.is_empty(), "below the acceptance: {bad:?}");
}
