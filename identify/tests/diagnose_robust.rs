//! The diagnosis where it used to fail silently (issue 11): an estimate set
//! that makes the equation error homogeneous, other sample rates, and a
//! credit that belonged to a restart, not to the effect. Data are made by
//! `synth` (the library call of `plantc synth`), so the truth is known.

mod common;

use common::simulated::pendulum_text;

use plantc_identify::{
    diagnose_with, DiagnoseOptions, Diagnosis, Experiment, FitOptions, SynthOptions, SynthSpec,
};

/// Synthesise `experiments` of `text` with `effects` hidden and read them
/// back as the CLI would.
fn synth(
    test: &str,
    text: &str,
    effects: &[&str],
    values: &[(&str, f64)],
    experiments: &[&str],
    rate: f64,
) -> Vec<Experiment> {
    let spec = SynthSpec {
        options: SynthOptions {
            rate,
            seed: 1,
            ..SynthOptions::default()
        },
        ..common::synth_spec(test, "model.plant", effects, values, experiments, 1)
    };
    common::synthesized(test, text, &spec)
}

fn verdict(d: &Diagnosis) -> Option<String> {
    d.verdict.as_ref().map(|c| c.label())
}

fn show(name: &str, d: &Diagnosis) {
    eprintln!(
        "{name}: {} (baseline {:.2}x the floor)",
        d.verdict_line(),
        d.baseline.after_cost / d.floor
    );
    for n in &d.notes {
        eprintln!("  note: {n}");
    }
    for r in d.ranking.iter().take(4) {
        eprintln!(
            "  {:<28} BIC {:>8.1}  gain {:.2}",
            r.candidate.label(),
            r.evidence.bic_gain,
            r.gain
        );
    }
}

/// A Furuta pendulum in lumped parameters, as a user would mark it:
/// inertias, the pendulum's centre-of-mass distance, both dampings and the
/// input gain all `estimate`. The torque residual is then homogeneous of
/// degree 1 in all six (scaled together they leave the motion unchanged),
/// which made every equation-error score exactly 0 and the verdict a silent
/// "adequate".
const FURUTA: &str = r#"model furuta "Furuta pendulum, lumped parameters"

coordinate theta : angle  "arm angle"
coordinate alpha : angle  "pendulum angle, 0 = upright"
input Vm [V] limits [-10, 10]  "motor voltage"

parameter Jr = 2.5e-4 [kg*m^2]   "arm inertia about the motor axis"   estimate [1e-6, 1e-1]
parameter Jp = 1.3e-4 [kg*m^2]   "pendulum inertia about its pivot"  estimate [1e-7, 1e-1]
parameter mp = 0.024 [kg]        "pendulum mass"
parameter Lr = 0.085 [m]         "arm length"
parameter lp = 0.0645 [m]        "pendulum pivot to centre of mass"  estimate [1e-3, 1]
parameter br = 1.5e-3 [N*m*s/rad] "arm damping"                       estimate [0, 0.1]
parameter bp = 2e-5 [N*m*s/rad]  "pendulum damping"                  estimate [0, 0.01]
parameter K = 5e-3 [N*m/V]       "input gain"                        estimate [1e-5, 1]
parameter g = 9.81 [m/s^2]

kinetic T = 1/2*(Jr + Jp*sin(alpha)^2)*theta'^2 + mp*Lr*lp*cos(alpha)*theta'*alpha' + 1/2*Jp*alpha'^2
potential V = mp*g*lp*cos(alpha)

force theta = K*Vm + viscous_friction(br)
force alpha = viscous_friction(bp)
"#;

