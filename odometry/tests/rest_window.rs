//! The covariance propagated once per `OdometryConfig::propagation_interval_s` and, at rest,
//! one zero-velocity and one zero-rate update per propagation carrying the information of one
//! per sample, against an independent computation: the same stage propagating and updating at
//! every sample (interval 0), on the same simulated drives. The two see the same information;
//! they differ by where the transition is linearised (the nominal state between updates) and
//! by the rest window's drift bound (`navigator::REST_WINDOW_DRIFT`: the steady velocity
//! variance at rest within -11 % and +12 % of the per-sample limit). So their end positions
//! must differ by a small part of the reported 1-sigma (a tenth: far below the drive's own
//! error, which is of the order of the 1-sigma), and their reported 1-sigma by a few percent.

mod common;

use common::{Case, Simulation};
use ipc_types::{OdometryState, odometry_flags};
use mems_sim::model::G_MPS2;
use odometry::config::OdometryConfig;
use odometry::stage::OdometryStage;

/// The last live state of the stage over the drive, the last live state of every rest, and
/// the filter's gyro bias estimate and its 1-sigma at the end (rad/s, x axis).
struct Run {
    last: OdometryState,
    rest_ends: Vec<OdometryState>,
    gyro_bias: (f64, f64),
}

fn run(c: &Case, interval_s: f64) -> Run {
    let mut sim = Simulation::new(c, 5);
    sim.session();
    let cfg = OdometryConfig {
        propagation_interval_s: interval_s,
        ..OdometryConfig::mpu9250(G_MPS2)
    };
    let mut stage = OdometryStage::new(cfg);
    let (mut last, mut rest_ends) = (None::<OdometryState>, Vec::new());
    sim.drive(|s, _| {
        stage
            .process(s, &mut |o| {
                if o.flags & odometry_flags::REVISION != 0 {
                    return;
                }
                if let Some(l) = last
                    && l.flags & odometry_flags::ZERO_VELOCITY != 0
                    && o.flags & odometry_flags::ZERO_VELOCITY == 0
                {
                    rest_ends.push(l);
                }
                last = Some(*o);
            })
            .unwrap();
    });
    let kf = stage.filter().expect("aligned");
    Run {
        last: last.expect("states"),
        rest_ends,
        gyro_bias: (kf.x.b_g.x, kf.cov[(12, 12)].sqrt()),
    }
}

fn compare(c: &Case) {
    let every = run(c, 0.0);
    let windowed = run(c, 0.01);
    let (a, b) = (&every.last, &windowed.last);
    for axis in 0..2 {
        let sigma = a.position_sigma_m[axis];
        let diff = b.position_m[axis] - a.position_m[axis];
        assert!(
            diff.abs() < 0.1 * sigma,
            "{} Hz axis {axis}: positions differ by {diff:.4} m, 1-sigma {sigma:.4} m",
            c.rate_hz
        );
        let ratio = b.position_sigma_m[axis] / sigma;
        assert!(
            (ratio - 1.0).abs() < 0.03,
            "{} Hz axis {axis}: position 1-sigma ratio {ratio}",
            c.rate_hz
        );
    }
    // Both take the same rests, and at the end of each the velocity 1-sigma is within the
    // window's bound of the per-sample one.
    assert_eq!(every.rest_ends.len(), windowed.rest_ends.len());
    assert!(
        every.rest_ends.len() >= 5,
        "{} rests",
        every.rest_ends.len()
    );
    for (e, w) in every.rest_ends.iter().zip(&windowed.rest_ends) {
        assert_eq!(e.seq, w.seq);
        let ratio = w.velocity_sigma_mps[0] / e.velocity_sigma_mps[0];
        assert!(
            (0.85..1.15).contains(&ratio),
            "{} Hz rest ending at seq {}: velocity 1-sigma ratio {ratio}",
            c.rate_hz,
            e.seq
        );
    }
    let (bias, sigma) = every.gyro_bias;
    assert!(
        (windowed.gyro_bias.0 - bias).abs() < 0.1 * sigma,
        "{} Hz gyro bias {} against {bias} (1-sigma {sigma})",
        c.rate_hz,
        windowed.gyro_bias.0
    );
}

#[test]
fn windowed_rest_updates_match_updates_at_every_sample() {
    // White samples at 1 kHz (the window's drift bound closes rest windows after a few
    // samples) and the driver's 20 Hz DLPF at 200 Hz (two samples per window); with turns.
    for (rate_hz, dlpf) in [
        (1000.0, None),
        (200.0, Some(mems_sim::dlpf::DlpfConfig::driver(200.0))),
    ] {
        let c = Case {
            duration_s: 300.0,
            rate_hz,
            dlpf,
            turns: true,
            ..Case::straight()
        };
        compare(&c);
    }
}
