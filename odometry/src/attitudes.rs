//! The attitudes an accelerometer rested at, and the per-axis bias and scale they determine.
//!
//! At rest the accelerometer reads gravity alone: `f = S g_s + b` (sensor frame, `g_s` the
//! gravity direction in the sensor frame times local `g`). One attitude gives `|f| - g`, one
//! number. Rests at attitudes that put gravity along different sensor axes give more: the
//! six-position calibration's constraint `|S^-1 (f - b)| = g`, which the label-free fit of
//! `calibrate_fit::labelfree` solves for 3 biases and the 6 entries of an upper-triangular
//! `S^-1` once there are at least 9 well-spread attitudes (it refuses fewer, or attitudes in
//! one plane or a narrow cone: its Jacobian's condition number above
//! `calibrate_fit::labelfree::MAX_CONDITION`). The fit is reused here, unchanged.
//!
//! [`RestAttitudes`] gathers the rest samples (corrected specific force, m/s^2, sensor frame)
//! into at most [`CAPACITY`] attitude bins, a sample joining the bin whose mean direction is
//! within `calibrate_fit::labelfree::DISTINCT_ANGLE_DEG` of its own: a fixed array, no
//! allocation per sample (the live stage gathers them too). A bin of at least
//! [`MIN_SAMPLES`] samples is one pose of the fit. [`RestAttitudes::fit`] (allocates; once,
//! after a pass) returns the bias and the diagonal of `S` with their 1-sigma from the fit's
//! covariance (residual-scaled: the scatter of the poses' magnitudes about `g`, which holds
//! rests that were not perfectly still), or why it cannot.
//!
//! Units: the fit works in g (`f / g`); [`AttitudeFit`] reports the bias in m/s^2 and the
//! scale as a fraction (`S_ii - 1`: `+0.04` reads 4 % high), both in the frame of the samples
//! the stage corrected.

use calibrate_fit::fit::{Pose, Weighting};
use calibrate_fit::labelfree::{
    DISTINCT_ANGLE_DEG, LabelFreeError, MIN_POSES, distinct_orientations, fit_label_free,
};
use nalgebra::Vector3;

/// Most attitude bins gathered; samples at a further attitude are counted in
/// [`RestAttitudes::missed`].
pub const CAPACITY: usize = 48;

/// Fewest rest samples a bin needs to count as a pose.
pub const MIN_SAMPLES: u32 = 10;

/// Smallest angle, degrees, between two rest attitudes for the bias across gravity to count as
/// observed ([`RestAttitudes::spread_deg`]): below it the alignment's tilt and that bias read
/// the same (`crate::uncalibrated`).
pub const OBSERVED_SPREAD_DEG: f64 = 20.0;

/// One attitude: sums of its samples, m/s^2.
#[derive(Debug, Clone, Copy, Default)]
struct Bin {
    sum: Vector3<f64>,
    sum_sq: Vector3<f64>,
    n: u32,
    /// Unit vector of the mean.
    dir: Vector3<f64>,
}

/// Rest samples gathered by attitude (see the module documentation).
#[derive(Debug, Clone)]
pub struct RestAttitudes {
    bins: [Bin; CAPACITY],
    len: usize,
    missed: u64,
    cos_max: f64,
}

impl Default for RestAttitudes {
    fn default() -> Self {
        Self {
            bins: [Bin::default(); CAPACITY],
            len: 0,
            missed: 0,
            cos_max: DISTINCT_ANGLE_DEG.to_radians().cos(),
        }
    }
}

/// The per-axis accelerometer error several rest attitudes determined.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct AttitudeFit {
    /// Bias, m/s^2, sensor frame.
    pub bias_mps2: [f64; 3],
    /// Its 1-sigma, m/s^2.
    pub bias_sigma_mps2: [f64; 3],
    /// Scale error of each axis, `S_ii - 1`, fraction.
    pub scale: [f64; 3],
    /// Its 1-sigma, fraction.
    pub scale_sigma: [f64; 3],
    /// Poses (attitudes of at least [`MIN_SAMPLES`] samples) fitted.
    pub poses: usize,
    /// Condition number of the fit's Jacobian.
    pub condition: f64,
}

impl RestAttitudes {
    /// Adds one rest sample's specific force `f` (m/s^2, sensor frame). No allocation.
    #[inline]
    pub fn push(&mut self, f: &Vector3<f64>) {
        let Some(u) = f.try_normalize(1e-9) else {
            return;
        };
        let cos_max = self.cos_max;
        let bin = match self.bins[..self.len]
            .iter()
            .position(|b| b.dir.dot(&u) >= cos_max)
        {
            Some(i) => i,
            None if self.len < CAPACITY => {
                self.len += 1;
                self.len - 1
            }
            None => {
                self.missed += 1;
                return;
            }
        };
        let b = &mut self.bins[bin];
        b.sum += f;
        b.sum_sq += f.component_mul(f);
        b.n += 1;
        b.dir = b.sum.normalize();
    }

    /// Rest samples at an attitude beyond the [`CAPACITY`] bins, not gathered.
    pub fn missed(&self) -> u64 {
        self.missed
    }

    fn full_bins(&self) -> impl Iterator<Item = &Bin> {
        self.bins[..self.len].iter().filter(|b| b.n >= MIN_SAMPLES)
    }

