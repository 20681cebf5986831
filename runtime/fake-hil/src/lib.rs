//! plantc-fake-hil: a fake Quanser HIL library with the C ABI of `hil.h`.
//!
//! Exports the subset of the HIL API that the plantc runtime binds, backed by
//! the reference rotary pendulum (`plantc_runtime::RotaryPendulumReference`)
//! simulated inside the library in virtual time: the plant advances by one
//! period on every `hil_read_encoder` and by `num_samples` task periods on
//! every `hil_task_read_encoder`, so tests run as fast as the CPU allows.
//!
//! Configuration via the environment, read at `hil_open`:
//! - `PLANTC_FAKE_HIL`: comma-separated `key=value` list, e.g.
//!   `alpha0=5deg,fault=read_error@2.0`. Keys: `alpha0`, `theta0` (angles,
//!   `deg` or rad), `period` (non-task read step, default 1 ms), `cpr`
//!   (counts/rev, default 4096), `substeps`, `no_tasks`, and `fault=` one of
//!   `read_error@T`, `stuck_encoder@T`, `slow_calls@T` (each call sleeps 1.5
//!   periods of wall time), `no_reload@T` (watchdog reloads ignored, so it
//!   expires), `watchdog_refused`, `no_tasks`, `write_error@T` (every analog
//!   write fails), `write_error_zero` (writes of exactly 0 V fail),
//!   `reload_error@T` (reloads return an error), `watchdog_start_error`,
//!   `watchdog_stop_error`, `close_error` (the card closes, the call fails),
//!   `hang_read@T`, `hang_write@T`, `hang_close` (the call never returns).
//!   T is virtual time in seconds (default 0).
//! - `PLANTC_FAKE_HIL_TRACE`: a file receiving every analog write, watchdog
//!   start, stop, expiry and expiration state, every injected failure and the
//!   output at close, one `t=<virtual s> ...` line each, flushed line by line
//!   (so the file tells the board's state when the process ends, however it
//!   ends).
//!
//! Encoders model a rig zeroed with the pendulum hanging: channel 1 counts 0
//! at alpha = pi (the runtime's default pendulum map adds pi and wraps).
//! Error codes are the fake's own (see `errors`), not Quanser's.
//! Only one card can be open per process.

#![allow(non_camel_case_types)]

mod card;
mod config;
mod errors;

use card::{Card, Task};
use config::FakeConfig;
use errors::*;
use std::ffi::{c_char, c_int, c_uint, c_void};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Mutex;

type t_error = c_int;
type t_card = *mut c_void;
type t_task = *mut c_void;

static CARD: Mutex<Option<Card>> = Mutex::new(None);
static CARD_TOKEN: u8 = 1;
static TASK_TOKEN: u8 = 2;
const MAX_CHANNELS: u32 = 64;

fn card_handle() -> t_card {
    (&CARD_TOKEN as *const u8).cast_mut().cast()
}

fn task_handle() -> t_task {
    (&TASK_TOKEN as *const u8).cast_mut().cast()
}

fn guarded(f: impl FnOnce() -> t_error) -> t_error {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or(ERR_INVALID_ARGUMENT)
}

fn with_card(card: t_card, f: impl FnOnce(&mut Card) -> t_error) -> t_error {
    guarded(|| {
        if card != card_handle() {
            return ERR_INVALID_CARD;
        }
        let mut g = CARD.lock().unwrap_or_else(|e| e.into_inner());
        match g.as_mut() {
            Some(c) => f(c),
            None => ERR_INVALID_CARD,
        }
    })
}

fn with_task(task: t_task, f: impl FnOnce(&mut Card) -> t_error) -> t_error {
    guarded(|| {
        if task != task_handle() {
            return ERR_INVALID_CARD;
        }
        let mut g = CARD.lock().unwrap_or_else(|e| e.into_inner());
        match g.as_mut() {
            Some(c) if c.task.is_some() => f(c),
            _ => ERR_INVALID_CARD,
        }
    })
}

/// # Safety
/// `p` must point to `n` readable values (or `n == 0`).
unsafe fn slice<'a, T>(p: *const T, n: u32) -> Option<&'a [T]> {
    if n > MAX_CHANNELS || (p.is_null() && n > 0) {
        return None;
    }
    if n == 0 {
        return Some(&[]);
    }
    Some(std::slice::from_raw_parts(p, n as usize))
}

