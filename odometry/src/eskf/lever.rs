//! Body-frame velocity measurements at a point other than the IMU: the lever arm.
//!
//! A wheeled platform's non-holonomic constraint and its wheel speed describe the motion of
//! the rear axle, not of an IMU mounted elsewhere on the rigid body. With `r_b` the vector
//! from the IMU to that point (body frame: x forward, y left, z up; m) and `omega_b` the
//! body's angular rate in the body frame (rad/s, counter-clockwise positive about each axis),
//! the point moves at
//!
//! `v_point = v_b + omega_b x r_b`, with `v_b = R_bs q^-1 v` and `omega_b = R_bs (w - b_g)`
//!
//! (the rigid-body velocity transfer: Titterton and Weston, "Strapdown Inertial Navigation
//! Technology", 2nd ed., section 10.3, lever-arm compensation; Groves, "Principles of GNSS,
//! Inertial, and Multisensor Integrated Navigation Systems", 2nd ed., section 14.3.1, the
//! odometer's lever arm). An IMU `l` metres ahead of the rear axle (`r_b = (-l, 0, 0)`)
//! turning at the yaw rate `w_z` moves sideways at `w_z l` (to the left in a left turn)
//! while the axle does not: that is what the constraint, applied at the IMU, would take for
//! skid. `w` is the newest gyro sample the filter predicted with ([`Eskf::predict`]).
//!
//! The Jacobian of `v_point` with respect to the error state (the attitude error local, as
//! in the filter): `R_bs q^-1` on `dv`, `R_bs [q^-1 v]x` on `dtheta`, and, from
//! `d(omega_b x r_b) = -(R_bs db_g) x r_b = [r_b]x R_bs db_g`, `[r_b]x R_bs` on `db_g`. With
//! `r_b = 0` the measurement is the IMU's body velocity, computed exactly as before.

use super::*;

/// What a velocity update does with the mounting-yaw state [`MY`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MountingYaw {
    /// The mounting is taken as exact: the state is not in the measurement.
    Exact,
    /// The state is in the measurement and estimated.
    Learned,
    /// The state's uncertainty is counted as the measurement's noise (`c c^T sigma_m^2`, `c`
    /// its [`Eskf::mounting_yaw_column`]), its estimate and covariances kept: a consider
    /// treatment that leaves out its correlation with the other states.
    Considered,
}

impl Eskf {
    /// The angular rate of the newest sample, bias removed, rad/s, sensor frame.
    pub fn rate(&self) -> Vector3<f64> {
        self.last.w - self.x.b_g
    }

    /// The body-frame velocity of the point `r_b` (body frame, m, from the IMU to the point),
    /// m/s, with `r_bs` rotating sensor-frame vectors into the body frame (module
    /// documentation); [`Self::body_velocity`] when `r_b` is zero.
    pub fn point_velocity(&self, r_bs: &Matrix3<f64>, r_b: &Vector3<f64>) -> Vector3<f64> {
        let v_b = self.body_velocity(r_bs);
        if *r_b == Vector3::zeros() {
            return v_b;
        }
        v_b + self.lever_velocity(r_bs, r_b)
    }

    /// The point `r_b`'s velocity relative to the IMU, `omega_b x r_b` (body frame, m/s;
    /// module documentation), with the newest sample's rate.
    pub fn lever_velocity(&self, r_bs: &Matrix3<f64>, r_b: &Vector3<f64>) -> Vector3<f64> {
        (r_bs * self.rate()).cross(r_b)
    }

    /// The Jacobian of [`Self::point_velocity`] with respect to the error state (module
    /// documentation).
    pub fn point_velocity_jacobian(
        &self,
        r_bs: &Matrix3<f64>,
        r_b: &Vector3<f64>,
    ) -> SMatrix<f64, 3, N> {
        let r_t = self.x.q.to_rotation_matrix().into_inner().transpose();
        let mut h = SMatrix::<f64, 3, N>::zeros();
        h.fixed_view_mut::<3, 3>(0, V).copy_from(&(r_bs * r_t));
        h.fixed_view_mut::<3, 3>(0, TH)
            .copy_from(&(r_bs * skew(&(r_t * self.x.v))));
        if *r_b != Vector3::zeros() {
            h.fixed_view_mut::<3, 3>(0, BG)
                .copy_from(&(skew(r_b) * r_bs));
        }
        h
    }

