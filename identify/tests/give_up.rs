//! A fit that stops short where it cannot reach a cost
//! ([`plantc_identify::GiveUp`], what a diagnosis' screening refit of a
//! candidate gets): on synthetic rotary pendulum records with a Coulomb
//! friction the model lacks, so the fit's minimum is well above the noise.
//!
//! The three cases: told to reach half of what the full fit reaches (no
//! model of the residual can: the part outside the sensitivities' span is
//! about the whole residual there), the fit gives up before converging;
//! told to stop only at a cost of 0 (never), it is the full fit itself, to
//! the bit; and the full fit never reports giving up.

mod common;

use common::simulated::{model, pendulum_text};
use plantc_identify::{fit, FitOptions, GiveUp};

#[test]
fn a_fit_gives_up_only_where_its_model_cannot_reach_the_cost() {
    let text = pendulum_text();
    let m = model(&text);
    let values = vec![("J1".to_string(), 1.35e-3), ("b2".to_string(), 6e-4)];
    let exps =
        common::short_pendulum_records("give_up", &text, "coulomb_friction:alpha=6e-4", values);
    let opts = FitOptions {
        multistart: 0,
        ..FitOptions::default()
    };
    let full = fit(&m, &exps, &opts).expect("fits");
    assert!(!full.gave_up);
    let short = fit(
        &m,
        &exps,
        &FitOptions {
            give_up: Some(GiveUp {
                once_at: f64::INFINITY,
                unless_below: 0.5 * full.after_cost,
            }),
            ..opts.clone()
        },
    )
    .expect("fits");
    let never = fit(
        &m,
        &exps,
        &FitOptions {
            give_up: Some(GiveUp {
                once_at: 0.0,
                unless_below: 0.5 * full.after_cost,
            }),
            ..opts.clone()
        },
    )
    .expect("fits");
    eprintln!(
        "full: cost {:.4e} in {} iterations; told to reach half: cost {:.4e} in {} (gave up: {}); never: {:.4e} in {}",
        full.after_cost,
        full.iterations,
        short.after_cost,
        short.iterations,
        short.gave_up,
        never.after_cost,
        never.iterations
    );
    assert!(short.gave_up);
    assert!(short.iterations < full.iterations);
    // stopped on the way down, not below the minimum the full fit found
    assert!(short.after_cost >= full.after_cost * (1.0 - 1e-6));
    assert!(!never.gave_up);
    assert_eq!(never.after_cost, full.after_cost);
    assert_eq!(never.iterations, full.iterations);
}
