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
//!   the MPU-9250's figures (`crate::config::OdometryConfig::mpu9250`), and the largest term
//!   left out, the velocity/bias cross-covariance, is `q_ba T^2 / 2`;
//! - the sensitivity's increment `G <- F G + B` (zero at the start), non-zero on the
//!   position, velocity and attitude rows.
//!
//! The covariance then becomes `Phi P Phi^T + Q` and the sensitivity `Phi M + G`: the same,
//! to rounding, as `K` propagations of one sample each (tested below against dense products).

use super::{BA, BG, Cov, N, NC, P, TH, V};
use nalgebra::{Matrix3, SMatrix, Vector3};

/// Sensitivity of the error state to the consider parameters (as in [`super`]), transposed:
/// `M^T`, one column per error-state component.
pub(super) type Sensitivity = SMatrix<f64, NC, N>;

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
    /// The noise's position, velocity and attitude blocks (upper triangle). The attitude's
    /// is `q_th I`: the attitude noise is isotropic, and each sample's `F_thth` a rotation.
    q_pp: Matrix3<f64>,
    q_pv: Matrix3<f64>,
    q_pth: Matrix3<f64>,
    q_vv: Matrix3<f64>,
    q_vth: Matrix3<f64>,
    q_th: f64,
    /// Summed bias random-walk variances per axis.
    q_ba: f64,
    q_bg: f64,
    /// `G`'s position and velocity rows; its attitude rows (only the gyro's 9 columns are
    /// non-zero) are `Phi_thth S`, `S` the sum of `Phi_thth^T B_th` over the samples (each
    /// sample's `F_thth` being a rotation, `G_th <- F_thth G_th + B_th` keeps that form).
    g_p: SMatrix<f64, 3, NC>,
    g_v: SMatrix<f64, 3, NC>,
    s_th: SMatrix<f64, 3, 9>,
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
            q_th: 0.0,
            q_ba: 0.0,
            q_bg: 0.0,
            g_p: SMatrix::zeros(),
            g_v: SMatrix::zeros(),
            s_th: SMatrix::zeros(),
        }
    }
}

/// `a b`, for the small fixed sizes here: nalgebra's general product runs its generic
/// loops, this one unrolls (a sample's accumulation took 15 % less time with it).
#[inline(always)]
fn mul<const R: usize, const K: usize, const C: usize>(
    a: &SMatrix<f64, R, K>,
    b: &SMatrix<f64, K, C>,
) -> SMatrix<f64, R, C> {
    let mut out = SMatrix::<f64, R, C>::zeros();
    for j in 0..C {
        for k in 0..K {
            let bkj = b[(k, j)];
            for i in 0..R {
                out[(i, j)] += a[(i, k)] * bkj;
            }
        }
    }
    out
}

