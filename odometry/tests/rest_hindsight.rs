//! Rest in hindsight: a rest flag that motion follows within `rest_hindsight_s` is withdrawn.
//!
//! On a simulated drive whose rest flags come late (each rest spell runs on 0.4 s into the
//! following motion, as the calibration stage's windowed detector does on a gentle start):
//! - the live stage's output equals, bit for bit, a stage without hindsight fed the flags with
//!   the withdrawal done offline (every flag followed by a motion flag within the hindsight
//!   cleared beforehand): the latest state of every sample (forward, then revised) and the
//!   final filter.
//!
//! What the withdrawal is for (the distance a late flag cuts) is tested on the analytic drive
//! of `straight_drive.rs`.

mod common;

use std::collections::BTreeMap;

use common::{Case, Simulation};
use ipc_types::{CorrectedImuSample, OdometryState, corrected_flags, odometry_flags};
use mems_sim::model::G_MPS2;
use odometry::stage::{OdometryConfig, OdometryStage};

/// How long the simulated detector keeps saying rest after a motion has started, s.
const LATE_S: f64 = 0.4;

/// A 3-minute straight drive at 200 Hz with late rest flags.
fn late_flagged_drive() -> Vec<CorrectedImuSample> {
    let c = Case {
        duration_s: 180.0,
        ..Case::straight()
    };
    let mut sim = Simulation::new(&c, 4);
    sim.session();
    let mut samples = Vec::new();
    let mut motion_since: Option<u64> = None;
    sim.drive(|s, truth| {
        let mut s = *s;
        if truth.at_rest {
            motion_since = None;
        } else {
            let t0 = *motion_since.get_or_insert(s.stamps.sample_ns);
            let lagging = samples
                .last()
                .is_some_and(|p: &CorrectedImuSample| p.flags & corrected_flags::ZERO_STATE != 0);
            if lagging && (s.stamps.sample_ns - t0) as f64 * 1e-9 < LATE_S {
                s.flags |= corrected_flags::ZERO_STATE;
            }
        }
        samples.push(s);
    });
    samples
}

/// Every rest flag followed by a motion flag within `hindsight_s` cleared.
fn withdrawn_offline(samples: &[CorrectedImuSample], hindsight_s: f64) -> Vec<CorrectedImuSample> {
    let lag_ns = (hindsight_s * 1e9).round() as u64;
    let mut out = samples.to_vec();
    let mut next_motion_ns = u64::MAX;
    for s in out.iter_mut().rev() {
        if s.flags & corrected_flags::ZERO_STATE == 0 {
            next_motion_ns = s.stamps.sample_ns;
        } else if next_motion_ns - s.stamps.sample_ns < lag_ns {
            s.flags &= !corrected_flags::ZERO_STATE;
        }
    }
    out
}

/// The stage's output: the latest state per sequence number, and the stage.
fn run(
    cfg: OdometryConfig,
    samples: &[CorrectedImuSample],
) -> (BTreeMap<u64, OdometryState>, OdometryStage) {
    let mut stage = OdometryStage::new(cfg);
    let mut latest = BTreeMap::new();
    for s in samples {
        stage
            .process(s, &mut |o| {
                latest.insert(o.seq, *o);
            })
            .unwrap();
    }
    (latest, stage)
}

#[test]
fn the_live_withdrawal_equals_the_offline_one() {
    let samples = late_flagged_drive();
    let cfg = OdometryConfig::mpu9250(G_MPS2);
    assert!(cfg.rest_hindsight_s > LATE_S);

    let (live, stage) = run(cfg, &samples);
    let offline_flags = withdrawn_offline(&samples, cfg.rest_hindsight_s);
    let withdrawn = samples
        .iter()
        .zip(&offline_flags)
        .filter(|(a, b)| a.flags != b.flags)
        .count() as u64;
    assert!(withdrawn > 300, "{withdrawn} flags withdrawn offline");
    assert_eq!(stage.withdrawn_rest_samples(), withdrawn);
    let no_hindsight = OdometryConfig {
        rest_hindsight_s: 0.0,
        ..cfg
    };
    let (offline, offline_stage) = run(no_hindsight, &offline_flags);
    assert_eq!(live.len(), samples.len());
    for (seq, a) in &live {
        let b = &offline[seq];
        // The live stage revised what it first emitted; the offline one may not have had to.
        let flags = |o: &OdometryState| o.flags & !odometry_flags::REVISION;
        assert_eq!(flags(a), flags(b), "seq {seq}");
        assert_eq!(
            OdometryState { flags: 0, ..*a },
            OdometryState { flags: 0, ..*b },
            "seq {seq}"
        );
    }
    let (kf, kf_offline) = (stage.filter().unwrap(), offline_stage.filter().unwrap());
    assert_eq!(kf.x, kf_offline.x);
    assert_eq!(kf.cov, kf_offline.cov);
}
