//! A deadline on every HIL call of an open board: a call that does not
//! return ends the process.
//!
//! A call stuck inside the vendor library (a USB transfer that never
//! completes) cannot be cancelled from Rust, and calling into the same
//! library from another thread while it is stuck is not safe. What holds the
//! output then is the board's watchdog: it is reloaded only between calls, so
//! it expires while the call hangs and drives the output to its 0 V
//! expiration state. The monitor thread started with the board therefore
//! makes no HIL call: once a call is past its deadline it prints what the
//! board was doing (the call, the last voltage written, whether the watchdog
//! is armed) and ends the process with exit code [`HUNG_CALL_EXIT_CODE`],
//! instead of hanging for ever with the user's terminal blocked.
//!
//! Rule for the deadline (see [`deadline_for`]): ten times the longer of the
//! loop period and the watchdog timeout (1 s at the defaults: 1 kHz, 0.1 s).
//! A blocking encoder read waits at most one period and a write or a
//! watchdog call returns at once, so a call ten times over its longest
//! legitimate wait is stuck, not slow; and by then the watchdog (reloaded
//! only between calls) has expired nine timeouts earlier.
//!
//! Per-sample cost: two atomic stores per call; the monitor wakes four
//! times per deadline.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Exit code of a process ended because a HIL call hung (the run failed).
pub const HUNG_CALL_EXIT_CODE: i32 = 1;

/// The HIL functions a board calls after `hil_open`, named in the message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum HilCall {
    /// `hil_set_card_specific_options`.
    SetOptions = 1,
    /// `hil_set_analog_output_ranges`.
    SetRanges,
    /// `hil_set_encoder_counts`.
    SetEncoderCounts,
    /// `hil_read_encoder`.
    ReadEncoder,
    /// `hil_write_analog`.
    WriteAnalog,
    /// `hil_watchdog_set_analog_expiration_state`.
    WatchdogSetExpiration,
    /// `hil_watchdog_start`.
    WatchdogStart,
    /// `hil_watchdog_reload`.
    WatchdogReload,
    /// `hil_watchdog_stop`.
    WatchdogStop,
    /// `hil_watchdog_clear`.
    WatchdogClear,
    /// `hil_watchdog_is_expired`.
    WatchdogIsExpired,
    /// `hil_task_create_encoder_reader`.
    TaskCreate,
    /// `hil_task_start`.
    TaskStart,
    /// `hil_task_read_encoder`.
    TaskReadEncoder,
    /// `hil_task_stop`.
    TaskStop,
    /// `hil_task_delete`.
    TaskDelete,
    /// `hil_close`.
    Close,
}

impl HilCall {
    const ALL: [HilCall; 17] = [
        HilCall::SetOptions,
        HilCall::SetRanges,
        HilCall::SetEncoderCounts,
        HilCall::ReadEncoder,
        HilCall::WriteAnalog,
        HilCall::WatchdogSetExpiration,
        HilCall::WatchdogStart,
        HilCall::WatchdogReload,
        HilCall::WatchdogStop,
        HilCall::WatchdogClear,
        HilCall::WatchdogIsExpired,
        HilCall::TaskCreate,
        HilCall::TaskStart,
        HilCall::TaskReadEncoder,
        HilCall::TaskStop,
        HilCall::TaskDelete,
        HilCall::Close,
    ];

    /// The C function's name.
    pub fn name(self) -> &'static str {
        match self {
            HilCall::SetOptions => "hil_set_card_specific_options",
            HilCall::SetRanges => "hil_set_analog_output_ranges",
            HilCall::SetEncoderCounts => "hil_set_encoder_counts",
            HilCall::ReadEncoder => "hil_read_encoder",
            HilCall::WriteAnalog => "hil_write_analog",
            HilCall::WatchdogSetExpiration => "hil_watchdog_set_analog_expiration_state",
            HilCall::WatchdogStart => "hil_watchdog_start",
            HilCall::WatchdogReload => "hil_watchdog_reload",
            HilCall::WatchdogStop => "hil_watchdog_stop",
            HilCall::WatchdogClear => "hil_watchdog_clear",
            HilCall::WatchdogIsExpired => "hil_watchdog_is_expired",
            HilCall::TaskCreate => "hil_task_create_encoder_reader",
            HilCall::TaskStart => "hil_task_start",
            HilCall::TaskReadEncoder => "hil_task_read_encoder",
            HilCall::TaskStop => "hil_task_stop",
            HilCall::TaskDelete => "hil_task_delete",
            HilCall::Close => "hil_close",
        }
    }

    fn from_u8(v: u8) -> Option<HilCall> {
        HilCall::ALL.iter().copied().find(|c| *c as u8 == v)
    }
}

/// The deadline of a HIL call (see the module's rule): ten times the longer
/// of the loop period and the watchdog timeout.
pub fn deadline_for(period_s: f64, watchdog_timeout_s: f64) -> Duration {
    let longest = period_s.max(watchdog_timeout_s);
    let s = if longest.is_finite() && longest > 0.0 {
        10.0 * longest
    } else {
        1.0
    };
    Duration::from_secs_f64(s.min(3600.0))
}

struct Shared {
    base: Instant,
    /// Microseconds since `base` + 1 when the current call began; 0 = no call.
    call_started_us: AtomicU64,
    call: AtomicU8,
    deadline_us: AtomicU64,
    stop: AtomicBool,
    /// What holds the output, for the message.
    watchdog_armed: AtomicBool,
    watchdog_timeout_us: AtomicU64,
    last_volts_bits: AtomicU64,
}

