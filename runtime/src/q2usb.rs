//! Quanser Q2-USB backend over the HIL C API (loaded at run time).
//!
//! Open sequence (as Quanser's generated code for a `q2_usb`): `hil_open`,
//! card-specific options, `hil_watchdog_clear` (errors ignored), analog output
//! range, initial 0 V write, watchdog analog expiration state 0 V, encoder
//! counts zeroed. `start` arms the watchdog and starts an encoder-reader task
//! on `HARDWARE_CLOCK_0` as the loop clock (falling back to `hil_read_encoder`
//! with OS timing if the task cannot be created).
//!
//! Close (the safe stop; rule: the watchdog stays armed until a 0 V write is
//! confirmed): stop and delete the task, write 0 V (one retry). Confirmed:
//! stop the watchdog, `hil_close`. Not confirmed but the watchdog has expired
//! (seen by a reload or `hil_watchdog_is_expired`): the output is in its 0 V
//! expiration state; `hil_close` without clearing it. Neither: the watchdog is
//! left armed (armed now if it was not running) and never reloaded again, and
//! the board is left open, since what `hil_close` does to an armed watchdog is
//! not documented (`quanser-hil.md`) while the watchdog alone is known to
//! drive the output to 0 V. Every failed call is returned in
//! [`BackendError::SafeStop`] with what holds the output
//! ([`OutputHold`]); none is dropped.
//!
//! Every HIL call after `hil_open` runs under a deadline
//! ([`crate::hil_deadline`]): a call that hangs ends the process with the
//! watchdog armed.
//!
//! If the board refuses the watchdog expiration state, [`Q2Usb::open`] fails
//! with [`BackendError::WatchdogRefused`] unless
//! [`Q2UsbConfig::allow_no_watchdog`] is set.

use crate::backend::{Backend, BackendError, EncoderMap, OutputHold, Tick};
use crate::hil_deadline::{deadline_for, CallDeadline, HilCall};
use crate::hil_ffi::{
    null_card, null_task, t_card, t_error, t_task, HilApi, HARDWARE_CLOCK_0, INFINITE,
};
use crate::pacer::Pacer;
use std::f64::consts::PI;
use std::ffi::CString;
use std::path::PathBuf;
use std::time::Instant;

/// One encoder: its HIL channel and how its counts map to the state angle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EncoderChannel {
    /// HIL encoder channel number.
    pub channel: u32,
    /// Counts-to-angle map.
    pub map: EncoderMap,
}

/// Configuration of the Q2-USB backend. Defaults: SRV02 + ROTPEN wiring
/// (encoder 0 = arm, encoder 1 = pendulum, analog output 0 = motor), 4096
/// counts/rev, pendulum zeroed while hanging (offset pi, wrapped so upright = 0).
#[derive(Debug, Clone, PartialEq)]
pub struct Q2UsbConfig {
    /// Path of `hil.dll` / `libhil.so`; `None` tries the default names.
    pub library_path: Option<PathBuf>,
    /// Card type for `hil_open` (default `q2_usb`).
    pub card_type: String,
    /// Card identifier for `hil_open` (default `0`).
    pub card_identifier: String,
    /// Card-specific options string; `None` skips the call.
    pub card_options: Option<String>,
    /// Encoders in state order (arm, then pendulum).
    pub encoders: Vec<EncoderChannel>,
    /// Analog output channel of the motor amplifier (default 0).
    pub motor_channel: u32,
    /// Sign applied to the voltage before writing (+1 or -1).
    pub motor_sign: f64,
    /// Analog output range (default ±10 V).
    pub analog_range: (f64, f64),
    /// Hardware watchdog timeout in seconds (default 0.1).
    pub watchdog_timeout_s: f64,
    /// Drive the motor even if the board refuses the watchdog (default false: refuse).
    pub allow_no_watchdog: bool,
    /// Use an encoder-reader task on HARDWARE_CLOCK_0 as the loop clock (default true).
    pub use_task: bool,
    /// Samples in the task buffer (default 100).
    pub task_buffer_samples: u32,
    /// Deadline of one HIL call (s) after which the process ends
    /// ([`crate::hil_deadline`]); `None` (default): ten times the longer of
    /// the loop period and the watchdog timeout.
    pub call_deadline_s: Option<f64>,
}

