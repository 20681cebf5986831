//! Stop requests from outside: Ctrl-C, and every signal or console event
//! that ends a process while the motor may be driven.
//!
//! On Unix, SIGINT (Ctrl-C), SIGTERM (`kill`, `timeout`, systemd, `docker
//! stop`), SIGHUP (terminal or ssh session closed) and SIGQUIT (Ctrl-\); on
//! Windows, Ctrl-C, Ctrl-Break, console close, logoff and shutdown. The first
//! one sets a stop flag, which the control loop turns into `fault:stopped`
//! with 0 V written and the log flushed; the caller then closes the board and
//! reports [`stop_signal`] (exit code `128 + signal` by convention). A second
//! Ctrl-C (or SIGQUIT) terminates the process at once (exit code
//! `128 + signal` on Unix), for a loop stuck in a driver call; on a board the
//! armed watchdog then takes the output to its 0 V expiration state. A
//! repeated SIGTERM or SIGHUP is a duplicate and changes nothing. A signal
//! ignored when the process started (`nohup`, a script's background job)
//! stays ignored.
//!
//! On Windows the close, logoff and shutdown events end the process when
//! the handler returns, so the handler waits (at most [`WINDOWS_GRACE`]) until
//! the caller reports the safe stop complete with [`stop_completed`].
//!
//! No dependency: the handlers only store to atomics (async-signal-safe).

use std::sync::atomic::{AtomicBool, AtomicI32, AtomicPtr, Ordering};
use std::sync::Arc;

/// The flag the handler sets (a leaked `Arc` clone, so it lives forever).
static FLAG: AtomicPtr<AtomicBool> = AtomicPtr::new(std::ptr::null_mut());

/// The signal (Unix) or console event (Windows, offset by 1000) of the first
/// stop request; 0 for none.
static SIGNAL: AtomicI32 = AtomicI32::new(0);

/// Set by [`stop_completed`] once 0 V is written, the board closed and the
/// log flushed.
static COMPLETED: AtomicBool = AtomicBool::new(false);

/// How long a Windows console close/logoff/shutdown handler waits for the
/// safe stop before the OS ends the process (the OS allows about 5 s).
pub const WINDOWS_GRACE: std::time::Duration = std::time::Duration::from_millis(4500);

/// Sets `flag` on the first stop request (see the module docs for which).
/// Calling it again replaces the flag (the handlers are installed once).
/// Returns the OS error if a handler could not be installed.
pub fn stop_on_ctrl_c(flag: Arc<AtomicBool>) -> std::io::Result<()> {
    let ptr = Arc::into_raw(flag) as *mut AtomicBool;
    let old = FLAG.swap(ptr, Ordering::SeqCst);
    if old.is_null() {
        imp::install()
    } else {
        // The old flag stays alive (it may still be read by a handler in flight).
        Ok(())
    }
}

/// The same as [`stop_on_ctrl_c`]: every terminating signal stops the loop
/// safely, not only Ctrl-C.
pub fn stop_on_signals(flag: Arc<AtomicBool>) -> std::io::Result<()> {
    stop_on_ctrl_c(flag)
}

/// What asked the run to stop, if anything did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StopSignal {
    /// Its name: `SIGINT (Ctrl-C)`, `SIGTERM`, `SIGHUP`, `SIGQUIT (Ctrl-\)`, or a Windows
    /// console event (`CTRL_CLOSE_EVENT`, ...).
    pub name: &'static str,
    /// The exit code a process ended by it has by convention (`128 + n`
    /// on Unix: 130, 143, 129, 131).
    pub exit_code: i32,
}

/// The first stop request received, if any.
pub fn stop_signal() -> Option<StopSignal> {
    imp::describe(SIGNAL.load(Ordering::SeqCst))
}

/// Tells a waiting Windows console handler that the safe stop is complete
/// (0 V written, board closed, log flushed), so the process may end.
pub fn stop_completed() {
    COMPLETED.store(true, Ordering::SeqCst);
}

/// Passes a stop request this process received on to a child process (a
/// rig binary run by `plantc run --compiled`): on Unix the same signal, so a
/// `kill` of the parent stops the child safely too. Returns true if one was
/// sent. On Windows the console events already reach every process of the
/// console, so nothing is sent.
pub fn forward_stop(child_pid: u32) -> bool {
    imp::forward(SIGNAL.load(Ordering::SeqCst), child_pid)
}

/// Called by the OS handler with the signal or event; true if this was the
/// first request.
fn request_stop(code: i32) -> bool {
    let p = FLAG.load(Ordering::SeqCst);
    if p.is_null() {
        return false;
    }
    // SAFETY: the pointer comes from Arc::into_raw and is never released.
    let flag = unsafe { &*p };
    let first = !flag.swap(true, Ordering::SeqCst);
    if first {
        SIGNAL.store(code, Ordering::SeqCst);
    }
    first
}

#[cfg(unix)]
mod imp {
    use std::ffi::c_int;

    use super::StopSignal;

    const SIGHUP: c_int = 1;
    const SIGINT: c_int = 2;
    const SIGQUIT: c_int = 3;
    const SIGTERM: c_int = 15;
    const SIG_ERR: usize = usize::MAX;
    const SIG_IGN: usize = 1;
    /// The signals handled, with their names.
    const SIGNALS: [(c_int, &str); 4] = [
        (SIGINT, "SIGINT (Ctrl-C)"),
        (SIGTERM, "SIGTERM"),
        (SIGHUP, "SIGHUP"),
        (SIGQUIT, "SIGQUIT (Ctrl-\\)"),
    ];

