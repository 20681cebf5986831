//! Exact stability interval of the arm-feedback controller `fl_arm` (thesis
//! Ch. VII, reference notes "Arm-feedback controller"): with the Table 3 values
//! and no gear friction (`thesis` set), the closed-loop linearization is
//! asymptotically stable exactly for 0 < a = b < 1.002.

use std::path::Path;

use plantc_derive::analysis::{stability_interval, StabilityInterval};
use plantc_derive::control::{resolve, Derivation};
use plantc_derive::model::{load_model, ParameterValues};

fn sweep(controller: &str, vary: &[&str], set: Option<&str>) -> StabilityInterval {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/rotary_pendulum.plant");
    let loaded = load_model(&path).unwrap_or_else(|e| panic!("{}", e.render()));
    let model = &loaded.model;
    let values = ParameterValues::new(model, set, &[]).expect("values");
    let d = Derivation::new(model).expect("derivation");
    let c = resolve(model, &d, controller, &values).expect("controller");
    stability_interval(model, &d, &c, vary, &values).expect("interval")
}

#[test]
fn fl_arm_a_equals_b_interval() {
    let s = sweep("fl_arm", &["a", "b"], Some("thesis"));
    assert_eq!(
        s.intervals.len(),
        1,
        "{:?} (boundaries {:?})",
        s.intervals,
        s.boundaries
    );
    let (lo, hi) = s.intervals[0];
    let (lo, hi) = (lo.expect("bounded below"), hi.expect("bounded above"));
    // At k = 0 the law is plain feedback linearization and the zero dynamics
    // (a double integrator) put two eigenvalues at 0: the lower end is 0.
    assert!(lo.abs() < 1e-9, "lower end {lo}");
    assert!((hi - 1.002).abs() < 5e-4, "upper end {hi}");
    assert!(s.disagreements.is_empty(), "{:?}", s.disagreements);
    // The closed-loop matrix is affine in k here.
    assert!(s.a_cl.iter().flatten().all(|p| p.0.len() <= 2));
}

#[test]
fn fl_arm_single_gain() {
    // Trivial case: vary only a (b stays 0.5). The interval must contain no
    // negative values of a with b = 0.5 > 0 fixed... just check the sweep is
    // consistent with the closed-loop eigenvalues at sample points.
    let s = sweep("fl_arm", &["a"], Some("thesis"));
    assert!(s.disagreements.is_empty(), "{:?}", s.disagreements);
    for (lo, hi) in &s.intervals {
        if let (Some(l), Some(h)) = (lo, hi) {
            assert!(l < h);
        }
    }
}

#[test]
fn plain_feedback_linearization_never_asymptotically_stable() {
    // feedback_linearization has no arm feedback: varying wn alone leaves the
    // zero dynamics' double integrator, so no k gives asymptotic stability.
    let s = sweep("feedback_linearization", &["wn"], Some("thesis"));
    assert!(s.intervals.is_empty(), "{:?}", s.intervals);
}

#[test]
fn unknown_gain_and_state_feedback_are_errors() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/rotary_pendulum.plant");
    let loaded = load_model(&path).unwrap_or_else(|e| panic!("{}", e.render()));
    let model = &loaded.model;
    let values = ParameterValues::new(model, Some("thesis"), &[]).expect("values");
    let d = Derivation::new(model).expect("derivation");
    let c = resolve(model, &d, "fl_arm", &values).expect("controller");
    assert!(stability_interval(model, &d, &c, &["nope"], &values).is_err());
    let c = resolve(model, &d, "pole_placement", &values).expect("controller");
    assert!(stability_interval(model, &d, &c, &["a"], &values).is_err());
}
