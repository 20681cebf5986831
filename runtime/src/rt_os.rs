//! Best-effort real-time setup of the calling thread: FIFO priority and
//! memory locking where the OS permits, a note where it does not. The
//! previous scheduling policy is restored (and memory unlocked) when the
//! returned guard is dropped.

/// What [`try_realtime`] achieved, with human-readable notes.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RealtimeSetup {
    /// The thread runs under a real-time scheduling policy.
    pub priority: bool,
    /// Process memory is locked (no page faults in the loop).
    pub memory_locked: bool,
    /// Notes for the user (what was not done and why).
    pub notes: Vec<String>,
}

/// Undoes [`try_realtime`] on drop (previous policy restored, memory unlocked).
#[derive(Debug)]
pub struct RealtimeGuard {
    /// What was achieved.
    pub setup: RealtimeSetup,
    saved: imp::Saved,
}

impl Drop for RealtimeGuard {
    fn drop(&mut self) {
        imp::restore(&self.setup, &self.saved);
    }
}

/// Tries to raise the calling thread to real-time priority `priority`
/// (Linux: `SCHED_FIFO`) and to lock the pages mapped so far
/// (`mlockall(MCL_CURRENT)`); call it after allocating. Never fails; see the
/// notes. Keep the guard alive for the duration of the loop.
pub fn try_realtime(priority: i32) -> RealtimeGuard {
    let (setup, saved) = imp::enter(priority);
    RealtimeGuard { setup, saved }
}

#[cfg(target_os = "linux")]
mod imp {
    use super::RealtimeSetup;
    use std::ffi::c_int;

    #[repr(C)]
    struct SchedParam {
        sched_priority: c_int,
    }

    const SCHED_FIFO: c_int = 1;
    const MCL_CURRENT: c_int = 1;

    extern "C" {
        fn sched_setscheduler(pid: c_int, policy: c_int, param: *const SchedParam) -> c_int;
        fn sched_getscheduler(pid: c_int) -> c_int;
        fn sched_getparam(pid: c_int, param: *mut SchedParam) -> c_int;
        fn mlockall(flags: c_int) -> c_int;
        fn munlockall() -> c_int;
    }

    /// The policy and priority to restore.
    #[derive(Debug, Default)]
    pub struct Saved {
        policy: Option<(c_int, c_int)>,
    }

    pub fn enter(priority: i32) -> (RealtimeSetup, Saved) {
        let mut s = RealtimeSetup::default();
        let mut saved = Saved::default();
        let mut old = SchedParam { sched_priority: 0 };
        // SAFETY: plain syscalls with valid pointers to live structs; pid 0 = this thread.
        unsafe {
            let pol = sched_getscheduler(0);
            if pol >= 0 && sched_getparam(0, &mut old) == 0 {
                saved.policy = Some((pol, old.sched_priority));
            }
        }
        let param = SchedParam {
            sched_priority: priority.clamp(1, 99),
        };
        // SAFETY: as above.
        let r = unsafe { sched_setscheduler(0, SCHED_FIFO, &param) };
        if r == 0 {
            s.priority = true;
        } else {
            s.notes.push(format!(
                "real-time priority not set (sched_setscheduler SCHED_FIFO: {}); run as root or grant CAP_SYS_NICE",
                std::io::Error::last_os_error()
            ));
        }
        // Only current pages: MCL_FUTURE could make later allocations fail under a
        // small RLIMIT_MEMLOCK. The loop allocates everything before this call.
        // SAFETY: mlockall has no memory-safety preconditions.
        let r = unsafe { mlockall(MCL_CURRENT) };
        if r == 0 {
            s.memory_locked = true;
        } else {
            s.notes.push(format!(
                "memory not locked (mlockall: {}); raise RLIMIT_MEMLOCK or grant CAP_IPC_LOCK",
                std::io::Error::last_os_error()
            ));
        }
        (s, saved)
    }

    pub fn restore(setup: &RealtimeSetup, saved: &Saved) {
        // SAFETY: plain syscalls with valid pointers.
        unsafe {
            if setup.priority {
                if let Some((pol, prio)) = saved.policy {
                    let p = SchedParam {
                        sched_priority: prio,
                    };
                    let _ = sched_setscheduler(0, pol, &p);
                }
            }
            if setup.memory_locked {
                let _ = munlockall();
            }
        }
    }
}

#[cfg(not(target_os = "linux"))]
mod imp {
    use super::RealtimeSetup;

    /// Nothing to restore.
    #[derive(Debug, Default)]
    pub struct Saved;

    pub fn enter(_priority: i32) -> (RealtimeSetup, Saved) {
        (
            RealtimeSetup {
                priority: false,
                memory_locked: false,
                notes: vec![
                    "real-time priority and memory locking are not implemented on this OS; \
                     running at normal priority"
                        .to_string(),
                ],
            },
            Saved,
        )
    }

    pub fn restore(_setup: &RealtimeSetup, _saved: &Saved) {}
}