impl Default for Q2UsbConfig {
    fn default() -> Self {
        Self {
            library_path: None,
            card_type: "q2_usb".into(),
            card_identifier: "0".into(),
            card_options: Some(
                "d0=digital;d1=digital;led=auto;update_rate=normal;decimation=1".into(),
            ),
            encoders: vec![
                EncoderChannel {
                    channel: 0,
                    map: EncoderMap::plain(4096.0),
                },
                EncoderChannel {
                    channel: 1,
                    map: EncoderMap {
                        counts_per_rev: 4096.0,
                        sign: 1.0,
                        offset_rad: PI,
                        wrap: true,
                    },
                },
            ],
            motor_channel: 0,
            motor_sign: 1.0,
            analog_range: (-10.0, 10.0),
            watchdog_timeout_s: 0.1,
            allow_no_watchdog: false,
            use_task: true,
            task_buffer_samples: 100,
            call_deadline_s: None,
        }
    }
}

/// A Quanser board driven through the HIL API. Writes 0 V on close and on drop.
pub struct Q2Usb {
    api: HilApi,
    card: t_card,
    task: t_task,
    config: Q2UsbConfig,
    maps: Vec<EncoderMap>,
    channels: Vec<u32>,
    counts: Vec<i32>,
    watchdog_available: bool,
    watchdog_running: bool,
    /// The expiration state (0 V) was accepted by the board.
    expiration_state_set: bool,
    /// A reload reported that the watchdog had expired.
    watchdog_expired: bool,
    /// The last voltage the board accepted (V, as written after the sign).
    last_volts: f64,
    pacer: Option<Pacer>,
    period: f64,
    first_read: Option<Instant>,
    k: u64,
    started: bool,
    /// `close` was called (per-sample calls are refused from then on).
    closed: bool,
    /// `hil_close` was called: the card handle is gone.
    released: bool,
    notes: Vec<String>,
    deadline: CallDeadline,
}

impl Q2Usb {
    /// Loads the library, opens and initialises the board (output at 0 V).
    pub fn open(config: Q2UsbConfig) -> Result<Self, BackendError> {
        if config.encoders.is_empty() {
            return Err(BackendError::InvalidConfig("no encoders configured".into()));
        }
        if !(config.watchdog_timeout_s.is_finite() && config.watchdog_timeout_s > 0.0) {
            return Err(BackendError::InvalidConfig(
                "watchdog timeout must be > 0".into(),
            ));
        }
        if !(config.motor_sign == 1.0 || config.motor_sign == -1.0) {
            return Err(BackendError::InvalidConfig(
                "motor_sign must be +1 or -1".into(),
            ));
        }
        if let Some(d) = config.call_deadline_s {
            if !(d.is_finite() && d > 0.0) {
                return Err(BackendError::InvalidConfig(
                    "call deadline must be > 0 s".into(),
                ));
            }
        }
        let api = HilApi::load(config.library_path.as_deref())?;
        let card_type = CString::new(config.card_type.as_str())
            .map_err(|_| BackendError::InvalidConfig("card type contains NUL".into()))?;
        let card_id = CString::new(config.card_identifier.as_str())
            .map_err(|_| BackendError::InvalidConfig("card identifier contains NUL".into()))?;
        let mut card = null_card();
        // SAFETY: valid C strings and an out-pointer to a local.
        let r = unsafe { (api.open)(card_type.as_ptr(), card_id.as_ptr(), &mut card) };
        if r < 0 || card.is_null() {
            return Err(api.error("hil_open", r.min(-1)));
        }
        let n = config.encoders.len();
        let deadline = CallDeadline::start(
            config
                .call_deadline_s
                .map(std::time::Duration::from_secs_f64)
                .unwrap_or_else(|| deadline_for(0.0, config.watchdog_timeout_s)),
            config.watchdog_timeout_s,
        );
        let mut me = Self {
            card,
            task: null_task(),
            maps: config.encoders.iter().map(|e| e.map).collect(),
            channels: config.encoders.iter().map(|e| e.channel).collect(),
            counts: vec![0; n],
            watchdog_available: false,
            watchdog_running: false,
            expiration_state_set: false,
            watchdog_expired: false,
            last_volts: f64::NAN,
            pacer: None,
            period: 1e-3,
            first_read: None,
            k: 0,
            started: false,
            closed: false,
            released: false,
            notes: Vec::new(),
            deadline,
            config,
            api,
        };
        me.notes.push(format!("HIL library: {}", me.api.origin()));
        if let Err(e) = me.initialise() {
            // The safe stop, its failures reported after the cause.
            return Err(match me.close() {
                Ok(()) => e,
                Err(BackendError::SafeStop {
                    mut failures,
                    output,
                }) => {
                    failures.insert(0, e);
                    BackendError::SafeStop { failures, output }
                }
                Err(c) => BackendError::SafeStop {
                    failures: vec![e, c],
                    output: OutputHold::Unknown {
                        last_volts: me.last_volts,
                    },
                },
            });
        }
        Ok(me)
    }

