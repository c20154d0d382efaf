//! The calibration stage's bias refinement, followed by the filter's bias estimates.
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
//! The gyroscope's refinement (`refined_gyro_rps`, rad/s) is followed the same way only where
//! the odometry refuses the stage's rest as vibration (`REST_VIBRATING`: an idling engine, a
//! cruise the detector took for rest): there the stage averaged the rate of a platform that
//! moves, and the filter, which takes no zero-rate update there, keeps the bias it had. At a
//! rest the filter accepts, the stage's refinement is the bias measurement that the filter's
//! own zero-rate updates, gated and not made on every platform, do not replace: followed
//! there as well, three hand-held phone walks of the corpus lost their coverage.

use super::*;

impl Eskf {
    /// Follows the stage's refinement of a sample, `accel` (m/s^2) and `gyro` (rad/s), sensor
    /// frame: the accelerometer bias and the held previous measurement move by the offset's
    /// change since the last call, and the rate bias likewise by the gyroscope's when
    /// `follow_gyro` (the first call after the alignment only records them).
    pub fn follow_refinement(&mut self, accel: [f64; 3], gyro: [f64; 3], follow_gyro: bool) {
        let now = (Vector3::from(accel), Vector3::from(gyro));
        if let Some(before) = self.refined.replace(now) {
            let change = now.0 - before.0;
            self.x.b_a -= change;
            self.last.f -= change;
            if follow_gyro {
                let change = now.1 - before.1;
                self.x.b_g -= change;
                self.last.w -= change;
            }
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
        kf.follow_refinement([0.0; 3], [0.0; 3], false);
        kf.predict(m, 0.01);
        // The stage now subtracts the bias it measured: the samples read true.
        let refined = Imu { f: m.f - bias, ..m };
        kf.follow_refinement(bias.into(), [0.0; 3], false);
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

    /// A level filter at rest whose stream's rate is `rate` (rad/s about z), after a step of
    /// the stage's gyroscope refinement by `step`, predicted for 10 s with or without
    /// following it: the yaw it integrates, rad.
    fn yaw_after_gyro_step(step: f64, follow: bool) -> f64 {
        let (mut kf, m) = at_rest(Vector3::zeros());
        kf.follow_refinement([0.0; 3], [0.0; 3], follow);
        kf.predict(m, 0.01);
        // The stage now subtracts `step` more: a still platform reads -step.
        let moved = Imu {
            w: Vector3::new(0.0, 0.0, -step),
            ..m
        };
        kf.follow_refinement([0.0; 3], [0.0, 0.0, step], follow);
        for _ in 0..1000 {
            kf.predict(moved, 0.01);
        }
        kf.x.q.euler_angles().2
    }

    #[test]
    fn a_followed_gyro_step_leaves_the_heading_and_an_unfollowed_one_turns_it() {
        let step = 2e-4;
        let followed = yaw_after_gyro_step(step, true);
        assert!(followed.abs() < 1e-12, "yaw {followed}");
        // 10 s at -2e-4 rad/s.
        let unfollowed = yaw_after_gyro_step(step, false);
        assert!((unfollowed + 2e-3).abs() < 1e-6, "yaw {unfollowed}");
    }
}
