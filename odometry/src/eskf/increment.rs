//! The error-state transition, process noise and consider sensitivity accumulated over the
//! samples since the covariance was last propagated (standard IMU preintegration: the nominal
//! state integrates every sample, the covariance takes the samples' product at once; Forster et
//! al., "On-Manifold Preintegration for Real-Time Visual-Inertial Odometry", IEEE T-RO 2017,
//! section VI-A, accumulate the preintegrated measurements' noise the same way).
//!
//! Frames, units and the error state are those of [`super`]. One sample's transition `F` is
//! the identity but for `F_pv = dt I`, `F_vth = -R [f]x dt`, `F_vba = -R dt`,
//! `F_thth = Exp(-w dt)` and `F_thbg = -dt I`; its process noise `D` is diagonal, on the
//! velocity (`q_v`, (m/s)^2), attitude (`q_th`, rad^2) and bias (`q_ba`, `q_bg`) errors; the
//! consider parameters drive `B` (`-E_g w dt` on the attitude, `-R E_a (f - f_align) dt` on the
//! velocity). Over samples `1..K`:
//!
//! - the transition is the product `Phi = F_K ... F_1`. It keeps `F`'s shape: the identity
//!   on the velocity, bias and scale rows, `Phi_pv = (sum dt) I`, and dense 3 x 3 blocks
//!   `Phi_pth`, `Phi_pba`, `Phi_pbg`, `Phi_vth`, `Phi_vba`, `Phi_vbg`, `Phi_thth`, `Phi_thbg`;
//!   `Phi <- F Phi` is a handful of 3 x 3 products per sample;
//! - the noise `Q <- F Q F^T + D` is accumulated exactly on the position, velocity and
//!   attitude errors (a 9 x 9 symmetric matrix, six 3 x 3 blocks). The bias random walks
//!   are summed on their own blocks and their effect on the other errors within the
//!   interval `T` is left out (it enters from the next propagation on): on the velocity it is
//!   `q_ba T^3 / 3` against the white noise's `q_v T` kept, some 1e-8 of it over 10 ms with
//!   the MPU-9250's figures (`crate::stage::OdometryConfig::mpu9250`), and the largest term
//!   left out, the velocity/bias cross-covariance, is `q_ba T^2 / 2`;
//! - the sensitivity's increment `G <- F G + B` (zero at the start), non-zero on the
//!   position, velocity and attitude rows.
//!
//! The covariance then becomes `Phi P Phi^T + Q` and the sensitivity `Phi M + G`: the same,
//! to rounding, as `K` propagations of one sample each (tested below against dense products).

use super::{BA, BG, Cov, N, NC, P, TH, V};
use nalgebra::{Matrix3, SMatrix, Vector3};

/// Sensitivity of the error state to the consider parameters (as in [`super`]).
pub(super) type Sensitivity = SMatrix<f64, N, NC>;

/// One sample's transition and noise (module documentation).
#[derive(Debug, Clone, Copy)]
pub(super) struct Step {
    /// Sample interval, s.
    pub dt: f64,
    /// `F_vth`.
    pub v_th: Matrix3<f64>,
    /// `F_vba`.
    pub v_ba: Matrix3<f64>,
    /// `F_thth`.
    pub th_th: Matrix3<f64>,
    /// Velocity, attitude, accelerometer-bias and gyro-bias noise variances added per axis.
    pub q_v: f64,
    pub q_th: f64,
    pub q_ba: f64,
    pub q_bg: f64,
    /// Bias-corrected angular rate (rad/s) and change of specific force since alignment
    /// (m/s^2), sensor frame, and the sensor-to-navigation rotation, at the interval's
    /// midpoint: what the consider parameters act on.
    pub w: Vector3<f64>,
    pub df: Vector3<f64>,
    pub r: Matrix3<f64>,
}

/// The accumulated transition, noise and sensitivity increment (module documentation).
#[derive(Debug, Clone, Copy)]
pub(super) struct Increment {
    /// Samples accumulated.
    steps: u32,
    /// Their total interval, s (`Phi_pv = t I`).
    t: f64,
    p_th: Matrix3<f64>,
    p_ba: Matrix3<f64>,
    p_bg: Matrix3<f64>,
    v_th: Matrix3<f64>,
    v_ba: Matrix3<f64>,
    v_bg: Matrix3<f64>,
    th_th: Matrix3<f64>,
    th_bg: Matrix3<f64>,
    /// The noise's position, velocity and attitude blocks (upper triangle).
    q_pp: Matrix3<f64>,
    q_pv: Matrix3<f64>,
    q_pth: Matrix3<f64>,
    q_vv: Matrix3<f64>,
    q_vth: Matrix3<f64>,
    q_thth: Matrix3<f64>,
    /// Summed bias random-walk variances per axis.
    q_ba: f64,
    q_bg: f64,
    /// `G`'s position and velocity rows, and its attitude rows (only the gyro's 9 columns).
    g_p: SMatrix<f64, 3, NC>,
    g_v: SMatrix<f64, 3, NC>,
    g_th: SMatrix<f64, 3, 9>,
}

