//! Hooks for programs that run the command line in process ([`crate::run`]),
//! such as the Python module.

use std::sync::OnceLock;

static PROGRESS_HOOK: OnceLock<fn()> = OnceLock::new();

/// Installs `hook`, called on the calling thread at every progress report of
/// a long command (each fit iteration, each story step). The Python module
/// unwinds an interrupted call from it. The first hook installed stays;
/// returns whether this one was installed.
pub fn set_progress_hook(hook: fn()) -> bool {
    PROGRESS_HOOK.set(hook).is_ok()
}

/// Calls the installed hook, if any.
pub(crate) fn progress() {
    if let Some(h) = PROGRESS_HOOK.get() {
        h();
    }
}
