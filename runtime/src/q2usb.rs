//! Quanser Q2-USB backend over the HIL C API (loaded at run time).
//!
//! Open sequence (as Quanser's generated code for a `q2_usb`): `hil_open`,
//! card-specific options, `hil_watchdog_clear` (errors ignored), analog output
//! range, initial 0 V write, watchdog analog expiration state 0 V, encoder
//! counts zeroed. `start` arms the watchdog and starts an encoder-reader task
//! on `HARDWARE_CLOCK_0` as the loop clock (falling back to `hil_read_encoder`
//! with OS timing if the task cannot be created). Close: 0 V, stop and delete
//! the task, stop/clear the watchdog, final 0 V write, `hil_close`.
//!
//! If the board refuses the watchdog expiration state, [`Q2Usb::open`] fails
//! with [`BackendError::WatchdogRefused`] unless
//! [`Q2UsbConfig::allow_no_watchdog`] is set.

use crate::backend::{Backend, BackendError, EncoderMap, Tick};
use crate::hil_ffi::{null_card, null_task, t_card, t_task, HilApi, HARDWARE_CLOCK_0, INFINITE};
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
    pacer: Option<Pacer>,
    period: f64,
    first_read: Option<Instant>,
    k: u64,
    started: bool,
    closed: bool,
    notes: Vec<String>,
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
        let mut me = Self {
            card,
            task: null_task(),
            maps: config.encoders.iter().map(|e| e.map).collect(),
            channels: config.encoders.iter().map(|e| e.channel).collect(),
            counts: vec![0; n],
            watchdog_available: false,
            watchdog_running: false,
            pacer: None,
            period: 1e-3,
            first_read: None,
            k: 0,
            started: false,
            closed: false,
            notes: Vec::new(),
            config,
            api,
        };
        me.notes.push(format!("HIL library: {}", me.api.origin()));
        // On error `me` is dropped, which writes 0 V and closes the card.
        me.initialise()?;
        Ok(me)
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
            let r = unsafe { f(card, c.as_ptr(), opts.len()) };
            if r < 0 {
                return Err(self.api.error("hil_set_card_specific_options", r));
            }
        }
        if let Some(f) = self.api.watchdog_clear {
            // An error meaning "nothing to clear" is expected and ignored.
            // SAFETY: valid card.
            let _ = unsafe { f(card) };
        }
        let ch = [self.config.motor_channel];
        if let Some(f) = self.api.set_analog_output_ranges {
            let (lo, hi) = self.config.analog_range;
            // SAFETY: one channel, one minimum, one maximum.
            let r = unsafe { f(card, ch.as_ptr(), 1, &lo, &hi) };
            if r < 0 {
                return Err(self.api.error("hil_set_analog_output_ranges", r));
            }
        }
        self.write_raw(0.0)?;
        match self.api.watchdog_set_analog_expiration_state {
            Some(f) => {
                let zero = [0.0f64];
                // SAFETY: one channel, one voltage.
                let r = unsafe { f(card, ch.as_ptr(), 1, zero.as_ptr()) };
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
        let r = unsafe {
            (self.api.set_encoder_counts)(
                card,
                self.channels.as_ptr(),
                self.channels.len() as u32,
                zeros.as_ptr(),
            )
        };
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
        // SAFETY: valid card, one channel, one value.
        let r = unsafe { (self.api.write_analog)(self.card, ch.as_ptr(), 1, v.as_ptr()) };
        if r < 0 {
            return Err(self.api.error("hil_write_analog", r));
        }
        Ok(())
    }

    fn stop_task(&mut self) {
        if let (false, Some(t)) = (self.task.is_null(), self.api.task) {
            // SAFETY: a task created by us and not yet deleted.
            unsafe {
                let _ = (t.stop)(self.task);
                let _ = (t.delete)(self.task);
            }
            self.task = null_task();
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
        if self.watchdog_available {
            if let Some(f) = self.api.watchdog_start {
                // SAFETY: valid card.
                let r = unsafe { f(self.card, self.config.watchdog_timeout_s) };
                if r < 0 {
                    if !self.config.allow_no_watchdog {
                        return Err(BackendError::WatchdogRefused {
                            code: r,
                            message: self.api.error_message(r),
                        });
                    }
                    self.notes.push(format!(
                        "hil_watchdog_start failed ({r}); running without watchdog"
                    ));
                } else {
                    self.watchdog_running = true;
                }
            }
        }
        self.task = null_task();
        if let (true, Some(t)) = (self.config.use_task, self.api.task) {
            let mut task = null_task();
            // SAFETY: valid card, channel array with its length, out-pointer.
            let r = unsafe {
                (t.create_encoder_reader)(
                    self.card,
                    self.config.task_buffer_samples.max(2),
                    self.channels.as_ptr(),
                    self.channels.len() as u32,
                    &mut task,
                )
            };
            if r >= 0 && !task.is_null() {
                // SAFETY: a freshly created task.
                let r2 = unsafe { (t.start)(task, HARDWARE_CLOCK_0, 1.0 / period_s, INFINITE) };
                if r2 >= 0 {
                    self.task = task;
                } else {
                    // SAFETY: created above, not started.
                    unsafe {
                        let _ = (t.delete)(task);
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
        // SAFETY: started task; buffer holds one sample of every channel.
        let r = unsafe { (t.read_encoder)(self.task, 1, self.counts.as_mut_ptr()) };
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
            // SAFETY: channel and buffer arrays of equal length.
            let r = unsafe {
                (self.api.read_encoder)(
                    self.card,
                    self.channels.as_ptr(),
                    self.channels.len() as u32,
                    self.counts.as_mut_ptr(),
                )
            };
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
        // SAFETY: valid card.
        let r = unsafe { f(self.card) };
        match r {
            1.. => Ok(()),
            0 => Err(BackendError::WatchdogExpired),
            _ => Err(self.api.error("hil_watchdog_reload", r)),
        }
    }

    fn close(&mut self) -> Result<(), BackendError> {
        if self.closed {
            return Ok(());
        }
        self.closed = true;
        let mut first_err = self.write_raw(0.0).err();
        self.stop_task();
        if self.watchdog_running {
            // SAFETY: valid card.
            unsafe {
                if let Some(f) = self.api.watchdog_stop {
                    let _ = f(self.card);
                }
                if let Some(f) = self.api.watchdog_clear {
                    let _ = f(self.card);
                }
            }
            self.watchdog_running = false;
        }
        // Final voltage (also after a watchdog expiry has been cleared).
        if let Err(e) = self.write_raw(0.0) {
            first_err.get_or_insert(e);
        } else {
            first_err = None;
        }
        // SAFETY: valid card, closed once.
        let r = unsafe { (self.api.close)(self.card) };
        self.card = null_card();
        if r < 0 {
            first_err.get_or_insert(self.api.error("hil_close", r));
        }
        match first_err {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

impl Drop for Q2Usb {
    fn drop(&mut self) {
        let _ = self.close();
    }
}
