//! Real processes: `mems-calibrate serve` between `mems-acquire` (simulated MPU-9250, datasheet
//! preset, drive scenario starting with a 10 s rest) and this test's own subscribers.
//!
//! The calibration is fitted the way a user would: `mems-sim six-position` with the same
//! (uncalibrated, datasheet) preset, then `mems-calibrate fit`. The acquisition runs twice (a
//! restarted publisher whose sequence numbers start again at 0), and a `mems-topic` subscriber
//! comes and goes during the first run. Every raw sample must come out corrected, once, in
//! order, with its stamps; rest must be detected after the (shortened) learning interval; the
//! corrected magnitude at rest must be local gravity; SIGTERM must end the service cleanly.
//!
//! Needs the binaries: `cargo build -p acquire -p calibrate -p mems-sim -p mems-topic` (or
//! `cargo test --workspace`, which builds them).

use std::time::Duration;

use integration_tests::{Proc, calibrate_sim_part, path_arg, unique_namespace};
use ipc_types::{CorrectedImuSample, RawImuSample, corrected_flags, service};

#[test]
fn serve_corrects_every_raw_sample_once_in_order_and_survives_restarts() {
    let ns = unique_namespace("calserve");
    let dir = std::env::temp_dir().join(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let calib = calibrate_sim_part(&dir, 1);

    // The test's own subscribers, before any publisher, so that they see every sample.
    let node = service::node().unwrap();
    let raw_svc =
        service::open::<RawImuSample>(&node, &service::full_name(&ns, service::RAW)).unwrap();
    let raw_sub = service::subscriber(&raw_svc).unwrap();
    let cor_svc =
        service::open::<CorrectedImuSample>(&node, &service::full_name(&ns, service::CORRECTED))
            .unwrap();
    let cor_sub = service::subscriber(&cor_svc).unwrap();
    let mut raw: Vec<RawImuSample> = Vec::new();
    let mut cor: Vec<CorrectedImuSample> = Vec::new();
    let drain = |raw: &mut Vec<RawImuSample>, cor: &mut Vec<CorrectedImuSample>| {
        while let Some(s) = raw_sub.receive().unwrap() {
            raw.push(*s.payload());
        }
        while let Some(s) = cor_sub.receive().unwrap() {
            cor.push(*s.payload());
        }
    };

    let serve = Proc::spawn(
        "mems-calibrate",
        &[
            "serve",
            "--calib",
            path_arg(&calib),
            "--namespace",
            &ns,
            "--learn-s",
            "1",
            "--learn-first-s",
            "1",
        ],
    );
    std::thread::sleep(Duration::from_millis(700));
    let mut runs = Vec::new();
    for (i, duration) in ["3", "2"].into_iter().enumerate() {
        let topic = (i == 0).then(|| {
            Proc::spawn(
                "mems-topic",
                &[
                    "hz",
                    "mems/imu/corrected",
                    "--namespace",
                    &ns,
                    "--duration",
                    "1",
                    "--json",
                ],
            )
        });
        let acquire = Proc::spawn(
            "mems-acquire",
            &[
                "--source",
                "sim",
                "--rate",
                "1000",
                "--duration",
                duration,
                "--namespace",
                &ns,
            ],
        );
        // Drain while the processes run: a subscriber connects to a publisher when it receives,
        // so samples of a publisher that is gone before the first receive would never arrive.
        let waiter = std::thread::spawn(move || {
            let acquired = acquire.wait(Duration::from_secs(30));
            let topic = topic.map(|t| t.wait(Duration::from_secs(30)));
            (acquired, topic)
        });
        while !waiter.is_finished() {
            drain(&mut raw, &mut cor);
            std::thread::sleep(Duration::from_millis(1));
        }
        let ((status, _), topic) = waiter.join().unwrap();
        assert!(status.success(), "mems-acquire failed: {status}");
        if let Some((status, out)) = topic {
            assert!(status.success(), "mems-topic failed: {status}");
            let report: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
            assert_eq!(report["lost"], 0, "{report}");
        }
        // The service releases the last partial batch once the publisher is gone.
        for _ in 0..500 {
            drain(&mut raw, &mut cor);
            std::thread::sleep(Duration::from_millis(1));
        }
        runs.push(raw.len());
    }
    serve.signal(libc::SIGTERM);
    let (status, _) = serve.wait(Duration::from_secs(20));
    assert!(
        status.success(),
        "mems-calibrate serve did not exit cleanly: {status}"
    );
    drain(&mut raw, &mut cor);
    std::fs::remove_dir_all(&dir).unwrap();

    // One-to-one, in order, stamps copied.
    assert!(
        runs[0] > 2900 && runs[1] - runs[0] > 1900,
        "raw samples per run {runs:?}"
    );
    assert_eq!(cor.len(), raw.len());
    for (c, r) in cor.iter().zip(&raw) {
        assert_eq!(
            (c.seq, c.stamps.sample_ns, c.stamps.acquired_ns),
            (r.seq, r.stamps.sample_ns, r.stamps.acquired_ns)
        );
        assert!(c.stamps.calibrated_ns >= r.stamps.acquired_ns);
        assert_eq!(c.raw_flags, r.flags);
        assert_eq!(c.calib_id, cor[0].calib_id);
    }
    assert_ne!(cor[0].calib_id, 0);
    assert_eq!(
        raw[runs[0]].seq, 0,
        "the second publisher starts again at 0"
    );

    // Each run is a new session: not ready during its 1 s of learning, then ready, refined and
    // at rest (the drive starts with 10 s at rest).
    for (start, end) in [(0, runs[0]), (runs[0], runs[1])] {
        let run = &cor[start..end];
        let ready = run
            .iter()
            .position(|c| c.flags & corrected_flags::DETECTOR_READY != 0)
            .expect("detector ready");
        assert!((980..=1100).contains(&ready), "ready at sample {ready}");
        let after = &run[ready..run.len() - 20];
        assert!(
            after
                .iter()
                .all(|c| c.flags & corrected_flags::BIAS_REFINED != 0)
        );
        // The GLRT's 0.5 s window starts full of the learned rest: the drive's rest is rest
        // from the first batch after learning on.
        let rest: Vec<_> = after
            .iter()
            .filter(|c| c.flags & corrected_flags::ZERO_STATE != 0)
            .collect();
        assert!(
            rest.len() as f64 > 0.9 * after.len() as f64,
            "{} of {}",
            rest.len(),
            after.len()
        );
        assert!(
            after[20..40]
                .iter()
                .all(|c| c.flags & corrected_flags::ZERO_STATE != 0)
        );
        // Corrected magnitude at rest is local gravity once the refinement along gravity has
        // settled (the second half of the rest); the raw reading's is off by the datasheet
        // part's biases and scale errors.
        let mean = |f: &dyn Fn(usize) -> f64| (0..3).map(f).map(|x| x * x).sum::<f64>().sqrt();
        let settled = &rest[rest.len() / 2..];
        let n = settled.len() as f64;
        let corrected = mean(&|i| settled.iter().map(|c| c.accel_mps2[i]).sum::<f64>() / n);
        let raw_run = &raw[start..end];
        let raw_mag =
            mean(&|i| raw_run.iter().map(|r| r.accel_g[i]).sum::<f64>() / raw_run.len() as f64)
                * 9.80665;
        // 3 mg: repeated runs of the same simulated part measured 1.0-2.1 mg off, varying from
        // run to run more than the noise explains (an open question, see the issue notes); the
        // raw reading is 10 times further off.
        assert!(
            (corrected - 9.80665).abs() < 0.03,
            "corrected |a| {corrected} over the settled half of the rest"
        );
        assert!((raw_mag - 9.80665).abs() > 0.1, "raw |a| {raw_mag}");
    }
}
