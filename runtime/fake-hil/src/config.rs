//! Parsing of `PLANTC_FAKE_HIL`, e.g. `alpha0=5deg,fault=read_error@2.0`.

use std::f64::consts::PI;

/// An injected fault and the virtual time (s) it starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// Encoder reads fail from T on.
    ReadError(f64),
    /// Encoder counts freeze at T.
    StuckEncoder(f64),
    /// Every read/write call sleeps 1.5 periods (wall clock) from T on.
    SlowCalls(f64),
    /// Watchdog reloads are ignored from T on, so it expires after its timeout.
    NoReload(f64),
    /// Every `hil_write_analog` fails from T on (0 V writes included).
    WriteError(f64),
    /// `hil_watchdog_reload` fails (an error code, not an expiry) from T on.
    ReloadError(f64),
    /// `hil_read_encoder` / `hil_task_read_encoder` never return from T on.
    HangRead(f64),
    /// `hil_write_analog` never returns from T on.
    HangWrite(f64),
}

/// Settings of the fake board.
#[derive(Debug, Clone, PartialEq)]
pub struct FakeConfig {
    /// Initial arm angle (rad).
    pub theta0: f64,
    /// Initial pendulum angle (rad, 0 = upright).
    pub alpha0: f64,
    /// Period of a non-task `hil_read_encoder` step (s).
    pub period: f64,
    /// Encoder counts per revolution.
    pub counts_per_rev: f64,
    /// RK4 sub-steps per sample.
    pub substeps: u32,
    /// The board refuses `hil_watchdog_set_analog_expiration_state`.
    pub watchdog_refused: bool,
    /// The board refuses to create tasks (runtime must fall back to OS timing).
    pub no_tasks: bool,
    /// Every write of exactly 0 V fails (the safe-stop write).
    pub write_error_zero: bool,
    /// `hil_watchdog_start` fails.
    pub watchdog_start_error: bool,
    /// `hil_watchdog_stop` fails (the watchdog keeps running).
    pub watchdog_stop_error: bool,
    /// `hil_close` closes the card but returns an error.
    pub close_error: bool,
    /// `hil_close` never returns.
    pub hang_close: bool,
    /// Timed faults.
    pub faults: Vec<Fault>,
}

impl Default for FakeConfig {
    fn default() -> Self {
        Self {
            theta0: 0.0,
            alpha0: 5f64.to_radians(),
            period: 1e-3,
            counts_per_rev: 4096.0,
            substeps: 10,
            watchdog_refused: false,
            no_tasks: false,
            write_error_zero: false,
            watchdog_start_error: false,
            watchdog_stop_error: false,
            close_error: false,
            hang_close: false,
            faults: Vec::new(),
        }
    }
}

fn angle(v: &str) -> Result<f64, String> {
    let v = v.trim();
    if let Some(d) = v.strip_suffix("deg") {
        d.trim()
            .parse::<f64>()
            .map(f64::to_radians)
            .map_err(|e| format!("{v}: {e}"))
    } else {
        let r = v.strip_suffix("rad").unwrap_or(v);
        r.trim().parse::<f64>().map_err(|e| format!("{v}: {e}"))
    }
}

fn seconds(v: &str) -> Result<f64, String> {
    let v = v.trim();
    let (num, scale) = if let Some(n) = v.strip_suffix("ms") {
        (n, 1e-3)
    } else if let Some(n) = v.strip_suffix('s') {
        (n, 1.0)
    } else {
        (v, 1.0)
    };
    let x = num.trim().parse::<f64>().map_err(|e| format!("{v}: {e}"))? * scale;
    if x.is_finite() && x >= 0.0 {
        Ok(x)
    } else {
        Err(format!("{v}: not a time"))
    }
}

impl FakeConfig {
    /// Parses the comma-separated `key=value` list (empty = defaults).
    pub fn parse(s: &str) -> Result<Self, String> {
        let mut c = FakeConfig::default();
        for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let (k, v) = item.split_once('=').unwrap_or((item, ""));
            match k.trim() {
                "alpha0" => c.alpha0 = angle(v)?,
                "theta0" => c.theta0 = angle(v)?,
                "period" => c.period = seconds(v)?.max(1e-6),
                "cpr" | "counts_per_rev" => {
                    c.counts_per_rev = v.trim().parse().map_err(|e| format!("{v}: {e}"))?
                }
                "substeps" => c.substeps = v.trim().parse().map_err(|e| format!("{v}: {e}"))?,
                "no_tasks" => c.no_tasks = true,
                "watchdog_refused" => c.watchdog_refused = true,
                "fault" => {
                    let (name, at) = v.split_once('@').unwrap_or((v, "0"));
                    let at = seconds(at)?;
                    match name.trim() {
                        "read_error" => c.faults.push(Fault::ReadError(at)),
                        "stuck_encoder" => c.faults.push(Fault::StuckEncoder(at)),
                        "slow_calls" => c.faults.push(Fault::SlowCalls(at)),
                        "no_reload" | "watchdog_expiry" => c.faults.push(Fault::NoReload(at)),
                        "watchdog_refused" => c.watchdog_refused = true,
                        "no_tasks" => c.no_tasks = true,
                        "write_error" => c.faults.push(Fault::WriteError(at)),
                        "reload_error" => c.faults.push(Fault::ReloadError(at)),
                        "hang_read" => c.faults.push(Fault::HangRead(at)),
                        "hang_write" => c.faults.push(Fault::HangWrite(at)),
                        "write_error_zero" => c.write_error_zero = true,
                        "watchdog_start_error" => c.watchdog_start_error = true,
                        "watchdog_stop_error" => c.watchdog_stop_error = true,
                        "close_error" => c.close_error = true,
                        "hang_close" => c.hang_close = true,
                        other => return Err(format!("unknown fault {other:?}")),
                    }
                }
                other => return Err(format!("unknown key {other:?}")),
            }
        }
        if !(c.counts_per_rev.is_finite() && c.counts_per_rev > 0.0) || c.substeps == 0 {
            return Err("cpr must be > 0 and substeps >= 1".into());
        }
        if !c.alpha0.is_finite() || !c.theta0.is_finite() || c.alpha0.abs() > 4.0 * PI {
            return Err("bad initial angle".into());
        }
        Ok(c)
    }

    /// Whether `f` is active at virtual time `t`.
    pub fn active(&self, t: f64, pick: fn(&Fault) -> Option<f64>) -> bool {
        self.faults.iter().filter_map(pick).any(|at| t >= at)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_documented_example() {
        let c = FakeConfig::parse("alpha0=5deg,fault=read_error@2.0").unwrap();
        assert!((c.alpha0 - 5f64.to_radians()).abs() < 1e-12);
        assert_eq!(c.faults, vec![Fault::ReadError(2.0)]);
        let c =
            FakeConfig::parse("fault=watchdog_refused, period=0.5ms, fault=slow_calls@1s").unwrap();
        assert!(c.watchdog_refused);
        assert_eq!(c.period, 0.0005);
        assert_eq!(c.faults, vec![Fault::SlowCalls(1.0)]);
        assert!(FakeConfig::parse("fault=bogus@1").is_err());
        let c = FakeConfig::parse("fault=write_error@0.5,fault=write_error_zero,fault=hang_close")
            .unwrap();
        assert_eq!(c.faults, vec![Fault::WriteError(0.5)]);
        assert!(c.write_error_zero && c.hang_close && !c.close_error);
        assert!(FakeConfig::parse("alpha0=x").is_err());
    }
}
