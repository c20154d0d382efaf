//! The steady-state loops allocate nothing from the system allocator. The global allocator here
//! is the one `mems-acquire` installs, [`alloc_count::pool::BlockPool`], wrapped in a counter of the
//! calls the current thread makes and of those that reach the system allocator (their result is
//! not a pool block). The driver's read loop makes no allocation call at all; the publishing
//! loop makes exactly one per sample, inside iceoryx2's loan, and the pool serves every one.

mod common;

use std::alloc::{GlobalAlloc, Layout};
use std::cell::Cell;

use acquire::driver::{Config, Dlpf, Mpu9250, OutputMode};
use acquire::registers as reg;
use alloc_count::pool::BlockPool;
use ipc_types::RawImuSample;

/// The pool of `mems-acquire`'s size, counting this thread's calls. Armed (as `mems-acquire`
/// arms it before its loop) at the start of each test.
struct Counting(BlockPool<1024>);

thread_local! {
    /// Allocation calls (alloc, realloc) made by this thread.
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
    /// Of those, the ones the system allocator served.
    static SYSTEM: Cell<u64> = const { Cell::new(0) };
}

impl Counting {
    fn count(&self, result: *mut u8) {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        if !self.0.contains(result) {
            SYSTEM.with(|c| c.set(c.get() + 1));
        }
    }
}