    /// Runs one HIL call under the deadline.
    fn hil<R>(&self, which: HilCall, f: impl FnOnce() -> R) -> R {
        self.deadline.call(which, f)
    }

    fn set_watchdog_running(&mut self, running: bool) {
        self.watchdog_running = running;
        self.deadline.set_watchdog_armed(running);
    }

    fn initialise(&mut self) -> Result<(), BackendError> {
        let card = self.card;
        if let (Some(opts), Some(f)) = (
            self.config.card_options.as_deref(),
            self.api.set_card_specific_options,
        ) {
            let c = CString::new(opts)
                .map_err(|_| BackendError::InvalidConfig("card options contain NUL".into()))?;
            // SAFETY: valid card and string with its length (without NUL, as Quanser's code passes).
            let r = self.hil(HilCall::SetOptions, || unsafe {
                f(card, c.as_ptr(), opts.len())
            });
            if r < 0 {
                return Err(self.api.error("hil_set_card_specific_options", r));
            }
        }
        if let Some(f) = self.api.watchdog_clear {
            // An error meaning "nothing to clear" is expected and ignored.
            // SAFETY: valid card.
            let _ = self.hil(HilCall::WatchdogClear, || unsafe { f(card) });
        }
        let ch = [self.config.motor_channel];
        if let Some(f) = self.api.set_analog_output_ranges {
            let (lo, hi) = self.config.analog_range;
            // SAFETY: one channel, one minimum, one maximum.
            let r = self.hil(HilCall::SetRanges, || unsafe {
                f(card, ch.as_ptr(), 1, &lo, &hi)
            });
            if r < 0 {
                return Err(self.api.error("hil_set_analog_output_ranges", r));
            }
        }
        self.write_raw(0.0)?;
        match self.api.watchdog_set_analog_expiration_state {
            Some(f) => {
                let zero = [0.0f64];
                // SAFETY: one channel, one voltage.
                let r = self.hil(HilCall::WatchdogSetExpiration, || unsafe {
                    f(card, ch.as_ptr(), 1, zero.as_ptr())
                });
                if r >= 0 {
                    self.expiration_state_set = true;
                }
                if r < 0 {
                    if !self.config.allow_no_watchdog {
                        return Err(BackendError::WatchdogRefused {
                            code: r,
                            message: self.api.error_message(r),
                        });
                    }
                    self.notes.push(format!(
                        "board refused the watchdog (HIL error {r}: {}); running WITHOUT a hardware watchdog (override set)",
                        self.api.error_message(r)
                    ));
                } else {
                    self.watchdog_available =
                        self.api.watchdog_start.is_some() && self.api.watchdog_reload.is_some();
                }
            }
            None => {
                if !self.config.allow_no_watchdog {
                    return Err(BackendError::WatchdogRefused {
                        code: 0,
                        message: "the HIL library has no hil_watchdog_set_analog_expiration_state"
                            .into(),
                    });
                }
                self.notes
                    .push("no watchdog in the HIL library; running without (override set)".into());
            }
        }
        let zeros = vec![0i32; self.channels.len()];
        // SAFETY: channel and value arrays of equal length.
        let r = self.hil(HilCall::SetEncoderCounts, || unsafe {
            (self.api.set_encoder_counts)(
                card,
                self.channels.as_ptr(),
                self.channels.len() as u32,
                zeros.as_ptr(),
            )
        });
        if r < 0 {
            return Err(self.api.error("hil_set_encoder_counts", r));
        }
        Ok(())
    }

