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
//! cruise the detector took for rest) or a fresh speed hint says the robot moves while the
//! rate before the stage's refinement exceeds a gyro's turn-on bias
//! (`odometry::cruise::MAX_TURN_ON_BIAS_RPS`): there the stage averaged the rate of a platform
//! that turns, and the filter, which takes no zero-rate update there, keeps the bias it had.
//! (The F1TENTH car of docs/real-data.md, whose detector learned its noise while driving a
//! loop, had 20-35 deg/s of its turning refined into the stage's bias; before the filter
//! aligns, the navigator keeps that share apart for the cruise alignment, `odometry::cruise`.
//! On a straight highway cruise the stage's refinement tracks the comma2k19 phone's bias, and
//! following it out there too took that car from 1.17 to 3.70 % at one point of the tuning
//! grid.) At a
//! rest the filter accepts, the stage's refinement is the bias measurement that the filter's
//! own zero-rate updates, gated and not made on every platform, do not replace: followed
//! there as well, three hand-held phone walks of the corpus lost their coverage. The one
//! gyroscope change always followed is the first after an alignment whose window straddled a
//! refinement (a robot's rest that began before the stage's learned verdict, which makes its
//! first refinement): the filter's bias is the window's mean rate over the window's mean
//! refinement, not a measurement the stage's newer one could replace. Left unfollowed, the
//! F1TENTH car of docs/real-data.md (f1tenth-ds3: its rest's samples four fifths before the
//! verdict) kept 0.28 deg/s of the stage's first refinement twice, and its heading drifted 30
//! degrees in 110 s.

use super::*;

/// The calibration stage's refinement offsets, sensor frame: accelerometer (m/s^2) and
/// gyroscope (rad/s, after the odometry's gyro correction), of one sample or the mean over an
/// alignment's window.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Refinement {
    pub accel: Vector3<f64>,
    pub gyro: Vector3<f64>,
}

/// The mean refinement over an alignment window's samples: the refinement its mean specific
/// force and rate carry, which the filter aligned on them follows from
/// ([`Eskf::with_refinement`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct RefinementMean {
    sum: Refinement,
    n: u64,
}

impl RefinementMean {
    /// `n` samples that all carry `r`.
    pub fn repeated(r: Refinement, n: u64) -> Self {
        let k = n as f64;
        Self {
            sum: Refinement {
                accel: r.accel * k,
                gyro: r.gyro * k,
            },
            n,
        }
    }

    /// Adds a sample's refinement.
    pub fn push(&mut self, r: Refinement) {
        self.sum.accel += r.accel;
        self.sum.gyro += r.gyro;
        self.n += 1;
    }

    /// The mean; `None` for no sample.
    pub fn mean(&self) -> Option<Refinement> {
        let k = self.n as f64;
        (self.n > 0).then(|| Refinement {
            accel: self.sum.accel / k,
            gyro: self.sum.gyro / k,
        })
    }
}

impl Eskf {
    /// The filter aligned on samples whose mean carries the refinement `r` (their window's
    /// mean, [`RefinementMean`]): the first [`Self::follow_refinement`] moves the bias by the
    /// change from there. Without it that first call only records the refinement, and a
    /// refinement that moved within the window (the stage's running mean at its first rests,
    /// most for a part whose rest reads gravity off) is left between the filter's bias and the
    /// stream's: on a TurtleBot recording with an uncalibrated accelerometer 0.8 m/s^2 along
    /// gravity, which the filter could not put in a bias its alignment had measured and drove
    /// into tilt and horizontal bias over the next second of rest (16 degrees).
    pub fn with_refinement(mut self, r: Refinement) -> Self {
        self.refined = Some(r);
        self.refined_window = true;
        self
    }

    /// Follows the stage's refinement `r` of a sample: the accelerometer bias and the held
    /// previous measurement move by the offset's change since the last call (or since the
    /// alignment window's mean, [`Self::with_refinement`]), and the rate bias likewise by the
    /// gyroscope's when `follow_gyro` or when the change is the one from the window's mean (the
    /// first call after an alignment without a window's refinement only records them).
    pub fn follow_refinement(&mut self, r: Refinement, follow_gyro: bool) {
        let follow_gyro = follow_gyro || std::mem::take(&mut self.refined_window);
        if let Some(before) = self.refined.replace(r) {
            let change = r.accel - before.accel;
            self.x.b_a -= change;
            self.last.f -= change;
            if follow_gyro {
                let change = r.gyro - before.gyro;
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
            m: 0.0,
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
        kf.follow_refinement(Refinement::default(), false);
        kf.predict(m, 0.01);
        // The stage now subtracts the bias it measured: the samples read true.
        let refined = Imu { f: m.f - bias, ..m };
        kf.follow_refinement(
            Refinement {
                accel: bias,
                ..Refinement::default()
            },
            false,
        );
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
        kf.follow_refinement(Refinement::default(), follow);
        kf.predict(m, 0.01);
        // The stage now subtracts `step` more: a still platform reads -step.
        let moved = Imu {
            w: Vector3::new(0.0, 0.0, -step),
            ..m
        };
        kf.follow_refinement(
            Refinement {
                gyro: Vector3::new(0.0, 0.0, step),
                ..Refinement::default()
            },
            follow,
        );
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

    #[test]
    fn the_step_from_an_alignment_windows_mean_refinement_is_followed_on_the_gyro_too() {
        // A rest whose samples were three quarters before the stage's first refinement of
        // `bias` about z: the window's mean refinement is a quarter of it, and its mean rate,
        // the filter's bias, the other three quarters.
        let bias = 3e-3;
        let (mut kf, m) = at_rest(Vector3::zeros());
        kf.x.b_g = Vector3::new(0.0, 0.0, 0.75 * bias);
        // The window's last sample, held for the next step, read the bias less a quarter.
        kf.last.w = kf.x.b_g;
        let mut kf = kf.with_refinement(Refinement {
            gyro: Vector3::new(0.0, 0.0, 0.25 * bias),
            ..Refinement::default()
        });
        // From here every sample carries the whole refinement and reads zero: still.
        let refined = Refinement {
            gyro: Vector3::new(0.0, 0.0, bias),
            ..Refinement::default()
        };
        for _ in 0..1000 {
            kf.follow_refinement(refined, false);
            kf.predict(m, 0.01);
        }
        // Bias and refinement together are the stage's: no yaw. (Unfollowed, the filter kept
        // 0.75 bias of its own beside it: 10 s at -2.25e-3 rad/s, 0.0225 rad.)
        assert!(kf.x.b_g.z.abs() < 1e-12, "b_g {}", kf.x.b_g);
        let yaw = kf.x.q.euler_angles().2;
        assert!(yaw.abs() < 1e-12, "yaw {yaw}");
        // Later steps are the stage's measurements: not followed on the gyro.
        let unfollowed = yaw_after_gyro_step(2e-4, false);
        assert!((unfollowed + 2e-3).abs() < 1e-6, "yaw {unfollowed}");
    }
}
