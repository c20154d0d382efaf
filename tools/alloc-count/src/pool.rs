//! A bounded, lock-free pool of small fixed-size blocks for use as a global allocator: once
//! [armed](BlockPool::arm), requests of at most [`BLOCK_SIZE`] bytes and alignment come from the
//! pool; everything else, any small request while the pool is empty, and everything before it is
//! armed come from the system allocator. Start-up (which may keep thousands of small blocks, such
//! as a simulated drive's plan) thus leaves the whole pool to the hot loop.
//!
//! Every live process installs it (`mems-acquire`, `mems-calibrate serve`, `mems-odometry serve`,
//! `mems-record`) and counts, once armed, the allocation calls it served and those that reached
//! the system allocator ([`BlockPool::counts`], reported in steady state by
//! [`crate::steady::SteadyState`]).
//!
//! Why a publishing process needs it: iceoryx2 0.10 allocates one small block per published sample
//! (`Publisher::loan_uninit`, and `send_copy` and the slice loans through it, wrap the loan's
//! shared state in an `Rc` (`ipc::Service`) or an `Arc` (`ipc_threadsafe::Service`) in
//! `ChunkMutSharedState::new`; no publishing API reuses it). That block is freed again when the
//! sample is sent, so in steady state the pool recycles one block per sample: a pop and a push
//! on a lock-free stack, no lock, no system call and no page fault (the blocks are static memory,
//! faulted in and locked by `mlockall` at start-up), so the hot loop never reaches the system
//! allocator. glibc's allocator usually serves such a block from its thread cache too, but
//! without a bound: it may take an arena lock, consolidate or call `brk`/`mmap`.
//!
//! Hand-written because the crates that exist replace the whole heap (talc, rlsf) and guard it
//! with a lock; what is needed here is the opposite: a small bounded pool for one block size,
//! freed from any thread, with everything else left to the system allocator.
//!
//! Design: `N` blocks of [`BLOCK_SIZE`] bytes, aligned to [`BLOCK_SIZE`], in the pool's own
//! storage (a `static` in the binary's zero-initialised data). Blocks are handed out first from
//! the never-used tail (an atomic bump index), then from a Treiber stack of freed blocks whose
//! links live in a separate array of atomics (so a stale link read is never a data race). The
//! stack head packs a 32-bit tag with the block index; the tag changes on every push and pop,
//! so a pop that raced with other pops and pushes of the same block fails its compare-exchange
//! (the ABA problem) unless exactly 2^32 operations happened in between. A block's owner
//! releases it with a Release compare-exchange and the next owner acquires it, so the old
//! owner's writes happen before the new owner's.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::{Cell, UnsafeCell};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, AtomicUsize, Ordering};

/// Size and alignment of every pool block, bytes (one cache line; iceoryx2 0.10's per-loan
/// shared state is 48 bytes).
pub const BLOCK_SIZE: usize = 64;

/// One block of storage.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct Block([u8; BLOCK_SIZE]);

/// Low 32 bits of the stack head: the top block's index + 1 (0: empty stack).
const INDEX_MASK: u64 = 0xFFFF_FFFF;

/// A pool of `N` blocks (N < 2^32 - 1) in front of the system allocator; see the module
/// documentation. Create it in a `static` with [`BlockPool::new`] and install it with
/// `#[global_allocator]`, or use it through [`GlobalAlloc`] directly.
pub struct BlockPool<const N: usize> {
    storage: UnsafeCell<[Block; N]>,
    /// Per block: the index + 1 of the block below it on the free stack (0: none).
    next: [AtomicU32; N],
    /// Tag (high 32 bits) and top index + 1 (low 32 bits) of the free stack.
    head: AtomicU64,
    /// Blocks `fresh..N` have never been handed out.
    fresh: AtomicUsize,
    /// Small requests that found the pool empty and went to the system allocator.
    fallbacks: AtomicU64,
    /// Whether small requests are served from the pool yet.
    armed: AtomicBool,
}

