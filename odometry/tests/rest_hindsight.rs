//! Rest in hindsight: a rest flag that motion follows within `rest_hindsight_s` is withdrawn.
//!
//! On a simulated drive whose rest flags come late (each rest spell runs on 0.4 s into the
//! following motion, as the calibration stage's windowed detector does on a gentle start):
//! - the live stage's output equals, bit for bit, a stage without hindsight fed the flags with
//!   the withdrawal done offline (every flag followed by a motion flag within the hindsight
//!   cleared beforehand): the latest state of every sample (forward, then revised) and the
//!   final filter.
//!
//! On a sensor at rest whose detector raises short false alarms (motion flags shorter than
//! `motion_confirm_s`), nothing is withdrawn: the output equals a stage without hindsight.
//!
//! What the withdrawal is for (the distance a late flag cuts) is tested on the analytic drive
//! of `straight_drive.rs`.

mod common;

use std::collections::BTreeMap;

use common::{Case, Simulation};
use ipc_types::{CorrectedImuSample, OdometryState, corrected_flags, odometry_flags};
use mems_sim::model::G_MPS2;
use odometry::config::OdometryConfig;
use odometry::stage::OdometryStage;

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

/// The rule done offline, with the whole stream known: every rest flag cleared that a
/// confirmed run of motion flags follows within `hindsight_s`. A run is confirmed unless it
/// lasts less than `confirm_s` and at least `hindsight_s` of rest flags follow it (up to the
/// next run, or to the last sample).
fn withdrawn_offline(
    samples: &[CorrectedImuSample],
    hindsight_s: f64,
    confirm_s: f64,
) -> Vec<CorrectedImuSample> {
    let (lag_ns, confirm_ns) = (
        (hindsight_s * 1e9).round() as u64,
        (confirm_s * 1e9).round() as u64,
    );
    let rest = |s: &CorrectedImuSample| s.flags & corrected_flags::ZERO_STATE != 0;
    // Every motion run: its start, and the first rest sample after it (None: to the end).
    let mut runs: Vec<(u64, Option<u64>)> = Vec::new();
    let mut i = 0;
    while i < samples.len() {
        if rest(&samples[i]) {
            i += 1;
            continue;
        }
        let j = samples[i..]
            .iter()
            .position(rest)
            .map_or(samples.len(), |k| i + k);
        runs.push((
            samples[i].stamps.sample_ns,
            samples.get(j).map(|s| s.stamps.sample_ns),
        ));
        i = j;
    }
    let last_ns = samples.last().map_or(0, |s| s.stamps.sample_ns);
    let starts: Vec<u64> = runs
        .iter()
        .enumerate()
        .filter(|(k, (start, end))| {
            end.is_none_or(|e| {
                let rest_until = runs.get(k + 1).map_or(last_ns, |r| r.0);
                e - start >= confirm_ns || rest_until - e < lag_ns
            })
        })
        .map(|(_, (start, _))| *start)
        .collect();
    samples
        .iter()
        .map(|s| {
            let t = s.stamps.sample_ns;
            let next = starts.iter().find(|&&m| m > t);
            let mut s = *s;
            if next.is_some_and(|m| m - t < lag_ns) {
                s.flags &= !corrected_flags::ZERO_STATE;
            }
            s
        })
        .collect()
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
    stage.finish(&mut |o| {
        latest.insert(o.seq, *o);
    });
    (latest, stage)
}

/// Runs the live stage (default hindsight) over `samples` and a stage without hindsight over
/// the flags withdrawn offline, checks that every sample's latest state and the final filter
/// agree bit for bit and that both count the same withdrawals; returns the live output and the
/// number of flags withdrawn.
fn check_against_offline(samples: &[CorrectedImuSample]) -> (BTreeMap<u64, OdometryState>, u64) {
    let cfg = OdometryConfig::mpu9250(G_MPS2);
    let offline_flags = withdrawn_offline(samples, cfg.rest_hindsight_s, cfg.motion_confirm_s);
    let withdrawn = samples
        .iter()
        .zip(&offline_flags)
        .filter(|(a, b)| a.flags != b.flags)
        .count() as u64;
    let (live, stage) = run(cfg, samples);
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
    (live, withdrawn)
}

#[test]
fn the_live_withdrawal_equals_the_offline_one() {
    assert!(OdometryConfig::mpu9250(G_MPS2).rest_hindsight_s > LATE_S);
    let (_, withdrawn) = check_against_offline(&late_flagged_drive());
    assert!(withdrawn > 300, "{withdrawn} flags withdrawn offline");
}

#[test]
fn short_false_alarms_at_rest_withdraw_nothing() {
    // 60 s at rest at 200 Hz (noise-free level sensor with a small bias, so a withdrawn update
    // would show), the detector flagging motion for one 0.1 s batch every 5 s; a real motion
    // flag run of 1 s at 40 s, and a flickering one at 50 s (three runs of 0.1 s, 0.2 s apart,
    // which confirm each other but for the last), both of which withdraw.
    let g = G_MPS2;
    let samples: Vec<CorrectedImuSample> = (0..12_000u64)
        .map(|k| {
            let t = k as f64 / 200.0;
            let glitch = t > 5.0 && t % 5.0 < 0.1;
            let flicker = [50.0, 50.3, 50.6]
                .iter()
                .any(|&s| (s..s + 0.1).contains(&t));
            let moving = (40.0..41.0).contains(&t) || flicker;
            CorrectedImuSample {
                stamps: ipc_types::Stamps {
                    sample_ns: k * 5_000_000,
                    ..Default::default()
                },
                seq: k,
                accel_mps2: [2e-3, -1e-3, g],
                flags: corrected_flags::DETECTOR_READY
                    | if glitch || moving {
                        0
                    } else {
                        corrected_flags::ZERO_STATE
                    },
                ..Default::default()
            }
        })
        .collect();
    let (live, withdrawn) = check_against_offline(&samples);
    // Only the rest samples less than 0.5 s before the real motion, t in (39.5, 40) s (99),
    // and before the flicker's first two runs, t in (49.5, 50.3) s (99 + 40).
    assert_eq!(withdrawn, 99 + 99 + 40);
    let no_hindsight = OdometryConfig {
        rest_hindsight_s: 0.0,
        ..OdometryConfig::mpu9250(g)
    };
    // The glitches' rest flags stood: the same as with every flag taken as it comes, until the
    // real motion's withdrawal.
    let (plain, _) = run(no_hindsight, &samples);
    let before_motion = (39.0 * 200.0) as u64;
    assert_eq!(
        live[&before_motion].position_m,
        plain[&before_motion].position_m
    );
}