    /// Notes gathered while opening/starting (watchdog override, timing fallback).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Whether the hardware watchdog is armed.
    pub fn watchdog_running(&self) -> bool {
        self.watchdog_running
    }

    /// Whether the loop is clocked by an encoder-reader task on HARDWARE_CLOCK_0.
    pub fn uses_hardware_clock(&self) -> bool {
        !self.task.is_null()
    }

    fn write_raw(&mut self, volts: f64) -> Result<(), BackendError> {
        let ch = [self.config.motor_channel];
        let v = [volts * self.config.motor_sign];
        let card = self.card;
        let write = self.api.write_analog;
        // SAFETY: valid card, one channel, one value.
        let r = self.hil(HilCall::WriteAnalog, || unsafe {
            write(card, ch.as_ptr(), 1, v.as_ptr())
        });
        if r < 0 {
            return Err(self.api.error("hil_write_analog", r));
        }
        self.last_volts = v[0];
        self.deadline.set_last_volts(v[0]);
        Ok(())
    }

    fn card_call(&self, which: HilCall, f: crate::hil_ffi::FnCard) -> t_error {
        let card = self.card;
        // SAFETY: valid card (every caller checks `released`).
        self.hil(which, || unsafe { f(card) })
    }

    /// Stops and deletes the encoder task; failures go to `failures`.
    fn stop_task(&mut self, failures: &mut Vec<BackendError>) {
        if let (false, Some(t)) = (self.task.is_null(), self.api.task) {
            let task = self.task;
            // SAFETY: a task created by us and not yet deleted.
            let r = self.hil(HilCall::TaskStop, || unsafe { (t.stop)(task) });
            if r < 0 {
                failures.push(self.api.error("hil_task_stop", r));
            }
            // SAFETY: as above; deleted once.
            let r = self.hil(HilCall::TaskDelete, || unsafe { (t.delete)(task) });
            if r < 0 {
                failures.push(self.api.error("hil_task_delete", r));
            }
            self.task = null_task();
        }
    }

    /// Writes 0 V, one retry (a transient USB error passes on a retry, a
    /// persistent one fails twice); every failed attempt goes to `failures`.
    fn write_zero_confirmed(&mut self, failures: &mut Vec<BackendError>) -> bool {
        for _ in 0..2 {
            match self.write_raw(0.0) {
                Ok(()) => return true,
                Err(e) => failures.push(e),
            }
        }
        false
    }

    /// Whether the watchdog is known to have expired (its outputs in the
    /// 0 V expiration state): a reload said so, or `hil_watchdog_is_expired`.
    fn watchdog_known_expired(&mut self, failures: &mut Vec<BackendError>) -> bool {
        if self.watchdog_expired {
            return true;
        }
        let Some(f) = self.api.watchdog_is_expired else {
            return false;
        };
        if !(self.watchdog_running && self.expiration_state_set) {
            return false;
        }
        let r = self.card_call(HilCall::WatchdogIsExpired, f);
        if r < 0 {
            failures.push(self.api.error("hil_watchdog_is_expired", r));
        }
        r > 0
    }

    /// Arms the watchdog (expiration state 0 V, started, never reloaded)
    /// when it is not running; failures go to `failures`.
    fn arm_watchdog_for_safe_stop(&mut self, failures: &mut Vec<BackendError>) {
        if self.watchdog_running {
            return;
        }
        if !self.expiration_state_set {
            let Some(f) = self.api.watchdog_set_analog_expiration_state else {
                return;
            };
            let ch = [self.config.motor_channel];
            let zero = [0.0f64];
            let card = self.card;
            // SAFETY: one channel, one voltage.
            let r = self.hil(HilCall::WatchdogSetExpiration, || unsafe {
                f(card, ch.as_ptr(), 1, zero.as_ptr())
            });
            if r < 0 {
                failures.push(
                    self.api
                        .error("hil_watchdog_set_analog_expiration_state", r),
                );
                return;
            }
            self.expiration_state_set = true;
        }
        let Some(f) = self.api.watchdog_start else {
            return;
        };
        let card = self.card;
        let timeout = self.config.watchdog_timeout_s;
        // SAFETY: valid card.
        let r = self.hil(HilCall::WatchdogStart, || unsafe { f(card, timeout) });
        if r < 0 {
            failures.push(self.api.error("hil_watchdog_start", r));
        } else {
            self.set_watchdog_running(true);
        }
    }
}

