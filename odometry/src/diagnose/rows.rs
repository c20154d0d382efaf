//! The residuals the diagnosis explains, one row each, with their noise and what every
//! candidate effect predicts for them per unit of its parameters.
//!
//! - Magnitude rows, one per rest: `r = |f| - g` (m/s^2), the specific force's magnitude
//!   against local gravity. With `u = f / |f|`, an accelerometer bias `b` (m/s^2, sensor axes)
//!   adds `u . b`, a scale error `s` (fraction per axis, `f = (I + diag(s)) f_true`) adds
//!   `g sum_i s_i u_i^2`, and a bias linear in temperature `c` (m/s^2/degC) adds
//!   `(T - T_ref) u . c`.
//! - Tilt rows, two per motion between rests: the gravity direction measured at the second
//!   rest against the one the gyro carried from the first, `e = u_carried x u_measured` (rad,
//!   sensor frame at the second rest), on two axes across gravity (about gravity a rest says
//!   nothing). A gyro error corrected by `omega_true = (I + N(p)) omega` leaves `-J p` in it,
//!   `J` its numerical derivative in `p` ([`Candidate::gyro_perturbation`]): a scale error
//!   (`N = diag(k)`, `k` fraction per axis), a cross-axis sensitivity (`N` symmetric with zero
//!   diagonal, `N_yz = N_zy = m_x`, `N_xz = N_zx = m_y`, `N_xy = N_yx = m_z`, fraction: the
//!   gyro's axes are not orthogonal) or a rotation of the gyro's axes against the
//!   accelerometer's (`N = [phi]x`, `phi` rad in the sensor frame: `omega_true = omega + phi x
//!   omega`). Together they are the gyro's full linear correction `C` of the calibration file.
//!   A motion during which the gyro clipped gives its rows a kind of their own; on them the
//!   saturation candidate adds to each clipped sample, on its clipped axis and with its sign,
//!   a rate `h` (rad/s per axis) the clip hid (`Evidence::carried`).
//!
//! - Velocity rows ([`Kind::Velocity`]) are formed apart (`super::velocity::all`), with the
//!   same design per candidate.
//!
//! Each row's `sigma` is what the samples' own noise predicts (white and low-pass
//! correlated, `evidence::mean_variance`; for tilt also the gyro's angle random walk and the
//! uncertainty of its bias, taken from the longest rest, over the motion); `floor` what the odometry's model already carries for
//! it (the configuration's accelerometer bias and residual scale 1-sigma, the gyro correction's
//! 1-sigma times the angle turned).

use nalgebra::{Matrix3, Vector3};

use super::evidence::{Evidence, Interval};
use crate::config::OdometryConfig;

/// A candidate effect the odometry's model lacks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Candidate {
    /// Accelerometer bias, m/s^2 per sensor axis.
    AccelBias,
    /// Accelerometer scale error, fraction per sensor axis.
    AccelScale,
    /// Accelerometer bias linear in die temperature, m/s^2/degC per sensor axis.
    AccelTempBias,
    /// Gyro scale error, fraction per sensor axis.
    GyroScale,
    /// Gyro cross-axis sensitivity (non-orthogonal axes), fraction per axis pair `yz, xz, xy`.
    GyroCrossAxis,
    /// Rotation of the gyro's axes against the accelerometer's, rad per sensor axis.
    GyroRotation,
    /// Gyro saturation: the rate each clipped sample hid beyond the range, rad/s per sensor
    /// axis (on the clipped rows only; no calibration term restores it).
    GyroSaturation,
    /// The accelerometer's lag behind the gyro, s (one parameter, the first; the sample
    /// stamped `t` holds the specific force at `t - lag`): seen in the velocity rows.
    AccelLag,
}

impl Candidate {
    /// Every candidate, in report order.
    pub const ALL: [Candidate; 8] = [
        Candidate::AccelBias,
        Candidate::AccelScale,
        Candidate::AccelTempBias,
        Candidate::GyroScale,
        Candidate::GyroCrossAxis,
        Candidate::GyroRotation,
        Candidate::GyroSaturation,
        Candidate::AccelLag,
    ];