    /// The variance the first-order Jacobian leaves out of the body-frame velocity `v_b = R_bs
    /// q^-1 v`, per body axis, (m/s)^2: its second-order term, the product of the attitude
    /// and velocity errors, `dtheta^T B_k dv` with `B_k = [r_k]x R^T` (`r_k` the body axis `k`
    /// in the sensor frame, `R` the attitude, the attitude error local). Its variance for
    /// jointly Gaussian errors is `tr(B_k^T P_tt B_k P_vv) + tr((B_k P_vt)^2)` (Isserlis'
    /// theorem; the Gaussian second-order filter's term, Gelb 1974, section 6.1). It matters
    /// where the velocity is uncertain across the body axis and the tilt is not exact (the
    /// first metres of a drive before a mounting is known), where the linearization about
    /// the velocity would read the vertical velocity as tilt.
    pub fn body_velocity_second_order_variance(&self, r_bs: &Matrix3<f64>) -> Vector3<f64> {
        let r_t = self.x.q.to_rotation_matrix().into_inner().transpose();
        let p_tt = self.cov.fixed_view::<3, 3>(TH, TH);
        let p_vv = self.cov.fixed_view::<3, 3>(V, V);
        let p_vt = self.cov.fixed_view::<3, 3>(V, TH);
        Vector3::from_fn(|k, _| {
            let r_k = r_bs.row(k).transpose();
            let b = skew(&r_k) * r_t;
            let bp = b * p_vt;
            ((b.transpose() * p_tt * b * p_vv).trace() + (bp * bp).trace()).max(0.0)
        })
    }

    /// The derivative of [`Self::point_velocity`] with respect to the mounting's yaw (rad
    /// about body up), `r_bs` the mounting in use: turning the body frame by `dm` turns both
    /// the body velocity and the rate, `z x v_b + (z x omega_b) x r_b`.
    pub fn mounting_yaw_column(&self, r_bs: &Matrix3<f64>, r_b: &Vector3<f64>) -> Vector3<f64> {
        let z = Vector3::z();
        let omega_b = r_bs * self.rate();
        z.cross(&self.body_velocity(r_bs)) + z.cross(&omega_b).cross(r_b)
    }