impl Default for Increment {
    /// No samples: the identity transition, no noise.
    fn default() -> Self {
        let z = Matrix3::zeros();
        Self {
            steps: 0,
            t: 0.0,
            p_th: z,
            p_ba: z,
            p_bg: z,
            v_th: z,
            v_ba: z,
            v_bg: z,
            th_th: Matrix3::identity(),
            th_bg: z,
            q_pp: z,
            q_pv: z,
            q_pth: z,
            q_vv: z,
            q_vth: z,
            q_thth: z,
            q_ba: 0.0,
            q_bg: 0.0,
            g_p: SMatrix::zeros(),
            g_v: SMatrix::zeros(),
            g_th: SMatrix::zeros(),
        }
    }
}

/// The 16 x 3 column block of `m` starting at column `c`.
#[inline]
fn cols<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>, c: usize) -> SMatrix<f64, R, 3> {
    SMatrix::from_fn(|i, j| m[(i, c + j)])
}

/// The 3-row block of `m` starting at row `r`.
#[inline]
fn rows<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>, r: usize) -> SMatrix<f64, 3, C> {
    SMatrix::from_fn(|i, j| m[(r + i, j)])
}

impl Increment {
    /// Samples accumulated since the last propagation.
    pub fn steps(&self) -> u32 {
        self.steps
    }

    /// Their total interval, s.
    pub fn interval_s(&self) -> f64 {
        self.t
    }