thread_local! {
    /// This thread's allocation calls served from a pool's blocks once armed.
    static POOL_CALLS: Cell<u64> = const { Cell::new(0) };
    /// This thread's allocation calls served by the system allocator once a pool was armed.
    static SYSTEM_CALLS: Cell<u64> = const { Cell::new(0) };
}

/// Adds one to a thread-local counter (const-initialised, no destructor: no allocation).
fn bump(counter: &'static std::thread::LocalKey<Cell<u64>>) {
    counter.with(|c| c.set(c.get() + 1));
}

/// Allocation calls (alloc, alloc_zeroed, realloc) the current thread made through a
/// [`BlockPool`] since it was armed: a process's serving loop, not its helper threads (such as
/// `ipc_types::service::DeadNodeCleanup`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    /// Served from the pool's blocks (no lock, no system call).
    pub pool: u64,
    /// Served by the system allocator (larger requests, and small ones while the pool is
    /// empty).
    pub system: u64,
}

// SAFETY: the storage is only reached through raw pointers to whole blocks, and a block is
// owned by exactly one caller between its pop (or bump) and its push: the free stack and the
// bump index hand each block out once, with the acquire/release ordering described in the
// module documentation. Every other field is atomic.
unsafe impl<const N: usize> Sync for BlockPool<N> {}

impl<const N: usize> Default for BlockPool<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> BlockPool<N> {
    /// An untouched, unarmed pool of `N` blocks (usable in a `static`).
    pub const fn new() -> Self {
        assert!(N < u32::MAX as usize, "BlockPool: N must be below 2^32 - 1");
        Self {
            storage: UnsafeCell::new([Block([0; BLOCK_SIZE]); N]),
            next: [const { AtomicU32::new(0) }; N],
            head: AtomicU64::new(0),
            fresh: AtomicUsize::new(0),
            fallbacks: AtomicU64::new(0),
            armed: AtomicBool::new(false),
        }
    }

    /// From now on, serves small requests from the pool (call it when start-up is over, just
    /// before the hot loop). Blocks already handed out by the system allocator are still freed
    /// there: frees are routed by address.
    pub fn arm(&self) {
        self.armed.store(true, Ordering::Relaxed);
    }

    /// Whether `ptr` is a block of this pool (anything else came from the system allocator).
    pub fn contains(&self, ptr: *const u8) -> bool {
        let base = self.storage.get() as usize;
        (base..base + N * BLOCK_SIZE).contains(&(ptr as usize))
    }

    /// How many small requests found the pool empty and were served by the system allocator
    /// instead, since start-up.
    pub fn fallbacks(&self) -> u64 {
        self.fallbacks.load(Ordering::Relaxed)
    }

    /// The allocation calls the current thread made since the pool was armed (a process has
    /// one pool: its global allocator).
    pub fn counts(&self) -> Counts {
        Counts {
            pool: POOL_CALLS.with(Cell::get),
            system: SYSTEM_CALLS.with(Cell::get),
        }
    }

    /// Counts a call served by the system allocator, once armed.
    fn count_system(&self) {
        if self.armed.load(Ordering::Relaxed) {
            bump(&SYSTEM_CALLS);
        }
    }

    /// One line for a process's summary: the most blocks in use at once, of the pool's `N`,
    /// and the requests that found it empty.
    pub fn summary(&self) -> String {
        format!(
            "small-block pool: peak {} of {N} blocks, {} requests found it empty",
            self.peak_blocks(),
            self.fallbacks()
        )
    }

    /// The most blocks that were ever in use at once (a block is taken from the never-used
    /// tail only when no freed one is available): how much of the pool start-up and the loop
    /// need.
    pub fn peak_blocks(&self) -> usize {
        self.fresh.load(Ordering::Relaxed).min(N)
    }

    /// Whether a request with `layout` is served from the pool (when it has a free block).
    pub fn fits(layout: Layout) -> bool {
        layout.size() <= BLOCK_SIZE && layout.align() <= BLOCK_SIZE
    }

    fn block_ptr(&self, index: usize) -> *mut u8 {
        debug_assert!(index < N);
        // SAFETY: index < N, so the offset stays inside the storage array.
        unsafe { self.storage.get().cast::<Block>().add(index).cast::<u8>() }
    }

