//! The stale-hint fallback with real processes: the built `mems-odometry serve` in a unique
//! namespace, fed corrected samples of a simulated drive and a controller's hints by this test
//! process over iceoryx2 (the hints with the controller's non-blocking publisher). The hints
//! stop for 10 s of sample time and resume: the process publishes a state for every sample
//! (no gap in the sequence numbers), flagged `HINT_STALE` exactly while the newest hint is
//! older than the maximum age, and its states are bit for bit those of the same stage run in
//! this process.

mod common;

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{
    Case, Simulation, identity_calibration, run_with_hints, unique_namespace, wait_until,
};
use iceoryx2::port::update_connections::UpdateConnections as _;
use iceoryx2::service::port_factory::PortFactory as _;
use ipc_types::{CorrectedImuSample, OdometryState, RobotHint, odometry_flags, service};
use mems_sim::hints::{HintParams, RestSource};
use mems_sim::model::G_MPS2;
use odometry::config::OdometryConfig;
use odometry::hints::HintConfig;

/// The serve process, killed when the test ends (unless it was stopped cleanly).
struct Serve(Option<Child>);

impl Drop for Serve {
    fn drop(&mut self) {
        if let Some(mut child) = self.0.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

#[test]
fn serve_falls_back_when_hints_stop_and_resumes_without_a_gap() {
    let namespace = unique_namespace("stale-hints");
    let dir = std::env::temp_dir().join(&namespace);
    std::fs::create_dir_all(&dir).unwrap();
    let calib = dir.join("calib.toml");
    identity_calibration().save(&calib).unwrap();

    // 40 s of a drive with turns at 100 Hz (perfect rest flags), the controller's hints with
    // none lost, except that none is published between 15 and 25 s.
    let c = Case {
        duration_s: 40.0,
        rate_hz: 100.0,
        turns: true,
        ..Case::straight()
    };
    let mut sim = Simulation::new(&c, 5);
    sim.session();
    let samples = sim.drive_samples();
    let mut p = HintParams::new(RestSource::Encoders);
    p.drop_fraction = 0.0;
    p.bursts_per_min = 0.0;
    let (gap_from, gap_to) = (15_000_000_000u64, 25_000_000_000u64);
    let hints: Vec<RobotHint> = c
        .hints(5, &p)
        .hints
        .into_iter()
        .filter(|h| !(gap_from..gap_to).contains(&h.stamps.acquired_ns))
        .collect();

    let node = service::node().unwrap();
    let corrected = service::open::<CorrectedImuSample>(
        &node,
        &service::full_name(&namespace, service::CORRECTED),
    )
    .unwrap();
    let hint_service =
        service::open::<RobotHint>(&node, &service::full_name(&namespace, service::HINT)).unwrap();
    let odometry =
        service::open::<OdometryState>(&node, &service::full_name(&namespace, service::ODOMETRY))
            .unwrap();
    let states_sub = service::subscriber(&odometry).unwrap();
    let sample_pub = service::publisher(&corrected).unwrap();
    let hint_pub = service::hint_publisher(&hint_service).unwrap();

    let mut serve = Serve(Some(
        Command::new(env!("CARGO_BIN_EXE_mems-odometry"))
            // The identity mounting, as `HintConfig::default()` below (without `--mount` the
            // process estimates the speed hints' forward axis first).
            .args([
                "serve",
                "--calib",
                calib.to_str().unwrap(),
                "--mount",
                "0,0,0",
            ])
            .env(service::NAMESPACE_ENV, &namespace)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start mems-odometry serve"),
    ));
    wait_until(Duration::from_secs(10), "serve's subscribers", || {
        corrected.dynamic_config().number_of_subscribers() >= 1
            && hint_service.dynamic_config().number_of_subscribers() >= 1
    });
    // Connect the publishers to the new subscribers before the first message (a hint sent
    // before the connection exists is discarded by the non-blocking hint publisher), and give
    // the process's receive loop (1 ms) time to connect its side.
    sample_pub.update_connections().unwrap();
    hint_pub.update_connections().unwrap();
    std::thread::sleep(Duration::from_millis(300));

    // Each hint at its publication time in sample time (before the first sample taken after
    // it), as a controller beside the IMU sends it, and as fast as the transport takes them.
    let mut states: Vec<OdometryState> = Vec::new();
    let mut next = 0;
    let drain = |states: &mut Vec<OdometryState>| {
        while let Some(s) = states_sub.receive().unwrap() {
            if s.flags & odometry_flags::REVISION == 0 {
                states.push(*s.payload());
            }
        }
    };
    for s in &samples {
        while next < hints.len() && hints[next].stamps.acquired_ns <= s.stamps.sample_ns {
            hint_pub.send_copy(hints[next]).unwrap();
            next += 1;
        }
        sample_pub.send_copy(*s).unwrap();
        drain(&mut states);
    }
    wait_until(Duration::from_secs(20), "a state per sample", || {
        drain(&mut states);
        states.len() >= samples.len()
    });

    // Stop cleanly (SIGTERM): exit status 0.
    let mut child = serve.0.take().unwrap();
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let start = Instant::now();
    let exit = loop {
        if let Some(exit) = child.try_wait().unwrap() {
            break exit;
        }
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "serve did not exit"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(exit.success(), "{exit}");

    // No gap: one state per sample, in order.
    assert_eq!(states.len(), samples.len());
    for (s, o) in samples.iter().zip(&states) {
        assert_eq!(o.seq, s.seq);
    }
    // The same stage in this process, fed the same way, gives the same states bit for bit.
    // The process's profile (auto, then a robot's) counts a false rest's glide in the
    // published 1-sigma (`ConsistencyConfig::false_rest_glides`) and takes the rests' rate
    // scatter in the zero-rate update (`OdometryConfig::rest_rate_scatter`); so does this stage.
    let mut cfg = OdometryConfig::mpu9250(G_MPS2);
    cfg.consistency.false_rest_glides = true;
    cfg.rest_rate_scatter = true;
    let local = run_with_hints(cfg, HintConfig::default(), &samples, &hints).states;
    for (a, b) in states.iter().zip(&local) {
        let mut a = *a;
        a.stamps.odometry_ns = 0;
        assert_eq!(
            a.position_m.map(f64::to_bits),
            b.position_m.map(f64::to_bits)
        );
        assert_eq!(a, *b, "seq {}", a.seq);
    }
    // Stale exactly while the newest delivered hint is older than the maximum age.
    let cfg = HintConfig::default();
    let (delivery, max_age) = ((cfg.delivery_s * 1e9) as u64, (cfg.max_age_s * 1e9) as u64);
    let mut stale = 0;
    for o in &states {
        let t = o.stamps.sample_ns;
        let newest = hints
            .iter()
            .filter(|h| h.stamps.acquired_ns + delivery <= t)
            .map(|h| h.stamps.sample_ns)
            .max();
        let expected = newest.is_some_and(|n| t - n > max_age);
        assert_eq!(o.flags & odometry_flags::HINT_STALE != 0, expected, "t {t}");
        stale += usize::from(expected);
    }
    // About 10 s at 100 Hz, less the maximum age.
    assert!((950..1000).contains(&stale), "{stale} stale states");
    // Hints are used again after the gap.
    assert!(
        states
            .iter()
            .any(|o| o.stamps.sample_ns > gap_to && o.flags & odometry_flags::HINT_SPEED != 0)
    );

    std::fs::remove_dir_all(&dir).unwrap();
}