    extern "C" {
        fn signal(signum: c_int, handler: usize) -> usize;
        fn _exit(status: c_int) -> !;
        fn kill(pid: c_int, sig: c_int) -> c_int;
    }

    pub fn forward(code: i32, child_pid: u32) -> bool {
        let Ok(pid) = c_int::try_from(child_pid) else {
            return false;
        };
        // SIGINT and SIGQUIT come from the terminal to the whole process
        // group (the child has them already, and a second one would make
        // it exit at once); SIGTERM and SIGHUP may reach the parent alone.
        if pid <= 0 || !(code == SIGTERM || code == SIGHUP) {
            return false;
        }
        // SAFETY: sends a signal to one child process id (never a group: pid > 0).
        unsafe { kill(pid, code) == 0 }
    }

    extern "C" fn on_signal(sig: c_int) {
        // A repeated SIGINT/SIGQUIT is the user insisting (a loop stuck in a
        // driver call): exit at once. A repeated SIGTERM/SIGHUP is a
        // duplicate (sent to the process group and forwarded by a parent
        // `plantc run --compiled`, or a terminal hang-up reaching both), so
        // it must not cut the safe stop short.
        if !super::request_stop(sig) && (sig == SIGINT || sig == SIGQUIT) {
            // SAFETY: _exit is async-signal-safe.
            unsafe { _exit(128 + sig) }
        }
    }

    pub fn install() -> std::io::Result<()> {
        let handler: extern "C" fn(c_int) = on_signal;
        for (sig, _) in SIGNALS {
            // SAFETY: installs a handler that only touches atomics (or exits).
            let r = unsafe { signal(sig, handler as usize) };
            if r == SIG_ERR {
                return Err(std::io::Error::last_os_error());
            }
            if r == SIG_IGN {
                // ignored when plantc started (`nohup`, a script's background
                // job): it stays ignored, as shells do
                // SAFETY: restores the inherited disposition.
                unsafe { signal(sig, SIG_IGN) };
            }
        }
        Ok(())
    }

    pub fn describe(code: i32) -> Option<StopSignal> {
        SIGNALS
            .iter()
            .find(|(s, _)| *s == code)
            .map(|(s, name)| StopSignal {
                name,
                exit_code: 128 + s,
            })
    }
}

#[cfg(windows)]
mod imp {
    use std::sync::atomic::Ordering;

    use super::StopSignal;

    const CTRL_C_EVENT: u32 = 0;
    const CTRL_BREAK_EVENT: u32 = 1;
    const CTRL_CLOSE_EVENT: u32 = 2;
    const CTRL_LOGOFF_EVENT: u32 = 5;
    const CTRL_SHUTDOWN_EVENT: u32 = 6;
    /// Events are stored offset so that 0 means "none".
    const OFFSET: i32 = 1000;

    #[link(name = "kernel32")]
    extern "system" {
        fn SetConsoleCtrlHandler(
            handler: Option<unsafe extern "system" fn(u32) -> i32>,
            add: i32,
        ) -> i32;
    }

    unsafe extern "system" fn on_ctrl(event: u32) -> i32 {
        match event {
            // TRUE: handled (the loop stops); FALSE on a second Ctrl-C lets
            // the default handler terminate the process.
            CTRL_C_EVENT | CTRL_BREAK_EVENT => {
                i32::from(super::request_stop(OFFSET + event as i32))
            }
            // The process ends when this returns: stop the loop and wait for
            // the safe stop (0 V, board closed, log flushed).
            CTRL_CLOSE_EVENT | CTRL_LOGOFF_EVENT | CTRL_SHUTDOWN_EVENT => {
                super::request_stop(OFFSET + event as i32);
                let start = std::time::Instant::now();
                while !super::COMPLETED.load(Ordering::SeqCst)
                    && start.elapsed() < super::WINDOWS_GRACE
                {
                    std::thread::sleep(std::time::Duration::from_millis(10));
                }
                1
            }
            _ => 0,
        }
    }

    pub fn install() -> std::io::Result<()> {
        // SAFETY: registers a handler that only touches atomics and sleeps.
        let r = unsafe { SetConsoleCtrlHandler(Some(on_ctrl), 1) };
        if r == 0 {
            Err(std::io::Error::last_os_error())
        } else {
            Ok(())
        }
    }

    pub fn forward(_code: i32, _child_pid: u32) -> bool {
        false
    }

    pub fn describe(code: i32) -> Option<StopSignal> {
        let (name, exit_code) = match u32::try_from(code - OFFSET).ok()? {
            CTRL_C_EVENT => ("Ctrl-C", 130),
            CTRL_BREAK_EVENT => ("Ctrl-Break", 130),
            CTRL_CLOSE_EVENT => ("CTRL_CLOSE_EVENT", 129),
            CTRL_LOGOFF_EVENT => ("CTRL_LOGOFF_EVENT", 129),
            CTRL_SHUTDOWN_EVENT => ("CTRL_SHUTDOWN_EVENT", 143),
            _ => return None,
        };
        Some(StopSignal { name, exit_code })
    }
}

#[cfg(not(any(unix, windows)))]
mod imp {
    use super::StopSignal;

    pub fn install() -> std::io::Result<()> {
        Err(std::io::Error::new(
            std::io::ErrorKind::Unsupported,
            "Ctrl-C handling is not implemented on this OS",
        ))
    }

    pub fn describe(_code: i32) -> Option<StopSignal> {
        None
    }

    pub fn forward(_code: i32, _child_pid: u32) -> bool {
        false
    }
}
