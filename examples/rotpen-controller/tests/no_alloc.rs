//! Counting global allocator: the generated controllers (FL, pole placement,
//! the hybrid swing-up with its mode switches, sliding mode) and RK4 step
//! never allocate.
//! Only allocations on the test's own thread count (the test harness may
//! allocate on its main thread meanwhile), as in `runtime/tests/no_alloc.rs`.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use rotpen_controller::rotary_pendulum::*;

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    static ACTIVE: Cell<bool> = const { Cell::new(false) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if ACTIVE.with(Cell::get) {
            ALLOCS.fetch_add(1, Ordering::SeqCst);
        }
        System.alloc(l)
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        System.dealloc(p, l)
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        if ACTIVE.with(Cell::get) {
            ALLOCS.fetch_add(1, Ordering::SeqCst);
        }
        System.realloc(p, l, n)
    }
}

#[global_allocator]
static A: Counting = Counting;

#[test]
fn controller_and_rk4_do_not_allocate() {
    let p = Params::default();
    let mut fl = FeedbackLinearization::default();
    let mut pp = PolePlacement::new();
    let mut swing = SwingUp::default();
    let mut smc = SlidingMode::default();
    let mut x = [0.0, 0.1, 0.0, 0.0];
    ACTIVE.with(|a| a.set(true));
    let before = ALLOCS.load(Ordering::SeqCst);
    let mut acc = 0.0;
    for _ in 0..100_000 {
        let u = fl.control(&x);
        acc += pp.control(&x)[0];
        x = rk4_step(&x, &u, &p, 1e-4);
    }
    // the hybrid controller through a swing-up (mode switches included) and
    // the sliding-mode law
    let mut y = [0.0, std::f64::consts::PI - 0.05, 0.0, 0.0];
    for _ in 0..20_000 {
        let u = swing.control(&y);
        acc += smc.control(&y)[0];
        y = rk4_step(&y, &u, &p, 1e-4);
    }
    acc += swing.mode() as f64;
    for _ in 0..1_000 {
        acc += jacobian_x(&x, &[0.0], &p)[2][1] + jacobian_u(&x, &[0.0], &p)[2][0];
    }
    let after = ALLOCS.load(Ordering::SeqCst);
    ACTIVE.with(|a| a.set(false));
    std::hint::black_box(acc);
    assert_eq!(
        after - before,
        0,
        "allocations during 1e5 controller + RK4 steps"
    );
}