impl Backend for Q2Usb {
    fn encoders(&self) -> &[EncoderMap] {
        &self.maps
    }

    fn is_virtual_time(&self) -> bool {
        false
    }

    fn start(&mut self, period_s: f64) -> Result<(), BackendError> {
        if self.closed {
            return Err(BackendError::Closed);
        }
        if !(period_s.is_finite() && period_s > 0.0) {
            return Err(BackendError::InvalidConfig("period must be > 0".into()));
        }
        self.period = period_s;
        if self.config.call_deadline_s.is_none() {
            self.deadline
                .set_deadline(deadline_for(period_s, self.config.watchdog_timeout_s));
        }
        if self.watchdog_available {
            if let Some(f) = self.api.watchdog_start {
                let card = self.card;
                let timeout = self.config.watchdog_timeout_s;
                // SAFETY: valid card.
                let r = self.hil(HilCall::WatchdogStart, || unsafe { f(card, timeout) });
                if r < 0 {
                    if !self.config.allow_no_watchdog {
                        return Err(BackendError::Hil {
                            function: "hil_watchdog_start",
                            code: r,
                            message: format!(
                                "{}; refusing to drive the motor without a hardware watchdog \
                                 (override: allow_no_watchdog)",
                                self.api.error_message(r)
                            ),
                        });
                    }
                    self.notes.push(format!(
                        "hil_watchdog_start failed ({r}); running without watchdog"
                    ));
                } else {
                    self.set_watchdog_running(true);
                }
            }
        }
        self.task = null_task();
        if let (true, Some(t)) = (self.config.use_task, self.api.task) {
            let mut task = null_task();
            let card = self.card;
            let samples = self.config.task_buffer_samples.max(2);
            // SAFETY: valid card, channel array with its length, out-pointer.
            let r = self.hil(HilCall::TaskCreate, || unsafe {
                (t.create_encoder_reader)(
                    card,
                    samples,
                    self.channels.as_ptr(),
                    self.channels.len() as u32,
                    &mut task,
                )
            });
            if r >= 0 && !task.is_null() {
                // SAFETY: a freshly created task.
                let r2 = self.hil(HilCall::TaskStart, || unsafe {
                    (t.start)(task, HARDWARE_CLOCK_0, 1.0 / period_s, INFINITE)
                });
                if r2 >= 0 {
                    self.task = task;
                } else {
                    // SAFETY: created above, not started.
                    let r3 = self.hil(HilCall::TaskDelete, || unsafe { (t.delete)(task) });
                    if r3 < 0 {
                        self.notes.push(format!(
                            "hil_task_delete of the task that did not start failed ({})",
                            self.api.error_message(r3)
                        ));
                    }
                    self.notes.push(format!(
                        "hil_task_start failed ({}); falling back to hil_read_encoder with OS timing",
                        self.api.error_message(r2)
                    ));
                }
            } else {
                self.notes.push(format!(
                    "hil_task_create_encoder_reader failed ({}); falling back to hil_read_encoder with OS timing",
                    self.api.error_message(r)
                ));
            }
        } else if self.config.use_task {
            self.notes.push(
                "HIL task functions unavailable; using hil_read_encoder with OS timing".into(),
            );
        }
        if self.task.is_null() {
            self.pacer = Some(Pacer::new(period_s));
        }
        self.first_read = None;
        self.k = 0;
        self.started = true;
        Ok(())
    }

    fn wait_next_period(&mut self) -> Result<Tick, BackendError> {
        if !self.started || self.closed {
            return Err(BackendError::NotStarted);
        }
        if let Some(p) = self.pacer.as_mut() {
            let (t, missed) = p.wait();
            return Ok(Tick { t, missed });
        }
        let Some(t) = self.api.task else {
            return Err(BackendError::NotStarted);
        };
        // Blocks until the hardware clock's next sample.
        let task = self.task;
        let counts = self.counts.as_mut_ptr();
        // SAFETY: started task; buffer holds one sample of every channel.
        let r = self.deadline.call(HilCall::TaskReadEncoder, || unsafe {
            (t.read_encoder)(task, 1, counts)
        });
        if r < 0 {
            return Err(self.api.error("hil_task_read_encoder", r));
        }
        let now = Instant::now();
        let start = *self.first_read.get_or_insert(now);
        let tk = self.k as f64 * self.period;
        self.k += 1;
        // Late by more than a period: a sample was buffered while we were busy.
        let late = now.duration_since(start).as_secs_f64() - tk;
        let missed = u32::from(late > self.period);
        Ok(Tick { t: tk, missed })
    }

