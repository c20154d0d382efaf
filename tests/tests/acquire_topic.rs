//! Real processes over real iceoryx2 services: `mems-acquire` on the simulated sensor at
//! 4 kHz (over simulated SPI: a 400 kHz I2C bus cannot carry it) with `mems-topic hz`
//! subscribed. Every sequence number must arrive exactly once and
//! the sample times must be monotonic at the configured period.

use integration_tests::{Proc, unique_namespace};
use std::time::Duration;

#[test]
fn acquire_at_4khz_loses_nothing() {
    let ns = unique_namespace("acq4k");
    // The subscriber first, so that it sees sample 0; it outlives the publisher.
    let topic = Proc::spawn(
        "mems-topic",
        &[
            "hz",
            "mems/imu/raw",
            "--namespace",
            &ns,
            "--duration",
            "6",
            "--json",
        ],
    );
    std::thread::sleep(Duration::from_millis(500));
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
        ],
    );
    let (status, _) = acquire.wait(Duration::from_secs(20));
    assert!(status.success(), "mems-acquire failed: {status}");
    let (status, out) = topic.wait(Duration::from_secs(20));
    assert!(status.success(), "mems-topic failed: {status}");
    let report: serde_json::Value = serde_json::from_str(out.trim()).expect("JSON report");
    let received = report["received"].as_u64().unwrap();
    // 4 s at 4 kHz, give or take the start-up and the last read.
    assert!((15_000..=16_500).contains(&received), "received {received}");
    assert_eq!(report["lost"], 0, "{report}");
    assert_eq!(report["duplicated"], 0, "{report}");
    assert_eq!(report["non_monotonic"], 0, "{report}");
    let rate = report["rate_hz"].as_f64().unwrap();
    assert!((rate - 4000.0).abs() < 4.0, "rate {rate}");
    // Reconstructed sample times sit on the 250 us grid: the spacing never strays by more than
    // a quarter period (the driver's bound on per-read anchor corrections).
    let min = report["sample_period_us"]["min"].as_f64().unwrap();
    let max = report["sample_period_us"]["max"].as_f64().unwrap();
    assert!(min > 187.5 && max < 312.5, "period {min}..{max} us");
}
