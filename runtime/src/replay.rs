//! Replays a velocity estimator and a controller over the measurements of a
//! logged run, to compare two implementations of the same control path
//! (`plantc run --compiled --compare`: the generated code ran on the rig,
//! the interpreted one is replayed over exactly what it measured).
//!
//! The replay performs the loop's steps in the loop's order for every row:
//! angles from the logged encoder counts through the backend's encoder maps,
//! the estimator fed with the voltage applied in the previous row, and, in
//! rows where the supervisor let the controller drive (engaged, or swinging
//! up for a hybrid controller; a trailing `mode` column is accepted), the
//! controller (reset when it starts driving) with its output clamped to the input limits like the loop does.
//! Compare logs written with full precision ([`crate::LogWriter::set_full_precision`]).

use std::fmt;
use std::time::Instant;

use crate::backend::EncoderMap;
use crate::controller::Controller;
use crate::estimator::VelocityEstimator;
use crate::histogram::Histogram;
use crate::report::Percentiles;

/// Why a log could not be replayed.
#[derive(Debug, Clone, PartialEq)]
pub enum ReplayError {
    /// The header does not have the columns of a run log for these encoders.
    Header {
        /// What was found.
        found: String,
        /// What is needed.
        expected: String,
    },
    /// A row could not be read.
    Row {
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
}

impl fmt::Display for ReplayError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReplayError::Header { found, expected } => {
                write!(f, "log header `{found}`: expected {expected}")
            }
            ReplayError::Row { line, reason } => write!(f, "log line {line}: {reason}"),
        }
    }
}

impl std::error::Error for ReplayError {}

/// What a replay found.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayReport {
    /// Rows replayed.
    pub rows: u64,
    /// Rows in which the controller ran (engaged).
    pub compared: u64,
    /// Largest |applied voltage of the replay - logged applied voltage| (V).
    pub max_volts_diff: f64,
    /// Time of that row (s).
    pub max_volts_diff_t: f64,
    /// Largest |replayed velocity - logged velocity| over all rows (rad/s).
    pub max_velocity_diff: f64,
    /// Estimator update + controller call of the replay (ns), engaged rows.
    pub path_ns: Percentiles,
}

impl fmt::Display for ReplayReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "replayed {} rows ({} engaged): max |Vm difference| {:.3e} V (t = {:.3} s), \
             max |velocity difference| {:.3e} rad/s; replayed estimator + controller p50 {} ns, p99 {} ns",
            self.rows,
            self.compared,
            self.max_volts_diff,
            self.max_volts_diff_t,
            self.max_velocity_diff,
            self.path_ns.p50,
            self.path_ns.p99
        )
    }
}