    /// The candidate's name in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::AccelBias => "accel_bias",
            Self::AccelScale => "accel_scale",
            Self::AccelTempBias => "accel_temp_bias",
            Self::GyroScale => "gyro_scale",
            Self::GyroCrossAxis => "gyro_cross_axis",
            Self::GyroRotation => "gyro_rotation",
            Self::GyroSaturation => "gyro_saturation",
            Self::AccelLag => "accel_lag",
        }
    }

    /// How many of its three parameter slots it uses (the lag one, the others three).
    pub fn params(self) -> usize {
        if self == Self::AccelLag { 1 } else { 3 }
    }

    /// Whether a rerun can model it (every candidate but saturation: the lag through the
    /// rerun's samples, `offline --accel-lag-s`, the others through the calibration file).
    pub fn is_correctable(self) -> bool {
        self != Self::GyroSaturation
    }

    /// Whether it acts on the gyro (its rows are the tilt rows).
    pub fn is_gyro(self) -> bool {
        matches!(
            self,
            Self::GyroScale | Self::GyroCrossAxis | Self::GyroRotation
        )
    }

    /// For a gyro candidate, `N(p)` of `omega_true = (I + N(p)) omega` (module documentation);
    /// zero for the others.
    pub fn gyro_perturbation(self, p: &Vector3<f64>) -> Matrix3<f64> {
        match self {
            Self::GyroScale => Matrix3::from_diagonal(p),
            Self::GyroCrossAxis => Matrix3::new(
                0.0, p.z, p.y, //
                p.z, 0.0, p.x, //
                p.y, p.x, 0.0,
            ),
            Self::GyroRotation => p.cross_matrix(),
            _ => Matrix3::zeros(),
        }
    }

    /// The unit of its parameters.
    pub fn unit(self) -> &'static str {
        match self {
            Self::AccelBias => "m/s^2",
            Self::AccelScale | Self::GyroScale | Self::GyroCrossAxis => "",
            Self::AccelTempBias => "m/s^2/degC",
            Self::GyroRotation => "rad",
            Self::GyroSaturation => "rad/s",
            Self::AccelLag => "s",
        }
    }
}

/// Rows of one kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A rest's specific-force magnitude.
    Magnitude,
    /// A motion's tilt.
    Tilt,
    /// The tilt of a motion during which the gyro clipped.
    ClippedTilt,
    /// A motion's velocity change from rest to rest ([`super::velocity`]).
    Velocity,
}

/// One residual.
#[derive(Debug, Clone)]
pub struct Row {
    /// What it measures.
    pub kind: Kind,
    /// Rows that are left out together (one rest, one motion's tilt, one motion's velocity).
    pub group: usize,
    /// The residual (m/s^2 or rad).
    pub r: f64,
    /// Its 1-sigma from the samples' noise.
    pub sigma: f64,
    /// Its 1-sigma from what the model already carries.
    pub floor: f64,
    /// Per candidate in [`Candidate::ALL`] order, the residual each of its three parameters
    /// adds per unit (zero where the candidate does not act on the row).
    pub design: [Vector3<f64>; Candidate::ALL.len()],
}

/// Step of the numerical derivative of a tilt row in a gyro parameter.
pub(super) const GYRO_STEP: f64 = 1e-3;
/// Step of the numerical derivative of a tilt row in a hidden rate, rad/s.
const HIDDEN_STEP_RPS: f64 = 1e-2;

/// The rows of `evidence` for a run with configuration `config`; `t_ref_c` is the reference
/// temperature of the temperature candidate. Motions during which the gyro clipped give
/// [`Kind::ClippedTilt`] rows (their rotation was not all measured), the saturation
/// candidate's.
pub fn rows(evidence: &Evidence, config: &OdometryConfig, t_ref_c: f64) -> Vec<Row> {
    let g = config.gravity_mps2;
    let mut out = Vec::new();
    for (k, rest) in evidence.rests.iter().enumerate() {
        let f = rest.accel_mps2;
        let u = f / f.norm();
        let var = u.component_mul(&u).dot(&rest.accel_mean_var);
        let bias = Vector3::from(config.accel_bias_sigma_mps2);
        let floor2 = u.component_mul(&u).dot(&bias.component_mul(&bias))
            + (g * config.accel_residual_scale).powi(2);
        let dt = if rest.temp_c.is_finite() {
            rest.temp_c - t_ref_c
        } else {
            0.0
        };
        out.push(Row {
            kind: Kind::Magnitude,
            group: k,
            r: f.norm() - g,
            sigma: var.sqrt(),
            floor: floor2.sqrt(),
            design: [
                u,
                u.component_mul(&u) * g,
                u * dt,
                Vector3::zeros(),
                Vector3::zeros(),
                Vector3::zeros(),
                Vector3::zeros(),
                Vector3::zeros(),
            ],
        });
    }
    let groups = evidence.rests.len();
    for (j, interval) in evidence.intervals.iter().enumerate() {
        if interval.samples.len() >= 2 {
            out.extend(tilt_rows(evidence, config, interval, groups + j));
        }
    }
    out
}