    /// Takes a free block: the top of the free stack, else a never-used one.
    fn pop(&self) -> Option<usize> {
        let mut head = self.head.load(Ordering::Acquire);
        while head & INDEX_MASK != 0 {
            let index = (head & INDEX_MASK) as usize - 1;
            let below = u64::from(self.next[index].load(Ordering::Relaxed));
            let tag = (head >> 32).wrapping_add(1) & INDEX_MASK;
            match self.head.compare_exchange_weak(
                head,
                (tag << 32) | below,
                Ordering::Acquire,
                Ordering::Acquire,
            ) {
                Ok(_) => return Some(index),
                Err(now) => head = now,
            }
        }
        self.fresh
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |i| {
                (i < N).then_some(i + 1)
            })
            .ok()
    }

    /// Returns block `index` to the free stack.
    fn push(&self, index: usize) {
        let mut head = self.head.load(Ordering::Relaxed);
        loop {
            self.next[index].store((head & INDEX_MASK) as u32, Ordering::Relaxed);
            let tag = (head >> 32).wrapping_add(1) & INDEX_MASK;
            match self.head.compare_exchange_weak(
                head,
                (tag << 32) | (index as u64 + 1),
                Ordering::Release,
                Ordering::Relaxed,
            ) {
                Ok(_) => return,
                Err(now) => head = now,
            }
        }
    }

    /// The index of the pool block at `ptr` (which [`Self::contains`]).
    fn index_of(&self, ptr: *const u8) -> usize {
        (ptr as usize - self.storage.get() as usize) / BLOCK_SIZE
    }
}

