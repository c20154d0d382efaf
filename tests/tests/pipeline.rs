//! Three real processes and two observers: `mems-acquire` (simulated MPU-9250, datasheet
//! preset, a drive starting with 10 s of rest) -> `mems-calibrate serve` -> `mems-odometry
//! serve`, with `mems-record` and this test's own subscriber to the odometry state.
//!
//! The live run and an offline run (`mems-odometry offline`) over the raw samples the recorder
//! captured must agree exactly: the subscriber's final displacement equals the offline end
//! displacement bit for bit, because both run the same stage code on the same samples.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use integration_tests::{Proc, calibrate_sim_part, path_arg, run_ok, unique_namespace};
use ipc_types::{OdometryState, odometry_flags, service};

#[test]
fn live_pipeline_matches_offline_replay_exactly() {
    let ns = unique_namespace("pipeline");
    let dir = std::env::temp_dir().join(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let calib = calibrate_sim_part(&dir, 1001);
    let rec = dir.join("run.mcap");

    // The observer: every odometry state, drained continuously (iceoryx2 ports stay in the
    // thread that made them).
    let states: Arc<Mutex<Vec<OdometryState>>> = Arc::default();
    let stop = Arc::new(AtomicBool::new(false));
    let observer = {
        let (states, stop, ns) = (states.clone(), stop.clone(), ns.clone());
        std::thread::spawn(move || {
            let node = service::node().unwrap();
            let svc =
                service::open::<OdometryState>(&node, &service::full_name(&ns, service::ODOMETRY))
                    .unwrap();
            let sub = service::subscriber(&svc).unwrap();
            while !stop.load(Ordering::Relaxed) {
                while let Some(s) = sub.receive().unwrap() {
                    states.lock().unwrap().push(*s);
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            while let Some(s) = sub.receive().unwrap() {
                states.lock().unwrap().push(*s);
            }
        })
    };

    let ns_args = ["--namespace", ns.as_str()];
    let record = Proc::spawn(
        "mems-record",
        &[&["--out", path_arg(&rec)][..], &ns_args].concat(),
    );
    let odometry = Proc::spawn(
        "mems-odometry",
        &[&["serve", "--calib", path_arg(&calib)][..], &ns_args].concat(),
    );
    let calibrate = Proc::spawn(
        "mems-calibrate",
        &[&["serve", "--calib", path_arg(&calib)][..], &ns_args].concat(),
    );
    std::thread::sleep(Duration::from_millis(1500));
    // 10 s of rest (alignment after the 5 s of detector learning) and then driving.
    run_ok(
        "mems-acquire",
        &[
            &[
                "--source",
                "sim",
                "--rate",
                "1000",
                "--duration",
                "16",
                "--seed",
                "1",
            ][..],
            &ns_args,
        ]
        .concat(),
    );
    // Let the stages drain what is in flight, then stop them (the calibration stage releases
    // its last partial batch when its publisher is gone).
    std::thread::sleep(Duration::from_millis(1500));
    for p in [&calibrate, &odometry, &record] {
        p.signal(libc::SIGTERM);
    }
    for p in [calibrate, odometry, record] {
        let (status, _) = p.wait(Duration::from_secs(20));
        assert!(status.success(), "a stage failed: {status}");
    }
    stop.store(true, Ordering::Relaxed);
    observer.join().unwrap();

    let states = states.lock().unwrap();
    let live: Vec<&OdometryState> = states
        .iter()
        .filter(|s| s.flags & odometry_flags::REVISION == 0)
        .collect();
    let last = *live.last().expect("odometry states arrived");
    assert!(live.len() > 15_000, "{} live states", live.len());
    assert!(last.flags & odometry_flags::ALIGNED != 0, "the run aligned");
    for w in live.windows(2) {
        assert_eq!(w[1].seq, w[0].seq + 1, "one state per sample, in order");
    }
    assert_eq!(live[0].seq, 0, "the observer saw the stream from the start");

    let out = run_ok(
        "mems-odometry",
        &[
            "offline",
            "--calib",
            path_arg(&calib),
            "--input",
            path_arg(&rec),
            "--json",
        ],
    );
    let offline: serde_json::Value = serde_json::from_str(out.trim()).expect("JSON");
    let end: Vec<f64> = offline["end_displacement_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(
        offline["seq"].as_u64().unwrap(),
        last.seq,
        "same last sample"
    );
    for (axis, (offline, live)) in end.iter().zip(last.position_m).enumerate() {
        assert_eq!(
            offline.to_bits(),
            live.to_bits(),
            "axis {axis}: offline {offline} vs live {live}"
        );
    }
    // The robot moved: the comparison is not between two zero vectors.
    assert!(last.distance_m > 0.5, "distance {}", last.distance_m);
    std::fs::remove_dir_all(&dir).unwrap();
}