    /// [`Self::body_velocity_update_with`] at the point `r_b` (body frame, m, from the IMU):
    /// the measurement is `z = ((1 + k) v_p.x, v_p.y, v_p.z)` with `v_p` the
    /// [`Self::point_velocity`], 1-sigma `sigma` per component (m/s); `residual` is `z`
    /// minus its prediction. With an estimated mounting whose yaw error is the state [`MY`]
    /// (`yaw` other than [`MountingYaw::Exact`]), `r_bs` is the mounting in use
    /// ([`Self::mounted`]) and the update reaches the state through
    /// [`Self::mounting_yaw_column`]. Returns the normalized innovation squared (`None`:
    /// singular, nothing updated).
    pub fn point_velocity_update(
        &mut self,
        r_bs: &Matrix3<f64>,
        r_b: &Vector3<f64>,
        residual: Vector3<f64>,
        sigma: Vector3<f64>,
        heading: Heading,
        yaw: MountingYaw,
    ) -> Option<f64> {
        self.propagate();
        let before = self.point_velocity(r_bs, r_b);
        let mut h = self.point_velocity_jacobian(r_bs, r_b);
        let mut var = Matrix3::from_diagonal(&sigma.component_mul(&sigma));
        match yaw {
            MountingYaw::Exact => {}
            MountingYaw::Learned => h.set_column(MY, &self.mounting_yaw_column(r_bs, r_b)),
            MountingYaw::Considered => {
                let column = self.mounting_yaw_column(r_bs, r_b);
                var += column * column.transpose() * self.cov[(MY, MY)].max(0.0);
            }
        }
        // The forward row reads (1 + k) v_p.x.
        let scale = 1.0 + self.x.k;
        for c in 0..N {
            h[(0, c)] *= scale;
        }
        h[(0, KS)] = before.x;
        self.update(&h, residual, &var, heading)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A filter in a turn: moving, tilted, with biases and a scale error.
    fn turning() -> Eskf {
        let x = Nominal {
            p: Vector3::new(1.0, 2.0, 0.5),
            v: Vector3::new(3.0, -1.0, 0.2),
            q: UnitQuaternion::from_euler_angles(0.1, -0.2, 0.7),
            b_a: Vector3::new(0.01, -0.02, 0.03),
            b_g: Vector3::new(0.002, -0.001, 0.003),
            k: 0.01,
            m: 0.03,
        };
        let first = Imu {
            f: Vector3::new(0.3, 0.1, 9.8),
            w: Vector3::new(0.05, -0.1, 0.4),
        };
        Eskf::new(
            x,
            Cov::identity() * 1e-2,
            9.81,
            super::super::tests::noise(),
            first,
        )
    }

    fn mounting() -> Matrix3<f64> {
        UnitQuaternion::from_euler_angles(0.05, 0.02, -0.3)
            .to_rotation_matrix()
            .into_inner()
    }

    #[test]
    fn the_jacobian_is_the_numerical_one() {
        let kf = turning();
        let (r_bs, r_b) = (mounting(), Vector3::new(-1.2, 0.3, 0.4));
        let h = kf.point_velocity_jacobian(&r_bs, &r_b);
        let eps = 1e-6;
        for c in 0..N {
            let mut dx = VecN::zeros();
            dx[c] = eps;
            let (mut plus, mut minus) = (kf.clone(), kf.clone());
            plus.inject(&dx);
            minus.inject(&-dx);
            let numeric = (plus.point_velocity(&r_bs, &r_b) - minus.point_velocity(&r_bs, &r_b))
                / (2.0 * eps);
            let analytic = h.column(c);
            assert!(
                (numeric - analytic).norm() < 1e-6,
                "column {c}: numeric {numeric:?} analytic {analytic:?}"
            );
        }
    }

    #[test]
    fn the_mounting_yaw_column_is_the_numerical_one() {
        let kf = turning();
        let (base, r_b) = (mounting(), Vector3::new(-1.2, 0.3, 0.4));
        let column = kf.mounting_yaw_column(&kf.mounted(&base), &r_b);
        let eps = 1e-6;
        let at = |m: f64| {
            let mut x = kf.clone();
            x.x.m = m;
            x.point_velocity(&x.mounted(&base), &r_b)
        };
        let numeric = (at(kf.x.m + eps) - at(kf.x.m - eps)) / (2.0 * eps);
        assert!((numeric - column).norm() < 1e-6, "{numeric:?} {column:?}");
    }

    /// A level filter moving at 2 m/s along the body's true forward axis, its velocity known
    /// to 1 mm/s, given a mounting 0.1 rad off in yaw: the constraint's zero lateral velocity
    /// is then `2 sin 0.1` off. With the yaw a state (1-sigma 0.2 rad) the update explains it
    /// (normalized innovation squared 0.25) by the yaw, which ends within 0.01 rad of the
    /// truth, and leaves the velocity; taken as exact, nothing explains it (100); considered
    /// (a turn, `crate::nonholonomic`), it explains it and stays.
    #[test]
    fn a_mounting_off_in_yaw_is_learned_not_read_as_velocity() {
        let level = || {
            let mut kf = turning();
            kf.x.q = UnitQuaternion::identity();
            kf.x.v = Vector3::new(2.0, 0.0, 0.0);
            kf.x.k = 0.0;
            kf.x.m = 0.0;
            kf.last.w = Vector3::zeros();
            kf.x.b_g = Vector3::zeros();
            kf.cov = Cov::identity() * 1e-6;
            kf
        };
        let off = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.1)
            .to_rotation_matrix()
            .into_inner();
        let sigma = Vector3::new(1e3, 0.02, 0.02);
        let mut learned = level();
        learned.restart_mounting(0.2);
        let r = learned.mounted(&off);
        let v_b = learned.point_velocity(&r, &Vector3::zeros());
        let residual = Vector3::new(0.0, -v_b.y, -v_b.z);
        let update = |kf: &mut Eskf, r: &Matrix3<f64>, yaw: MountingYaw| {
            let zero = Vector3::zeros();
            kf.point_velocity_update(r, &zero, residual, sigma, Heading::Kept, yaw)
                .unwrap()
        };
        let mut considered = learned.clone();
        let nis = update(&mut learned, &r, MountingYaw::Learned);
        assert!((nis - 0.25).abs() < 0.02, "{nis}");
        assert!((learned.x.m + 0.1).abs() < 0.01, "{}", learned.x.m);
        assert!(
            (learned.x.v - Vector3::new(2.0, 0.0, 0.0)).norm() < 1e-3,
            "{}",
            learned.x.v
        );
        let mut exact = level();
        let nis = update(&mut exact, &off, MountingYaw::Exact);
        assert!(nis > 90.0, "{nis}");
        assert_eq!(exact.x.m, 0.0);
        // Considered, the yaw's uncertainty explains the residual as well, and neither the yaw
        // nor its variance moves.
        let nis = update(&mut considered, &r, MountingYaw::Considered);
        assert!((nis - 0.25).abs() < 0.02, "{nis}");
        let (m, sigma_m) = considered.mounting_yaw();
        assert!(m == 0.0 && (sigma_m - 0.2).abs() < 1e-12, "{m} {sigma_m}");
    }