/// `hil_open`: opens the (only) fake card, reading the environment.
///
/// # Safety
/// C strings must be valid or null; `card` must be writable.
#[no_mangle]
pub unsafe extern "C" fn hil_open(
    card_type: *const c_char,
    _card_identifier: *const c_char,
    card: *mut t_card,
) -> t_error {
    guarded(|| {
        if card.is_null() || card_type.is_null() {
            return ERR_INVALID_ARGUMENT;
        }
        let mut g = CARD.lock().unwrap_or_else(|e| e.into_inner());
        if g.is_some() {
            return ERR_ALREADY_OPEN;
        }
        let spec = std::env::var("PLANTC_FAKE_HIL").unwrap_or_default();
        let Ok(cfg) = FakeConfig::parse(&spec) else {
            return ERR_BAD_CONFIG;
        };
        let trace = std::env::var("PLANTC_FAKE_HIL_TRACE").ok();
        *g = Some(Card::new(cfg, trace.as_deref()));
        *card = card_handle();
        0
    })
}

/// `hil_close`.
///
/// # Safety
/// Any pointer value is accepted.
#[no_mangle]
pub unsafe extern "C" fn hil_close(card: t_card) -> t_error {
    guarded(|| {
        if card != card_handle() {
            return ERR_INVALID_CARD;
        }
        let mut g = CARD.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(c) = g.as_mut().filter(|c| c.cfg.hang_close) {
            c.hang("hil_close");
        }
        match g.take() {
            Some(mut c) => {
                c.close();
                if c.cfg.close_error {
                    c.trace_line(format_args!("close err=injected"));
                    return ERR_INJECTED;
                }
                0
            }
            None => ERR_INVALID_CARD,
        }
    })
}

/// `hil_set_card_specific_options`: accepted and traced.
///
/// # Safety
/// `options` must be valid for `size` bytes or null.
#[no_mangle]
pub unsafe extern "C" fn hil_set_card_specific_options(
    card: t_card,
    options: *const c_char,
    size: usize,
) -> t_error {
    with_card(card, |c| {
        if options.is_null() || size > 4096 {
            return ERR_INVALID_ARGUMENT;
        }
        let bytes = std::slice::from_raw_parts(options.cast::<u8>(), size);
        c.trace_line(format_args!("options {}", String::from_utf8_lossy(bytes)));
        0
    })
}

/// `hil_set_encoder_counts`.
///
/// # Safety
/// Arrays must hold `num_channels` values.
#[no_mangle]
pub unsafe extern "C" fn hil_set_encoder_counts(
    card: t_card,
    channels: *const u32,
    num_channels: u32,
    buffer: *const i32,
) -> t_error {
    with_card(card, |c| {
        let (Some(ch), Some(v)) = (slice(channels, num_channels), slice(buffer, num_channels))
        else {
            return ERR_INVALID_ARGUMENT;
        };
        for (&ch, &v) in ch.iter().zip(v) {
            if let Err(e) = c.set_counts(ch, v) {
                return e;
            }
        }
        0
    })
}

fn fill_counts(c: &mut Card, ch: &[u32], out: &mut [i32]) -> t_error {
    for (o, &ch) in out.iter_mut().zip(ch) {
        match c.counts(ch) {
            Ok(v) => *o = v,
            Err(e) => return e,
        }
    }
    0
}

/// `hil_read_encoder`: advances the plant by one `period` and reads.
///
/// # Safety
/// Arrays must hold `num_channels` values.
#[no_mangle]
pub unsafe extern "C" fn hil_read_encoder(
    card: t_card,
    channels: *const u32,
    num_channels: u32,
    buffer: *mut i32,
) -> t_error {
    with_card(card, |c| {
        let Some(ch) = slice(channels, num_channels) else {
            return ERR_INVALID_ARGUMENT;
        };
        if buffer.is_null() {
            return ERR_INVALID_ARGUMENT;
        }
        let period = c.cfg.period;
        c.maybe_slow(period);
        c.step(period);
        if c.hang_read_active() {
            c.hang("hil_read_encoder");
        }
        if c.read_error_active() {
            c.trace_line(format_args!("read err=injected"));
            return ERR_READ_FAILED;
        }
        let out = std::slice::from_raw_parts_mut(buffer, ch.len());
        fill_counts(c, ch, out)
    })
}

