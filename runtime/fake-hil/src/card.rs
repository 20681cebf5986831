//! The simulated board: the reference pendulum, encoders, one analog output,
//! a watchdog, one encoder-reader task, in virtual time.

use crate::config::{FakeConfig, Fault};
use crate::errors::*;
use plantc_runtime::integrate::{rk4_step, Rk4Scratch};
use plantc_runtime::RotaryPendulumReference;
use std::f64::consts::PI;
use std::fs::File;
use std::io::{LineWriter, Write};
use std::time::Duration;

/// Watchdog state.
#[derive(Debug, Default)]
pub struct Watchdog {
    pub expiration_set: bool,
    pub running: bool,
    pub timeout: f64,
    pub last_reload: f64,
    pub expired: bool,
}

/// The encoder-reader task.
#[derive(Debug)]
pub struct Task {
    pub channels: Vec<u32>,
    pub period: f64,
    pub started: bool,
}

/// The whole fake board.
pub struct Card {
    pub cfg: FakeConfig,
    plant: RotaryPendulumReference,
    x: [f64; 4],
    scratch: Rk4Scratch,
    /// Virtual time (s).
    pub t: f64,
    /// Voltage on the motor output (V).
    pub output: f64,
    offsets: [i64; 2],
    stuck: Option<[i32; 2]>,
    pub watchdog: Watchdog,
    pub task: Option<Task>,
    trace: Option<LineWriter<File>>,
}

impl Card {
    pub fn new(cfg: FakeConfig, trace_path: Option<&str>) -> Self {
        let trace = trace_path
            .and_then(|p| File::create(p).ok())
            .map(LineWriter::new);
        let mut c = Self {
            x: [cfg.theta0, cfg.alpha0, 0.0, 0.0],
            cfg,
            plant: RotaryPendulumReference::default(),
            scratch: Rk4Scratch::new(4),
            t: 0.0,
            output: 0.0,
            offsets: [0, 0],
            stuck: None,
            watchdog: Watchdog::default(),
            task: None,
            trace,
        };
        let a0 = c.x[1];
        c.trace_line(format_args!("open alpha0={a0:.6}"));
        c
    }

    /// Appends a line `t=<virtual time> <text>` to the trace file.
    pub fn trace_line(&mut self, args: std::fmt::Arguments<'_>) {
        let t = self.t;
        if let Some(w) = self.trace.as_mut() {
            let _ = writeln!(w, "t={t:.6} {args}");
        }
    }

    pub fn flush_trace(&mut self) {
        if let Some(w) = self.trace.as_mut() {
            let _ = w.flush();
        }
    }

    fn fault_at(&self, pick: fn(&Fault) -> Option<f64>) -> bool {
        self.cfg.active(self.t, pick)
    }

    /// Sleeps 1.5 periods of wall time if `slow_calls` is active.
    pub fn maybe_slow(&self, period: f64) {
        if self.fault_at(|f| match f {
            Fault::SlowCalls(at) => Some(*at),
            _ => None,
        }) {
            std::thread::sleep(Duration::from_secs_f64(1.5 * period));
        }
    }

    pub fn read_error_active(&self) -> bool {
        self.fault_at(|f| match f {
            Fault::ReadError(at) => Some(*at),
            _ => None,
        })
    }

    pub fn hang_read_active(&self) -> bool {
        self.fault_at(|f| match f {
            Fault::HangRead(at) => Some(*at),
            _ => None,
        })
    }

    pub fn hang_write_active(&self) -> bool {
        self.fault_at(|f| match f {
            Fault::HangWrite(at) => Some(*at),
            _ => None,
        })
    }

    /// Never returns (an injected hung call); traced first.
    pub fn hang(&mut self, call: &str) -> ! {
        self.trace_line(format_args!("hang {call}"));
        self.flush_trace();
        loop {
            std::thread::sleep(Duration::from_secs(1000));
        }
    }

    fn no_reload_active(&self) -> bool {
        self.fault_at(|f| match f {
            Fault::NoReload(at) => Some(*at),
            _ => None,
        })
    }

