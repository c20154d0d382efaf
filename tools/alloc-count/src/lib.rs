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
//!
//! For fuzzing, a thread can also cap the size of a single allocation ([`set_limit`]): a larger
//! request runs the hook set with [`on_refusal`] (to say which input asked) and then fails, which
//! makes `handle_alloc_error` abort the process; [`largest_request`] reports the largest request
//! made.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

pub mod pool;
pub mod steady;

/// A global allocator that forwards every call to [`System`] and counts, per thread, the
/// allocation calls (`alloc`, `alloc_zeroed`, `realloc`) and the largest request; deallocations
/// are not counted. A request over the thread's [`set_limit`] fails.
pub struct Counting;

thread_local! {
    /// Allocation calls (alloc, alloc_zeroed, realloc) made by this thread.
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
    /// Largest single request this thread may make, bytes.
    static LIMIT: Cell<usize> = const { Cell::new(usize::MAX) };
    /// Largest single request this thread made, bytes.
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

/// The hook run before a request over the limit fails (a `fn(usize)` as an address; 0: none).
static ON_REFUSAL: AtomicUsize = AtomicUsize::new(0);

/// Counts a request of `size` bytes; `false` if it is over this thread's limit.
fn count(size: usize) -> bool {
    ALLOCATIONS.with(|c| c.set(c.get() + 1));
    LARGEST.with(|c| c.set(c.get().max(size)));
    if size <= LIMIT.with(Cell::get) {
        return true;
    }
    let hook = ON_REFUSAL.load(Ordering::Relaxed);
    if hook != 0 {
        // SAFETY: only `on_refusal` stores here, and it stores a `fn(usize)`.
        let hook: fn(usize) = unsafe { std::mem::transmute::<usize, fn(usize)>(hook) };
        // The hook may allocate (small amounts): lift the limit while it runs.
        let limit = LIMIT.with(|c| c.replace(usize::MAX));
        hook(size);
        LIMIT.with(|c| c.set(limit));
    }
    false
}

/// Caps every later single allocation of this thread at `bytes` (`usize::MAX`: no cap). A
/// larger request fails after the [`on_refusal`] hook ran; Rust's `handle_alloc_error` then
/// aborts with the size.
pub fn set_limit(bytes: usize) {
    LIMIT.with(|c| c.set(bytes));
}

/// Sets the hook run (with the requested size) before a request over the limit fails.
pub fn on_refusal(hook: fn(usize)) {
    ON_REFUSAL.store(hook as usize, Ordering::Relaxed);
}

/// The largest single allocation request this thread has made, bytes (since it started or
/// the last [`reset_largest`]).
pub fn largest_request() -> usize {
    LARGEST.with(Cell::get)
}

/// Starts [`largest_request`] over from 0.
pub fn reset_largest() {
    LARGEST.with(|c| c.set(0));
}

// SAFETY: every call is forwarded unchanged to `System` or fails with null (allowed by the
// `GlobalAlloc` contract); the thread-locals are const-initialised `Cell`s without destructors,
// which need no allocation to access.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if !count(layout.size()) {
            return std::ptr::null_mut();
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if !count(layout.size()) {
            return std::ptr::null_mut();
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if !count(new_size) {
            return std::ptr::null_mut();
        }
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
    fn tracks_the_largest_request_and_refuses_one_over_the_limit() {
        static REFUSED: AtomicU64 = AtomicU64::new(0);
        on_refusal(|size| REFUSED.store(size as u64, Ordering::Relaxed));
        reset_largest();
        let v: Vec<u8> = black_box(Vec::with_capacity(1000));
        assert_eq!(largest_request(), 1000);
        drop(v);
        set_limit(4096);
        let mut big: Vec<u8> = Vec::new();
        assert!(big.try_reserve_exact(1 << 20).is_err(), "over the limit");
        assert_eq!(REFUSED.load(Ordering::Relaxed), 1 << 20);
        assert!(big.try_reserve_exact(4096).is_ok(), "at the limit");
        set_limit(usize::MAX);
        assert_eq!(largest_request(), 1 << 20);
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
