//! Allocators for the "no allocation per sample" guarantee: [`Counting`], a per-thread counting
//! global allocator for tests; [`pool::BlockPool`], the bounded small-block pool every live
//! process installs, with its counts; [`steady::SteadyState`], those counts after a warm-up.
//!
//! A test binary declares it as its global allocator and reads [`allocations`] before and
//! after the code under test:
//!
//! ```
//! #[global_allocator]
//! static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;
//!
//! fn main() {
//!     let before = alloc_count::allocations();
//!     let v: Vec<u8> = std::hint::black_box(Vec::with_capacity(8));
//!     assert_eq!(alloc_count::allocations() - before, 1);
//!     drop(v);
//! }
//! ```
//!
//! Only the calling thread's calls are counted, so allocations by the test harness or by other
//! tests running in parallel do not disturb the count.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

pub mod pool;
pub mod steady;

/// A global allocator that forwards every call to [`System`] and counts, per thread, the
/// allocation calls (`alloc`, `alloc_zeroed`, `realloc`); deallocations are not counted.
pub struct Counting;

thread_local! {
    /// Allocation calls (alloc, alloc_zeroed, realloc) made by this thread.
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn count() {
    ALLOCATIONS.with(|c| c.set(c.get() + 1));
}

// SAFETY: every call is forwarded unchanged to `System`; the thread-local counter is a
// const-initialised `Cell` without a destructor, which needs no allocation to access.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// The number of allocation calls the current thread has made through [`Counting`] since it
/// started (0 if [`Counting`] is not the global allocator).
pub fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::hint::black_box;
    use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

    #[global_allocator]
    static ALLOCATOR: Counting = Counting;

    #[test]
    fn counts_allocations_and_reallocations_of_this_thread() {
        let before = allocations();
        let mut v: Vec<u64> = black_box(Vec::with_capacity(4));
        assert_eq!(allocations() - before, 1, "with_capacity allocates once");
        v.reserve_exact(1000);
        black_box(&mut v);
        assert_eq!(allocations() - before, 2, "growing reallocates once");
        drop(v);
        let z = black_box(vec![0u8; 64]);
        assert_eq!(allocations() - before, 3, "a zeroed allocation counts");
        drop(z);
        let e: Vec<u64> = black_box(Vec::new());
        drop(e);
        assert_eq!(
            allocations() - before,
            3,
            "freeing and empty Vecs count nothing"
        );
    }

    #[test]
    fn does_not_count_other_threads() {
        // Flags instead of channels: the main thread must not allocate while it waits.
        let go = AtomicBool::new(false);
        let done = AtomicBool::new(false);
        let counted_there = AtomicU64::new(u64::MAX);
        std::thread::scope(|s| {
            s.spawn(|| {
                while !go.load(Ordering::Acquire) {
                    std::thread::yield_now();
                }
                let before = allocations();
                let v: Vec<u64> = black_box(Vec::with_capacity(1000));
                counted_there.store(allocations() - before, Ordering::Relaxed);
                done.store(true, Ordering::Release);
                drop(v);
            });
            let before = allocations();
            go.store(true, Ordering::Release);
            while !done.load(Ordering::Acquire) {
                std::thread::yield_now();
            }
            assert_eq!(
                allocations() - before,
                0,
                "the other thread's Vec counted here"
            );
        });
        assert_eq!(
            counted_there.load(Ordering::Relaxed),
            1,
            "counted on its own thread"
        );
    }
}
