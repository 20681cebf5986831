//! Ctrl-C wiring: the first Ctrl-C (SIGINT on Unix, CTRL_C/CTRL_BREAK on
//! Windows) sets a stop flag, which the control loop turns into
//! `fault:stopped` with 0 V written and the log flushed. A second Ctrl-C
//! terminates the process at once (exit code 130 on Unix), for a loop stuck
//! in a driver call; on a board the armed watchdog then takes the output to
//! its 0 V expiration state.
//!
//! No dependency: the handler only stores to an atomic (async-signal-safe).

use std::sync::atomic::{AtomicBool, AtomicPtr, Ordering};
use std::sync::Arc;

/// The flag the handler sets (a leaked `Arc` clone, so it lives forever).
static FLAG: AtomicPtr<AtomicBool> = AtomicPtr::new(std::ptr::null_mut());

/// Sets `flag` on the first Ctrl-C. Calling it again replaces the flag
/// (the handler is installed once). Returns the OS error if the handler
/// could not be installed.
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

/// Called by the OS handler; true if this was the first request.
fn request_stop() -> bool {
    let p = FLAG.load(Ordering::SeqCst);
    if p.is_null() {
        return false;
    }
    // SAFETY: the pointer comes from Arc::into_raw and is never released.
    let flag = unsafe { &*p };
    !flag.swap(true, Ordering::SeqCst)
}

#[cfg(unix)]
mod imp {
    use std::ffi::c_int;

    const SIGINT: c_int = 2;
    const SIG_ERR: usize = usize::MAX;

    extern "C" {
        fn signal(signum: c_int, handler: usize) -> usize;
        fn _exit(status: c_int) -> !;
    }

    extern "C" fn on_sigint(_sig: c_int) {
        if !super::request_stop() {
            // SAFETY: _exit is async-signal-safe.
            unsafe { _exit(130) }
        }
    }

    pub fn install() -> std::io::Result<()> {
        let handler: extern "C" fn(c_int) = on_sigint;
        // SAFETY: installs a handler that only touches atomics (or exits).
        let r = unsafe { signal(SIGINT, handler as usize) };
        if r == SIG_ERR {
            Err(std::io::Error::last_os_error())
        } else {
            Ok(())
        }
    }
}

#[cfg(windows)]
mod imp {
    const CTRL_C_EVENT: u32 = 0;
    const CTRL_BREAK_EVENT: u32 = 1;

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
            CTRL_C_EVENT | CTRL_BREAK_EVENT => i32::from(super::request_stop()),
            _ => 0,
        }
    }

    pub fn install() -> std::io::Result<()> {
        // SAFETY: registers a handler that only touches atomics.
        let r = unsafe { SetConsoleCtrlHandler(Some(on_ctrl), 1) };
        if r == 0 {
            Err(std::io::Error::last_os_error())
        } else {
            Ok(())
        }
    }
}

#[cfg(not(any(unix, windows)))]
mod imp {
    pub fn install() -> std::io::Result<()> {
        Err(std::io::Error::new(
            std::io::ErrorKind::Unsupported,
            "Ctrl-C handling is not implemented on this OS",
        ))
    }
}
