//! A counting global allocator: how the loops prove the "no allocation" rule in tests.
//!
//! A real-time tick must not allocate: `malloc` can take a lock, fault in pages or call the
//! kernel. Claims like "the tick allocates nothing" are only worth something when a test counts,
//! so each crate's `no_alloc` test binary installs [`Counting`] as its global allocator and wraps
//! the code under test in [`allocations`]. Counting is armed per thread, so the test harness's
//! own threads do not disturb the count.
//!
//! ```
//! // In a test binary: `#[global_allocator] static A: rt::alloc_count::Counting = rt::alloc_count::Counting;`
//! // Without it installed the count stays 0, which is why every user also checks that the
//! // counter sees a deliberate allocation.
//! let n = rt::alloc_count::allocations(|| {});
//! assert_eq!(n, 0);
//! ```

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// The system allocator, counting the allocations (and reallocations) of armed threads.
pub struct Counting;

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
}

fn bump() {
    // `try_with`: the allocator can be called while thread-locals are being torn down.
    let _ = ARMED.try_with(|a| {
        if a.get() {
            COUNT.with(|c| c.set(c.get() + 1));
        }
    });
}

// SAFETY: every call is forwarded unchanged to `System`; counting touches only thread-locals
// that never allocate (const-initialised `Cell`s).
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        bump();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new: usize) -> *mut u8 {
        bump();
        unsafe { System.realloc(ptr, layout, new) }
    }
}

/// The number of allocations `f` makes on this thread (0 unless [`Counting`] is the global
/// allocator).
pub fn allocations(f: impl FnOnce()) -> u64 {
    COUNT.with(|c| c.set(0));
    ARMED.with(|a| a.set(true));
    f();
    ARMED.with(|a| a.set(false));
    COUNT.with(|c| c.get())
}