    fn read_encoders(&mut self, counts: &mut [i32]) -> Result<(), BackendError> {
        if !self.started || self.closed {
            return Err(BackendError::NotStarted);
        }
        if self.task.is_null() {
            let (card, read) = (self.card, self.api.read_encoder);
            let (channels, n) = (self.channels.as_ptr(), self.channels.len() as u32);
            let buffer = self.counts.as_mut_ptr();
            // SAFETY: channel and buffer arrays of equal length.
            let r = self.deadline.call(HilCall::ReadEncoder, || unsafe {
                read(card, channels, n, buffer)
            });
            if r < 0 {
                return Err(self.api.error("hil_read_encoder", r));
            }
        }
        for (d, s) in counts.iter_mut().zip(&self.counts) {
            *d = *s;
        }
        Ok(())
    }

    fn write_voltage(&mut self, volts: f64) -> Result<(), BackendError> {
        if self.closed {
            return Err(BackendError::Closed);
        }
        let (lo, hi) = self.config.analog_range;
        let v = if volts.is_finite() {
            volts.clamp(lo, hi)
        } else {
            0.0
        };
        self.write_raw(v)
    }

    fn reload_watchdog(&mut self) -> Result<(), BackendError> {
        if !self.watchdog_running {
            return Ok(());
        }
        let Some(f) = self.api.watchdog_reload else {
            return Ok(());
        };
        if self.closed {
            return Err(BackendError::Closed);
        }
        let r = self.card_call(HilCall::WatchdogReload, f);
        match r {
            1.. => Ok(()),
            0 => {
                self.watchdog_expired = true;
                Err(BackendError::WatchdogExpired)
            }
            _ => Err(self.api.error("hil_watchdog_reload", r)),
        }
    }

    fn close(&mut self) -> Result<(), BackendError> {
        if self.released {
            return Ok(());
        }
        self.closed = true;
        let mut failures = Vec::new();
        self.stop_task(&mut failures);
        let output = if self.write_zero_confirmed(&mut failures) {
            if self.watchdog_running {
                if let Some(f) = self.api.watchdog_stop {
                    // After a confirmed 0 V a watchdog that fails to stop is
                    // harmless (it would drive 0 V), but it is reported.
                    let r = self.card_call(HilCall::WatchdogStop, f);
                    if r < 0 {
                        failures.push(self.api.error("hil_watchdog_stop", r));
                    } else {
                        self.set_watchdog_running(false);
                    }
                }
            }
            OutputHold::ZeroConfirmed
        } else if self.watchdog_known_expired(&mut failures) {
            // The expiration state holds 0 V; not cleared (a clear would
            // hand the output back before a write could be confirmed).
            OutputHold::WatchdogExpired
        } else {
            self.arm_watchdog_for_safe_stop(&mut failures);
            return Err(BackendError::SafeStop {
                failures,
                output: if self.watchdog_running {
                    OutputHold::WatchdogArmed {
                        timeout_s: self.config.watchdog_timeout_s,
                    }
                } else {
                    OutputHold::Unknown {
                        last_volts: self.last_volts * self.config.motor_sign,
                    }
                },
            });
        };
        let close = self.api.close;
        let r = self.card_call(HilCall::Close, close);
        self.released = true;
        self.card = null_card();
        if r < 0 {
            failures.push(self.api.error("hil_close", r));
        }
        if failures.is_empty() {
            Ok(())
        } else {
            Err(BackendError::SafeStop { failures, output })
        }
    }
}

impl Drop for Q2Usb {
    /// Closes if nobody did; an error is printed (never dropped). A close
    /// that already failed is not repeated: its error went to the caller and
    /// the board stays as that close left it (watchdog armed).
    fn drop(&mut self) {
        if !self.closed {
            if let Err(e) = self.close() {
                eprintln!("error: closing the board: {e}");
            }
        }
    }
}