/// `a b^T`, as [`mul`].
#[inline(always)]
fn mul_t(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Matrix3<f64> {
    mul(a, &b.transpose())
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
        // Noise first: it reads the blocks before this sample. `Q_thth` stays `q_th I`.
        let q_th = self.q_th;
        let pth_dt = self.q_pth + self.q_vth * dt;
        let vth_a = self.q_vth + a * q_th;
        let a_vth_t = mul_t(a, &self.q_vth);
        let q_pv = self.q_pv + self.q_vv * dt + mul_t(&pth_dt, a);
        self.q_pp += (self.q_pv + self.q_pv.transpose()) * dt + self.q_vv * (dt * dt);
        self.q_vv += a_vth_t + a_vth_t.transpose() + mul_t(a, a) * q_th;
        self.q_pv = q_pv;
        self.q_pth = mul_t(&pth_dt, c);
        self.q_vth = mul_t(&vth_a, c);
        self.q_th += s.q_th;
        for i in 0..3 {
            self.q_vv[(i, i)] += s.q_v;
        }
        self.q_ba += s.q_ba;
        self.q_bg += s.q_bg;

        // `F_vth Phi_thth`: the velocity row's change, of the transition and of `G`.
        let a_psi = mul(a, &self.th_th);
        // Sensitivity: the position row takes the old velocity row, the velocity row the old
        // attitude row (`Phi_thth S`).
        self.g_p += self.g_v * dt;
        let a_gth = mul(&a_psi, &self.s_th);
        for k in 0..9 {
            for i in 0..3 {
                self.g_v[(i, k)] += a_gth[(i, k)];
            }
        }
        for j in 0..3 {
            for k in 0..3 {
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
        self.v_th += a_psi;
        self.v_ba += s.v_ba;
        self.v_bg += mul(a, &self.th_bg);
        self.th_th = mul(c, &self.th_th);
        self.th_bg = mul(c, &self.th_bg);
        for i in 0..3 {
            self.th_bg[(i, i)] -= dt;
        }
        // `S += Phi_thth^T B_th` with the new `Phi_thth`: column `3 r + k` takes
        // `-dt w_k` times `Phi_thth`'s row `r`.
        for r in 0..3 {
            for k in 0..3 {
                let f = -dt * s.w[k];
                for i in 0..3 {
                    self.s_th[(i, 3 * r + k)] += f * self.th_th[(r, i)];
                }
            }
        }
        self.steps += 1;
    }

    /// `P <- Phi P Phi^T + Q` and `M <- Phi M + G`; the increment is then empty again.
    pub fn apply(&mut self, cov: &mut Cov, sens: &mut Sensitivity) {
        self.apply_cov(cov);
        self.apply_sens(sens);
        *self = Self::default();
    }

    /// `Phi`'s position, velocity and attitude rows, dense (its other rows are the identity's).
    fn top_rows(&self) -> [[f64; N]; 9] {
        let mut phi = [[0.0; N]; 9];
        let blocks: [(usize, usize, &Matrix3<f64>); 8] = [
            (P, TH, &self.p_th),
            (P, BA, &self.p_ba),
            (P, BG, &self.p_bg),
            (V, TH, &self.v_th),
            (V, BA, &self.v_ba),
            (V, BG, &self.v_bg),
            (TH, TH, &self.th_th),
            (TH, BG, &self.th_bg),
        ];
        for (r, c, m) in blocks {
            for i in 0..3 {
                for j in 0..3 {
                    phi[r + i][c + j] = m[(i, j)];
                }
            }
        }
        for i in 0..3 {
            phi[P + i][P + i] = 1.0;
            phi[P + i][V + i] = self.t;
            phi[V + i][V + i] = 1.0;
        }
        phi
    }

    /// `P <- Phi P Phi^T + Q`: `W = P Phi^T` changes only the position, velocity and attitude
    /// columns, `Phi W` then only their rows, and by symmetry only the 9 x 9 block of both and
    /// the 16 x 9 block of those columns are computed.
    fn apply_cov(&self, cov: &mut Cov) {
        let phi = self.top_rows();
        let w = times_phi_t::<N>(&phi, cov.as_slice());
        // `(Phi W)[:, j] = sum_c W[c, j] Phi[:, c]`, on `Phi`'s non-zero rows of column `c`.
        let mut top = [[0.0; 9]; 9];
        for (tj, wj) in top.iter_mut().zip(&w) {
            for (c, &f) in wj.iter().enumerate() {
                for i in 0..PHI_ROWS[c / 3] {
                    tj[i] += f * phi[i][c];
                }
            }
        }
        let q = [
            [self.q_pp, self.q_pv, self.q_pth],
            [self.q_pv.transpose(), self.q_vv, self.q_vth],
            [
                self.q_pth.transpose(),
                self.q_vth.transpose(),
                Matrix3::identity() * self.q_th,
            ],
        ];
        for (j, col) in top.iter().enumerate() {
            for (i, v) in col.iter().enumerate() {
                cov[(i, j)] = v + q[i / 3][j / 3][(i % 3, j % 3)];
            }
        }
        for (j, wj) in w.iter().enumerate() {
            for (r, &v) in wj.iter().enumerate().skip(9) {
                cov[(r, j)] = v;
                cov[(j, r)] = v;
            }
        }
        for i in 0..3 {
            cov[(BA + i, BA + i)] += self.q_ba;
            cov[(BG + i, BG + i)] += self.q_bg;
        }
    }

    /// `M <- Phi M + G` on the position, velocity and attitude rows: `M^T <- M^T Phi^T + G^T`
    /// on those columns of the transposed storage.
    fn apply_sens(&self, m: &mut Sensitivity) {
        let phi = self.top_rows();
        let new = times_phi_t::<NC>(&phi, m.as_slice());
        let g_th = mul(&self.th_th, &self.s_th);
        for (j, col) in new.iter().enumerate() {
            for (k, v) in col.iter().enumerate() {
                let g = match j {
                    0..3 => self.g_p[(j, k)],
                    3..6 => self.g_v[(j - 3, k)],
                    _ if k < 9 => g_th[(j - 6, k)],
                    _ => 0.0,
                };
                m[(k, j)] = v + g;
            }
        }
    }
}

/// How many of `Phi`'s top 9 rows can be non-zero in the columns of each error (position,
/// velocity, attitude, the biases, the scale; module documentation): rows `0..PHI_ROWS[c / 3]`
/// of column `c`.
const PHI_ROWS: [usize; 6] = [3, 6, 9, 6, 9, 0];

/// `X Phi^T`'s first 9 columns for the column-major `R x 16` matrix `x`: column `j` is
/// `sum_c Phi[j, c] X[:, c]`, sums of `X`'s contiguous columns over `Phi`'s non-zero entries.
fn times_phi_t<const R: usize>(phi: &[[f64; N]; 9], x: &[f64]) -> [[f64; R]; 9] {
    let mut w = [[0.0; R]; 9];
    for (wj, phi_j) in w.iter_mut().zip(phi) {
        for (c, &f) in phi_j.iter().enumerate() {
            if f != 0.0 {
                for (y, x) in wj.iter_mut().zip(&x[c * R..(c + 1) * R]) {
                    *y += f * x;
                }
            }
        }
    }
    w
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
    fn dense(s: &Step) -> (Cov, Cov, SMatrix<f64, N, NC>) {
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
        let mut b = SMatrix::<f64, N, NC>::zeros();
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
                SMatrix::<f64, N, NC>::from_fn(|i, j| ((i * 5 + j) as f64).cos()),
            );
            let (mut p_inc, mut m_inc) = (p_dense, m_dense.transpose());
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
                (m_inc.transpose() - m_dense).abs().max() <= 1e-12 * m_scale,
                "sensitivity differs by {:e}",
                (m_inc.transpose() - m_dense).abs().max()
            );
            // The increment covers what the samples did: a non-trivial change.
            assert!((p_dense - full_cov()).abs().max() > 1e-6);
        }
    }
}