    /// The accumulated noise's position and velocity variances (the diagonals of `Q_pp`
    /// and `Q_vv`), m^2 and (m/s)^2.
    pub fn noise_variance(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.q_pp.diagonal(), self.q_vv.diagonal())
    }

    /// Appends one sample: `Phi <- F Phi`, `Q <- F Q F^T + D`, `G <- F G + B`, each new
    /// block from the old ones.
    #[inline]
    pub fn push(&mut self, s: &Step) {
        let dt = s.dt;
        let (a, c) = (&s.v_th, &s.th_th);
        // Noise first: it reads the blocks before this sample.
        let a_thth = a * self.q_thth;
        let pth_dt = self.q_pth + self.q_vth * dt;
        let vth_a = self.q_vth + a_thth;
        let a_vth_t = a * self.q_vth.transpose();
        let q_pv = self.q_pv + self.q_vv * dt + pth_dt * a.transpose();
        self.q_pp += (self.q_pv + self.q_pv.transpose()) * dt + self.q_vv * (dt * dt);
        self.q_vv += a_vth_t + a_vth_t.transpose() + a_thth * a.transpose();
        self.q_pv = q_pv;
        self.q_pth = pth_dt * c.transpose();
        self.q_vth = vth_a * c.transpose();
        self.q_thth = c * self.q_thth * c.transpose();
        for i in 0..3 {
            self.q_vv[(i, i)] += s.q_v;
            self.q_thth[(i, i)] += s.q_th;
        }
        self.q_ba += s.q_ba;
        self.q_bg += s.q_bg;

        // Sensitivity: the position row takes the old velocity row, the velocity row the old
        // attitude row.
        self.g_p += self.g_v * dt;
        let a_gth = a * self.g_th;
        for k in 0..9 {
            for i in 0..3 {
                self.g_v[(i, k)] += a_gth[(i, k)];
            }
        }
        self.g_th = c * self.g_th;
        for j in 0..3 {
            for k in 0..3 {
                self.g_th[(j, 3 * j + k)] -= s.w[k] * dt;
                for i in 0..3 {
                    self.g_v[(i, 9 + 3 * j + k)] -= s.r[(i, j)] * s.df[k] * dt;
                }
            }
        }

        // Transition, in the same order.
        self.p_th += self.v_th * dt;
        self.p_ba += self.v_ba * dt;
        self.p_bg += self.v_bg * dt;
        self.t += dt;
        self.v_th += a * self.th_th;
        self.v_ba += s.v_ba;
        self.v_bg += a * self.th_bg;
        self.th_th = c * self.th_th;
        self.th_bg = c * self.th_bg;
        for i in 0..3 {
            self.th_bg[(i, i)] -= dt;
        }
        self.steps += 1;
    }

    /// `P <- Phi P Phi^T + Q` and `M <- Phi M + G`; the increment is then empty again.
    pub fn apply(&mut self, cov: &mut Cov, sens: &mut Sensitivity) {
        self.apply_cov(cov);
        self.apply_sens(sens);
        *self = Self::default();
    }

    /// `W = P Phi^T` changes only the position, velocity and attitude columns; `Phi W` then
    /// changes their rows, and by symmetry only the 16 x 9 block of those columns is computed.
    fn apply_cov(&self, cov: &mut Cov) {
        let (cp, cv, cth, cba, cbg) = (
            cols(cov, P),
            cols(cov, V),
            cols(cov, TH),
            cols(cov, BA),
            cols(cov, BG),
        );
        let wp = cp
            + cv * self.t
            + cth * self.p_th.transpose()
            + cba * self.p_ba.transpose()
            + cbg * self.p_bg.transpose();
        let wv = cv
            + cth * self.v_th.transpose()
            + cba * self.v_ba.transpose()
            + cbg * self.v_bg.transpose();
        let wth = cth * self.th_th.transpose() + cbg * self.th_bg.transpose();
        // The rows of `W`'s 16 x 9 block, by error.
        let mut w = SMatrix::<f64, N, 9>::zeros();
        w.fixed_columns_mut::<3>(0).copy_from(&wp);
        w.fixed_columns_mut::<3>(3).copy_from(&wv);
        w.fixed_columns_mut::<3>(6).copy_from(&wth);
        let (rp, rv, rth, rba, rbg) = (
            rows(&w, P),
            rows(&w, V),
            rows(&w, TH),
            rows(&w, BA),
            rows(&w, BG),
        );
        let np = rp + rv * self.t + self.p_th * rth + self.p_ba * rba + self.p_bg * rbg;
        let nv = rv + self.v_th * rth + self.v_ba * rba + self.v_bg * rbg;
        let nth = self.th_th * rth + self.th_bg * rbg;
        let q = [
            [self.q_pp, self.q_pv, self.q_pth],
            [self.q_pv.transpose(), self.q_vv, self.q_vth],
            [self.q_pth.transpose(), self.q_vth.transpose(), self.q_thth],
        ];
        let new = [np, nv, nth];
        for (bi, rows) in new.iter().enumerate() {
            for i in 0..3 {
                for bj in 0..3 {
                    for j in 0..3 {
                        cov[(3 * bi + i, 3 * bj + j)] = rows[(i, 3 * bj + j)] + q[bi][bj][(i, j)];
                    }
                }
            }
        }
        for j in 0..9 {
            for i in 9..N {
                cov[(i, j)] = w[(i, j)];
                cov[(j, i)] = w[(i, j)];
            }
        }
        for i in 0..3 {
            cov[(BA + i, BA + i)] += self.q_ba;
            cov[(BG + i, BG + i)] += self.q_bg;
        }
    }

    /// `M <- Phi M + G` on the position, velocity and attitude rows.
    fn apply_sens(&self, m: &mut Sensitivity) {
        let (mp, mv, mth, mba, mbg) = (
            rows(m, P),
            rows(m, V),
            rows(m, TH),
            rows(m, BA),
            rows(m, BG),
        );
        let np = mp + mv * self.t + self.p_th * mth + self.p_ba * mba + self.p_bg * mbg + self.g_p;
        let nv = mv + self.v_th * mth + self.v_ba * mba + self.v_bg * mbg + self.g_v;
        let mut nth = self.th_th * mth + self.th_bg * mbg;
        for i in 0..3 {
            for k in 0..9 {
                nth[(i, k)] += self.g_th[(i, k)];
            }
        }
        for (r, block) in [(P, np), (V, nv), (TH, nth)] {
            for i in 0..3 {
                for j in 0..NC {
                    m[(r + i, j)] = block[(i, j)];
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::skew;
    use super::*;
    use nalgebra::UnitQuaternion;

    /// A dense, well-conditioned covariance with every entry non-zero.
    fn full_cov() -> Cov {
        let a = Cov::from_fn(|i, j| ((7 * i + 3 * j) as f64).sin());
        a * a.transpose() * 1e-3 + Cov::identity() * 1e-4
    }

    /// Sample `k` of a turning, accelerating motion at `dt`.
    fn step(k: usize, dt: f64, bias_noise: bool) -> Step {
        let t = k as f64 * dt;
        let r = UnitQuaternion::from_scaled_axis(Vector3::new(0.1, -0.2, 0.8 * t))
            .to_rotation_matrix()
            .into_inner();
        let f = Vector3::new(1.0 + (3.0 * t).sin(), 0.5 * (2.0 * t).cos(), 9.81);
        let w = Vector3::new(0.3 * (5.0 * t).sin(), -0.2, 0.8 + 0.4 * t);
        let b = if bias_noise { 1.0 } else { 0.0 };
        Step {
            dt,
            v_th: -r * skew(&f) * dt,
            v_ba: -r * dt,
            th_th: UnitQuaternion::from_scaled_axis(-w * dt)
                .to_rotation_matrix()
                .into_inner(),
            q_v: (3e-3f64).powi(2) * dt,
            q_th: (2e-4f64).powi(2) * dt,
            q_ba: b * (1e-4f64).powi(2) * dt,
            q_bg: b * (1e-6f64).powi(2) * dt,
            w,
            df: f - Vector3::new(0.0, 0.0, 9.81),
            r,
        }
    }

    /// One sample's dense 16 x 16 transition, noise and consider input.
    fn dense(s: &Step) -> (Cov, Cov, Sensitivity) {
        let mut f = Cov::identity();
        f.fixed_view_mut::<3, 3>(P, V)
            .copy_from(&(Matrix3::identity() * s.dt));
        f.fixed_view_mut::<3, 3>(V, TH).copy_from(&s.v_th);
        f.fixed_view_mut::<3, 3>(V, BA).copy_from(&s.v_ba);
        f.fixed_view_mut::<3, 3>(TH, TH).copy_from(&s.th_th);
        f.fixed_view_mut::<3, 3>(TH, BG)
            .copy_from(&(-Matrix3::identity() * s.dt));
        let mut d = Cov::zeros();
        for i in 0..3 {
            d[(V + i, V + i)] = s.q_v;
            d[(TH + i, TH + i)] = s.q_th;
            d[(BA + i, BA + i)] = s.q_ba;
            d[(BG + i, BG + i)] = s.q_bg;
        }
        let mut b = Sensitivity::zeros();
        for j in 0..3 {
            for k in 0..3 {
                b[(TH + j, 3 * j + k)] = -s.w[k] * s.dt;
                for i in 0..3 {
                    b[(V + i, 9 + 3 * j + k)] = -s.r[(i, j)] * s.df[k] * s.dt;
                }
            }
        }
        (f, d, b)
    }

    /// `K` single-sample propagations with dense products against one propagation of the
    /// accumulated increment, over 0.1 s of a turning motion. Without bias noise they agree
    /// to rounding (1e-12 of the largest entry); with it they differ by the bias noise's
    /// effect within the interval, at most about `q_ba T^2 / 2` (module documentation).
    #[test]
    fn accumulated_increment_is_the_product_of_single_steps() {
        let dt = 1e-3;
        let k = 100;
        for bias_noise in [false, true] {
            let (mut p_dense, mut m_dense) = (
                full_cov(),
                Sensitivity::from_fn(|i, j| ((i * 5 + j) as f64).cos()),
            );
            let (mut p_inc, mut m_inc) = (p_dense, m_dense);
            let mut inc = Increment::default();
            let mut q_b = 0.0f64;
            for i in 0..k {
                let s = step(i, dt, bias_noise);
                let (f, d, b) = dense(&s);
                p_dense = f * p_dense * f.transpose() + d;
                m_dense = f * m_dense + b;
                inc.push(&s);
                q_b = q_b.max(s.q_ba / dt);
            }
            assert_eq!(inc.steps(), k as u32);
            inc.apply(&mut p_inc, &mut m_inc);
            assert_eq!(inc.steps(), 0);
            let t = k as f64 * dt;
            let tol = if bias_noise {
                q_b * t * t + 1e-12
            } else {
                1e-12
            };
            let scale = p_dense.abs().max();
            assert!(
                (p_inc - p_dense).abs().max() <= tol * scale.max(1.0),
                "covariance differs by {:e} (tolerance {tol:e})",
                (p_inc - p_dense).abs().max()
            );
            let m_scale = m_dense.abs().max();
            assert!(
                (m_inc - m_dense).abs().max() <= 1e-12 * m_scale,
                "sensitivity differs by {:e}",
                (m_inc - m_dense).abs().max()
            );
            // The increment covers what the samples did: a non-trivial change.
            assert!((p_dense - full_cov()).abs().max() > 1e-6);
        }
    }
}