    #[test]
    fn a_point_behind_a_left_turn_moves_right_of_the_imu() {
        // Level, identity mounting, a pure yaw rate of 0.5 rad/s and no velocity: the axle
        // 1.5 m behind the IMU (r_b = (-1.5, 0, 0)) moves at omega x r = (0, -0.75, 0).
        let mut kf = turning();
        kf.x.q = UnitQuaternion::identity();
        kf.x.v = Vector3::zeros();
        kf.x.b_g = Vector3::zeros();
        kf.last.w = Vector3::new(0.0, 0.0, 0.5);
        let v = kf.point_velocity(&Matrix3::identity(), &Vector3::new(-1.5, 0.0, 0.0));
        assert!((v - Vector3::new(0.0, -0.75, 0.0)).norm() < 1e-12, "{v:?}");
    }

    #[test]
    fn no_lever_arm_is_the_body_velocity_update() {
        let (r_bs, residual) = (mounting(), Vector3::new(0.1, -0.2, 0.05));
        let sigma = Vector3::new(0.3, 0.1, 0.1);
        let mut a = turning();
        let mut b = turning();
        let nis_a = a.body_velocity_update(&r_bs, residual, sigma);
        let nis_b = b.point_velocity_update(
            &r_bs,
            &Vector3::zeros(),
            residual,
            sigma,
            Heading::Corrected,
            MountingYaw::Exact,
        );
        assert_eq!(nis_a, nis_b);
        assert_eq!(a.x, b.x);
        assert_eq!(a.cov, b.cov);
    }

    /// The second-order variance against a sampled one: attitude and velocity errors drawn
    /// from the filter's covariance, the exact body velocity less its first-order prediction.
    #[test]
    fn the_second_order_variance_is_the_sampled_one() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut kf = turning();
        kf.x.v = Vector3::new(12.0, -5.0, 0.3);
        let a = SMatrix::<f64, 6, 6>::from_fn(|i, j| ((3 * i + 5 * j) as f64).sin());
        let block = a * a.transpose() * 0.05 + SMatrix::<f64, 6, 6>::identity() * 0.01;
        // Velocity 1-sigmas of metres per second, attitude of about a hundredth of a radian.
        let s = SMatrix::<f64, 6, 6>::from_diagonal(&SVector::<f64, 6>::new(
            10.0, 10.0, 3.0, 0.01, 0.01, 0.02,
        ));
        let joint = s * block * s;
        kf.cov = Cov::identity() * 1e-6;
        for (i, r) in [V, V + 1, V + 2, TH, TH + 1, TH + 2].iter().enumerate() {
            for (j, c) in [V, V + 1, V + 2, TH, TH + 1, TH + 2].iter().enumerate() {
                kf.cov[(*r, *c)] = joint[(i, j)];
            }
        }
        let r_bs = mounting();
        let expected = kf.body_velocity_second_order_variance(&r_bs);
        let chol = joint.cholesky().unwrap().l();
        let h = kf.point_velocity_jacobian(&r_bs, &Vector3::zeros());
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let n = 200_000;
        let mut sum = Vector3::zeros();
        let mut sum_sq = Vector3::zeros();
        for _ in 0..n {
            let e = chol * SVector::<f64, 6>::from_fn(|_, _| StandardNormal.sample(&mut rng));
            let mut dx = VecN::zeros();
            dx.fixed_rows_mut::<6>(V).copy_from(&e);
            // The exact velocity's share of the velocity error less its first-order one (the
            // attitude error's own second-order term, `|v| dtheta^2 / 2`, is not this term's).
            let mut turned = kf.clone();
            let mut only_turn = dx;
            only_turn.fixed_rows_mut::<3>(V).fill(0.0);
            turned.inject(&only_turn);
            let mut x = turned.clone();
            x.x.v += e.fixed_rows::<3>(0);
            let rest = x.body_velocity(&r_bs)
                - turned.body_velocity(&r_bs)
                - h.fixed_columns::<3>(V) * e.fixed_rows::<3>(0);
            sum += rest;
            sum_sq += rest.component_mul(&rest);
        }
        let mean = sum / n as f64;
        let sampled = sum_sq / n as f64 - mean.component_mul(&mean);
        for k in 0..3 {
            let relative = (sampled[k] - expected[k]).abs() / expected[k];
            assert!(relative < 0.03, "{k}: {sampled} {expected}");
        }
    }
}