/// Replays `estimator` and `controller` over the log `text` of a run whose
/// encoders map through `maps`, with the input clamped to `limits`.
pub fn replay_log(
    text: &str,
    maps: &[EncoderMap],
    limits: (f64, f64),
    estimator: &mut dyn VelocityEstimator,
    controller: &mut dyn Controller,
) -> Result<ReplayReport, ReplayError> {
    let nq = maps.len();
    let n = 2 * nq;
    let width = 1 + n + nq + 4;
    let mut lines = text.lines().enumerate();
    let header = lines.next().map(|(_, h)| h).unwrap_or("");
    let cols: Vec<&str> = header.split(',').collect();
    let counts_ok = cols
        .get(1 + n..1 + n + nq)
        .is_some_and(|c| c.iter().all(|s| s.ends_with("_counts")));
    // a hybrid controller's log ends with its `mode`
    let fields = if cols.len() == width + 1 && cols[width] == "mode" {
        width + 1
    } else {
        width
    };
    if cols.len() != fields || cols[0] != "t" || !counts_ok || cols[width - 2] != "state" {
        return Err(ReplayError::Header {
            found: header.to_string(),
            expected: format!(
                "t, {n} states, {nq} `_counts` columns, the input, its `_cmd`, state, overrun \
                 (and mode)"
            ),
        });
    }
    let mut q = vec![0.0; nq];
    let mut qu = vec![0.0; nq];
    let mut v = vec![0.0; nq];
    let mut x = vec![0.0; n];
    let mut u = [0.0f64];
    let mut u_prev = 0.0;
    let mut was_engaged = false;
    let mut hist = Histogram::new();
    let mut report = ReplayReport {
        rows: 0,
        compared: 0,
        max_volts_diff: 0.0,
        max_volts_diff_t: 0.0,
        max_velocity_diff: 0.0,
        path_ns: Percentiles::default(),
    };
    for (i, line) in lines {
        if line.is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        let bad = |reason: String| ReplayError::Row {
            line: i + 1,
            reason,
        };
        if f.len() != fields {
            return Err(bad(format!("{} fields, expected {fields}", f.len())));
        }
        let num = |j: usize| {
            f[j].parse::<f64>()
                .map_err(|_| bad(format!("`{}` is not a number", f[j])))
        };
        let t = num(0)?;
        for k in 0..nq {
            let c: i32 = f[1 + n + k]
                .parse()
                .map_err(|_| bad(format!("`{}` is not an encoder count", f[1 + n + k])))?;
            (q[k], qu[k]) = maps[k].angles(c);
        }
        let applied = num(1 + n + nq)?;
        // the loop runs the controller when engaged or swinging up
        let engaged = matches!(f[width - 2], "engaged" | "swing_up");
        let t0 = Instant::now();
        estimator.update(&q, &qu, u_prev, &mut v);
        x[..nq].copy_from_slice(&q);
        x[nq..].copy_from_slice(&v);
        if engaged {
            if !was_engaged {
                controller.reset();
            }
            u[0] = 0.0;
            controller.control(t, &x, &mut u);
            hist.record(t0.elapsed().as_nanos() as u64);
            let mine = if u[0].is_finite() {
                u[0].clamp(limits.0, limits.1)
            } else {
                f64::NAN
            };
            let d = (mine - applied).abs();
            if d.is_nan() || d > report.max_volts_diff {
                report.max_volts_diff = if d.is_nan() { f64::INFINITY } else { d };
                report.max_volts_diff_t = t;
            }
            report.compared += 1;
        }
        for (k, vk) in v.iter().enumerate() {
            let d = (vk - num(1 + nq + k)?).abs();
            if d.is_nan() || d > report.max_velocity_diff {
                report.max_velocity_diff = if d.is_nan() { f64::INFINITY } else { d };
            }
        }
        was_engaged = engaged;
        u_prev = applied;
        report.rows += 1;
    }
    report.path_ns = hist.percentiles();
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::controller::StateFeedback;
    use crate::estimator::DerivativeEstimator;

    #[test]
    fn a_log_replays_against_itself_and_a_changed_voltage_shows() {
        let maps = [EncoderMap::plain(4096.0); 2];
        let mut text = String::from(
            "t,theta,alpha,theta_dot,alpha_dot,theta_counts,alpha_counts,Vm,Vm_cmd,state,overrun\n",
        );
        // Rows as the loop would log them with K = [0, 10, 0, 0] and the
        // filtered derivative (alpha fixed at 3 counts: zero velocity).
        let alpha = 3.0 * 2.0 * std::f64::consts::PI / 4096.0;
        for k in 0..5 {
            let vm = -10.0 * alpha;
            text.push_str(&format!(
                "{:?},0.0,{alpha:?},0.0,0.0,0,3,{vm:?},{vm:?},engaged,0\n",
                k as f64 * 1e-3
            ));
        }
        let mut est = DerivativeEstimator::new(2, 50.0, 1e-3);
        let mut ctl = StateFeedback::new(vec![0.0, 10.0, 0.0, 0.0]);
        let r = replay_log(&text, &maps, (-10.0, 10.0), &mut est, &mut ctl).unwrap();
        assert_eq!((r.rows, r.compared), (5, 5));
        assert_eq!(r.max_volts_diff, 0.0, "{r}");
        // Every applied voltage off by 1 uV: the replay sees it.
        let changed = text.replace(
            &format!("{:?},{:?},engaged", -10.0 * alpha, -10.0 * alpha),
            &format!("{:?},{:?},engaged", -10.0 * alpha + 1e-6, -10.0 * alpha),
        );
        let mut est = DerivativeEstimator::new(2, 50.0, 1e-3);
        let r = replay_log(&changed, &maps, (-10.0, 10.0), &mut est, &mut ctl).unwrap();
        assert!((r.max_volts_diff - 1e-6).abs() < 1e-12, "{r}");
        let mut est = DerivativeEstimator::new(2, 50.0, 1e-3);
        assert!(matches!(
            replay_log("t,x\n", &maps, (-10.0, 10.0), &mut est, &mut ctl),
            Err(ReplayError::Header { .. })
        ));
    }

    #[test]
    fn a_hybrid_log_with_its_mode_column_and_swing_up_rows_replays() {
        let maps = [EncoderMap::plain(4096.0); 2];
        let mut text = String::from(
            "t,theta,alpha,theta_dot,alpha_dot,theta_counts,alpha_counts,Vm,Vm_cmd,state,overrun,mode\n",
        );
        let alpha = 3.0 * 2.0 * std::f64::consts::PI / 4096.0;
        let vm = -10.0 * alpha;
        text.push_str(&format!(
            "0.0,0.0,{alpha:?},0.0,0.0,0,3,0.0,0.0,armed,0,pump\n"
        ));
        text.push_str(&format!(
            "0.001,0.0,{alpha:?},0.0,0.0,0,3,{vm:?},{vm:?},swing_up,0,pump\n"
        ));
        text.push_str(&format!(
            "0.002,0.0,{alpha:?},0.0,0.0,0,3,{vm:?},{vm:?},engaged,0,catch\n"
        ));
        let mut est = DerivativeEstimator::new(2, 50.0, 1e-3);
        let mut ctl = StateFeedback::new(vec![0.0, 10.0, 0.0, 0.0]);
        let r = replay_log(&text, &maps, (-10.0, 10.0), &mut est, &mut ctl).unwrap();
        // the controller drives in the swing-up and the engaged rows
        assert_eq!((r.rows, r.compared), (3, 2));
        assert_eq!(r.max_volts_diff, 0.0, "{r}");
        // a row without its mode is an error
        let short = text.replace(",0,catch", ",0");
        let mut est = DerivativeEstimator::new(2, 50.0, 1e-3);
        assert!(matches!(
            replay_log(&short, &maps, (-10.0, 10.0), &mut est, &mut ctl),
            Err(ReplayError::Row { line: 4, .. })
        ));
    }
}
