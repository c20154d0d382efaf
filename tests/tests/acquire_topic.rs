//! Real processes over real iceoryx2 services: `mems-acquire` on the simulated sensor at
//! 4 kHz (over simulated SPI: a 400 kHz I2C bus cannot carry it) with `mems-topic hz`
//! subscribed. Every sequence number must arrive exactly once, the sample times must be
//! monotonic at the configured period, and whatever the sensor lost must be flagged and
//! counted: the sample grid's rate, those samples counted in, within 4 Hz of 4000.
//!
//! At 4 kHz the 512-byte FIFO (PS-MPU-9250A-01 section 4.17) fills in 10.7 ms (85 six-byte
//! frames at 8000 frames/s): a reader that the host does not run for longer than that loses
//! samples at the sensor (flagged and counted, never silent, but real losses, which shorten the
//! stream against its span and show as a gap in the spacing). A SCHED_OTHER reader on the
//! loaded 2-core CI machine is regularly kept off the CPU that long (4 busy loops beside it: 5
//! runs of 5 overflowed 1 to 12 times, 120 to 634 samples lost, `mems-topic` rates 3844-3970 Hz
//! while the rate of the sample grid, counting the flagged losses, stayed within 2.3 Hz of
//! 4000). So acquire runs its loop under SCHED_FIFO, as a sensor driver must on a loaded host
//! (PX4 runs its SPI sensor drivers on real-time work queues just below its rate controller,
//! platforms/common/include/px4_platform_common/px4_work_queue/WorkQueueManager.hpp); the
//! same load then left 5 runs of 5 without an overflow, 4000.02-4000.06 Hz. The test does not
//! ask for no overflow, which would ask the host to run it promptly: this guest's wake-up
//! latency is not bounded (docs/acquisition.md), and a CI run with nothing beside it once lost
//! about 80 samples under SCHED_FIFO (3980.5 Hz without them). Needs CAP_SYS_NICE or
//! RLIMIT_RTPRIO >= 50: where refused, acquire exits at start-up saying so.

use integration_tests::{Proc, raw_topic_hz, unique_namespace};
use std::time::Duration;

#[test]
fn acquire_at_4khz_loses_nothing_unflagged() {
    let ns = unique_namespace("acq4k");
    // The subscriber first, so that it sees sample 0; it outlives the publisher.
    let topic = raw_topic_hz(&ns, "6");
    let acquire = Proc::spawn(
        "mems-acquire",
        &[
            "--namespace",
            &ns,
            "--source",
            "sim-spi",
            "--rate",
            "4000",
            "--duration",
            "4",
            "--sched-fifo",
            "50",
        ],
    );
    let (status, _) = acquire.wait(Duration::from_secs(20));
    assert!(status.success(), "mems-acquire failed: {status}");
    let (status, out) = topic.wait(Duration::from_secs(20));
    assert!(status.success(), "mems-topic failed: {status}");
    let report: serde_json::Value = serde_json::from_str(out.trim()).expect("JSON report");
    println!("mems-topic: {report}");
    let received = report["received"].as_u64().unwrap();
    let at_sensor = report["lost_at_source"].as_u64().unwrap();
    // Every published sample arrives once and in order, whatever the host's scheduling.
    assert_eq!(report["lost"], 0, "{report}");
    assert_eq!(report["duplicated"], 0, "{report}");
    assert_eq!(report["non_monotonic"], 0, "{report}");
    // 4 s at 4 kHz, give or take the start-up and the last read, with what the sensor lost
    // counted: a FIFO overflow is flagged on the next sample with the samples it lost.
    let grid = received + at_sensor;
    assert!(
        (15_000..=16_500).contains(&grid),
        "{grid} samples: {report}"
    );
    let rate = report["source_rate_hz"].as_f64().unwrap();
    assert!(
        (rate - 4000.0).abs() < 4.0,
        "sample grid at {rate} Hz: {report}"
    );
    // Reconstructed sample times sit on the 250 us grid: the spacing never strays by more than
    // a quarter period (the driver's bound on per-read anchor corrections). An overflow resets
    // the FIFO and the anchor, so the spacing is checked only when the sensor lost nothing.
    let min = report["sample_period_us"]["min"].as_f64().unwrap();
    let max = report["sample_period_us"]["max"].as_f64().unwrap();
    assert!(
        at_sensor > 0 || (min > 187.5 && max < 312.5),
        "period {min}..{max} us"
    );
    if at_sensor > 0 {
        println!("{at_sensor} samples lost at the sensor, flagged and counted");
    }
}
