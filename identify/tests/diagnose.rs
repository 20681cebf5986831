//! Diagnosis on the shared recordings (`../shared/data`, skipped when
//! absent). Reference values come from each case's `truth.json`
//! (`effect`, `coordinate`, `effect_parameters`, `true_parameters`).
//!
//! Everything runs by default (the three full diagnoses, baseline fit +
//! refits of the leaders, take about 10 s together in the test profile); to
//! see the rankings and timings:
//! `cargo test -p plantc-identify --release --test diagnose -- --nocapture`.

mod common;

use std::path::{Path, PathBuf};
use std::time::Instant;

use plantc_identify::diagnose::{model_from_text, regressor_for};
use plantc_identify::{
    candidates, diagnose, estimated_parameters, fit, read_experiments, EquationError,
    EquationErrorOptions, Experiment, FitOptions, ReadOptions, Regressor, Score,
};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn pendulum_text() -> String {
    std::fs::read_to_string(repo().join("models/rotary_pendulum.plant")).expect("model text")
}

/// The three experiments and truth.json of a shared case, or None (skip).
fn case(name: &str) -> Option<(Vec<Experiment>, serde_json::Value)> {
    let dir = repo().join("../shared/data").join(name);
    if !dir.is_dir() {
        eprintln!("skipping: {} not present", dir.display());
        return None;
    }
    let files: Vec<PathBuf> = ["free_swing_large", "free_swing_small", "driven"]
        .iter()
        .map(|n| dir.join(format!("{n}.csv")))
        .collect();
    let (exps, _) =
        read_experiments(&files, &common::pendulum_spec(), &ReadOptions::default()).expect("reads");
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).expect("truth"))
            .expect("parses");
    Some((exps, truth))
}

