//! A counting global allocator: zero allocations over 1e5 loop cycles after start.

use plantc_runtime::{
    run, Controller, LogWriter, ObserverSpec, RotaryPendulumReference, RunConfig, SimBackend,
    SimConfig, SimNoise, StateFeedback, SupervisorState,
};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

struct Counting;

static ALLOCS: AtomicU64 = AtomicU64::new(0);

thread_local! {
    static ACTIVE: Cell<bool> = const { Cell::new(false) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if ACTIVE.with(Cell::get) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if ACTIVE.with(Cell::get) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Counts allocations on the loop thread from its first call to its
/// `until`-th call, i.e. over `until - 1` full loop cycles.
struct Probe {
    inner: StateFeedback,
    calls: u64,
    until: u64,
}

impl Controller for Probe {
    fn control(&mut self, t: f64, x: &[f64], u: &mut [f64]) {
        self.calls += 1;
        if self.calls == 1 {
            ACTIVE.with(|a| a.set(true));
        }
        if self.calls == self.until {
            ACTIVE.with(|a| a.set(false));
        }
        self.inner.control(t, x, u);
    }
}

#[test]
fn no_allocation_in_the_loop() {
    count_loop_allocations(false, "noalloc");
}

#[test]
fn no_allocation_in_the_loop_with_the_velocity_observer() {
    count_loop_allocations(true, "noalloc-observer");
}

fn count_loop_allocations(observer: bool, name: &str) {
    let plant = RotaryPendulumReference::default();
    let mut cfg = RunConfig::for_plant(&plant);
    cfg.duration_s = Some(100.0);
    if observer {
        cfg.observer = Some(ObserverSpec::from_smooth_plant(&plant).unwrap());
    }
    let sim = SimConfig {
        noise: Some(SimNoise {
            seed: 1,
            counts_std: 0.3,
            volts_std: 0.01,
        }),
        input_delay_samples: 2,
        ..SimConfig::default()
    };
    let mut be = SimBackend::new(Box::new(plant), vec![0.0, 0.05, 0.0, 0.0], sim).unwrap();
    let cycles = 100_000;
    let mut ctl = Probe {
        inner: StateFeedback::new(vec![-7.8914, 37.8313, -2.9850, 3.6222]),
        calls: 0,
        until: cycles + 1,
    };
    let path = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("{}-{name}.csv", std::process::id()));
    let mut log = LogWriter::create(&path).unwrap();
    let report = run(&cfg, &mut be, &mut ctl, Some(&mut log)).unwrap();
    assert_eq!(report.final_state, SupervisorState::Engaged, "{report}");
    assert!(ctl.calls > cycles, "{}", ctl.calls);
    let n = ALLOCS.load(Ordering::Relaxed);
    println!("allocations over {cycles} loop cycles (with CSV logging, observer {observer}): {n}");
    assert_eq!(n, 0);
    if observer {
        assert!(
            report.notes.iter().any(|n| n.contains("Kalman observer")),
            "{report}"
        );
    }
}
