//! The calibration stage allocates nothing per sample: a counting global allocator sees zero
//! allocations on this thread while both detectors' stages process a simulated drive (learning,
//! rest, motion, refinement, a gap, a restarted stream and the end of the stream included).

use alloc_count::allocations;
use calibrate::calibfile::CalibrationFile;
use calibrate::stage::{CalibrationStage, RefineConfig};
use calibrate::zero_state::{DetectorConfig, DetectorKind};
use ipc_types::RawImuSample;
use ipc_types::units::{AccelRange, GyroRange};
use mems_sim::model::{G_MPS2, SensorModel};
use mems_sim::scenario::{Drive, DriveParams, ns_from_s};
use mems_sim::vibration::VibrationModel;
use mems_sim::{SimSensor, adc};
use mems_stage::Stage;

#[global_allocator]
static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;

/// 40 s of a drive with turns (10 s initial rest), quantized like the device.
fn drive_samples() -> Vec<RawImuSample> {
    let mut params = DriveParams::new(40.0);
    params.turns = true;
    params.in_place_turns = true;
    let drive = Drive::new(&params, 3).unwrap();
    let model = SensorModel::mpu9250_calibrated();
    let mut sim = SimSensor::new(drive, &model, &VibrationModel::moderate(1.0), 3).unwrap();
    (0..40_000u64)
        .map(|k| {
            let t = k as f64 / 1000.0;
            let analog = sim.sample_with_truth(t, 1000.0).0;
            adc::quantize_sample(&analog, AccelRange::G2, GyroRange::Dps250, ns_from_s(t), k)
        })
        .collect()
}

#[test]
fn the_stage_allocates_nothing_per_sample() {
    // The counter works: a Vec allocates.
    let before = allocations();
    let v: Vec<u64> = Vec::with_capacity(4);
    assert_eq!(allocations() - before, 1);
    drop(v);

    let mut samples = drive_samples();
    // A gap: 100 samples lost in the middle of the drive.
    samples.drain(20_000..20_100);
    let calib = CalibrationFile::identity(G_MPS2);
    for kind in [DetectorKind::Yu, DetectorKind::Glrt] {
        let mut stage = CalibrationStage::new(
            &calib,
            DetectorConfig::new(kind, G_MPS2),
            RefineConfig::default(),
        )
        .unwrap();
        let (mut released, mut rest, mut checksum) = (0u64, 0u64, 0.0);
        let before = allocations();
        // The drive, then its first 6 s again: a restarted publisher (seq from 0).
        for s in samples.iter().chain(&samples[..6000]) {
            stage
                .process(s, &mut |c| {
                    released += 1;
                    rest += u64::from(c.flags & ipc_types::corrected_flags::ZERO_STATE != 0);
                    checksum += c.accel_mps2[2];
                })
                .unwrap();
        }
        stage.finish(&mut |_| {});
        let allocs = allocations() - before;
        assert_eq!(
            allocs,
            0,
            "{kind:?}: {allocs} allocations for {} samples",
            samples.len()
        );
        assert_eq!(released, samples.len() as u64 + 6000);
        // The run went through learning, rest and refinement, the gap and the restart (and
        // learned again).
        assert!(stage.detector().is_ready() && stage.refinement().2);
        assert_eq!(stage.stats().restarts, 1);
        assert!(rest > 10_000, "{kind:?}: {rest} rest samples");
        assert_eq!(stage.stats().gaps, 1);
        assert!(checksum.is_finite());
    }
}
