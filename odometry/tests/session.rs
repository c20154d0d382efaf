//! The odometry session (`odometry::session`), the policies every process shares around the
//! stage, against the stage driven by hand:
//! - hints that arrive at any time before the samples they precede give exactly the states of
//!   the stage handed each hint just before the first sample taken at or after its
//!   publication;
//! - a sample the calibration stage marked `NEW_SESSION` starts a new stage (which aligns
//!   again), after the old one's revisions;
//! - a sample without a gyroscope gives a `NO_GYRO` state without position (live) or is
//!   navigated at the held attitude (offline);
//! - a malformed hint, and a hint beyond the queue, are refused and change nothing.

mod common;

use common::{Case, Simulation};
use ipc_types::{
    CorrectedImuSample, OdometryState, RobotHint, corrected_flags, odometry_flags, raw_flags,
};
use mems_sim::hints::{HintParams, RestSource};
use mems_sim::model::G_MPS2;
use mems_stage::Stage;
use odometry::config::OdometryConfig;
use odometry::hints::HintConfig;
use odometry::session::{HINT_QUEUE, Input, NoGyro, OdometrySession, Refusal};
use odometry::stage::OdometryStage;

/// A 60 s drive with turns at 100 Hz (white samples), and its encoder hints.
fn drive() -> (Vec<CorrectedImuSample>, Vec<RobotHint>) {
    let c = Case {
        duration_s: 60.0,
        rate_hz: 100.0,
        dlpf: None,
        turns: true,
        ..Case::straight()
    };
    let mut sim = Simulation::new(&c, 5);
    sim.session();
    let samples = sim.drive_samples();
    let hints = c.hints(5, &HintParams::new(RestSource::Encoders)).hints;
    (samples, hints)
}

/// The stage's own hint buffer, kept small: a hint handed over long before its samples would
/// push out another (counted in `HintStats::overflowed`).
fn hint_config() -> HintConfig {
    HintConfig {
        capacity: 8,
        ..HintConfig::default()
    }
}

fn session(no_gyro: NoGyro) -> OdometrySession {
    OdometrySession::new(OdometryConfig::mpu9250(G_MPS2), hint_config(), no_gyro).unwrap()
}

/// Every state emitted (revisions included), with the hints arriving `lead_ns` before their
/// publication.
fn through_session(
    samples: &[CorrectedImuSample],
    hints: &[RobotHint],
    lead_ns: u64,
) -> Vec<OdometryState> {
    let mut s = session(NoGyro::Unnavigated);
    let mut out = Vec::new();
    let mut hints = hints.iter().peekable();
    for x in samples {
        while let Some(h) = hints.next_if(|h| h.stamps.acquired_ns <= x.stamps.sample_ns + lead_ns)
        {
            s.process(&Input::Hint(*h), &mut |_| panic!("a hint emits nothing"))
                .unwrap();
        }
        s.process(&Input::Sample(*x), &mut |o| out.push(*o))
            .unwrap();
    }
    s.finish(&mut |o| out.push(*o));
    out
}

fn bits(states: &[OdometryState]) -> Vec<([u64; 3], u16, u64)> {
    states
        .iter()
        .map(|o| (o.position_m.map(f64::to_bits), o.flags, o.seq))
        .collect()
}

#[test]
fn hints_arriving_early_give_the_states_of_hints_handed_over_at_their_time() {
    let (samples, hints) = drive();
    assert!(hints.len() > 1000, "{} hints", hints.len());
    // By hand: each hint just before the first sample at or after its publication.
    let mut stage =
        OdometryStage::with_hints(OdometryConfig::mpu9250(G_MPS2), hint_config()).unwrap();
    let mut expected = Vec::new();
    let mut next = 0;
    for x in &samples {
        while next < hints.len() && hints[next].stamps.acquired_ns <= x.stamps.sample_ns {
            stage
                .hint(&hints[next], &mut |o| expected.push(*o))
                .unwrap();
            next += 1;
        }
        stage.process(x, &mut |o| expected.push(*o)).unwrap();
    }
    stage.finish(&mut |o| expected.push(*o));
    let used = expected
        .iter()
        .filter(|o| o.flags & odometry_flags::HINT_SPEED != 0)
        .count();
    assert!(used > 300, "the hints were used: {used} speed updates");
    assert_eq!(stage.hint_stats().overflowed, 0);
    for lead_ns in [0, 300_000_000, 5_000_000_000] {
        let got = through_session(&samples, &hints, lead_ns);
        assert!(
            bits(&got) == bits(&expected),
            "hints {lead_ns} ns early changed the states"
        );
    }
}

