//! The stage allocates nothing per sample: a counting global allocator sees zero allocations
//! on this thread while it aligns, navigates, applies zero-velocity updates and republishes
//! revised motion histories over a simulated drive with turns, and while it takes robot hints
//! (stationary and speed updates, losses and a stale spell) and estimates the mounting,
//! while it reconstructs clipped gyroscope motions at their rests, and while the walking
//! profile counts steps and makes their updates.

mod common;

use alloc_count::allocations;
use common::{Case, Simulation};
use ipc_types::{CorrectedImuSample, RobotHint, corrected_flags, odometry_flags, raw_flags};
use mems_sim::hints::{HintParams, RestSource};
use mems_sim::model::G_MPS2;
use mems_stage::Stage;
use odometry::config::OdometryConfig;
use odometry::hints::HintConfig;
use odometry::session::{Input, NoGyro, OdometrySession};
use odometry::stage::OdometryStage;

#[global_allocator]
static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;

#[test]
fn processing_samples_allocates_nothing() {
    let c = Case {
        duration_s: 60.0,
        rate_hz: 50.0,
        turns: true,
        ..Case::straight()
    };
    let mut sim = Simulation::new(&c, 2);
    sim.session();
    let samples = sim.drive_samples();
    let mut stage = OdometryStage::new(OdometryConfig::mpu9250(G_MPS2));

    let (mut live, mut revised) = (0u64, 0u64);
    let before = allocations();
    for s in &samples {
        stage
            .process(s, &mut |o| {
                if o.flags & odometry_flags::REVISION != 0 {
                    revised += 1;
                } else {
                    live += 1;
                }
            })
            .unwrap();
    }
    let during = allocations() - before;
    assert_eq!(
        during,
        0,
        "{during} allocations over {} samples",
        samples.len()
    );
    // The run exercised every path: a state per sample, revised histories, and rest flags
    // withdrawn in hindsight at every start (the lagging navigator copied into the live one).
    assert_eq!(live, samples.len() as u64);
    assert!(stage.aligned() && revised > 100, "{revised} revised states");
    assert!(stage.withdrawn_rest_samples() > 0);
}

#[test]
fn dead_reckoning_steps_allocates_nothing() {
    let c = Case {
        duration_s: 60.0,
        rate_hz: 100.0,
        turns: true,
        ..Case::straight()
    };
    let mut sim = Simulation::new(&c, 3);
    sim.session();
    let mut samples = sim.drive_samples();
    // A walker's bounce on the drive's samples: 1 m/s^2 peak to peak at 1.7 steps/s.
    for s in &mut samples {
        let t = s.stamps.sample_ns as f64 * 1e-9;
        s.accel_mps2[2] += 0.5 * (std::f64::consts::TAU * 1.7 * t).sin();
    }
    let config = odometry::profile::Profile::Walking.odometry(OdometryConfig::mpu9250(G_MPS2));
    let mut stage = OdometryStage::new(config);
    let before = allocations();
    for s in &samples {
        stage.process(s, &mut |_| {}).unwrap();
    }
    let during = allocations() - before;
    assert_eq!(during, 0, "{during} allocations");
    let w = stage.walking_stats().expect("the walking profile");
    assert!(w.steps > 50 && w.step_updates > 50, "{w:?}");
}

#[test]
fn reconstructing_clipped_motions_allocates_nothing() {
    let c = Case {
        duration_s: 60.0,
        rate_hz: 20.0,
        turns: true,
        ..Case::straight()
    };
    let mut sim = Simulation::new(&c, 2);
    sim.session();
    // At 20 Hz a motion fits the clip ring (1024 samples). The turns' yaw rate clipped at 0.8
    // of its peak in motion, as a part with that range would read it (the rests stay
    // unclipped; a lower range makes the noise cross it more often than a motion's runs hold).
    let samples = sim.drive_samples();
    let moving = |s: &CorrectedImuSample| s.flags & corrected_flags::ZERO_STATE == 0;
    let peak = samples
        .iter()
        .filter(|s| moving(s))
        .fold(0.0f64, |a, s| a.max(s.gyro_rps[2].abs()));
    let limit = 0.8 * peak;
    let samples: Vec<_> = samples
        .into_iter()
        .map(|mut s| {
            if moving(&s) && s.gyro_rps[2].abs() > limit {
                s.gyro_rps[2] = s.gyro_rps[2].clamp(-limit, limit);
                s.flags |= corrected_flags::CLIPPED;
                s.raw_flags |= raw_flags::SATURATED | raw_flags::saturated_axis(5);
            }
            s
        })
        .collect();
    let mut stage = OdometryStage::new(OdometryConfig::mpu9250(G_MPS2));
    let before = allocations();
    for s in &samples {
        stage.process(s, &mut |_| {}).unwrap();
    }
    let during = allocations() - before;
    assert_eq!(during, 0, "{during} allocations");
    let clip = stage.clip_stats();
    let clipped = samples
        .iter()
        .filter(|s| s.flags & corrected_flags::CLIPPED != 0)
        .count();
    assert!(
        clip.reconstructed > 0,
        "{clip:?} ({clipped} samples clipped at {limit} rad/s, aligned {})",
        stage.aligned()
    );
}

#[test]
fn taking_hints_allocates_nothing() {
    let c = Case {
        duration_s: 60.0,
        rate_hz: 50.0,
        turns: true,
        ..Case::straight()
    };
    let mut sim = Simulation::new(&c, 3);
    sim.session();
    let samples = sim.drive_samples();
    let mut p = HintParams::new(RestSource::Encoders);
    p.drop_fraction = 0.3;
    // Hints stop for 5 s in the middle (stale), then resume.
    let hints: Vec<RobotHint> = c
        .hints(3, &p)
        .hints
        .into_iter()
        .filter(|h| !(30_000_000_000..35_000_000_000).contains(&h.stamps.acquired_ns))
        .collect();
    let estimate = HintConfig {
        mounting: None,
        ..HintConfig::default()
    };
    // The session, as the live process runs it: hints queued as they arrive (here half a
    // second before their publication), then handed over with the samples.
    let mut session = OdometrySession::new(
        OdometryConfig::mpu9250(G_MPS2),
        estimate,
        NoGyro::Unnavigated,
    )
    .unwrap();

    let mut stale = 0u64;
    let mut hints = hints.iter().peekable();
    let before = allocations();
    for s in &samples {
        while let Some(h) =
            hints.next_if(|h| h.stamps.acquired_ns <= s.stamps.sample_ns + 500_000_000)
        {
            session.process(&Input::Hint(*h), &mut |_| {}).unwrap();
        }
        session
            .process(&Input::Sample(*s), &mut |o| {
                stale += u64::from(o.flags & odometry_flags::HINT_STALE != 0);
            })
            .unwrap();
    }
    let during = allocations() - before;
    assert_eq!(during, 0, "{during} allocations");
    let h = session.hint_stats();
    assert!(h.speed_updates > 100 && stale > 0, "{h:?}, {stale} stale");
    assert!(
        session.stage().mounting().is_some(),
        "the mounting was estimated"
    );
}
