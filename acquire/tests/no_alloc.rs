//! The steady-state read loop (driver on the simulated device) allocates nothing: a counting
//! global allocator sees zero allocations on this thread over thousands of reads.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use acquire::driver::{Config, Dlpf, Mpu9250, OutputMode};
use acquire::registers as reg;
use ipc_types::RawImuSample;

/// Counts allocations made by the current thread, delegating to the system allocator.
struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

// SAFETY: every call is forwarded unchanged to `System`; the thread-local counter is a
// const-initialised `Cell`, which needs no allocation to access.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

/// Runs `reads` reads 5 ms apart after a warm-up; returns (allocations, samples) of the
/// measured part.
fn measure(config: Config, reads: usize) -> (u64, usize) {
    let sim = common::noisy_sim(1, 0);
    let clock = sim.clock().clone();
    let mut drv = Mpu9250::new(sim, "sim", reg::ADDRESS_AD0_LOW);
    drv.init(config, &clock).unwrap();
    let mut buf = [RawImuSample::default(); 128];
    let mut read = |drv: &mut Mpu9250<_>| {
        clock.advance(5_000_000);
        drv.read_samples(&clock, &mut buf).unwrap()
    };
    for _ in 0..100 {
        read(&mut drv);
    }
    let before = allocations();
    let samples: usize = (0..reads).map(|_| read(&mut drv)).sum();
    (allocations() - before, samples)
}

#[test]
fn steady_state_reads_allocate_nothing() {
    // The counter works: a Vec allocates.
    let before = allocations();
    let v: Vec<u64> = Vec::with_capacity(4);
    assert_eq!(allocations() - before, 1);
    drop(v);

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
/// Our part allocates nothing. iceoryx2 0.10 allocates exactly one small block per loaned sample
/// (`Publisher::loan_uninit` creates the sample's `ChunkMutSharedState` with `Arc::new`); the
/// test pins that count, so it fails if our loop, the driver or the subscriber side ever
/// allocate, or if iceoryx2 starts allocating more.
#[test]
fn publishing_loop_allocates_only_iceoryx2s_loan() {
    use acquire::acquisition::{Acquisition, config_for_rate};
    use ipc_types::service;

    let sim = common::noisy_sim(2, 0);
    let clock = sim.clock().clone();
    let driver = Mpu9250::new(sim, "sim", reg::ADDRESS_AD0_LOW);
    let mut acq = Acquisition::start(
        driver,
        clock.clone(),
        config_for_rate(4000).unwrap(),
        5_000_000,
    )
    .unwrap();
    let node = service::node().unwrap();
    let name = service::full_name(&format!("noalloc-{}", std::process::id()), service::RAW);
    let raw = service::open::<RawImuSample>(&node, &name).unwrap();
    let publisher = service::publisher(&raw).unwrap();
    let subscriber = service::subscriber(&raw).unwrap();

    // Counts allocations made while loaning, and everywhere else, separately.
    let mut in_loan = 0u64;
    let mut received = 0u64;
    let step = |acq: &mut Acquisition<_, _>, in_loan: &mut u64, received: &mut u64| {
        clock.advance(5_000_000);
        let mut publish = |s: &RawImuSample| -> Result<(), String> {
            let before = allocations();
            let sample = publisher.loan_uninit().map_err(|e| format!("{e:?}"))?;
            *in_loan += allocations() - before;
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
    let total = allocations() - before;
    let samples = acq.stats().published - published_before;
    assert!(samples >= 39_000, "{samples} samples");
    assert_eq!(
        received,
        acq.stats().published,
        "every sample received, in order"
    );
    assert_eq!(total - in_loan, 0, "allocations outside iceoryx2's loan");
    assert_eq!(in_loan, samples, "iceoryx2 0.10 allocates one Arc per loan");
}