/// The two tilt rows of `interval` (group `group`): [`Kind::ClippedTilt`] where the gyro
/// clipped in it.
fn tilt_rows(
    evidence: &Evidence,
    config: &OdometryConfig,
    interval: &Interval,
    group: usize,
) -> [Row; 2] {
    let g = config.gravity_mps2;
    let (a, b) = (
        &evidence.rests[interval.from],
        &evidence.rests[interval.from + 1],
    );
    let tilt = |n: &Matrix3<f64>, hidden: &Vector3<f64>| {
        let q = evidence.carried(interval, n, hidden);
        let carried = q.inverse_transform_vector(&a.accel_mps2.normalize());
        carried.cross(&b.accel_mps2.normalize())
    };
    let zero = Vector3::zeros();
    let e0 = tilt(&Matrix3::zeros(), &zero);
    let u = b.accel_mps2.normalize();
    let across1 = u
        .cross(&Vector3::x())
        .try_normalize(1e-3)
        .unwrap_or_else(|| u.cross(&Vector3::y()).normalize());
    let across2 = u.cross(&across1);
    let unit = |i: usize, step: f64| Vector3::from_fn(|j, _| if i == j { step } else { 0.0 });
    // Per candidate, the derivative of the tilt in each of its three parameters.
    let derivative = Candidate::ALL.map(|c| match c {
        _ if c.is_gyro() => std::array::from_fn(|i| {
            let n = c.gyro_perturbation(&unit(i, GYRO_STEP));
            (tilt(&n, &zero) - e0) / GYRO_STEP
        }),
        Candidate::GyroSaturation if interval.gyro_clipped > 0 => std::array::from_fn(|i| {
            (tilt(&Matrix3::zeros(), &unit(i, HIDDEN_STEP_RPS)) - e0) / HIDDEN_STEP_RPS
        }),
        _ => [Vector3::zeros(); 3],
    });
    let duration = evidence.samples[interval.samples.end - 1].t_s
        - evidence.samples[interval.samples.start].t_s;
    let angle = evidence.carried(interval, &Matrix3::zeros(), &zero).angle();
    let noise = &config.noise;
    let var = (a.accel_mean_var.sum() + b.accel_mean_var.sum()) / (3.0 * g * g)
        + noise.gyro_noise_density.powi(2) * duration
        + evidence.gyro_bias_var.sum() / 3.0 * duration * duration;
    let c = &config.gyro_correction_sigma;
    let scale_sigma = c[(0, 0)].max(c[(1, 1)]).max(c[(2, 2)]);
    [across1, across2].map(|axis| Row {
        kind: if interval.gyro_clipped > 0 {
            Kind::ClippedTilt
        } else {
            Kind::Tilt
        },
        group,
        r: e0.dot(&axis),
        sigma: var.sqrt(),
        floor: scale_sigma * angle,
        design: derivative.map(|d| Vector3::from_fn(|i, _| -d[i].dot(&axis))),
    })
}

#[cfg(test)]
mod tests {
    use approx::assert_relative_eq;

    use super::*;

    #[test]
    fn gyro_perturbations_follow_their_documented_conventions() {
        let (p, w) = (
            Vector3::new(0.01, -0.02, 0.03),
            Vector3::new(0.5, -1.0, 2.0),
        );
        let rotation = Candidate::GyroRotation.gyro_perturbation(&p);
        assert_relative_eq!(rotation * w, p.cross(&w), epsilon = 1e-15);
        let cross = Candidate::GyroCrossAxis.gyro_perturbation(&p);
        assert_relative_eq!(cross, cross.transpose());
        assert_eq!(cross.diagonal(), Vector3::zeros());
        // m_z couples x and y, m_y x and z, m_x y and z.
        assert_eq!(
            (cross[(0, 1)], cross[(0, 2)], cross[(1, 2)]),
            (p.z, p.y, p.x)
        );
        let scale = Candidate::GyroScale.gyro_perturbation(&p);
        assert_eq!(scale, Matrix3::from_diagonal(&p));
        assert_eq!(Candidate::AccelBias.gyro_perturbation(&p), Matrix3::zeros());
    }
}
