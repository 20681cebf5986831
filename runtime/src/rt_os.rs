//! Best-effort real-time setup of the calling thread: FIFO priority and
//! memory locking where the OS permits, a note where it does not.

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

/// Tries to raise the calling thread to real-time priority `priority`
/// (Linux: `SCHED_FIFO`) and to lock the pages mapped so far (`mlockall(MCL_CURRENT)`);
/// call it after allocating. Never fails; see the notes.
pub fn try_realtime(priority: i32) -> RealtimeSetup {
    imp::try_realtime(priority)
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
        fn mlockall(flags: c_int) -> c_int;
    }

    pub fn try_realtime(priority: i32) -> RealtimeSetup {
        let mut s = RealtimeSetup::default();
        let param = SchedParam {
            sched_priority: priority.clamp(1, 99),
        };
        // SAFETY: plain syscalls with a valid pointer to a live struct; pid 0 = this thread.
        let r = unsafe { sched_setscheduler(0, SCHED_FIFO, &param) };
        if r == 0 {
            s.priority = true;
        } else {
            s.notes.push(format!(
                "real-time priority not set (sched_setscheduler SCHED_FIFO: {}); run as root or grant CAP_SYS_NICE",
                std::io::Error::last_os_error()
            ));
        }
        // SAFETY: mlockall has no memory-safety preconditions.
        // Only current pages: MCL_FUTURE could make later allocations fail under a
        // small RLIMIT_MEMLOCK. The loop allocates everything before this call.
        let r = unsafe { mlockall(MCL_CURRENT) };
        if r == 0 {
            s.memory_locked = true;
        } else {
            s.notes.push(format!(
                "memory not locked (mlockall: {}); raise RLIMIT_MEMLOCK or grant CAP_IPC_LOCK",
                std::io::Error::last_os_error()
            ));
        }
        s
    }
}

#[cfg(not(target_os = "linux"))]
mod imp {
    use super::RealtimeSetup;

    pub fn try_realtime(_priority: i32) -> RealtimeSetup {
        RealtimeSetup {
            priority: false,
            memory_locked: false,
            notes: vec![
                "real-time priority and memory locking are not implemented on this OS; \
                 running at normal priority"
                    .to_string(),
            ],
        }
    }
}
