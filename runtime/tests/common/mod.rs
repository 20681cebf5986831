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
        if row.t.is_nan() || row.t <= prev_t {
            return Err(format!("line {}: t not increasing", i + 2));
        }
        prev_t = row.t;
        rows.push(row);
    }
    Ok(rows)
}

/// Builds (once per test process) and locates the fake HIL cdylib.
///
/// Runs `cargo build -p plantc-fake-hil` with the cargo that runs the tests,
/// then looks for the library next to the test binary's profile directory
/// (`target/<profile>/`), falling back to `<workspace>/target/debug/`.
pub fn fake_hil_lib() -> PathBuf {
    use std::sync::OnceLock;
    static PATH: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    PATH.get_or_init(build_fake_hil)
        .clone()
        .unwrap_or_else(|e| panic!("cannot build/locate the fake HIL: {e}"))
}

fn build_fake_hil() -> Result<PathBuf, String> {
    let workspace = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .ok_or("no workspace dir")?
        .to_path_buf();
    let status = std::process::Command::new(env!("CARGO"))
        .args(["build", "-p", "plantc-fake-hil"])
        .current_dir(&workspace)
        .status()
        .map_err(|e| format!("running cargo: {e}"))?;
    if !status.success() {
        return Err(format!("cargo build -p plantc-fake-hil: {status}"));
    }
    let name = format!(
        "{}plantc_fake_hil{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    );
    let mut candidates = Vec::new();
    if let Ok(exe) = std::env::current_exe() {
        // target/<profile>/deps/<test> -> target/<profile>/
        if let Some(dir) = exe.parent().and_then(|d| d.parent()) {
            candidates.push(dir.join(&name));
            // A test profile directory other than debug: the build went to debug.
            if let Some(target) = dir.parent() {
                candidates.push(target.join("debug").join(&name));
            }
        }
    }
    if let Ok(t) = std::env::var("CARGO_TARGET_DIR") {
        candidates.push(PathBuf::from(t).join("debug").join(&name));
    }
    candidates.push(workspace.join("target").join("debug").join(&name));
    candidates
        .iter()
        .find(|p| p.is_file())
        .cloned()
        .ok_or_else(|| format!("{name} not found in {candidates:?}"))
}

/// Parsed fake-HIL trace: voltages of successful writes and the output at close.
#[derive(Debug, Default)]
pub struct Trace {
    pub ok_writes: Vec<f64>,
    pub failed_writes: usize,
    pub close_output: Option<f64>,
    pub expired: bool,
    pub lines: Vec<String>,
}

pub fn read_trace(path: &std::path::Path) -> Trace {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let mut tr = Trace::default();
    for line in text.lines() {
        tr.lines.push(line.to_string());
        let mut it = line.split_whitespace();
        let _t = it.next();
        match it.next() {
            Some("write") => {
                let _ch = it.next();
                let v = it
                    .next()
                    .and_then(|v| v.strip_prefix("v="))
                    .and_then(|v| v.parse::<f64>().ok());
                match (v, it.next()) {
                    (Some(v), Some("ok")) => tr.ok_writes.push(v),
                    _ => tr.failed_writes += 1,
                }
            }
            Some("close") => {
                tr.close_output = it
                    .next()
                    .and_then(|v| v.strip_prefix("output="))
                    .and_then(|v| v.parse().ok())
            }
            Some("watchdog_expired") => tr.expired = true,
            _ => {}
        }
    }
    tr
}
