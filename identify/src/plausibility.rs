//! Unit plausibility checks on columns read without a unit suffix.
//!
//! An angle column without suffix is read as radians. It draws a warning
//! ([`DataWarning::LooksLikeDegrees`]) when any of these rules fires:
//!
//! 1. **Magnitude**: max |value| > 40 pi (more than 20 revolutions in radians,
//!    implausible for a lab rig; a hanging pendulum in degrees sits at 180).
//! 2. **Encoder quantum**: the values are quantised (at least 90 % of the
//!    nonzero sample-to-sample steps are integer multiples, within 2 %, of the
//!    smallest step q), and 360/q is, within 0.05 counts, a usual encoder
//!    resolution N (a power of two from 256 to 2^20, or 1000, 2000, 4000, 5000,
//!    8000, 10000, 20000 or 40000 counts/rev) while 2 pi/q is not an integer.
//!    A 4096-count encoder read in degrees has q = 360/4096; in radians q = 2 pi/4096.
//! 3. **Speed**: the peak-to-peak range exceeds 2 pi and the 99th percentile of
//!    |velocity| (first differences) exceeds 50 rad/s (8 rev/s): a swinging
//!    pendulum logged in degrees moves at hundreds of "rad/s".
//!
//! A length column without suffix draws [`DataWarning::LooksLikeMillimetres`]
//! when max |value| > 10 (metres), which suggests mm or cm.

use std::f64::consts::PI;

use crate::data::{ChannelSpec, Experiment};
use crate::error::DataWarning;
use crate::units::Kind;

/// Time steps at least this long (s, i.e. sampling at 2 Hz or slower) in a
/// time column without unit suffix suggest milliseconds: rigs are sampled at
/// tens of Hz to kHz (a 500 Hz log in ms steps by 2 "s").
pub const SLOW_TIME_STEP: f64 = 0.5;

/// A warning when a time column read as seconds (no unit suffix) steps by
/// [`SLOW_TIME_STEP`] or more.
pub(crate) fn time_unit_warning(file: &std::path::Path, t: &[f64]) -> Option<DataWarning> {
    let dt = crate::data::median_dt(t)?;
    (dt >= SLOW_TIME_STEP).then(|| DataWarning::LooksLikeMilliseconds {
        file: file.to_path_buf(),
        median_dt: dt,
    })
}

/// `1/dt` for messages, compactly.
pub(crate) fn rate_text(dt: f64) -> String {
    let r = 1.0 / dt;
    if r >= 0.01 {
        format!("{}", (r * 1000.0).round() / 1000.0)
    } else {
        format!("{r:.1e}")
    }
}

/// Runs the checks on the expected coordinates that had no unit suffix.
pub(crate) fn check(exp: &Experiment, spec: &ChannelSpec) -> Vec<DataWarning> {
    let mut out = Vec::new();
    for (name, kind) in &spec.coordinates {
        let Some(ch) = exp.channel(name) else {
            continue;
        };
        if ch.unit_note.is_some() {
            continue;
        }
        match kind {
            Kind::Angle => {
                if let Some(reason) = degrees_reason(&exp.t, &ch.values) {
                    out.push(DataWarning::LooksLikeDegrees {
                        file: exp.file.clone(),
                        column: name.clone(),
                        reason,
                    });
                }
            }
            Kind::Length => {
                let max_abs = ch.values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                if max_abs > 10.0 {
                    out.push(DataWarning::LooksLikeMillimetres {
                        file: exp.file.clone(),
                        column: name.clone(),
                        max_abs,
                    });
                }
            }
            _ => {}
        }
    }
    out
}

/// Why an angle signal looks like degrees, or None. See the module doc.
pub fn degrees_reason(t: &[f64], x: &[f64]) -> Option<String> {
    if x.len() < 2 || t.len() != x.len() {
        return None;
    }
    let max_abs = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if max_abs > 40.0 * PI {
        return Some(format!(
            "max |value| = {max_abs:.4} exceeds 20 revolutions in radians"
        ));
    }
    if let Some(q) = crate::weights::quantum(x) {
        let deg_n = 360.0 / q;
        let rad_n = 2.0 * PI / q;
        let is_int = |n: f64| (n - n.round()).abs() < 0.05;
        if is_int(deg_n) && usual_resolution(deg_n.round()) && !is_int(rad_n) {
            return Some(format!(
                "values are quantised in steps of {q:.6} = 360/{:.0}, an encoder read in degrees",
                deg_n.round()
            ));
        }
    }
    let (lo, hi) = x
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    if hi - lo > 2.0 * PI {
        let mut speeds: Vec<f64> = x
            .windows(2)
            .zip(t.windows(2))
            .filter(|(_, tw)| tw[1] > tw[0])
            .map(|(xw, tw)| ((xw[1] - xw[0]) / (tw[1] - tw[0])).abs())
            .collect();
        if !speeds.is_empty() {
            speeds.sort_by(f64::total_cmp);
            let p99 = speeds[(speeds.len() * 99 / 100).min(speeds.len() - 1)];
            if p99 > 50.0 {
                return Some(format!(
                    "range {:.2} > 2 pi and 99th-percentile speed {p99:.1} > 50 rad/s",
                    hi - lo
                ));
            }
        }
    }
    None
}

/// True for a usual encoder resolution in counts per revolution.
fn usual_resolution(n: f64) -> bool {
    const OTHERS: [f64; 8] = [
        1000.0, 2000.0, 4000.0, 5000.0, 8000.0, 10000.0, 20000.0, 40000.0,
    ];
    let pow2 = (8..=20).any(|k| n == f64::from(1u32 << k));
    pow2 || OTHERS.contains(&n)
}
