//! Helpers shared by the runtime's integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

/// Thesis pole-placement gain (poles -2±3.464j, -40, -45) for u = -K x. It
/// was designed on the thesis' linear model (Quanser manual parameters:
/// pivot inertia 9.98e-4, l2 = 0.1685, eta = 1), which differs slightly from
/// the reference plant used here (Table 3 values, eta_m = 0.69, eta_g = 0.9):
/// the test checks that it still catches and balances.
pub const K_THESIS: [f64; 4] = [-7.8914, 37.8313, -2.9850, 3.6222];

/// Expected log header for the rotary pendulum.
pub const HEADER: &str =
    "t,theta,alpha,theta_dot,alpha_dot,theta_counts,alpha_counts,Vm,Vm_cmd,state,overrun";

/// A scratch file path unique to this test process.
pub fn tmp_path(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let _ = std::fs::create_dir_all(&dir);
    dir.join(format!("{}-{}", std::process::id(), name))
}

/// One parsed log row.
#[derive(Debug, Clone)]
pub struct Row {
    pub t: f64,
    pub theta: f64,
    pub alpha: f64,
    pub theta_dot: f64,
    pub alpha_dot: f64,
    pub theta_counts: i64,
    pub alpha_counts: i64,
    pub vm: f64,
    pub vm_cmd: f64,
    pub state: String,
    pub overrun: bool,
}

/// A tiny CSV check: the header must match, every complete line must have 11
/// fields that parse, t must increase. If `allow_cut_last` the last line may
/// be incomplete (a killed writer), and is dropped.
pub fn parse_log(text: &str, allow_cut_last: bool) -> Result<Vec<Row>, String> {
    let mut lines: Vec<&str> = text.split('\n').collect();
    // A complete file ends with '\n', leaving an empty last element.
    let last = lines.pop().unwrap_or("");
    if !last.is_empty() && !allow_cut_last {
        return Err(format!("last line not terminated: {last:?}"));
    }
    let mut it = lines.into_iter();
    let header = it.next().ok_or("empty log")?;
    if header != HEADER {
        return Err(format!("bad header {header:?}"));
    }
    let mut rows = Vec::new();
    let mut prev_t = f64::NEG_INFINITY;
    for (i, line) in it.enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() != 11 {
            return Err(format!("line {}: {} fields: {line:?}", i + 2, f.len()));
        }
        let num = |j: usize| -> Result<f64, String> {
            f[j].parse::<f64>()
                .map_err(|e| format!("line {}: field {j} {:?}: {e}", i + 2, f[j]))
        };
        let int = |j: usize| -> Result<i64, String> {
            f[j].parse::<i64>()
                .map_err(|e| format!("line {}: field {j} {:?}: {e}", i + 2, f[j]))
        };
        let state = f[9].to_string();
        let ok_state = matches!(state.as_str(), "idle" | "armed" | "engaged")
            || state.strip_prefix("fault:").is_some_and(|s| !s.is_empty());
        if !ok_state {
            return Err(format!("line {}: bad state {state:?}", i + 2));
        }
        let row = Row {
            t: num(0)?,
            theta: num(1)?,
            alpha: num(2)?,
            theta_dot: num(3)?,
            alpha_dot: num(4)?,
            theta_counts: int(5)?,
            alpha_counts: int(6)?,
            vm: num(7)?,
            vm_cmd: num(8)?,
            state,
            overrun: match f[10] {
                "0" => false,
                "1" => true,
                o => return Err(format!("line {}: overrun {o:?}", i + 2)),
            },
        };
        if !(row.t > prev_t) {
            return Err(format!("line {}: t not increasing", i + 2));
        }
        prev_t = row.t;
        rows.push(row);
    }
    Ok(rows)
}
