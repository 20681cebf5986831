//! The DFKI double pendulum recording (`../shared/data/real/
//! dfki_double_pendulum_sysid`, BSD-3-Clause): both joints driven, measured
//! torques as input, `models/double_pendulum.plant`. Skipped when the shared
//! data are absent.

mod common;

use std::path::{Path, PathBuf};

use plantc_derive::model::load_model;
use plantc_identify::{
    fit_reading_inputs, read_experiments, ChannelSpec, Experiment, FitOptions, Kind, ReadOptions,
};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The recording (`trajectory_00.csv`) with the measured torques as the
/// inputs; None (and a note) when the shared data are absent.
fn read_trajectory() -> Option<Vec<Experiment>> {
    let file =
        repo().join("../shared/data/real/dfki_double_pendulum_sysid/converted/trajectory_00.csv");
    if !file.is_file() {
        eprintln!("skipping: {} not present", file.display());
        return None;
    }
    let spec = ChannelSpec::new()
        .angle("q1")
        .angle("q2")
        .input("tau1", Kind::Torque)
        .input("tau2", Kind::Torque);
    let opts = ReadOptions {
        rename: vec![
            ("tau1".into(), "tau1_meas".into()),
            ("tau2".into(), "tau2_meas".into()),
        ],
        ..ReadOptions::default()
    };
    let (exps, _) = read_experiments(&[file], &spec, &opts).expect("reads");
    Some(exps)
}

/// Fit % >= 92 on both joints (issue acceptance) with the measured torques
/// as input; the fitted friction is printed next to the lab's identified
/// values (`model_parameters_design_A.0_model_2.0.yml`: viscous 0.001 N m s,
/// Coulomb 0.093 / 0.078 N m in `cf atan(100 q')`, i.e. 0.146 / 0.123 N m
/// at speed; the lab's 2022-08-19 controller files list 0.0928 / 0.0771 N m
/// and 0.0111 / 0.0044 N m s), and each Coulomb level is within 20 % of the
/// lab's (issue 26's DFKI acceptance). The measured torques are samples of
/// a continuous signal, and the fit reads them so (`fit_reading_inputs`,
/// weighted RMS 56.18 held, 54.36 continuous). Measured 2026-11-28: Fc1
/// 0.1265 (-13 %), Fc2 0.1376 (+12 %); held, 0.1286 and 0.1495 (+22 %).
#[test]
fn measured_torques_fit_both_joints() {
    let Some(exps) = read_trajectory() else {
        return;
    };
    let model = load_model(&repo().join("models/double_pendulum.plant"))
        .expect("model loads")
        .model;
    let t = std::time::Instant::now();
    let (r, continuous) =
        fit_reading_inputs(&model, &exps, &FitOptions::default(), &mut |_| {}).expect("fits");
    eprintln!("inputs read as continuous: {continuous:?}");
    assert!(continuous.is_some(), "the measured torques read as sampled");
    eprintln!(
        "fit in {:.1} s; notes {:?}",
        t.elapsed().as_secs_f64(),
        r.notes
    );
    assert!(r.after_cost <= r.before_cost);
    let e = &r.experiments[0];
    eprintln!(
        "fit %: q1 {:.1} -> {:.1}, q2 {:.1} -> {:.1}",
        e.fit_before[0].unwrap_or(f64::NAN),
        e.fit_after[0].unwrap_or(f64::NAN),
        e.fit_before[1].unwrap_or(f64::NAN),
        e.fit_after[1].unwrap_or(f64::NAN)
    );
    let get = |n: &str| r.parameters.iter().find(|p| p.name == n).expect(n);
    eprintln!("| friction | fitted | std error | lab |");
    eprintln!("|---|---|---|---|");
    for (name, lab) in [
        ("b1", "0.001 (controller files: 0.0111)"),
        ("b2", "0.001 (controller files: 0.0044)"),
        (
            "Fc1",
            "0.146 = 0.093 pi/2 (controller files: 0.0928 pi/2 = 0.146)",
        ),
        (
            "Fc2",
            "0.123 = 0.078 pi/2 (controller files: 0.0771 pi/2 = 0.121)",
        ),
    ] {
        let p = get(name);
        eprintln!("| {name} | {:.4e} | {:.1e} | {lab} |", p.value, p.std_error);
    }
    for m in r.identifiability.messages() {
        eprintln!("  {m}");
    }
    assert!(e.fit_after[0].expect("q1 fit") >= 92.0);
    assert!(e.fit_after[1].expect("q2 fit") >= 92.0);
    // dry friction is what this rig has: both levels near the lab's
    for (name, lab) in [("Fc1", 0.146), ("Fc2", 0.123)] {
        let v = get(name).value;
        assert!((v / lab - 1.0).abs() < 0.2, "{name} = {v} against {lab}");
    }
}