    /// The poses (bins of at least [`MIN_SAMPLES`]), in g for gravity `g` (m/s^2).
    pub fn poses(&self, g: f64) -> Vec<Pose> {
        self.full_bins()
            .map(|b| {
                let n = f64::from(b.n);
                let mean = b.sum / n;
                let var = (b.sum_sq / n - mean.component_mul(&mean)).map(|v| v.max(0.0));
                Pose {
                    truth_g: Vector3::zeros(),
                    mean_g: mean / g,
                    std_g: var.map(f64::sqrt) / g,
                    n: Some(b.n as usize),
                }
            })
            .collect()
    }

    /// Number of poses (bins of at least [`MIN_SAMPLES`]).
    pub fn poses_count(&self) -> usize {
        self.full_bins().count()
    }

    /// Largest angle between two poses' directions, degrees (0 with fewer than two).
    pub fn spread_deg(&self) -> f64 {
        let mut min_cos = 1.0_f64;
        for (i, a) in self.full_bins().enumerate() {
            for b in self.full_bins().skip(i + 1) {
                min_cos = min_cos.min(a.dir.dot(&b.dir));
            }
        }
        min_cos.clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// Whether a second attitude at least [`OBSERVED_SPREAD_DEG`] from another was seen.
    pub fn observed_across_gravity(&self) -> bool {
        self.spread_deg() >= OBSERVED_SPREAD_DEG
    }

    /// The label-free fit of the poses for gravity `g` (m/s^2), or why there is none.
    pub fn fit(&self, g: f64) -> Result<AttitudeFit, LabelFreeError> {
        let poses = self.poses(g);
        if distinct_orientations(&poses) < MIN_POSES {
            return Err(LabelFreeError::TooFewPoses {
                poses: poses.len(),
                distinct: distinct_orientations(&poses),
            });
        }
        let fit = fit_label_free(&poses, Weighting::Unweighted)?;
        let sigma = |k: usize| fit.covariance[(k, k)].max(0.0).sqrt();
        let idx = |i: usize| calibrate::model::scale_index(i, i);
        let b = fit.model.bias_g();
        let s = fit.model.scale();
        Ok(AttitudeFit {
            bias_mps2: [b.x * g, b.y * g, b.z * g],
            bias_sigma_mps2: [sigma(0) * g, sigma(1) * g, sigma(2) * g],
            scale: [s[(0, 0)] - 1.0, s[(1, 1)] - 1.0, s[(2, 2)] - 1.0],
            scale_sigma: [sigma(idx(0)), sigma(idx(1)), sigma(idx(2))],
            poses: poses.len(),
            condition: fit.condition,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, UnitQuaternion};

    const G: f64 = 9.81;

    /// Rests at `n` attitudes spread over the sphere (a Fibonacci lattice), each `samples`
    /// long, read through `S = diag(1 + scale)` and bias `bias` (m/s^2).
    fn rests(n: usize, samples: u32, scale: Vector3<f64>, bias: Vector3<f64>) -> RestAttitudes {
        let s = Matrix3::from_diagonal(&scale.add_scalar(1.0));
        let mut r = RestAttitudes::default();
        for k in 0..n {
            let z = 1.0 - 2.0 * (k as f64 + 0.5) / n as f64;
            let phi = k as f64 * 2.399_963;
            let rho = (1.0 - z * z).sqrt();
            let up = Vector3::new(rho * phi.cos(), rho * phi.sin(), z);
            for j in 0..samples {
                // A little still-noise: a slow wobble of 0.05 degrees.
                let wobble =
                    UnitQuaternion::from_scaled_axis(Vector3::x() * 1e-3 * (j as f64).sin());
                r.push(&(s * (wobble * up) * G + bias));
            }
        }
        r
    }

    #[test]
    fn rests_at_many_attitudes_give_the_per_axis_scale_and_bias() {
        let scale = Vector3::new(0.04, -0.03, 0.02);
        let bias = Vector3::new(1.47, -0.5, 0.9);
        let r = rests(14, 50, scale, bias);
        assert!(r.observed_across_gravity());
        let fit = r.fit(G).expect("14 spread attitudes");
        assert_eq!(fit.poses, 14);
        for i in 0..3 {
            assert!((fit.scale[i] - scale[i]).abs() < 2e-3, "{fit:?}");
            assert!((fit.bias_mps2[i] - bias[i]).abs() < 0.02, "{fit:?}");
        }
    }

    #[test]
    fn one_attitude_gives_no_fit_and_no_observed_spread() {
        let mut r = RestAttitudes::default();
        for _ in 0..100 {
            r.push(&Vector3::new(0.1, 0.2, 10.3));
        }
        assert!(!r.observed_across_gravity());
        assert_eq!(r.poses(G).len(), 1);
        assert!(matches!(
            r.fit(G),
            Err(LabelFreeError::TooFewPoses { distinct: 1, .. })
        ));
    }

    #[test]
    fn bins_beyond_capacity_are_counted_not_gathered() {
        let r = rests(CAPACITY + 6, 1, Vector3::zeros(), Vector3::zeros());
        assert_eq!(r.missed(), 6);
        // Single samples make no pose.
        assert!(r.poses(G).is_empty());
    }
}
