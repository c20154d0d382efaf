//! A restarted acquisition continues the sensor session: the real acquisition loop and driver
//! against the simulated MPU-9250 on a virtual clock, a first process's loop dropped mid-run
//! (as kill -9 leaves it: nothing said at the end), and a second one started on the same
//! session file 0.3 s later.
//!
//! Asserted: the second loop's first sample takes the next sequence number, flagged
//! `GAP_BEFORE | RESUMED`, with `lost_before` the sample periods of the hole; its time is on the
//! same clock, after the hole; the simulated motion went on in wall time (the part's time
//! origin is the session's, not the restart); another part's options start a new session.

use acquire::acquisition::{Acquisition, config_for_rate};
use acquire::clock::{Clock, SimClock};
use acquire::driver::Mpu9250;
use acquire::session::Session;
use acquire::sim::{SimConfig, SimMpu9250};
use ipc_types::{RawImuSample, raw_flags};
use mems_sim::{AnalogSample, SampleSource};

/// An x specific force that grows with the part's time, 0.01 g/s: a sample shows when, since
/// power-on, it was taken.
struct Ramp;

impl SampleSource for Ramp {
    fn sample(&mut self, t_s: f64, _rate_hz: f64) -> AnalogSample {
        AnalogSample {
            accel_g: [0.01 * t_s, 0.0, 1.0],
            ..AnalogSample::default()
        }
    }
}

/// Runs an acquisition loop at 1 kHz on `clock` in the session of `path` for `part` for
/// `reads` reads; returns its samples.
fn run(clock: &SimClock, path: &std::path::Path, part: &str, reads: usize) -> Vec<RawImuSample> {
    let session = Session::open(path, part, clock.now_ns()).unwrap();
    let device = SimMpu9250::new(
        Ramp,
        clock.clone(),
        SimConfig {
            model_dlpf: false,
            power_on_ns: Some(session.origin_ns()),
            ..SimConfig::default()
        },
    );
    let driver = Mpu9250::new(device, "sim", 0x68);
    let config = config_for_rate(1000, None).unwrap();
    let mut acq = Acquisition::start(driver, clock.clone(), config, 4_500_000)
        .unwrap()
        .in_session(session);
    let mut out = Vec::new();
    for _ in 0..reads {
        clock.sleep_until(acq.next_read_ns());
        let mut keep = |s: &RawImuSample| {
            out.push(*s);
            Ok::<_, ()>(())
        };
        acq.read_and_publish(&mut keep).unwrap().unwrap();
    }
    out
}

#[test]
fn a_restart_continues_the_session_with_a_counted_hole() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("acquire.session");
    let clock = SimClock::new_virtual(7_000_000_000);
    let part = "sim, 1000 Hz, seed 1";
    let first = run(&clock, &path, part, 400);
    let last = *first.last().unwrap();
    assert!(last.seq > 1500, "{} samples", last.seq + 1);
    assert_eq!(first[0].seq, 0);
    // Killed: the next process starts 0.3 s later.
    clock.advance(300_000_000);
    let second = run(&clock, &path, part, 100);
    let s = second[0];
    assert_eq!(s.seq, last.seq + 1, "the session's next number");
    assert_eq!(
        s.flags & (raw_flags::GAP_BEFORE | raw_flags::RESUMED),
        raw_flags::GAP_BEFORE | raw_flags::RESUMED
    );
    let hole_ms = (s.stamps.sample_ns - last.stamps.sample_ns) as f64 * 1e-6;
    assert!(hole_ms > 300.0, "hole {hole_ms} ms");
    assert_eq!(u64::from(s.lost_before), hole_ms.round() as u64 - 1);
    assert!(
        second.windows(2).all(|w| w[1].seq == w[0].seq + 1),
        "numbered on"
    );
    assert!(
        second[1..]
            .iter()
            .all(|s| s.flags & raw_flags::RESUMED == 0)
    );
    // The ramp went on in wall time: 0.01 g/s, so the first sample after the hole is about
    // 0.01 g/s x the hole above the last one before it (the simulation did not start again).
    let rise_g = s.accel_g[0] - last.accel_g[0];
    let expected_g = 0.01 * hole_ms * 1e-3;
    assert!(
        (rise_g - expected_g).abs() < 2e-4,
        "rise {rise_g} g over the hole, expected {expected_g}"
    );
    assert!(last.accel_g[0] > 0.015, "{}", last.accel_g[0]);

    // Another part (or configuration) on the same file: a new session from 0, whose part
    // starts at its own power-on.
    clock.advance(100_000_000);
    let other = run(&clock, &path, "sim, 1000 Hz, seed 2", 50);
    assert_eq!(other[0].seq, 0);
    assert_eq!(other[0].flags & raw_flags::RESUMED, 0);
    // (Its start-up, reset and settling take about 0.2 s of part time.)
    assert!(other[0].accel_g[0] < 0.005, "{}", other[0].accel_g[0]);
}