/// `hil_write_analog`.
///
/// # Safety
/// Arrays must hold `num_channels` values.
#[no_mangle]
pub unsafe extern "C" fn hil_write_analog(
    card: t_card,
    channels: *const u32,
    num_channels: u32,
    buffer: *const f64,
) -> t_error {
    with_card(card, |c| {
        let (Some(ch), Some(v)) = (slice(channels, num_channels), slice(buffer, num_channels))
        else {
            return ERR_INVALID_ARGUMENT;
        };
        let period = c.task.as_ref().map_or(c.cfg.period, |t| t.period);
        c.maybe_slow(period);
        if c.hang_write_active() {
            c.hang("hil_write_analog");
        }
        for (&ch, &v) in ch.iter().zip(v) {
            let r = c.write(ch, v);
            if r < 0 {
                return r;
            }
        }
        0
    })
}

/// `hil_set_analog_output_ranges`: accepted and traced.
///
/// # Safety
/// Arrays must hold `num_channels` values.
#[no_mangle]
pub unsafe extern "C" fn hil_set_analog_output_ranges(
    card: t_card,
    channels: *const u32,
    num_channels: u32,
    minimums: *const f64,
    maximums: *const f64,
) -> t_error {
    with_card(card, |c| {
        let (Some(ch), Some(lo), Some(hi)) = (
            slice(channels, num_channels),
            slice(minimums, num_channels),
            slice(maximums, num_channels),
        ) else {
            return ERR_INVALID_ARGUMENT;
        };
        for i in 0..ch.len() {
            c.trace_line(format_args!("range ch={} {}..{}", ch[i], lo[i], hi[i]));
        }
        0
    })
}

/// `hil_watchdog_set_analog_expiration_state`: only 0 V is accepted.
///
/// # Safety
/// Arrays must hold `num_channels` values.
#[no_mangle]
pub unsafe extern "C" fn hil_watchdog_set_analog_expiration_state(
    card: t_card,
    channels: *const c_uint,
    num_channels: c_uint,
    voltages: *const f64,
) -> t_error {
    with_card(card, |c| {
        if c.cfg.watchdog_refused {
            return ERR_WATCHDOG_STATE_UNSUPPORTED;
        }
        let (Some(_), Some(v)) = (slice(channels, num_channels), slice(voltages, num_channels))
        else {
            return ERR_INVALID_ARGUMENT;
        };
        if v.iter().any(|&v| v != 0.0) {
            return ERR_INVALID_ARGUMENT;
        }
        c.watchdog.expiration_set = true;
        c.trace_line(format_args!("watchdog_expiration_state v=0"));
        0
    })
}

/// `hil_watchdog_start`.
///
/// # Safety
/// Any pointer value is accepted.
#[no_mangle]
pub unsafe extern "C" fn hil_watchdog_start(card: t_card, timeout: f64) -> t_error {
    with_card(card, |c| {
        if !(timeout.is_finite() && timeout > 0.0) {
            return ERR_INVALID_ARGUMENT;
        }
        if c.cfg.watchdog_start_error {
            c.trace_line(format_args!("watchdog_start err=injected"));
            return ERR_INJECTED;
        }
        c.watchdog.running = true;
        c.watchdog.timeout = timeout;
        c.watchdog.last_reload = c.t;
        c.watchdog.expired = false;
        c.trace_line(format_args!("watchdog_start timeout={timeout}"));
        0
    })
}

/// `hil_watchdog_reload`: 1 if reloaded in time, 0 if it had expired.
///
/// # Safety
/// Any pointer value is accepted.
#[no_mangle]
pub unsafe extern "C" fn hil_watchdog_reload(card: t_card) -> t_error {
    with_card(card, |c| c.reload())
}

/// `hil_watchdog_stop`.
///
/// # Safety
/// Any pointer value is accepted.
#[no_mangle]
pub unsafe extern "C" fn hil_watchdog_stop(card: t_card) -> t_error {
    with_card(card, |c| {
        if c.cfg.watchdog_stop_error {
            c.trace_line(format_args!("watchdog_stop err=injected"));
            return ERR_INJECTED;
        }
        c.watchdog.running = false;
        c.trace_line(format_args!("watchdog_stop"));
        0
    })
}

/// `hil_watchdog_is_expired`: 1 if the watchdog has expired, else 0.
///
/// # Safety
/// Any pointer value is accepted.
#[no_mangle]
pub unsafe extern "C" fn hil_watchdog_is_expired(card: t_card) -> t_error {
    with_card(card, |c| t_error::from(c.watchdog.expired))
}

/// `hil_watchdog_clear`: clears an expiry (error if there was none).
///
/// # Safety
/// Any pointer value is accepted.
#[no_mangle]
pub unsafe extern "C" fn hil_watchdog_clear(card: t_card) -> t_error {
    with_card(card, |c| {
        if c.watchdog.expired {
            c.watchdog.expired = false;
            c.trace_line(format_args!("watchdog_clear"));
            0
        } else {
            ERR_NOTHING_TO_CLEAR
        }
    })
}

