//! Real processes: `mems-acquire` on a simulated part whose clock is 8 % slow or fast (the
//! internal oscillator's tolerance is +-10 %), with `mems-topic hz` subscribed. Nothing may be
//! lost, duplicated or flagged as a gap, the sample times must follow the part's true period,
//! and acquire's own summary must show the sample times within 2 ms of the acquisition clock.

use integration_tests::{bin, raw_topic_hz, unique_namespace};
use std::process::{Command, Stdio};
use std::time::Duration;

/// The number after `label` in `text` (the first one).
fn number_after(text: &str, label: &str) -> f64 {
    let at = text
        .find(label)
        .unwrap_or_else(|| panic!("{label:?} not in: {text}"));
    text[at + label.len()..]
        .split_whitespace()
        .next()
        .and_then(|w| w.trim_end_matches([',', ';']).parse().ok())
        .unwrap_or_else(|| panic!("no number after {label:?} in: {text}"))
}

fn run(ppm: i64) {
    let ns = unique_namespace("acqclock");
    let topic = raw_topic_hz(&ns, "6");
    let acquire = Command::new(bin("mems-acquire"))
        .args(["--namespace", &ns, "--rate", "1000", "--duration", "4"])
        .arg(format!("--sim-clock-ppm={ppm}"))
        .stderr(Stdio::piped())
        .output()
        .expect("run mems-acquire");
    let summary = String::from_utf8_lossy(&acquire.stderr);
    assert!(acquire.status.success(), "mems-acquire failed: {summary}");
    let (status, out) = topic.wait(Duration::from_secs(20));
    assert!(status.success(), "mems-topic failed: {status}");
    let report: serde_json::Value = serde_json::from_str(out.trim()).expect("JSON report");
    assert_eq!(report["lost"], 0, "{report}");
    assert_eq!(report["duplicated"], 0, "{report}");
    assert_eq!(report["non_monotonic"], 0, "{report}");
    // The part's true period; the mean spacing of the sample times follows it.
    let true_period_us = 1000.0 / (1.0 + ppm as f64 * 1e-6);
    let mean = report["sample_period_us"]["mean"].as_f64().unwrap();
    assert!(
        (mean - true_period_us).abs() < 0.002 * true_period_us,
        "{ppm} ppm: mean spacing {mean} us, true period {true_period_us} us"
    );
    // No gap: the largest spacing is far from two periods.
    let max = report["sample_period_us"]["max"].as_f64().unwrap();
    assert!(
        max < 1.5 * true_period_us,
        "{ppm} ppm: spacing up to {max} us"
    );
    assert_eq!(number_after(&summary, "gaps "), 0.0, "{summary}");
    assert_eq!(number_after(&summary, "lost "), 0.0, "{summary}");
    // Sample times (plus the filter delay) stay in [read start - period, acquisition] to 2 ms.
    let ahead = number_after(&summary, "FIFO time at most ");
    let behind = number_after(&summary, "ms after its acquisition and ");
    assert!(ahead <= 2.0 && behind <= 2.0, "{ppm} ppm: {summary}");
}

#[test]
fn acquire_follows_a_part_clock_8_percent_slow() {
    run(-80_000);
}

#[test]
fn acquire_follows_a_part_clock_8_percent_fast() {
    run(80_000);
}