// SAFETY: every call is forwarded unchanged to the pool; the thread-local counters are
// const-initialised `Cell`s, which need no allocation to access.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: same contract as the caller's.
        let p = unsafe { self.0.alloc(layout) };
        self.count(p);
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { self.0.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: same contract as the caller's.
        let p = unsafe { self.0.realloc(ptr, layout, new_size) };
        self.count(p);
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting(BlockPool::new());

/// (allocation calls, of which served by the system allocator) so far on this thread.
fn allocations() -> (u64, u64) {
    (ALLOCATIONS.with(Cell::get), SYSTEM.with(Cell::get))
}

/// Runs `reads` reads 5 ms apart after a warm-up; returns (allocations, samples) of the
/// measured part.
/// The 4 kHz accelerometer mode runs over simulated SPI, the others over simulated I2C.
fn measure(config: Config, reads: usize) -> (u64, usize) {
    let sim = common::noisy_sim(1, 0);
    let clock = sim.clock().clone();
    if config.mode == OutputMode::Accel4kHz {
        measure_on(Mpu9250::new_spi(sim, "sim-spi"), &clock, config, reads)
    } else {
        let drv = Mpu9250::new(sim, "sim", reg::ADDRESS_AD0_LOW);
        measure_on(drv, &clock, config, reads)
    }
}

fn measure_on<B: embedded_hal::i2c::I2c>(
    mut drv: Mpu9250<B>,
    clock: &acquire::clock::SimClock,
    config: Config,
    reads: usize,
) -> (u64, usize) {
    drv.init(config, clock).unwrap();
    let mut buf = [RawImuSample::default(); 128];
    let mut read = |drv: &mut Mpu9250<B>| {
        clock.advance(5_000_000);
        drv.read_samples(clock, &mut buf).unwrap()
    };
    for _ in 0..100 {
        read(&mut drv);
    }
    let before = allocations().0;
    let samples: usize = (0..reads).map(|_| read(&mut drv)).sum();
    (allocations().0 - before, samples)
}

#[test]
fn steady_state_reads_allocate_nothing() {
    ALLOCATOR.0.arm();
    // The counters work: a small Vec takes a pool block, a large one goes to the system.
    let before = allocations();
    let small: Vec<u64> = Vec::with_capacity(4);
    assert_eq!(allocations(), (before.0 + 1, before.1));
    let large: Vec<u64> = Vec::with_capacity(1000);
    assert_eq!(allocations(), (before.0 + 2, before.1 + 1));
    drop((small, large));

    let (allocs, samples) = measure(Config::default(), 2000);
    assert!(samples >= 39_000, "{samples} samples");
    assert_eq!(
        allocs, 0,
        "{allocs} allocations for {samples} samples at 4 kHz"
    );
    let imu = Config {
        mode: OutputMode::Imu {
            dlpf: Dlpf::Hz92,
            divider: 0,
        },
        ..Config::default()
    };
    let (allocs, samples) = measure(imu, 2000);
    assert!(samples >= 9_900, "{samples} samples");
    assert_eq!(
        allocs, 0,
        "{allocs} allocations for {samples} samples at 1 kHz"
    );
}

/// The hot loop of `mems-acquire`: FIFO read, numbering, stamping and publication on a real
/// iceoryx2 service, with a subscriber draining it in the same thread.
///
/// Our part makes no allocation call. iceoryx2 0.10 makes exactly one per loaned sample
/// (`Publisher::loan_uninit` creates the sample's `ChunkMutSharedState` with `Rc::new`, freed
/// when the sample is sent); the pool serves every one of them, so in steady state nothing
/// reaches the system allocator: 0 per sample. The test also pins the one call per loan, so it
/// fails if our loop, the driver or the subscriber side ever allocate.
#[test]
fn publishing_loop_reaches_the_system_allocator_zero_times_per_sample() {
    use acquire::acquisition::{Acquisition, config_for_rate};
    use ipc_types::service;

    ALLOCATOR.0.arm();
    let sim = common::noisy_sim(2, 0);
    let clock = sim.clock().clone();
    let driver = Mpu9250::new_spi(sim, "sim-spi");
    let mut acq = Acquisition::start(
        driver,
        clock.clone(),
        config_for_rate(4000, None).unwrap(),
        5_000_000,
    )
    .unwrap();
    let node = service::node().unwrap();
    let name = service::full_name(&format!("noalloc-{}", std::process::id()), service::RAW);
    let raw = service::open::<RawImuSample>(&node, &name).unwrap();
    let publisher = service::publisher(&raw).unwrap();
    let subscriber = service::subscriber(&raw).unwrap();

    // Counts the allocation calls made while loaning, and everywhere else, separately.
    let mut in_loan = 0u64;
    let mut received = 0u64;
    let step = |acq: &mut Acquisition<_, _>, in_loan: &mut u64, received: &mut u64| {
        clock.advance(5_000_000);
        let mut publish = |s: &RawImuSample| -> Result<(), String> {
            let before = allocations().0;
            let sample = publisher.loan_uninit().map_err(|e| format!("{e:?}"))?;
            *in_loan += allocations().0 - before;
            sample
                .write_payload(*s)
                .send()
                .map_err(|e| format!("{e:?}"))?;
            Ok(())
        };
        acq.read_and_publish(&mut publish).unwrap().unwrap();
        while let Some(sample) = subscriber.receive().unwrap() {
            assert_eq!(sample.seq, *received);
            *received += 1;
        }
    };
    for _ in 0..200 {
        step(&mut acq, &mut in_loan, &mut received);
    }
    in_loan = 0;
    let before = allocations();
    let published_before = acq.stats().published;
    for _ in 0..2000 {
        step(&mut acq, &mut in_loan, &mut received);
    }
    let (calls, system) = {
        let now = allocations();
        (now.0 - before.0, now.1 - before.1)
    };
    let samples = acq.stats().published - published_before;
    assert!(samples >= 39_000, "{samples} samples");
    assert_eq!(
        received,
        acq.stats().published,
        "every sample received, in order"
    );
    assert_eq!(
        system, 0,
        "{system} calls reached the system allocator for {samples} samples"
    );
    assert_eq!(
        calls - in_loan,
        0,
        "allocation calls outside iceoryx2's loan"
    );
    assert_eq!(
        in_loan, samples,
        "iceoryx2 0.10 allocates one block per loan"
    );
    assert_eq!(ALLOCATOR.0.fallbacks(), 0, "the pool never ran empty");
    eprintln!(
        "pool peak use: {} of 1024 blocks",
        ALLOCATOR.0.peak_blocks()
    );
}
