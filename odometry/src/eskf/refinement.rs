//! The calibration stage's accelerometer refinement, followed exactly.
//!
//! The calibration stage subtracts from every sample, beyond the calibration file's bias, the
//! offset its refinement at rest measured (`CorrectedImuSample::refined_accel_mps2`, m/s^2,
//! sensor frame), and refines it at every rest: a running mean over rest time that starts from
//! the file's value with the weight of one second of rest, so that for a part whose file is
//! off (an identity calibration, gravity read 1-2 % off at rest) the offset moves along
//! gravity by up to that error over the first seconds of rest, after the filter aligned. The
//! filter's `b_a` is the stream's residual bias, so a change of the offset by `da` from one
//! sample to the next changes it by exactly `-da`, with no uncertainty: the nominal state moves
//! and the covariance stays. Without this the filter, whose bias random walk is a calibrated
//! part's (1e-4 m/s^3/sqrt(Hz)), kept the bias it aligned with while the stream's moved by
//! 0.05 m/s^2 under it (a car's 10 s start rest, docs/real-data.md), and integrated the
//! difference as vertical velocity once the car drove.
//!
//! The gyroscope's refinement is not followed: at a rest it is the measurement of the bias
//! that the filter's own zero-rate updates, gated and not made on every platform, do not
//! replace (followed as well, three hand-held phone walks of the corpus lost their coverage).

use super::*;

impl Eskf {
    /// Follows the stage's accelerometer refinement offset of a sample, `accel` (m/s^2,
    /// sensor frame): the bias and the held previous measurement move by its change since the
    /// last call (the first call after the alignment only records it).
    pub fn follow_refinement(&mut self, accel: [f64; 3]) {
        let now = Vector3::from(accel);
        if let Some(before) = self.refined.replace(now) {
            let change = now - before;
            self.x.b_a -= change;
            self.last.f -= change;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A filter at rest, level, aligned with a stream whose accelerometer reads `bias` too
    /// much on every axis, and that stream's sample.
    fn at_rest(bias: Vector3<f64>) -> (Eskf, Imu) {
        let g = 9.81;
        let m = Imu {
            f: Vector3::new(0.0, 0.0, g) + bias,
            w: Vector3::zeros(),
        };
        let x = Nominal {
            p: Vector3::zeros(),
            v: Vector3::zeros(),
            q: UnitQuaternion::identity(),
            b_a: bias,
            b_g: Vector3::zeros(),
            k: 0.0,
        };
        let kf = Eskf::new(
            x,
            Cov::identity() * 1e-6,
            g,
            super::super::tests::noise(),
            m,
        );
        (kf, m)
    }

    #[test]
    fn a_refinement_step_moves_the_bias_and_leaves_the_velocity_at_rest() {
        let bias = Vector3::new(0.02, -0.01, 0.05);
        let (mut kf, m) = at_rest(bias);
        kf.follow_refinement([0.0; 3]);
        kf.predict(m, 0.01);
        // The stage now subtracts the bias it measured: the samples read true.
        let refined = Imu { f: m.f - bias, ..m };
        kf.follow_refinement(bias.into());
        for _ in 0..100 {
            kf.predict(refined, 0.01);
        }
        assert!(kf.x.b_a.norm() < 1e-12, "b_a {}", kf.x.b_a);
        assert!(kf.x.v.norm() < 1e-12, "v {}", kf.x.v);
    }

    #[test]
    fn without_following_the_same_step_is_integrated_as_motion() {
        let bias = Vector3::new(0.0, 0.0, 0.05);
        let (mut kf, m) = at_rest(bias);
        let refined = Imu { f: m.f - bias, ..m };
        for _ in 0..100 {
            kf.predict(refined, 0.01);
        }
        // 1 s at -0.05 m/s^2: the stream's change taken for a vertical acceleration.
        assert!((kf.x.v.z + 0.05).abs() < 1e-3, "v {}", kf.x.v);
    }
}