/// The monitor of one open board. Dropping it stops the monitor thread.
pub struct CallDeadline {
    shared: Arc<Shared>,
    monitor: Option<JoinHandle<()>>,
}

impl CallDeadline {
    /// Starts the monitor thread with `deadline` (a HIL call longer than it
    /// ends the process; see the module documentation).
    pub fn start(deadline: Duration, watchdog_timeout_s: f64) -> Self {
        let shared = Arc::new(Shared {
            base: Instant::now(),
            call_started_us: AtomicU64::new(0),
            call: AtomicU8::new(0),
            deadline_us: AtomicU64::new(deadline.as_micros() as u64),
            stop: AtomicBool::new(false),
            watchdog_armed: AtomicBool::new(false),
            watchdog_timeout_us: AtomicU64::new((watchdog_timeout_s * 1e6) as u64),
            last_volts_bits: AtomicU64::new(f64::NAN.to_bits()),
        });
        let s = Arc::clone(&shared);
        let monitor = std::thread::Builder::new()
            .name("hil-deadline".into())
            .spawn(move || monitor(&s))
            .ok();
        Self { shared, monitor }
    }

    /// Changes the deadline (at start, once the loop period is known).
    pub fn set_deadline(&self, deadline: Duration) {
        self.shared
            .deadline_us
            .store(deadline.as_micros() as u64, Ordering::Relaxed);
    }

    /// The current deadline.
    pub fn deadline(&self) -> Duration {
        Duration::from_micros(self.shared.deadline_us.load(Ordering::Relaxed))
    }

    /// Runs one HIL call under the deadline.
    pub fn call<R>(&self, which: HilCall, f: impl FnOnce() -> R) -> R {
        let now = self.shared.base.elapsed().as_micros() as u64 + 1;
        self.shared.call.store(which as u8, Ordering::Relaxed);
        self.shared.call_started_us.store(now, Ordering::Release);
        let r = f();
        self.shared.call_started_us.store(0, Ordering::Release);
        r
    }

    /// Records whether the watchdog is armed (for the message).
    pub fn set_watchdog_armed(&self, armed: bool) {
        self.shared.watchdog_armed.store(armed, Ordering::Relaxed);
    }

    /// Records the last voltage the board accepted (for the message).
    pub fn set_last_volts(&self, volts: f64) {
        self.shared
            .last_volts_bits
            .store(volts.to_bits(), Ordering::Relaxed);
    }
}

impl Drop for CallDeadline {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.monitor.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

fn monitor(s: &Shared) {
    while !s.stop.load(Ordering::Relaxed) {
        let deadline_us = s.deadline_us.load(Ordering::Relaxed).max(1);
        std::thread::park_timeout(Duration::from_micros(deadline_us / 4));
        let started = s.call_started_us.load(Ordering::Acquire);
        if started == 0 || s.stop.load(Ordering::Relaxed) {
            continue;
        }
        let now = s.base.elapsed().as_micros() as u64 + 1;
        let waited_us = now.saturating_sub(started);
        if waited_us <= deadline_us {
            continue;
        }
        // Still the same call (not a later one that began meanwhile)?
        if s.call_started_us.load(Ordering::Acquire) != started {
            continue;
        }
        let call =
            HilCall::from_u8(s.call.load(Ordering::Relaxed)).map_or("a HIL call", |c| c.name());
        let volts = f64::from_bits(s.last_volts_bits.load(Ordering::Relaxed));
        let last = if volts.is_nan() {
            "none yet".to_string()
        } else {
            format!("{volts:.3} V")
        };
        let hold = if s.watchdog_armed.load(Ordering::Relaxed) {
            format!(
                "the board's watchdog is armed (timeout {} s, expiration state 0 V) and is not \
                 reloaded any more: it drives the output to 0 V",
                s.watchdog_timeout_us.load(Ordering::Relaxed) as f64 / 1e6
            )
        } else {
            format!(
                "NO hardware watchdog is armed: the output may stay at the last voltage written \
                 ({last}); switch the amplifier off"
            )
        };
        eprintln!(
            "error: {call} has not returned after {:.1} s (deadline {:.1} s): the HIL library \
             is stuck; ending the process without further HIL calls (the board is not closed). \
             Last voltage the board accepted: {last}; {hold}.",
            waited_us as f64 / 1e6,
            deadline_us as f64 / 1e6
        );
        std::process::exit(HUNG_CALL_EXIT_CODE);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_deadline_is_ten_times_the_longer_wait() {
        assert_eq!(deadline_for(1e-3, 0.1), Duration::from_secs(1));
        assert_eq!(deadline_for(0.5, 0.1), Duration::from_secs(5));
        assert_eq!(deadline_for(f64::NAN, f64::NAN), Duration::from_secs(1));
    }

    #[test]
    fn calls_within_the_deadline_pass_and_names_round_trip() {
        let d = CallDeadline::start(Duration::from_millis(200), 0.1);
        assert_eq!(d.call(HilCall::WriteAnalog, || 7), 7);
        for c in HilCall::ALL {
            assert_eq!(HilCall::from_u8(c as u8), Some(c));
        }
        drop(d);
    }
}