#[test]
fn every_candidate_edit_gives_a_valid_model() {
    let text = pendulum_text();
    let model = model_from_text("baseline", &text).expect("baseline checks");
    let cs = candidates(&model);
    // 5 force + added inertia + 1 sensor effects on each of 2 coordinates,
    // the drive effects cogging and speed limit on the actuated arm only, 4
    // actuator effects on Vm (offset, delay, deadzone, saturation)
    assert_eq!(cs.len(), 20);
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

/// Equation-error scores of every candidate at the model's nominal values
/// (the nuisance columns re-adjust the estimated parameters), best first.
fn equation_error_ranking(exps: &[Experiment]) -> (EquationError, Vec<(String, Score)>) {
    let text = pendulum_text();
    let model = model_from_text("baseline", &text).expect("checks");
    let base: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let ee = EquationError::new(
        &model,
        &base,
        &estimated_parameters(&model),
        exps,
        &EquationErrorOptions::default(),
    )
    .expect("prepares");
    let mut v: Vec<(String, Score)> = candidates(&model)
        .into_iter()
        .map(|c| {
            let m = model_from_text(&c.label(), &c.apply(&text).expect("applies")).expect("checks");
            let s = ee.score(&regressor_for(&c, m)).expect("scores");
            (c.label(), s)
        })
        .collect();
    v.sort_by(|a, b| b.1.bic_gain.total_cmp(&a.1.bic_gain));
    for (l, s) in &v {
        eprintln!(
            "{l:26} bic {:9.1} share {:.4} est {:?}",
            s.bic_gain,
            s.residual_share,
            s.estimates.iter().map(|e| e.value).collect::<Vec<_>>()
        );
    }
    (ee, v)
}

/// Fast (no simulation): the right effect leads the equation-error ranking
/// on the two shared cases with a hidden effect, and its linearised
/// estimate is in the right range (truth.json: Fc 8e-4, k 0.03; the smooth
/// `tanh` friction biases Fc low, the refit corrects it).
#[test]
fn equation_error_puts_the_hidden_effect_first() {
    for (name, label, param, tol) in [
        ("coulomb_pendulum", "coulomb_friction@alpha", "Fc", 0.25),
        ("spring_arm", "spring@theta", "k", 0.05),
    ] {
        let Some((exps, truth)) = case(name) else {
            return;
        };
        let start = Instant::now();
        let (_, ranking) = equation_error_ranking(&exps);
        eprintln!("{name}: equation-error ranking in {:?}", start.elapsed());
        let (top, score) = &ranking[0];
        assert_eq!(top, label, "{name}");
        let want = truth["effect_parameters"][param].as_f64().expect("truth");
        let got = score.estimates[0].value;
        assert!((got / want - 1.0).abs() < tol, "{name}: {got} vs {want}");
        // a clear margin over the runner-up that is not the same physics
        // (Stribeck contains Coulomb and cannot be told apart here, trap 6).
        // An added inertia on the pendulum also scores on `coulomb_pendulum`
        // (BIC gain 1278 against Coulomb's 1292, measured): it frees the
        // pendulum's inertia from l2. The ranking only chooses what to refit;
        // the refit separates them (plantc/tests/diagnose_vocabulary.rs,
        // case coulomb_alpha), so it is left out of the margin.
        let other = ranking
            .iter()
            .find(|(l, _)| {
                !l.starts_with("stribeck") && !l.starts_with("added_inertia") && l != label
            })
            .expect("runner-up");
        assert!(score.bic_gain > 2.0 * other.1.bic_gain.max(1.0), "{name}");
    }
}

/// Zero-order hold handled (notes, trap 2): on the clean case the input
/// delay estimated by equation error is far below the false half-sample
/// delay (1 ms at 500 Hz) that sampling the input at the instants gives.
#[test]
fn equation_error_shows_no_false_input_delay_on_clean_data() {
    let Some((exps, _)) = case("clean") else {
        return;
    };
    let (ee, _) = equation_error_ranking(&exps);
    let s = ee
        .score(&Regressor::InputDelay {
            input: 0,
            name: "Td".into(),
        })
        .expect("scores");
    let td = s.estimates[0].value;
    eprintln!("clean: input delay {td:.2e} s, bic {:.1}", s.bic_gain);
    assert!(td.abs() < 2.5e-4, "{td}");
}

fn report(d: &plantc_identify::Diagnosis) {
    eprintln!(
        "baseline rmse {:.3e} ({} it, {} sims)",
        d.baseline.after_rmse, d.baseline.iterations, d.baseline.simulations
    );
    for r in &d.ranking {
        eprintln!(
            "{:26} ee#{} bic {:8.1} share {:.4} gain {:7.2} params {:?} err {:?} | {}",
            r.candidate.label(),
            r.evidence.equation_error_rank,
            r.evidence.bic_gain,
            r.evidence.residual_share,
            r.gain,
            r.parameters
                .iter()
                .map(|e| format!("{}={:.4e}+-{:.1e}", e.name, e.value, e.std_error))
                .collect::<Vec<_>>(),
            r.error,
            r.evidence.acts_where
        );
    }
}

/// Acceptance on a case with a hidden effect: named first, accepted, and
/// apply + fit (from the nominal values) divides the baseline RMSE by at
/// least 5 with the effect parameter within 10 % of truth.json.
fn hidden_effect_case(name: &str, effect: &str, target: &str, param: &str) {
    let Some((exps, truth)) = case(name) else {
        return;
    };
    let text = pendulum_text();
    let start = Instant::now();
    let d = diagnose(&text, &exps, &FitOptions::default()).expect("diagnoses");
    eprintln!("{name}: diagnose in {:?}", start.elapsed());
    report(&d);
    let top = &d.ranking[0].candidate;
    assert_eq!((top.effect.as_str(), top.target.as_str()), (effect, target));
    let verdict = d.verdict.as_ref().expect("an effect is found");
    assert_eq!(verdict, top);
    // apply, then fit the edited model from its nominal values
    let edited = verdict.apply(&text).expect("applies");
    let m = model_from_text("applied", &edited).expect("checks");
    let start = Instant::now();
    let f = fit(&m, &exps, &FitOptions::default()).expect("fits");
    let ratio = d.baseline.after_rmse / f.after_rmse;
    let want = truth["effect_parameters"][param].as_f64().expect("truth");
    let est = f
        .parameters
        .iter()
        .find(|e| e.name == format!("{param}_{target}"))
        .expect("effect parameter estimated");
    eprintln!(
        "{name}: apply+fit in {:?}: rmse {:.3e} -> {:.3e} ({ratio:.1}x), {} = {:.4e} (truth {want:.4e}, {:+.1} %)",
        start.elapsed(),
        d.baseline.after_rmse,
        f.after_rmse,
        est.name,
        est.value,
        100.0 * (est.value / want - 1.0)
    );
    assert!(ratio >= 5.0, "{ratio}");
    assert!((est.value / want - 1.0).abs() < 0.10);
    // the diagnosis' own refit reaches the same level (what `--apply` and
    // `plantc identify` start from): a refit trapped by the distorted
    // baseline would not (spring_arm: 5.2x from the baseline, ~400x from
    // the nominal values)
    let refit = d.ranking[0].fit.as_ref().expect("refitted");
    assert!(
        refit.after_rmse <= 1.5 * f.after_rmse,
        "refit {:.3e} vs apply+fit {:.3e}",
        refit.after_rmse,
        f.after_rmse
    );
}

#[test]
fn coulomb_pendulum_names_coulomb_friction_on_alpha() {
    hidden_effect_case("coulomb_pendulum", "coulomb_friction", "alpha", "Fc");
}

#[test]
fn spring_arm_names_spring_on_theta() {
    hidden_effect_case("spring_arm", "spring", "theta", "k");
}

/// Clean data: no finding (a false alarm is a failure), and the baseline
/// fit recovers J1 and l2 within 5 % of truth.json's `true_parameters`.
///
/// The shared cases come from an independent simulator whose dry friction
/// is `tanh(v / 1e-3)` (`../shared/reference/identification-notes.md`, trap
/// 8: the smooth law the Python pipeline matched): its held arm creeps, and
/// the creep drains the pendulum's swing where a sticking arm would not.
/// Simulated with that law (`--friction smooth:1e-3`), the baseline reaches
/// the floor and nothing is named.
#[test]
fn clean_case_is_adequate_under_the_simulators_friction_law() {
    let Some((exps, truth)) = case("clean") else {
        return;
    };
    let mut opts = FitOptions::default();
    opts.sim.dry_friction = plantc_identify::DryFriction::Smooth { width: 1e-3 };
    clean_case_check(&exps, &truth, &opts);
}

/// The same records under plantc's default law: the diagnosis finds that
/// they creep ([`plantc_identify::friction_law`]) and adopts the creeping
/// law with its width fitted, within 10 % of the simulator's 1e-3 rad/s
/// (identification notes, trap 8); under the sticking law alone the rule
/// named a Coulomb friction of 1.65e-5 N m on the pendulum (weighted RMS
/// ratio 1.63, baseline 1.6x the floor), measured 2026-11-27.
#[test]
fn clean_case_is_adequate() {
    let Some((exps, truth)) = case("clean") else {
        return;
    };
    let d = clean_case_check(&exps, &truth, &FitOptions::default());
    let law = d.creeping.as_ref().expect("the creeping law adopted");
    eprintln!("{}", law.describe());
    assert!((law.width / 1e-3 - 1.0).abs() < 0.1, "width {}", law.width);
}

fn clean_case_check(
    exps: &[Experiment],
    truth: &serde_json::Value,
    opts: &FitOptions,
) -> plantc_identify::Diagnosis {
    let start = Instant::now();
    let d = diagnose(&pendulum_text(), exps, opts).expect("diagnoses");
    eprintln!("clean: diagnose in {:?}", start.elapsed());
    report(&d);
    assert!(d.verdict.is_none(), "false alarm: {:?}", d.verdict);
    for name in ["J1", "l2"] {
        let e = d
            .baseline
            .parameters
            .iter()
            .find(|e| e.name == name)
            .expect("estimated");
        let t = truth["true_parameters"][name].as_f64().expect("truth");
        eprintln!("{name} {:.5e} (true {t:.5e})", e.value);
        assert!((e.value / t - 1.0).abs() < 0.05, "{name}");
    }
    d
}

/// The generic columns for effects that are not force terms, on the clean
/// recordings with a known disturbance added here: alpha read 0.02 rad too
/// high (a sensor offset), and the logged voltage leading the applied one by
/// one sample (an input delay of 2 ms at 500 Hz). The equation error finds
/// both within 10 % (the disturbances are ours, so are the reference
/// values).
#[test]
fn equation_error_columns_for_sensor_offset_and_input_delay() {
    let Some((clean, _)) = case("clean") else {
        return;
    };
    let text = pendulum_text();
    let model = model_from_text("baseline", &text).expect("checks");
    let base: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let nuisance = estimated_parameters(&model);
    let opts = EquationErrorOptions::default();
    let alpha = model
        .coordinates
        .iter()
        .position(|c| c.name == "alpha")
        .expect("alpha");

    let mut offset = clean.clone();
    for e in &mut offset {
        let ch = e
            .channels
            .iter_mut()
            .find(|c| c.name == "alpha")
            .expect("alpha column");
        ch.values.iter_mut().for_each(|v| *v += 0.02);
    }
    let ee = EquationError::new(&model, &base, &nuisance, &offset, &opts).expect("prepares");
    let s = ee
        .score(&Regressor::SensorOffset {
            coordinate: alpha,
            name: "d_alpha".into(),
        })
        .expect("scores");
    let d = s.estimates[0].value;
    eprintln!("sensor offset: {d:.4e} rad, bic {:.1}", s.bic_gain);
    assert!((d / 0.02 - 1.0).abs() < 0.10, "{d}");

    let mut delayed = clean.clone();
    for e in &mut delayed {
        let ch = e
            .channels
            .iter_mut()
            .find(|c| c.name == "Vm")
            .expect("Vm column");
        let v = ch.values.clone();
        for k in 0..v.len() {
            ch.values[k] = v[(k + 1).min(v.len() - 1)];
        }
    }
    let ee = EquationError::new(&model, &base, &nuisance, &delayed, &opts).expect("prepares");
    let s = ee
        .score(&Regressor::InputDelay {
            input: 0,
            name: "Td".into(),
        })
        .expect("scores");
    let td = s.estimates[0].value;
    eprintln!("input delay: {td:.4e} s, bic {:.1}", s.bic_gain);
    assert!((td / 2e-3 - 1.0).abs() < 0.10, "{td}");
}

/// The deadzone column on the clean recordings with a known deadzone made
/// here: the logged voltage is replaced by `u = Vm + w sign(Vm)`, so the
/// plant (which received the recorded `Vm`) saw exactly `dz(u)` with
/// `w = 0.3 V`. The reference is our own disturbance; the start width
/// 0.05 V only selects the samples. The input jumps by `2w` at every sign
/// change, and the Savitzky-Golay smoothing of that jump biases the linear
/// estimate low (measured: 0.256 V, -15 %), hence 25 %; the simulation
/// refit of `diagnose` removes the bias (diagnose_vocabulary: within 0.1 %).
#[test]
fn equation_error_column_for_deadzone() {
    let Some((clean, _)) = case("clean") else {
        return;
    };
    let model = model_from_text("baseline", &pendulum_text()).expect("checks");
    let base: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let nuisance = estimated_parameters(&model);
    let mut dz = clean.clone();
    for e in &mut dz {
        let ch = e
            .channels
            .iter_mut()
            .find(|c| c.name == "Vm")
            .expect("Vm column");
        ch.values
            .iter_mut()
            .filter(|v| **v != 0.0)
            .for_each(|v| *v += 0.3 * v.signum());
    }
    let opts = EquationErrorOptions::default();
    let ee = EquationError::new(&model, &base, &nuisance, &dz, &opts).expect("prepares");
    let s = ee
        .score(&Regressor::Deadzone {
            input: 0,
            name: "w".into(),
            start: 0.05,
        })
        .expect("scores");
    let w = s.estimates[0].value;
    eprintln!("deadzone: {w:.4e} V, bic {:.1}", s.bic_gain);
    assert!((w / 0.3 - 1.0).abs() < 0.25, "{w}");
    assert!(s.bic_gain > 0.0);
    let bad = ee.score(&Regressor::Deadzone {
        input: 3,
        name: "w".into(),
        start: 0.05,
    });
    assert!(bad.is_err());
}

/// Bad requests are errors with data, not panics.
#[test]
fn equation_error_rejects_bad_requests() {
    use plantc_identify::equation_error::EquationErrorError;
    let Some((clean, _)) = case("clean") else {
        return;
    };
    let model = model_from_text("baseline", &pendulum_text()).expect("checks");
    let base: Vec<f64> = model.parameters.iter().map(|p| p.value).collect();
    let nuisance = estimated_parameters(&model);
    let opts = EquationErrorOptions::default();
    assert!(matches!(
        EquationError::new(&model, &base[1..], &nuisance, &clean, &opts),
        Err(EquationErrorError::ParameterCount { .. })
    ));
    // jittered stamps are resampled, not refused (issue 10: every command
    // accepts non-uniform time)
    let mut jittered = clean[..1].to_vec();
    jittered[0].t[100] += 0.3e-3;
    assert!(EquationError::new(&model, &base, &nuisance, &jittered, &opts).is_ok());
    let mut short = clean[..1].to_vec();
    short[0].t.truncate(40);
    for c in &mut short[0].channels {
        c.values.truncate(40);
    }
    let e = EquationError::new(&model, &base, &nuisance, &short, &opts);
    assert_eq!(e.err(), Some(EquationErrorError::NoSamples));
    let ee = EquationError::new(&model, &base, &nuisance, &clean[..1], &opts).expect("prepares");
    let bad = ee.score(&Regressor::SensorOffset {
        coordinate: 7,
        name: "d".into(),
    });
    assert_eq!(bad.err(), Some(EquationErrorError::BadIndex(7)));
}

/// The shared Coulomb case through the whole story under plantc's default
/// law: round 1 names the pendulum's dry friction (fitted sticking), round
/// 2 finds that both joints' dry friction creeps (the simulator's
/// `tanh(v/1e-3)`, identification notes trap 8) and adopts that law at the
/// floor. The friction is truth.json's within 2 % (the bar). Under
/// the sticking law alone the story went on to name a quadratic drag and a
/// cogging torque and stopped at 3 effects above the floor (measured
/// 2026-11-28).
#[test]
fn coulomb_case_story_names_the_friction_then_the_creeping_law() {
    let Some((exps, truth)) = case("coulomb_pendulum") else {
        return;
    };
    let story = plantc_identify::identify(
        &pendulum_text(),
        &exps,
        &plantc_identify::StoryOptions::default(),
        &mut |_| {},
    )
    .expect("identifies");
    eprintln!("{}", story.stop);
    let effects: Vec<String> = story.effects.iter().map(|e| e.label()).collect();
    assert_eq!(effects, ["coulomb_friction@alpha"], "{}", story.stop);
    let law = story.creeping.as_ref().expect("the creeping law adopted");
    assert!((law.width / 1e-3 - 1.0).abs() < 0.3, "width {}", law.width);
    let fc = common::final_value(&story, "Fc_alpha").expect("Fc_alpha");
    let want = truth["effect_parameters"]["Fc"].as_f64().expect("Fc");
    eprintln!(
        "Fc_alpha {fc:.4e} (true {want:.4e}), width {:.3e}",
        law.width
    );
    assert!((fc / want - 1.0).abs() < 0.02, "Fc_alpha = {fc}");
    assert!(story.fit.after_cost <= 1.3 * plantc_identify::weights::noise_cost(&story.fit.weights));
}