/// `hil_task_create_encoder_reader`: one task per card.
///
/// # Safety
/// `channels` must hold `num_channels` values; `task` must be writable.
#[no_mangle]
pub unsafe extern "C" fn hil_task_create_encoder_reader(
    card: t_card,
    _samples_in_buffer: u32,
    channels: *const u32,
    num_channels: u32,
    task: *mut t_task,
) -> t_error {
    with_card(card, |c| {
        if c.cfg.no_tasks {
            return ERR_TASKS_UNSUPPORTED;
        }
        let Some(ch) = slice(channels, num_channels) else {
            return ERR_INVALID_ARGUMENT;
        };
        if task.is_null() || c.task.is_some() || ch.iter().any(|&ch| ch > 1) {
            return ERR_INVALID_ARGUMENT;
        }
        c.task = Some(Task {
            channels: ch.to_vec(),
            period: c.cfg.period,
            started: false,
        });
        *task = task_handle();
        0
    })
}

/// `hil_task_start`: any clock; the frequency sets the virtual period.
///
/// # Safety
/// Any pointer value is accepted.
#[no_mangle]
pub unsafe extern "C" fn hil_task_start(
    task: t_task,
    clock: c_int,
    frequency: f64,
    _num_samples: u32,
) -> t_error {
    with_task(task, |c| {
        if !(frequency.is_finite() && frequency > 0.0) {
            return ERR_INVALID_ARGUMENT;
        }
        if let Some(t) = c.task.as_mut() {
            t.period = 1.0 / frequency;
            t.started = true;
        }
        c.trace_line(format_args!(
            "task_start clock={clock} frequency={frequency}"
        ));
        0
    })
}

/// `hil_task_read_encoder`: advances `num_samples` periods and returns them.
///
/// # Safety
/// `buffer` must hold `num_samples * channels` values.
#[no_mangle]
pub unsafe extern "C" fn hil_task_read_encoder(
    task: t_task,
    num_samples: u32,
    buffer: *mut i32,
) -> t_error {
    with_task(task, |c| {
        let Some((channels, period)) = c
            .task
            .as_ref()
            .filter(|t| t.started)
            .map(|t| (t.channels.clone(), t.period))
        else {
            return ERR_TASK_NOT_STARTED;
        };
        if buffer.is_null() || num_samples == 0 || num_samples > 10_000 {
            return ERR_INVALID_ARGUMENT;
        }
        let nch = channels.len();
        let out = std::slice::from_raw_parts_mut(buffer, nch * num_samples as usize);
        c.maybe_slow(period);
        for s in 0..num_samples as usize {
            c.step(period);
            if c.hang_read_active() {
                c.hang("hil_task_read_encoder");
            }
            if c.read_error_active() {
                c.trace_line(format_args!("read err=injected"));
                return ERR_READ_FAILED;
            }
            let r = fill_counts(c, &channels, &mut out[s * nch..(s + 1) * nch]);
            if r < 0 {
                return r;
            }
        }
        num_samples as t_error
    })
}

/// `hil_task_stop`.
///
/// # Safety
/// Any pointer value is accepted.
#[no_mangle]
pub unsafe extern "C" fn hil_task_stop(task: t_task) -> t_error {
    with_task(task, |c| {
        if let Some(t) = c.task.as_mut() {
            t.started = false;
        }
        0
    })
}

/// `hil_task_delete`.
///
/// # Safety
/// Any pointer value is accepted.
#[no_mangle]
pub unsafe extern "C" fn hil_task_delete(task: t_task) -> t_error {
    with_task(task, |c| {
        c.task = None;
        0
    })
}

/// `msg_get_error_messageA`: the fake's message for `code`.
///
/// # Safety
/// `buffer` must be writable for `length` bytes.
#[no_mangle]
pub unsafe extern "C" fn msg_get_error_messageA(
    _locale: *const c_char,
    code: t_error,
    buffer: *mut c_char,
    length: usize,
) -> t_error {
    guarded(|| {
        if buffer.is_null() || length == 0 {
            return ERR_INVALID_ARGUMENT;
        }
        let m = message(code).as_bytes();
        let n = m.len().min(length - 1);
        let out = std::slice::from_raw_parts_mut(buffer.cast::<u8>(), length);
        out[..n].copy_from_slice(&m[..n]);
        out[n] = 0;
        0
    })
}
