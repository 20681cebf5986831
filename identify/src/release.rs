//! Where a record starts to follow the model: a release transient at the
//! start.
//!
//! A rig is often started by hand: the QUBE recordings begin when the user
//! has raised the pendulum to 5 degrees off upright, and for the next
//! 0.2-0.3 s the hand still holds it (the arm stays put under -10..-2 V
//! that would turn a free arm by a radian). No initial state lets a model
//! without that hand follow those samples, and a simulation started there
//! is thrown off for a second or two (the clipped episodes' whole-record
//! fit % was 60-80 for this alone). The force is unknown and acts only at
//! the start; the samples it acts on are not the model's to explain.
//!
//! **The rule.** The record is cut into windows of [`OBSERVER_WINDOW`] (the
//! span over which a start is estimated), each started from the state that
//! lets the model follow it best (the observer of [`crate::fit`], every
//! window's whole state free within its data prior, parameters and sensor
//! zeros held; in closed loop when the fit runs one). A window's misfit is
//! its weighted residual sum of squares `S` per weighted sample (weights
//! `1 / noise`, so pure noise gives one). The record has a release
//! transient when its first window is
//! - *unexplained*: `S` above what predicting the window's mean would
//!   leave, noise allowed for (its weighted spread about its mean plus one
//!   per sample): no start lets the model come closer to the data than
//!   their own mean does (at rest both are near one: never; a missing
//!   effect strongest at the start, a drag in a free decay, leaves a
//!   fraction of the motion, not more than all of it); and
//! - *the worst of the record*: `S` above every later window's. Where the
//!   model follows the record equally well throughout, the first window is
//!   the worst with probability about one in the number of windows.
//!
//! The transient then lasts while the next window is still the worst of the
//! record from there on (a hand that lets go inside a window leaves that
//! window worse than any after it), and the record starts at the first
//! window that is not.
//!
//! On the 16 QUBE episodes the held windows have `rho` 100-130 against at
//! most 3-8 for any later window; the unclipped starts (a gentler hand)
//! pass the first test.
//!
//! Everything before the start is left out of the fit's cost, the
//! simulation and the fit % (the reports say so, with the time).

use crate::fit::{Setup, OBSERVER_WINDOW};

/// The first sample each record's model is asked to follow (0 when the
/// record follows it from the start), at the setup's start values.
pub(crate) fn record_starts(setup: &Setup<'_>) -> Vec<usize> {
    let records = setup.sigs.len();
    // The first windows alone first: a record whose first window is
    // explained has no transient, whatever its later windows (most records;
    // a few windows' work instead of the whole record's). The first
    // windows' starts are observed on their own here, which only settles
    // them further than beside every later window.
    let mut firsts = setup.nuisance_problem(Some(OBSERVER_WINDOW));
    firsts.blocks.dedup_by_key(|b| b.exp);
    let Some(first) = windows(setup, &firsts) else {
        return vec![0; records];
    };
    let suspect: Vec<bool> = (0..records)
        .map(|e| first.iter().any(|w| w.0 == e && w.2))
        .collect();
    if !suspect.contains(&true) {
        return vec![0; records];
    }
    let Some(windows) = windows(setup, &setup.nuisance_problem(Some(OBSERVER_WINDOW))) else {
        return vec![0; records];
    };
    (0..records)
        .map(|e| {
            let w: Vec<&Window> = windows.iter().filter(|w| w.0 == e).collect();
            // the largest misfit of the windows after each one
            let mut later = vec![f64::NEG_INFINITY; w.len()];
            for j in (0..w.len().saturating_sub(1)).rev() {
                later[j] = later[j + 1].max(w[j + 1].3);
            }
            let worst = |j: usize| w[j].3 > later[j];
            if !suspect[e] || w.len() < 2 || !(w[0].2 && worst(0)) {
                return 0;
            }
            let mut j = 1;
            while j + 1 < w.len() && worst(j) {
                j += 1;
            }
            w[j].1
        })
        .collect()
}

/// One window: (experiment, first sample, unexplained, misfit per sample).
type Window = (usize, usize, bool, f64);

/// Every block of `pb` (windows of [`OBSERVER_WINDOW`]) started from the
/// state that lets the model follow it best (the observer, parameters and
/// zeros held), judged; None when the observer or the model's offsets
/// cannot be computed.
fn windows(setup: &Setup<'_>, pb: &crate::problem::Problem<'_>) -> Option<Vec<Window>> {
    let n = setup.model().coordinates.len();
    let mut pt = setup.start_point(pb, &setup.free_start());
    if !crate::fit::observe_nuisance(setup, pb, &mut pt, false) {
        return None;
    }
    let full = pb.full_at(&pt.g);
    let model_off = setup.sim.model_offsets(&full).ok()?;
    Some(crate::parallel::par_map(pb.blocks.len(), |b| {
        let blk = &pb.blocks[b];
        let sig = &pb.sigs[blk.exp];
        let start = pb.block_start(b, &pt, &model_off, blk.range.clone());
        let k0 = blk.range.start;
        let len = blk.range.end - k0;
        let (mut s, mut d) = (0.0, 0.0);
        match setup.sim.simulate_block(sig, &full, &start) {
            Ok(tr) => {
                for i in 0..n {
                    let y = &sig.q[i][blk.range.clone()];
                    let mean = y.iter().sum::<f64>() / len as f64;
                    let w2 = pb.weights[i] * pb.weights[i];
                    for (a, b) in y.iter().zip(&tr.q[i]) {
                        s += w2 * (b - a).powi(2);
                        d += w2 * (a - mean).powi(2);
                    }
                }
            }
            Err(_) => s = f64::INFINITY,
        }
        let s = if s.is_finite() { s } else { f64::INFINITY };
        let m = (n * len) as f64;
        (blk.exp, k0, s > d + m, s / m)
    }))
}