/// Acceptance (issue 11): with a viscous-only model (the dry friction taken
/// out of `models/double_pendulum.plant`) and the measured torques, the
/// first finding on the real recording is Coulomb friction on a joint, and
/// its refitted level moves toward the lab's identified friction (table in
/// the output).
#[test]
fn viscous_only_model_first_finds_coulomb_friction() {
    let Some(exps) = read_trajectory() else {
        return;
    };
    let text = common::double_pendulum_without_dry_friction();
    let t = std::time::Instant::now();
    let d = plantc_identify::diagnose(&text, &exps, &FitOptions::default()).expect("diagnoses");
    eprintln!(
        "diagnose in {:.1} s: {}",
        t.elapsed().as_secs_f64(),
        d.verdict_line()
    );
    for n in &d.notes {
        eprintln!("  note: {n}");
    }
    for r in d.ranking.iter().take(5) {
        eprintln!(
            "  {:<28} BIC {:>9.1}  gain {:.2}  {:?}",
            r.candidate.label(),
            r.evidence.bic_gain,
            r.gain,
            r.parameters
                .iter()
                .map(|e| (e.name.clone(), e.value))
                .collect::<Vec<_>>()
        );
    }
    let v = d.verdict.as_ref().expect("a finding");
    assert_eq!(v.effect, "coulomb_friction", "{}", v.label());
    let top = &d.ranking[0];
    let fc = top.parameters[0].value;
    let lab = if v.target == "q1" { 0.146 } else { 0.123 };
    eprintln!("| joint | Coulomb refitted | lab |");
    eprintln!("|---|---|---|");
    eprintln!("| {} | {fc:.4} N m | {lab} N m |", v.target);
    // from the template's start (1e-4 N m) toward the lab's level
    assert!(fc > 0.3 * lab && fc < 3.0 * lab, "Fc = {fc}");
}

/// Issue 26 (item 7 and the DFKI acceptance): `identify` with the
/// viscous-only model finds both joints' dry friction, each within 20 % of
/// the lab's 0.146 / 0.123 N m (the lab's `cf atan(100 q')` at speed, see
/// `measured_torques_fit_both_joints`). The measured torques are read as
/// continuous signals with the first round's effect (the reading's margin
/// plus that of the q2 Coulomb friction it then names beat the friction
/// held), and the second round names q1's. Measured 2026-11-29 (release,
/// 21 s wall): Fc_q1 0.1264 (-13 %), Fc_q2 0.1376 (+12 %). Before the
/// reading was chosen with the round's effect, it was weighed against the
/// effect alone: q2's friction held, then a deadzone on tau2 (weighted RMS
/// ratio 1.144) over q1's friction (1.137), then the continuous reading.
#[test]
fn identify_finds_both_joints_dry_friction() {
    let Some(exps) = read_trajectory() else {
        return;
    };
    let text = common::double_pendulum_without_dry_friction();
    let t = std::time::Instant::now();
    let story = common::identify(&text, &exps);
    let effects = common::final_effects(&story);
    eprintln!(
        "{} in {:.1} s; inputs {:?}; final effects {effects:?}",
        story.stop,
        t.elapsed().as_secs_f64(),
        story.continuous_inputs
    );
    assert!(story.continuous_inputs.is_some());
    for (joint, lab) in [("q1", 0.146), ("q2", 0.123)] {
        assert!(
            effects.contains(&format!("coulomb_friction@{joint}")),
            "{effects:?}"
        );
        let name = format!("Fc_{joint}");
        let fc = common::final_value(&story, &name).expect("in the final model");
        eprintln!("{name} = {fc:.4} N m (lab {lab})");
        assert!((fc / lab - 1.0).abs() < 0.2, "{name} = {fc}");
    }
}