// SAFETY: pool blocks are BLOCK_SIZE bytes at BLOCK_SIZE alignment, so they satisfy any layout
// that `fits`; each is handed to one caller at a time (see the `Sync` impl) and taken back only
// through `dealloc`/`realloc` of that pointer. Everything else is forwarded to `System` with
// the caller's own arguments, and pointers are routed back by address (`contains`), so a
// system block never enters the pool and a pool block never reaches `System`.
unsafe impl<const N: usize> GlobalAlloc for BlockPool<N> {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if Self::fits(layout) && self.armed.load(Ordering::Relaxed) {
            if let Some(index) = self.pop() {
                bump(&POOL_CALLS);
                return self.block_ptr(index);
            }
            self.fallbacks.fetch_add(1, Ordering::Relaxed);
        }
        self.count_system();
        // SAFETY: the caller's layout contract is passed on unchanged.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if self.contains(ptr) {
            self.push(self.index_of(ptr));
        } else {
            // SAFETY: `ptr` did not come from the pool, so it came from `System` with `layout`.
            unsafe { System.dealloc(ptr, layout) }
        }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if !self.contains(ptr) {
            self.count_system();
            // SAFETY: a system block, with the caller's contract passed on unchanged.
            return unsafe { System.realloc(ptr, layout, new_size) };
        }
        if new_size <= BLOCK_SIZE {
            // The block already holds BLOCK_SIZE bytes at the same alignment.
            bump(&POOL_CALLS);
            return ptr;
        }
        self.count_system();
        // SAFETY: the caller guarantees that `new_size`, rounded up to `layout.align()`, does
        // not overflow isize, which is what `from_size_align_unchecked` requires.
        let grown = unsafe { Layout::from_size_align_unchecked(new_size, layout.align()) };
        // SAFETY: `grown` has a non-zero size (it exceeds BLOCK_SIZE).
        let new = unsafe { System.alloc(grown) };
        if !new.is_null() {
            // SAFETY: the old block holds `layout.size()` valid bytes, the new one at least
            // `new_size` > that, and they are distinct allocations.
            unsafe { std::ptr::copy_nonoverlapping(ptr, new, layout.size()) };
            self.push(self.index_of(ptr));
        }
        new
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;

    fn layout(size: usize, align: usize) -> Layout {
        Layout::from_size_align(size, align).unwrap()
    }

    /// Allocates `layout` from `pool` and checks the result is non-null and aligned.
    fn alloc<const N: usize>(pool: &BlockPool<N>, layout: Layout) -> *mut u8 {
        // SAFETY: the test layouts have non-zero sizes.
        let p = unsafe { pool.alloc(layout) };
        assert!(!p.is_null());
        assert_eq!(
            p as usize % layout.align(),
            0,
            "{layout:?} misaligned at {p:?}"
        );
        p
    }

    #[test]
    fn small_requests_come_from_the_pool_and_others_from_the_system() {
        let pool = Box::new(BlockPool::<8>::new());
        // Unarmed, everything goes to the system allocator.
        let before = alloc(&pool, layout(8, 8));
        assert!(!pool.contains(before));
        pool.arm();
        for (size, align) in [(1, 1), (48, 8), (64, 16), (64, 64), (3, 2)] {
            let p = alloc(&pool, layout(size, align));
            assert!(pool.contains(p), "({size}, {align})");
            // SAFETY: allocated above with this layout.
            unsafe { pool.dealloc(p, layout(size, align)) };
        }
        for (size, align) in [(65, 8), (4096, 8), (32, 128)] {
            let p = alloc(&pool, layout(size, align));
            assert!(!pool.contains(p), "({size}, {align}) is not a pool request");
            // SAFETY: allocated above with this layout.
            unsafe { pool.dealloc(p, layout(size, align)) };
        }
        // A system block allocated before arming is freed by the system allocator.
        // SAFETY: allocated above with this layout.
        unsafe { pool.dealloc(before, layout(8, 8)) };
        assert_eq!((pool.fallbacks(), pool.peak_blocks()), (0, 1));
        // Counted from arming on: five pool requests, three system ones.
        assert_eq!(pool.counts(), Counts { pool: 5, system: 3 });
    }

    #[test]
    fn blocks_are_distinct_and_an_empty_pool_falls_back() {
        let pool = Box::new(BlockPool::<16>::new());
        pool.arm();
        let l = layout(64, 8);
        // Reuse does not raise the peak: one block taken and freed ten times is one block.
        for _ in 0..10 {
            let p = alloc(&pool, l);
            // SAFETY: allocated just above with `l`.
            unsafe { pool.dealloc(p, l) };
        }
        assert_eq!(pool.peak_blocks(), 1);
        let blocks: Vec<*mut u8> = (0..16).map(|_| alloc(&pool, l)).collect();
        // Each block is whole and separate: fill each with its own pattern, then check all.
        for (i, p) in blocks.iter().enumerate() {
            // SAFETY: each block is 64 writable bytes owned by this test.
            unsafe { std::ptr::write_bytes(*p, i as u8, 64) };
        }
        for (i, p) in blocks.iter().enumerate() {
            assert!(pool.contains(*p));
            // SAFETY: as above, initialised just now.
            let bytes = unsafe { std::slice::from_raw_parts(*p, 64) };
            assert!(bytes.iter().all(|b| *b == i as u8), "block {i} overwritten");
        }
        assert_eq!(pool.peak_blocks(), 16);
        let extra = alloc(&pool, l);
        assert!(!pool.contains(extra));
        assert_eq!(pool.fallbacks(), 1);
        // A freed block is the next one handed out (last in, first out).
        // SAFETY: blocks[5] and `extra` were allocated with `l` and not freed.
        unsafe {
            pool.dealloc(blocks[5], l);
            pool.dealloc(extra, l);
        }
        assert_eq!(alloc(&pool, l), blocks[5]);
        assert_eq!(pool.fallbacks(), 1);
        for p in blocks {
            // SAFETY: every block is owned here again (blocks[5] re-allocated above).
            unsafe { pool.dealloc(p, l) };
        }
    }

    #[test]
    fn realloc_keeps_data_and_moves_out_of_the_pool_when_too_big() {
        let pool = Box::new(BlockPool::<4>::new());
        pool.arm();
        let l = layout(16, 8);
        let p = alloc(&pool, l);
        let data: Vec<u8> = (0..16).collect();
        // SAFETY: 16 writable bytes.
        unsafe { std::ptr::copy_nonoverlapping(data.as_ptr(), p, 16) };
        // Growing within the block keeps it.
        // SAFETY: `p` was allocated with `l`.
        let same = unsafe { pool.realloc(p, l, 64) };
        assert_eq!(same, p);
        // Growing past it moves to the system allocator with the contents, and frees the block.
        // SAFETY: `same` holds a 64-byte allocation of alignment 8.
        let big = unsafe { pool.realloc(same, layout(64, 8), 1000) };
        assert!(!big.is_null() && !pool.contains(big) && (big as usize).is_multiple_of(8));
        // SAFETY: the first 16 bytes were copied.
        assert_eq!(unsafe { std::slice::from_raw_parts(big, 16) }, &data[..]);
        assert_eq!(alloc(&pool, l), p, "the block went back to the pool");
        // A system block stays with the system allocator, contents kept.
        // SAFETY: `big` holds 1000 bytes at alignment 8.
        let small = unsafe { pool.realloc(big, layout(1000, 8), 8) };
        assert!(!pool.contains(small));
        // SAFETY: the first 8 bytes survive a shrink.
        assert_eq!(unsafe { std::slice::from_raw_parts(small, 8) }, &data[..8]);
        // SAFETY: both are live allocations with these layouts.
        unsafe {
            pool.dealloc(small, layout(8, 8));
            pool.dealloc(p, l);
        }
        assert_eq!(pool.fallbacks(), 0);
    }

    #[test]
    fn blocks_freed_on_other_threads_are_reused_and_never_shared() {
        const BLOCKS: usize = 64;
        let pool: &'static BlockPool<BLOCKS> = Box::leak(Box::new(BlockPool::new()));
        pool.arm();
        let l = layout(64, 64);
        // Pointers travel between threads as addresses.
        let (tx, rx) = mpsc::sync_channel::<usize>(16);
        let freer = std::thread::spawn(move || {
            let mut freed = 0u64;
            for addr in rx {
                let p = addr as *mut u8;
                // The block still carries what its owner wrote: nobody else had it meanwhile.
                // SAFETY: the sender wrote 64 bytes and handed the block over.
                let bytes = unsafe { std::slice::from_raw_parts(p, 64) };
                assert!(bytes.iter().all(|b| *b == bytes[0]), "block shared");
                // SAFETY: allocated with `l` by the sender, owned here now.
                unsafe { pool.dealloc(p, l) };
                freed += 1;
            }
            freed
        });
        // Three threads allocate, stamp, check and either free locally or pass on.
        let workers: Vec<_> = (0..3u8)
            .map(|id| {
                let tx = tx.clone();
                std::thread::spawn(move || {
                    let mut sent = 0u64;
                    for round in 0..20_000u32 {
                        let p = alloc(pool, l);
                        let stamp = id * 64 + (round % 64) as u8;
                        // SAFETY: a 64-byte block owned by this thread.
                        unsafe { std::ptr::write_bytes(p, stamp, 64) };
                        std::hint::spin_loop();
                        // SAFETY: as above.
                        let bytes = unsafe { std::slice::from_raw_parts(p, 64) };
                        assert!(bytes.iter().all(|b| *b == stamp), "block shared");
                        if round % 3 == 0 {
                            tx.send(p as usize).unwrap();
                            sent += 1;
                        } else {
                            // SAFETY: allocated above with `l`.
                            unsafe { pool.dealloc(p, l) };
                        }
                    }
                    sent
                })
            })
            .collect();
        drop(tx);
        let sent: u64 = workers.into_iter().map(|w| w.join().unwrap()).sum();
        assert_eq!(freer.join().unwrap(), sent);
        // Every block is back: the whole pool can be taken again without a fallback. Blocks in
        // flight in the channel (16) plus one per worker fit, so none fell back before either.
        let fallbacks = pool.fallbacks();
        let all: Vec<*mut u8> = (0..BLOCKS).map(|_| alloc(pool, l)).collect();
        assert!(all.iter().all(|p| pool.contains(*p)));
        assert_eq!(pool.fallbacks(), fallbacks);
        let mut sorted: Vec<usize> = all.iter().map(|p| *p as usize).collect();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), BLOCKS, "a block was handed out twice");
        assert_eq!(fallbacks, 0);
    }
}
