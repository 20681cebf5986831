//! The fake board's error codes and messages (its own codes, not Quanser's).

pub const ERR_INVALID_ARGUMENT: i32 = -1;
pub const ERR_INVALID_CARD: i32 = -2;
pub const ERR_ALREADY_OPEN: i32 = -3;
pub const ERR_INVALID_CHANNEL: i32 = -4;
pub const ERR_BAD_CONFIG: i32 = -5;
pub const ERR_READ_FAILED: i32 = -101;
pub const ERR_WATCHDOG_STATE_UNSUPPORTED: i32 = -102;
pub const ERR_WATCHDOG_EXPIRED: i32 = -103;
pub const ERR_TASKS_UNSUPPORTED: i32 = -104;
pub const ERR_WATCHDOG_NOT_RUNNING: i32 = -105;
pub const ERR_TASK_NOT_STARTED: i32 = -106;
pub const ERR_NOTHING_TO_CLEAR: i32 = -107;
pub const ERR_INJECTED: i32 = -108;

/// The text for a code.
pub fn message(code: i32) -> &'static str {
    match code {
        ERR_INVALID_ARGUMENT => "fake HIL: invalid argument",
        ERR_INVALID_CARD => "fake HIL: invalid card or task handle",
        ERR_ALREADY_OPEN => "fake HIL: the card is already open",
        ERR_INVALID_CHANNEL => "fake HIL: invalid channel",
        ERR_BAD_CONFIG => "fake HIL: cannot parse PLANTC_FAKE_HIL",
        ERR_READ_FAILED => "fake HIL: encoder read failed (injected read_error)",
        ERR_WATCHDOG_STATE_UNSUPPORTED => {
            "fake HIL: this card does not support configuring the watchdog expiration state (injected watchdog_refused)"
        }
        ERR_WATCHDOG_EXPIRED => "fake HIL: the watchdog has expired; outputs are in their expiration state",
        ERR_TASKS_UNSUPPORTED => "fake HIL: tasks are not supported (injected no_tasks)",
        ERR_WATCHDOG_NOT_RUNNING => "fake HIL: the watchdog is not running",
        ERR_TASK_NOT_STARTED => "fake HIL: the task has not been started",
        ERR_NOTHING_TO_CLEAR => "fake HIL: the watchdog had not expired; nothing to clear",
        ERR_INJECTED => "fake HIL: injected failure (PLANTC_FAKE_HIL fault)",
        _ => "fake HIL: unknown error code",
    }
}
