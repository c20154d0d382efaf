//! Provisional flags: the odometry stage fed the calibration stage's output as it leaves it
//! (each sample at once, `PROVISIONAL` until its batch is decided) ends with the same history
//! as a stage fed the final flags.
//!
//! A simulated drive (rests, motions and turns, moderate vibration) goes through the live
//! calibration stage (`mems-calibrate serve`'s detector) once. Its output goes to two odometry
//! stages:
//! - live: every sample as it leaves the calibration stage, provisional ones included; the
//!   history is the last state emitted for each sample (its live state, overwritten by every
//!   `REVISION` of it);
//! - final: the same output through a `Settler` (each sample held until its batch's verdict is
//!   known, then emitted with its final flags); the history likewise.
//!
//! Every sample's last state must be equal, field for field and bit for bit, apart from the
//! `REVISION` flag (a state the live stage had to revise may have been emitted once by the
//! other). And the provisional flags must have mattered: some live states were revised because
//! their batch's verdict changed.

mod common;

use mems_stage::Stage;
use std::collections::BTreeMap;

use calibrate::stage::Settler;
use common::{Case, Simulation, live_calibration_stage, live_detector};
use ipc_types::{CorrectedImuSample, OdometryState, corrected_flags, odometry_flags};
use mems_sim::model::G_MPS2;
use odometry::config::OdometryConfig;
use odometry::stage::OdometryStage;

/// The calibration stage's output on a 3-minute drive at 200 Hz with turns, in emission order.
fn calibrated_drive() -> Vec<CorrectedImuSample> {
    let c = Case {
        duration_s: 180.0,
        turns: true,
        ..Case::straight()
    };
    let mut sim = Simulation::new(&c, 7);
    sim.session();
    let mut calibration = live_calibration_stage(live_detector());
    let mut out = Vec::new();
    sim.drive_raw(|raw, _| {
        calibration
            .process(raw, &mut |s| out.push(*s))
            .expect("valid raw samples");
    });
    calibration.finish(&mut |_| {});
    out
}

/// The last state emitted for each sequence number, and how many states were emitted as
/// `REVISION`.
#[derive(Default)]
struct History {
    last: BTreeMap<u64, OdometryState>,
    revisions: u64,
}

impl History {
    fn take(&mut self, o: &OdometryState) {
        if o.flags & odometry_flags::REVISION != 0 {
            self.revisions += 1;
        }
        self.last.insert(o.seq, *o);
    }
}

#[test]
fn history_on_provisional_flags_equals_one_pass_on_final_flags() {
    let samples = calibrated_drive();
    let provisional = samples
        .iter()
        .filter(|s| s.flags & corrected_flags::PROVISIONAL != 0)
        .count();
    assert!(
        provisional > samples.len() / 2,
        "{provisional} of {} samples provisional",
        samples.len()
    );
    let cfg = OdometryConfig::mpu9250(G_MPS2);

    let mut live_stage = OdometryStage::new(cfg);
    let mut live = History::default();
    for s in &samples {
        live_stage.process(s, &mut |o| live.take(o)).unwrap();
    }
    live_stage.finish(&mut |o| live.take(o));

    let mut settler = Settler::default();
    let mut settled = Vec::with_capacity(samples.len());
    for s in &samples {
        settler.push(s, &mut |s| settled.push(*s));
    }
    settler.finish(&mut |s| settled.push(*s));
    assert_eq!(settled.len(), samples.len());
    // The verdicts did change some provisional flags (else this test shows nothing).
    let changed = samples
        .iter()
        .zip(&settled)
        .filter(|(a, b)| {
            let verdict = corrected_flags::ZERO_STATE | corrected_flags::DETECTOR_READY;
            a.flags & verdict != b.flags & verdict
        })
        .count();
    assert!(changed > 0, "no provisional flag changed");
    let mut final_stage = OdometryStage::new(cfg);
    let mut reference = History::default();
    for s in &settled {
        final_stage.process(s, &mut |o| reference.take(o)).unwrap();
    }
    final_stage.finish(&mut |o| reference.take(o));

    assert!(live_stage.aligned());
    assert_eq!(live.last.len(), samples.len());
    assert_eq!(reference.last.len(), samples.len());
    let moving = reference
        .last
        .values()
        .filter(|o| o.velocity_mps.iter().any(|v| v.abs() > 0.5))
        .count();
    assert!(moving > 1000, "{moving} states moving");
    let without_revision = |o: &OdometryState| OdometryState {
        flags: o.flags & !odometry_flags::REVISION,
        ..*o
    };
    for (seq, a) in &live.last {
        let b = &reference.last[seq];
        assert_eq!(without_revision(a), without_revision(b), "seq {seq}");
        for (x, y) in a.position_m.iter().zip(&b.position_m) {
            assert_eq!(x.to_bits(), y.to_bits(), "seq {seq}");
        }
    }
    // The live stage revised states for changed verdicts on top of the hindsight's revisions.
    assert!(
        live.revisions > reference.revisions,
        "live {} revisions, final flags {}",
        live.revisions,
        reference.revisions
    );
    assert_eq!(
        live_stage.withdrawn_rest_samples(),
        final_stage.withdrawn_rest_samples()
    );
}