    /// Advances the physics by `dt` with the current output held.
    pub fn step(&mut self, dt: f64) {
        let n = self.cfg.substeps.max(1);
        let h = dt / f64::from(n);
        let u = [self.output];
        for _ in 0..n {
            rk4_step(&self.plant, &mut self.x, &u, h, &mut self.scratch);
        }
        self.t += dt;
        self.check_watchdog();
    }

    fn check_watchdog(&mut self) {
        let w = &self.watchdog;
        if w.running && !w.expired && self.t - w.last_reload > w.timeout + 1e-12 {
            self.watchdog.expired = true;
            self.output = 0.0;
            self.trace_line(format_args!("watchdog_expired output=0"));
            self.flush_trace();
        }
    }

    /// Encoder counts of `channel` now: arm zero at theta = 0, pendulum zero
    /// hanging (alpha = pi), as if the encoders had been zeroed with the
    /// pendulum hanging before it was raised to `alpha0` by hand.
    pub fn counts(&mut self, channel: u32) -> Result<i32, i32> {
        let i = match channel {
            0 => 0usize,
            1 => 1usize,
            _ => return Err(ERR_INVALID_CHANNEL),
        };
        if self.stuck.is_none()
            && self.fault_at(|f| match f {
                Fault::StuckEncoder(at) => Some(*at),
                _ => None,
            })
        {
            let now = [self.raw_counts(0), self.raw_counts(1)];
            self.stuck = Some(now);
            self.trace_line(format_args!("encoders_stuck"));
        }
        Ok(match self.stuck {
            Some(s) => s[i],
            None => self.raw_counts(i),
        })
    }

    fn raw_counts(&self, i: usize) -> i32 {
        let reference = if i == 1 { PI } else { 0.0 };
        let c = ((self.x[i] - reference) / (2.0 * PI) * self.cfg.counts_per_rev).round();
        let c = if c.is_finite() { c as i64 } else { 0 };
        (c + self.offsets[i]).clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
    }

    pub fn set_counts(&mut self, channel: u32, value: i32) -> Result<(), i32> {
        match channel {
            0 | 1 => {
                self.offsets[channel as usize] = i64::from(value);
                Ok(())
            }
            _ => Err(ERR_INVALID_CHANNEL),
        }
    }

    pub fn write(&mut self, channel: u32, v: f64) -> i32 {
        let injected = self.fault_at(|f| match f {
            Fault::WriteError(at) => Some(*at),
            _ => None,
        }) || (self.cfg.write_error_zero && v == 0.0);
        if injected {
            self.trace_line(format_args!("write ch={channel} v={v:.6} err=injected"));
            return ERR_INJECTED;
        }
        if self.watchdog.expired {
            self.trace_line(format_args!(
                "write ch={channel} v={v:.6} err=watchdog_expired"
            ));
            return ERR_WATCHDOG_EXPIRED;
        }
        if !v.is_finite() {
            self.trace_line(format_args!("write ch={channel} v={v} err=invalid"));
            return ERR_INVALID_ARGUMENT;
        }
        let v = v.clamp(-10.0, 10.0);
        if channel == 0 {
            self.output = v;
        }
        self.trace_line(format_args!("write ch={channel} v={v:.6} ok"));
        0
    }

    pub fn reload(&mut self) -> i32 {
        if !self.watchdog.running {
            return ERR_WATCHDOG_NOT_RUNNING;
        }
        if self.fault_at(|f| match f {
            Fault::ReloadError(at) => Some(*at),
            _ => None,
        }) {
            self.trace_line(format_args!("watchdog_reload err=injected"));
            return ERR_INJECTED;
        }
        self.check_watchdog();
        if self.watchdog.expired {
            return 0;
        }
        if !self.no_reload_active() {
            self.watchdog.last_reload = self.t;
        }
        1
    }

    pub fn close(&mut self) {
        let out = self.output;
        self.trace_line(format_args!("close output={out:.6}"));
        self.flush_trace();
    }
}
