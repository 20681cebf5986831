//! Acceptance (issue 11): each effect real rigs need -- cogging on the arm,
//! the actuator's saturation, the drive's speed limit, an added inertia on
//! the pendulum -- is named first by the full diagnosis in at least 90 % of
//! synthetic rigs, and clean rigs get no finding; so is the rest of the
//! vocabulary (one known weak spot, see
//! `stribeck_friction_on_the_arm_is_mostly_named_first`). Each case varies what a
//! held-out rig would: the effect's size (0.7x to 1.4x the vocabulary's),
//! the true base parameters (J1, l2, b2 within 10 %), the multisine's
//! phases and the release angles. The truth is the synth spec of each case.
//!
//! `PLANTC_RATE_CASES` sets the cases per effect (default 5, where 90 %
//! means all of them); `PLANTC_RATE_CASES=10 cargo test --release -p
//! plantc-identify --test diagnose_rates -- --nocapture` is the long run.

mod common;

use common::simulated::pendulum_text;

use plantc_identify::diagnose::{diagnose_with, DiagnoseOptions};

fn cases() -> usize {
    std::env::var("PLANTC_RATE_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5)
}

/// Case `k`'s variation: effect size factor, base values, seeds, angles.
fn variation(k: usize) -> (f64, Vec<(String, f64)>, u64, [u32; 2]) {
    const SIZE: [f64; 10] = [1.0, 0.7, 1.4, 0.85, 1.2, 0.75, 1.3, 0.9, 1.1, 0.8];
    const DEV: [f64; 10] = [0.0, 0.08, -0.06, 0.04, -0.1, 0.1, -0.03, 0.06, -0.08, 0.02];
    let d = DEV[k % 10];
    let base = vec![
        ("J1".to_string(), 1.3e-3 * (1.0 + d)),
        ("l2".to_string(), 0.16 * (1.0 - 0.5 * d)),
        ("b1".to_string(), 3.2e-3),
        ("b2".to_string(), 1.1e-3 * (1.0 + d)),
        ("Fg1".to_string(), 0.012),
    ];
    let angles = [115 + 5 * (k as u32 % 3), 155 + 5 * (k as u32 % 4)];
    (SIZE[k % 10], base, 5 + k as u64, angles)
}

/// Synthesise case `k` with `effect` (empty: clean) and diagnose it with
/// the model's defaults: the verdict's label, or `adequate`/`unexplained`.
fn diagnose_case(test: &str, k: usize, effect: &str) -> String {
    let text = pendulum_text();
    let (_, base, seed, [large, small]) = variation(k);
    let dir = format!("{test}_{k}");
    let experiments = [
        format!("free_swing:alpha0={large}deg,duration=10,name=large"),
        format!("free_swing:alpha0={small}deg,duration=10,name=small"),
        format!("driven:alpha0=180deg,duration=10,seed={seed},rms=1.2,name=driven"),
    ];
    let exps = common::synth_pendulum(&dir, &text, effect, base, &experiments, seed);
    let _ = std::fs::remove_dir_all(common::scratch(&dir));
    let d = diagnose_with(&text, &exps, &DiagnoseOptions::default()).expect("diagnoses");
    match &d.verdict {
        Some(c) => c.label(),
        None if d.unexplained() => "unexplained".into(),
        None => "adequate".into(),
    }
}

/// Run the cases of one effect (`{v}` in `spec` is replaced by `size` times
/// the case's size factor) and require `want` first in >= 90 %.
fn rate(test: &str, spec: &str, size: f64, want: &str) {
    rate_at_least(test, spec, size, want, 0.9);
}

/// [`rate`] with another required share.
fn rate_at_least(test: &str, spec: &str, size: f64, want: &str, share: f64) {
    let n = cases();
    let mut right = 0;
    for k in 0..n {
        let (f, ..) = variation(k);
        let effect = spec.replace("{v}", &format!("{:.4e}", size * f));
        let found = diagnose_case(test, k, &effect);
        let ok = found == want;
        right += usize::from(ok);
        eprintln!(
            "{test} case {k}: {effect:<45} found {found:<24} {}",
            if ok { "ok" } else { "MISS" }
        );
    }
    eprintln!("{test}: {want} first in {right} of {n}");
    assert!(
        right as f64 >= share * n as f64,
        "{test}: {want} first in only {right} of {n}"
    );
}

#[test]
fn clean_rigs_get_no_finding() {
    let n = cases();
    let mut quiet = 0;
    for k in 0..n {
        let found = diagnose_case("rate_clean", k, "");
        quiet += usize::from(found == "adequate");
        eprintln!("rate_clean case {k}: found {found}");
    }
    eprintln!("rate_clean: no finding in {quiet} of {n}");
    assert!(quiet as f64 >= 0.9 * n as f64, "a finding on clean data");
}

#[test]
fn cogging_is_named_first() {
    rate(
        "rate_cogging",
        "cogging:theta:A={v},N=24,phi=0.5",
        0.01,
        "cogging@theta",
    );
}

#[test]
fn actuator_saturation_is_named_first() {
    rate("rate_saturation", "saturation:Vm={v}", 1.5, "saturation@Vm");
}

#[test]
fn speed_limit_is_named_first() {
    rate(
        "rate_speed_limit",
        "speed_limit:theta:vmax={v},c=0.1",
        1.0,
        "speed_limit@theta",
    );
}

#[test]
fn added_inertia_is_named_first() {
    rate(
        "rate_inertia",
        "added_inertia:alpha={v}",
        3e-4,
        "added_inertia@alpha",
    );
}

// The rest of the vocabulary, varied the same way (the sizes are the
// vocabulary test's). Measured when added (stop 21, release, 5 cases each):
// before that stop's changes the Stribeck friction on the pendulum was
// first in 3 of 5 (Coulomb friction credited: the Stribeck refit stalled in
// the Coulomb-like minimum), the deadzone 4 of 5 (a 0.56 V deadzone trapped
// its refit from the distorted baseline), the spring on the pendulum 4 of 5
// (a sensor offset credited against its own baseline while its refit sat
// 10x above the spring's), the drag on the arm 4 of 5 (baseline 1.8x the
// floor, the drag down to it by 1.92x, called adequate); after, 5 of 5 each,
// clean 5 of 5.

#[test]
fn coulomb_friction_on_the_pendulum_is_named_first() {
    rate(
        "rate_coulomb_alpha",
        "coulomb_friction:alpha={v}",
        5e-4,
        "coulomb_friction@alpha",
    );
}

#[test]
fn stribeck_friction_on_the_pendulum_is_named_first() {
    rate(
        "rate_stribeck_alpha",
        "stribeck_friction:alpha:Fc={v},Fs=1.2e-3,vs=0.1",
        4e-4,
        "stribeck_friction@alpha",
    );
}

/// The known weak spot: stiction on the arm 9-19x its Coulomb level on
/// top of the model's gearbox friction sticks the arm, the equation error
/// cannot see it (the stuck arm's torque is a constraint force) and the
/// refits stall (Fs = 0.056 N m: a spring on the arm credited at 1.50x).
/// Measured 3 of 5 (stop 21: cases 2 and 3 missed; case 3 is borderline,
/// found by `plantc diagnose` on the same spec synthesized from the CLI,
/// whose base values differ in the last digits); 4 of 5 since the leaders
/// are refitted in turn until one reaches the noise floor (case 2, Fs =
/// 0.056 N m, still a spring); required 3 of 5 so a regression shows.
/// Measured 1 of 5 under the one decision rule until the form test counted
/// the model's own gearbox friction as the sliding level under the hump
/// (the refit leaves the hump's `Fc` at 0, `Fg1` holding it); 4 of 5 since
/// (2026-11-28). 129 s
/// for this file's 16 tests x 5 cases (release, two threads; 278 s before
/// that change).
#[test]
fn stribeck_friction_on_the_arm_is_mostly_named_first() {
    rate_at_least(
        "rate_stribeck_theta",
        "stribeck_friction:theta:Fc=3e-3,Fs={v},vs=0.3",
        4e-2,
        "stribeck_friction@theta",
        0.6,
    );
}

#[test]
fn quadratic_drag_on_the_pendulum_is_named_first() {
    rate(
        "rate_drag_alpha",
        "quadratic_drag:alpha={v}",
        1.5e-4,
        "quadratic_drag@alpha",
    );
}

#[test]
fn quadratic_drag_on_the_arm_is_named_first() {
    rate(
        "rate_drag_theta",
        "quadratic_drag:theta={v}",
        1e-3,
        "quadratic_drag@theta",
    );
}

#[test]
fn spring_on_the_arm_is_named_first() {
    rate(
        "rate_spring_theta",
        "spring:theta={v}",
        0.05,
        "spring@theta",
    );
}

#[test]
fn spring_on_the_pendulum_is_named_first() {
    rate(
        "rate_spring_alpha",
        "spring:alpha={v}",
        0.005,
        "spring@alpha",
    );
}

#[test]
fn sensor_offset_is_named_first() {
    rate(
        "rate_offset",
        "sensor_offset:alpha={v}",
        0.03,
        "sensor_offset@alpha",
    );
}

#[test]
fn input_offset_is_named_first() {
    rate(
        "rate_input_offset",
        "input_offset:Vm={v}",
        0.3,
        "input_offset@Vm",
    );
}

#[test]
fn input_delay_is_named_first() {
    rate("rate_delay", "input_delay:Vm={v}", 4e-3, "input_delay@Vm");
}

#[test]
fn deadzone_is_named_first() {
    rate("rate_deadzone", "deadzone:Vm={v}", 0.4, "deadzone@Vm");
}