/// Acceptance (issue 11): the Furuta-like degenerate estimate set is not
/// blind. Dry friction of 1e-4 N m on the pendulum (the order measured on
/// the real QUBE's free swings, 5.3e-5 N m) is named with all six
/// parameters estimated, and the same data with only two of them estimated
/// (no homogeneity) give the same verdict.
#[test]
fn furuta_estimate_set_is_not_blind() {
    let exps = synth(
        "furuta",
        FURUTA,
        &["coulomb_friction:alpha=1e-4"],
        &[("Jr", 2.9e-4), ("lp", 0.066), ("bp", 3e-5)],
        &[
            "free_swing:alpha0=150deg,duration=8,name=swing",
            "driven:alpha0=180deg,duration=8,seed=2,rms=1.5,name=driven",
        ],
        500.0,
    );
    let d = diagnose_with(FURUTA, &exps, &DiagnoseOptions::default()).expect("diagnoses");
    show("furuta, six parameters estimated", &d);
    assert!(
        d.notes.iter().any(|n| n.contains("homogeneous")),
        "the scale degeneracy is reported: {:?}",
        d.notes
    );
    assert!(
        d.ranking.iter().any(|r| r.evidence.bic_gain > 0.0),
        "the equation-error ranking is not blind"
    );
    assert_eq!(verdict(&d).as_deref(), Some("coulomb_friction@alpha"));
    // a set without the homogeneity: the pendulum inertia and the input
    // gain fixed (at their true values; the others differ from nominal)
    let small = FURUTA
        .lines()
        .map(|l| {
            if ["Jp ", "K "]
                .iter()
                .any(|p| l.starts_with(&format!("parameter {p}")))
            {
                l.split(" estimate").next().unwrap_or(l)
            } else {
                l
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    let d2 = diagnose_with(&small, &exps, &DiagnoseOptions::default()).expect("diagnoses");
    show("furuta, four parameters estimated", &d2);
    assert!(d2.notes.iter().all(|n| !n.contains("homogeneous")));
    assert_eq!(verdict(&d2), verdict(&d));
}

/// Acceptance (issue 11, reliability reproducer 15): the same physics
/// (Coulomb friction 6e-4 N m on the pendulum, one driven run, the rig off
/// nominal) gives the same verdict at 100, 500, 2000 and 10,000 Hz. Before
/// the windows were in physical time, 100, 2000 and 10,000 Hz said
/// "adequate".
#[test]
fn same_verdict_from_100_hz_to_10_khz() {
    let text = pendulum_text();
    let mut verdicts = Vec::new();
    for rate in [100.0, 500.0, 2000.0, 10000.0] {
        let exps = synth(
            &format!("rate{rate}"),
            &text,
            &["coulomb_friction:alpha=6e-4"],
            &[
                ("J1", 1.35e-3),
                ("l2", 0.161),
                ("b1", 2.9e-3),
                ("b2", 6e-4),
                ("Fg1", 0.013),
            ],
            &["driven:alpha0=180deg,band=0.3-6,rms=1.5,seed=3,duration=8,name=driven"],
            rate,
        );
        let d = diagnose_with(&text, &exps, &DiagnoseOptions::default()).expect("diagnoses");
        show(&format!("{rate} Hz"), &d);
        verdicts.push((rate, verdict(&d)));
    }
    for (rate, v) in &verdicts {
        assert_eq!(
            v.as_deref(),
            Some("coulomb_friction@alpha"),
            "{rate} Hz: {verdicts:?}"
        );
    }
}

/// Acceptance (issue 11): an effect is never credited with a gain that
/// belongs to a restart. The baseline fit is cut short (2 iterations from a
/// start far off) while a candidate's second start, from the nominal values
/// that made these clean data, converges: before the re-baseline rule the
/// leading candidate was credited with the whole difference although its
/// parameter stayed negligible.
#[test]
fn a_restart_is_not_credited_to_an_effect() {
    let text = pendulum_text();
    let exps = synth(
        "restart",
        &text,
        &[],
        &[],
        &[
            "free_swing:alpha0=150deg,duration=6,name=swing",
            "driven:alpha0=180deg,duration=6,seed=4,rms=1.2,name=driven",
        ],
        500.0,
    );
    let m = common::simulated::model(&text);
    let mut start: Vec<f64> = m.parameters.iter().map(|p| p.value).collect();
    for (p, v) in m.parameters.iter().zip(start.iter_mut()) {
        match p.name.as_str() {
            "b2" => *v = 0.02,
            "l2" => *v = 0.19,
            "J1" => *v = 3e-3,
            _ => {}
        }
    }
    let opts = DiagnoseOptions {
        fit: FitOptions {
            start: Some(start),
            max_iterations: 2,
            multistart: 0,
            ..FitOptions::default()
        },
        ..DiagnoseOptions::default()
    };
    let d = diagnose_with(&text, &exps, &opts).expect("diagnoses");
    show("clean data, baseline cut short", &d);
    assert_eq!(verdict(&d), None, "nothing is missing from these data");
}

/// The rig of the vocabulary test: base parameters off nominal.
const RIG: &[(&str, f64)] = &[
    ("J1", 1.35e-3),
    ("l2", 0.161),
    ("b1", 2.9e-3),
    ("b2", 6e-4),
    ("Fg1", 0.013),
];

const THREE_RUNS: &[&str] = &[
    "free_swing:alpha0=120deg,duration=8,name=large",
    "free_swing:alpha0=160deg,duration=8,name=small",
    "driven:alpha0=180deg,duration=8,seed=7,rms=1.2,name=driven",
];

/// Acceptance (issue 11): a 4 ms input delay is found and estimated within
/// 10 % (it used to rank first by equation error and stall at 3 ms in the
/// refit, 1.53x, so the verdict was "adequate" 10x above the floor).
#[test]
fn a_4_ms_input_delay_is_found_within_10_percent() {
    let text = pendulum_text();
    let exps = synth(
        "delay",
        &text,
        &["input_delay:Vm=4e-3"],
        RIG,
        THREE_RUNS,
        500.0,
    );
    let d = diagnose_with(&text, &exps, &DiagnoseOptions::default()).expect("diagnoses");
    show("4 ms input delay", &d);
    assert_eq!(verdict(&d).as_deref(), Some("input_delay@Vm"));
    let td = d.ranking[0]
        .parameters
        .iter()
        .find(|e| e.name.starts_with("Td"))
        .expect("Td estimated")
        .value;
    eprintln!("Td = {td:.4e} s (truth 4e-3)");
    assert!((td / 4e-3 - 1.0).abs() < 0.1, "Td = {td}");
}

/// Acceptance (issue 11): two effects at once, Coulomb friction on the
/// pendulum and a 4 ms input delay, are named in turn by `identify`, and
/// the residual ends near the noise floor.
///
/// Coulomb friction with quadratic drag on the pendulum (the issue's
/// example) was tried first: with drag 1e-5 N m s^2 the re-estimated
/// viscous damping absorbs the drag and Coulomb alone ends below the floor
/// (3.04e-3 against 3.18e-3); with 1e-4, Stribeck friction plus the
/// re-estimated damping ends below the floor too (2.94e-3 against 3.21e-3).
/// On these runs the data cannot tell those apart, so one effect is the
/// right answer there; at 5e-4 N m and 1.5e-4 N m s^2 see
/// `coulomb_friction_and_drag_end_named_as_such`.
#[test]
fn two_effects_are_named_in_turn_and_the_residual_ends_near_the_floor() {
    let text = pendulum_text();
    let exps = synth(
        "two",
        &text,
        &["coulomb_friction:alpha=4e-4", "input_delay:Vm=4e-3"],
        RIG,
        THREE_RUNS,
        500.0,
    );
    let opts = plantc_identify::StoryOptions {
        max_effects: 3,
        ..Default::default()
    };
    let story = plantc_identify::identify(&text, &exps, &opts, &mut |_| {}).expect("identifies");
    let named: Vec<String> = story
        .rounds
        .iter()
        .filter_map(|r| r.effect.as_ref().map(|e| e.label()))
        .collect();
    let floor = plantc_identify::weights::noise_cost(&story.fit.weights);
    common::show_rounds(&story);
    eprintln!("floor {floor:.3e}");
    eprintln!("stop: {}", story.stop);
    assert!(
        named.len() >= 2
            && named[..2].contains(&"coulomb_friction@alpha".to_string())
            && named[..2].contains(&"input_delay@Vm".to_string()),
        "{named:?}"
    );
    assert!(
        story.fit.after_cost <= 1.3 * floor,
        "final cost {:.3e} vs floor {floor:.3e}",
        story.fit.after_cost
    );
}

/// The issue's two-effect example, Coulomb friction and quadratic drag on
/// the pendulum (5e-4 N m and 1.5e-4 N m s^2, the rate survey's rig):
/// round 1 takes a Stribeck friction over the Coulomb friction (4.21x
/// against 2.96x: its hump stands in for part of the drag), round 2 the
/// drag; with the drag in, the Stribeck friction does no better than the
/// Coulomb friction (1.01x) and the story replaces it, so both effects are
/// named as they are and estimated (Fc 5.01e-4, cd 1.53e-4 when written).
#[test]
fn coulomb_friction_and_drag_end_named_as_such() {
    let text = pendulum_text();
    let exps = synth(
        "coulomb_drag",
        &text,
        &["coulomb_friction:alpha=5e-4", "quadratic_drag:alpha=1.5e-4"],
        &[
            ("J1", 1.3e-3),
            ("l2", 0.16),
            ("b1", 3.2e-3),
            ("b2", 1.1e-3),
            ("Fg1", 0.012),
        ],
        &[
            "free_swing:alpha0=115deg,duration=10,name=large",
            "free_swing:alpha0=155deg,duration=10,name=small",
            "driven:alpha0=180deg,duration=10,seed=5,rms=1.2,name=driven",
        ],
        500.0,
    );
    let opts = plantc_identify::StoryOptions::default();
    let story = plantc_identify::identify(&text, &exps, &opts, &mut |_| {}).expect("identifies");
    common::show_rounds(&story);
    for s in &story.simplifications {
        eprintln!(
            "round {}: {} -> {} ({:.3e} -> {:.3e})",
            s.round,
            s.from.label(),
            s.to.label(),
            s.cost_with,
            s.cost_simpler
        );
    }
    assert_coulomb_and_drag(&story);
}

/// `story` ends with Coulomb friction and quadratic drag on the pendulum,
/// no Stribeck friction, within 5 % and 10 % of the synth truth (5e-4 N m,
/// 1.5e-4 N m s^2), at the noise floor.
fn assert_coulomb_and_drag(story: &plantc_identify::Story) {
    let floor = plantc_identify::weights::noise_cost(&story.fit.weights);
    assert!(
        story.fit.after_cost <= 1.3 * floor,
        "final cost {:.3e} vs floor {floor:.3e}",
        story.fit.after_cost
    );
    let model = plantc_identify::diagnose::model_from_text("final", &story.text).expect("checks");
    let value = |name: &str| {
        model
            .parameters
            .iter()
            .position(|p| p.name == name)
            .map(|i| story.fit.base[i])
    };
    assert!(model.parameter("Fs_alpha").is_none(), "{}", story.text);
    let fc = value("Fc_alpha").expect("Coulomb friction on alpha");
    let cd = value("cd_alpha").expect("quadratic drag on alpha");
    eprintln!("Fc {fc:.4e} (truth 5e-4), cd {cd:.4e} (truth 1.5e-4)");
    assert!((fc / 5e-4 - 1.0).abs() < 0.05, "Fc = {fc}");
    assert!((cd / 1.5e-4 - 1.0).abs() < 0.1, "cd = {cd}");
}

/// The same two effects on the survey's second rig (J1 +8 %, l2 -4 %, b2
/// +8 %, other release angles): round 1 takes a Stribeck friction, round 2's
/// diagnosis finds that model a minimum 2x lower from the drag candidate's
/// values and credits the drag nothing against it; the story keeps that
/// better fit (before: the round-1 fit, 2.2x the floor's RMSE). That minimum
/// is a Stribeck friction with `vs` at its 10 rad/s bound and `Fc > Fs`,
/// whose expansion is a Coulomb friction plus a quadratic drag; fitted to no
/// Stribeck shape, it is replaced by the Coulomb friction and diagnosed
/// again, which names the drag: Fc 4.99e-4, cd 1.49e-4 when written (truth
/// 5e-4, 1.5e-4), at the floor.
#[test]
fn coulomb_friction_and_drag_on_another_rig_end_named_as_such() {
    let text = pendulum_text();
    let exps = synth(
        "coulomb_drag_2",
        &text,
        &["coulomb_friction:alpha=5e-4", "quadratic_drag:alpha=1.5e-4"],
        &[
            ("J1", 1.3e-3 * 1.08),
            ("l2", 0.16 * 0.96),
            ("b1", 3.2e-3),
            ("b2", 1.1e-3 * 1.08),
            ("Fg1", 0.012),
        ],
        &[
            "free_swing:alpha0=120deg,duration=10,name=large",
            "free_swing:alpha0=160deg,duration=10,name=small",
            "driven:alpha0=180deg,duration=10,seed=6,rms=1.2,name=driven",
        ],
        500.0,
    );
    let story = plantc_identify::identify(
        &text,
        &exps,
        &plantc_identify::StoryOptions::default(),
        &mut |_| {},
    )
    .expect("identifies");
    let labels: Vec<&str> = story.stages.iter().map(|s| s.label.as_str()).collect();
    eprintln!("{labels:?}; {}", story.stop);
    assert_coulomb_and_drag(&story);
}

/// A mild Stribeck hump on the arm, over the gearbox friction the model
/// already estimates (`Fg1`): sliding level 0.015 N m, static 0.019 N m
/// (1.27x, a common ratio for a geared joint; the rate survey's arm case
/// has 3.5x), `vs` 0.2 rad/s. Every hump's linearised coefficient came out
/// with the sign of no friction, so the equation error gave the candidate
/// no column; a quadratic drag on the arm passed by a partial gain (1.69x)
/// and the next round was left 3.9x above the floor, unexplained. The
/// simulation-error refit of the Stribeck friction reaches the floor (by
/// hand: `plantc fit` with the effect added, sliding 0.0150, static 0.0191,
/// `vs` 0.1999): it must be named, with the hump's height and `vs` within
/// 15 % of the synth truth (4e-3 N m, 0.2 rad/s). Its refit reaches the
/// floor with the sliding level in `Fg1` (0.0150) and the hump's own `Fc`
/// at its bound 0: the form test counts the model's dry friction under the
/// hump (measured 2026-11-28: hump 4.01e-3, `vs` 0.197).
#[test]
fn a_mild_stribeck_hump_on_the_arm_is_named() {
    let (fc, fs, vs) = stribeck_named(
        "stribeck_arm_mild",
        "stribeck_friction:theta:Fc=4e-3,Fs=8e-3,vs=0.2",
        &[
            ("J1", 1.45e-3),
            ("l2", 0.159),
            ("b1", 2.6e-3),
            ("b2", 7e-4),
            ("Fg1", 0.011),
        ],
        &[
            "free_swing:alpha0=110deg,duration=15,name=fs1",
            "free_swing:alpha0=160deg,duration=15,name=fs2",
            "driven:alpha0=180deg,band=0.2-5,rms=1.2,seed=7,duration=15,name=driven",
        ],
    );
    let hump = fs - fc;
    eprintln!("hump {hump:.4e} N m (truth 4e-3), vs {vs:.4} rad/s (truth 0.2)");
    assert!((hump / 4e-3 - 1.0).abs() < 0.15, "hump = {hump}");
    assert!((vs / 0.2 - 1.0).abs() < 0.15, "vs = {vs}");
}

/// A Stribeck hump on the pendulum (synth truth Fc 4e-4, Fs 1.1e-3 N m,
/// vs 0.1 rad/s: bench/identify_cases.sh's `stribeck_alpha`, its rig) is named, its
/// levels within 15 % and `vs` within 20 % (the hump's width and height
/// trade against each other). The Stribeck refit started from the Coulomb
/// fit once kept that fit's nuisance too: pendulum zeros of -1e-3 rad that
/// stood in for part of the hump held the refit at 2.27 noise RMS, and the
/// Coulomb friction was named (then two drags); from the Coulomb fit's
/// parameters with the nuisance estimated again it reaches the floor
/// (0.82; measured 2026-11-28 on the bench case).
#[test]
fn a_stribeck_hump_on_the_pendulum_is_named() {
    let (fc, fs, vs) = stribeck_named(
        "stribeck_pendulum",
        "stribeck_friction:alpha:Fc=4e-4,Fs=1.1e-3,vs=0.1",
        &[
            ("J1", 1.35e-3),
            ("l2", 0.161),
            ("b1", 2.9e-3),
            ("b2", 6e-4),
            ("Fg1", 0.013),
        ],
        &[
            "free_swing:alpha0=120deg,duration=20,name=free_swing_large",
            "free_swing:alpha0=165deg,duration=20,name=free_swing_small",
            "driven:alpha0=180deg,band=0.3-6,rms=1.5,seed=3,duration=20",
        ],
    );
    eprintln!("Fc {fc:.4e}, Fs {fs:.4e} N m (truth 4e-4, 1.1e-3), vs {vs:.4} rad/s (truth 0.1)");
    assert!((fc / 4e-4 - 1.0).abs() < 0.15, "Fc = {fc}");
    assert!((fs / 1.1e-3 - 1.0).abs() < 0.15, "Fs = {fs}");
    assert!((vs / 0.1 - 1.0).abs() < 0.2, "vs = {vs}");
}

/// The pendulum rig at `values` with Stribeck friction `effect`
/// (`stribeck_friction:TARGET:...`) hidden, 500 Hz: the diagnosis must name
/// that Stribeck friction; its fitted `(Fc, Fs, vs)`.
fn stribeck_named(
    test: &str,
    effect: &str,
    values: &[(&str, f64)],
    experiments: &[&str],
) -> (f64, f64, f64) {
    let target = effect.split(':').nth(1).expect("a target");
    let text = pendulum_text();
    let exps = synth(test, &text, &[effect], values, experiments, 500.0);
    let d = diagnose_with(&text, &exps, &DiagnoseOptions::default()).expect("diagnoses");
    show(test, &d);
    let want = format!("stribeck_friction@{target}");
    assert_eq!(
        verdict(&d).as_deref(),
        Some(want.as_str()),
        "{}",
        d.verdict_line()
    );
    let top = &d.ranking[0];
    let value = |base: &str| {
        let name = format!("{base}_{target}");
        top.parameters
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.value)
            .expect("a Stribeck parameter")
    };
    (value("Fc"), value("Fs"), value("vs"))
}

/// The held-out-style rig of the tests below (values off nominal, a
/// driven run and two free swings of 15 s at 500 Hz) with `effects`
/// hidden, through the whole story.
fn story_on_held_out_rig(test: &str, effects: &[&str]) -> plantc_identify::Story {
    let text = pendulum_text();
    let exps = synth(
        test,
        &text,
        effects,
        &[
            ("J1", 1.45e-3),
            ("l2", 0.159),
            ("b1", 2.6e-3),
            ("b2", 7e-4),
            ("Fg1", 0.011),
        ],
        &[
            "driven:alpha0=180deg,band=0.2-5,rms=1.2,seed=7,duration=15,name=driven",
            "free_swing:alpha0=110deg,duration=15,name=fs1",
            "free_swing:alpha0=160deg,duration=15,name=fs2",
        ],
        500.0,
    );
    let story = common::identify(&text, &exps);
    eprintln!("{}", story.stop);
    story
}

/// The final model of `story`, checked to end at the noise floor (1.3x),
/// and its fitted value of parameter `name`.
fn final_at_floor(story: &plantc_identify::Story) -> impl Fn(&str) -> Option<f64> + '_ {
    let floor = plantc_identify::weights::noise_cost(&story.fit.weights);
    assert!(
        story.fit.after_cost <= 1.3 * floor,
        "final cost {:.3e} vs floor {floor:.3e}",
        story.fit.after_cost
    );
    move |name: &str| common::final_value(story, name)
}

/// Two effects that each hide the other: a spring on the arm (2.5e-3 N m
/// per rad) and dry friction in the pendulum's joint (5e-4 N m). Alone, the
/// Coulomb friction's refit gains 1.45x and the spring's 1.12x, 17.5x above
/// the noise floor: under the old fixed-gain thresholds no candidate passed
/// and the story stopped with an unexplained residual. Each alone takes a
/// real, effective-sample-significant part of the residual above the
/// noise, so the decision rule names one, and the next round the other:
/// both are found, each within 5 % of the synth truth, the final cost at
/// the floor.
#[test]
fn two_effects_that_hide_each_other_are_found() {
    let story = story_on_held_out_rig(
        "spring_arm_coulomb_pendulum",
        &["spring:theta=2.5e-3", "coulomb_friction:alpha=5e-4"],
    );
    // the final model's effects (round 1 may name a Stribeck friction that
    // the end steps simplify to the Coulomb friction it is once the spring
    // is in)
    let found = common::final_effects(&story);
    assert!(
        found.iter().any(|l| l == "spring@theta")
            && found.iter().any(|l| l == "coulomb_friction@alpha"),
        "{found:?}; {}",
        story.stop
    );
    let value = final_at_floor(&story);
    let (k, fc) = (value("k_theta").expect("k"), value("Fc_alpha").expect("Fc"));
    eprintln!("k {k:.4e} (truth 2.5e-3), Fc {fc:.4e} (truth 5e-4)");
    assert!((k / 2.5e-3 - 1.0).abs() < 0.05, "k = {k}");
    assert!((fc / 5e-4 - 1.0).abs() < 0.05, "Fc = {fc}");
}

/// A spring on the pendulum (2e-3 N m/rad) and a 4 ms input delay. A
/// spring about the upright acts near the hanging position like a constant
/// torque: it shifts every record's resting angle alike, so the per-file
/// zeros agreed and round 1 named a sensor offset on alpha, whose own fit
/// was worse than the round's baseline (a shared zero in place of per-file
/// ones); rounds 2 and 3 then named the spring and the delay, and the offset
/// ended at -4.9e-5 rad. The story's end step removes an earlier effect
/// that did not pay for its parameters in its own round when the model
/// does as well without it: the final model has the spring and the delay,
/// no sensor offset, within 5 % of the synth truth, at the floor.
#[test]
fn an_effect_the_later_ones_make_unnecessary_is_removed() {
    let story = story_on_held_out_rig(
        "spring_pendulum_delay",
        &["input_delay:Vm=4e-3", "spring:alpha=2e-3"],
    );
    for r in &story.removals {
        eprintln!(
            "removed {} (round {}): {:.4e} -> {:.4e}",
            r.effect.label(),
            r.round,
            r.cost_with,
            r.cost_without
        );
    }
    let value = final_at_floor(&story);
    assert!(value("d_alpha").is_none(), "{}", story.text);
    let (k, td) = (value("k_alpha").expect("k"), value("Td_Vm").expect("Td"));
    eprintln!("k {k:.4e} (truth 2e-3), Td {td:.4e} (truth 4e-3)");
    assert!((k / 2e-3 - 1.0).abs() < 0.05, "k = {k}");
    assert!((td / 4e-3 - 1.0).abs() < 0.05, "Td = {td}");
    assert_eq!(story.effects_added(), 2);
}