#[test]
fn a_new_session_mark_starts_a_new_stage_that_aligns_again() {
    let (samples, _) = drive();
    let mut s = session(NoGyro::Unnavigated);
    let mut first = Vec::new();
    for x in &samples {
        s.process(&Input::Sample(*x), &mut |o| first.push(*o))
            .unwrap();
    }
    assert!(first.last().unwrap().flags & odometry_flags::ALIGNED != 0);
    // The acquisition restarts: its sequence starts again at 0, its clock goes on, and the
    // calibration stage marks the new session on its first sample.
    let offset = samples.last().unwrap().stamps.sample_ns + 10_000_000;
    let restarted: Vec<CorrectedImuSample> = samples
        .iter()
        .enumerate()
        .map(|(i, x)| {
            let mut x = *x;
            x.stamps.sample_ns += offset;
            if i == 0 {
                x.flags |= corrected_flags::NEW_SESSION;
            }
            x
        })
        .collect();
    let mut second = Vec::new();
    for x in &restarted {
        s.process(&Input::Sample(*x), &mut |o| second.push(*o))
            .unwrap();
    }
    assert_eq!(s.stats().sessions, 2);
    let live: Vec<_> = second
        .iter()
        .filter(|o| o.flags & odometry_flags::REVISION == 0)
        .collect();
    assert_eq!(live.len(), samples.len(), "one state per sample");
    assert_eq!(live[0].flags & odometry_flags::ALIGNED, 0, "aligns again");
    // The new stage's states are those of a fresh session on the same samples (the old
    // stage's pending revisions come first, flagged as such).
    let fresh = through_session(&restarted, &[], 0);
    let fresh_live: Vec<_> = fresh
        .iter()
        .filter(|o| o.flags & odometry_flags::REVISION == 0)
        .collect();
    assert!(
        live.iter()
            .zip(&fresh_live)
            .all(|(a, b)| a.position_m == b.position_m),
        "the new session starts from nothing"
    );
}

#[test]
fn samples_without_a_gyroscope_give_what_the_configuration_says() {
    let (samples, _) = drive();
    let strip = |x: &CorrectedImuSample| {
        let mut x = *x;
        x.raw_flags &= !raw_flags::GYRO_VALID;
        x
    };
    let mut live = session(NoGyro::Unnavigated);
    let mut held = session(NoGyro::HoldAttitude);
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for x in &samples[..3000] {
        live.process(&Input::Sample(strip(x)), &mut |o| a.push(*o))
            .unwrap();
        held.process(&Input::Sample(strip(x)), &mut |o| b.push(*o))
            .unwrap();
    }
    assert_eq!(a.len(), 3000);
    assert!(
        a.iter()
            .all(|o| o.flags == odometry_flags::NO_GYRO && o.position_m == [0.0; 3])
    );
    assert_eq!(live.stats().no_gyro, 3000);
    assert_eq!(live.stats().first_no_gyro_seq, Some(samples[0].seq));
    // Offline, the stage navigates them (the drive's first rest aligns it).
    assert!(b.iter().all(|o| o.flags & odometry_flags::NO_GYRO == 0));
    assert!(b.iter().any(|o| o.flags & odometry_flags::ALIGNED != 0));
}

#[test]
fn a_malformed_hint_and_a_hint_beyond_the_queue_are_refused() {
    let (samples, hints) = drive();
    let mut s = session(NoGyro::Unnavigated);
    let mut bad = hints[0];
    bad.stamps.sample_ns = 0;
    let refused = s.process(&Input::Hint(bad), &mut |_| {});
    assert!(matches!(refused, Err(Refusal::Hint(_))), "{refused:?}");
    // Hints published after every sample wait; the queue holds HINT_QUEUE of them.
    let late = samples.last().unwrap().stamps.sample_ns + 1;
    for i in 0..HINT_QUEUE as u64 {
        let mut h = hints[0];
        h.seq = i;
        h.stamps.acquired_ns = late + i;
        assert!(s.hint_room());
        s.process(&Input::Hint(h), &mut |_| {}).unwrap();
    }
    assert!(!s.hint_room());
    let refused = s.process(&Input::Hint(hints[1]), &mut |_| {});
    assert!(
        matches!(refused, Err(Refusal::HintQueueFull { .. })),
        "{refused:?}"
    );
    assert!(refused.unwrap_err().to_string().contains("robot hint seq"));
    assert_eq!(s.stats().hints, HINT_QUEUE as u64);
    // None of them reached the stage: the samples run as without hints.
    let mut out = Vec::new();
    for x in &samples {
        s.process(&Input::Sample(*x), &mut |o| out.push(*o))
            .unwrap();
    }
    s.finish(&mut |o| out.push(*o));
    assert!(bits(&out) == bits(&through_session(&samples, &[], 0)));
}
