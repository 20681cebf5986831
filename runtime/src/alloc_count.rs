//! A counting global allocator, so a binary can show that its control loop
//! does not allocate (the rig binaries of `plantc gen --rig` install it).
//!
//! Install it in the binary:
//!
//! ```ignore
//! #[global_allocator]
//! static ALLOC: plantc_runtime::CountingAllocator = plantc_runtime::CountingAllocator;
//! ```
//!
//! Only allocations made on a thread that called [`count_on_this_thread`]
//! are counted (other threads, e.g. a test harness, may allocate meanwhile).
//! Counting costs one thread-local read per allocation.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// The system allocator with a counter of allocations and reallocations.
#[derive(Debug, Clone, Copy, Default)]
pub struct CountingAllocator;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);
static INSTALLED: AtomicBool = AtomicBool::new(false);

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
}

fn note() {
    if !INSTALLED.load(Ordering::Relaxed) {
        INSTALLED.store(true, Ordering::Relaxed);
    }
    // `try_with`: the thread-local may already be gone while a thread exits.
    if COUNTING.try_with(Cell::get).unwrap_or(false) {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

// SAFETY: forwards every call to `System` unchanged; the bookkeeping touches
// only atomics and a const-initialised thread-local (no allocation).
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        System.alloc(layout)
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note();
        System.alloc_zeroed(layout)
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        System.realloc(ptr, layout, new_size)
    }
}

/// Starts (`true`) or stops counting the allocations of the calling thread.
pub fn count_on_this_thread(on: bool) {
    let _ = COUNTING.try_with(|c| c.set(on));
}

/// Allocations counted so far (all counting threads).
pub fn allocations() -> u64 {
    ALLOCATIONS.load(Ordering::Relaxed)
}

/// Whether [`CountingAllocator`] is the global allocator of this process
/// (true once it has served an allocation).
pub fn installed() -> bool {
    INSTALLED.load(Ordering::Relaxed)
}
