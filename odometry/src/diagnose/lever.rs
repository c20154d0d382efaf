//! The lever-arm candidate: an IMU off the rear axle of a wheeled platform, where the
//! non-holonomic constraint holds (`crate::eskf`'s `lever` module). No rest-to-rest row sees
//! it (`omega x r` is zero at both rests): the constraint's own innovations do. An IMU `l`
//! metres ahead of the axle moves sideways at `w_z l` in a turn, which the constraint, applied
//! at the IMU, meets as a lateral innovation proportional to the yaw rate.
//!
//! The forward offset `r_x` (body frame, m, from the IMU to the axle: negative when the IMU
//! sits ahead of it) is estimated by its profile likelihood: the run is made again with the
//! constraint at a few offsets (`mems-odometry offline --lever-arm`), and the sum of the
//! constraint's normalized innovations squared (NIS, the innovation sequence's chi-square:
//! a filter whose model is right has white innovations, so their sum is the run's
//! -2 log-likelihood up to a term the offset barely moves; Bar-Shalom, Li, Kirubarajan,
//! "Estimation with Applications to Tracking and Navigation", 2001, section 5.4) is fitted
//! by a parabola in `r_x`. Its minimum is the estimate, its curvature the 1-sigma
//! (`chi2(r) = chi2_min + ((r - r_hat) / sigma)^2`), and the drop from the declared offset to
//! the minimum is the candidate's score (both over the NIS per degree of freedom at the
//! minimum where that exceeds 1: innovations the constraint's 1-sigma understates, as skid
//! makes them, count for less; R. T. Birge, Phys. Rev. 40, 207, 1932), as the other candidates' held-out gain: found when
//! it passes [`super::Settings::threshold`], the estimate lies [`super::Settings::beyond_model`]
//! of its 1-sigma from the declared offset, and within [`MAX_LEVER_ARM_M`]. The lateral and
//! vertical offsets are not tested: on a platform that drives forward they act through the
//! roll and pitch rates (`omega_x r_z`, `omega_y r_x`), which a road barely excites.

use serde::Serialize;

/// The offsets tried about the declared one, m: a parabola needs three points, a metre
/// apart (a car's IMU sits 1-3 m from its rear axle).
pub const PROBE_M: f64 = 1.0;
/// Largest plausible forward offset, m (a long vehicle's wheelbase).
pub const MAX_LEVER_ARM_M: f64 = 5.0;

/// One run of the profile: the forward offset used and its constraint's NIS sum and degrees
/// of freedom.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Point {
    /// Forward lever arm, m.
    pub r_x_m: f64,
    /// Sum of the constraint's NIS.
    pub chi2: f64,
    /// Their degrees of freedom.
    pub dof: f64,
}

/// What the lever-arm candidate found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LeverArm {
    /// Why it could not be tested, if so.
    pub untestable: Option<String>,
    /// The profile's runs, the declared offset first.
    pub points: Vec<Point>,
    /// The estimated forward offset, m (NaN when untested or the profile has no minimum).
    pub r_x_m: f64,
    /// Its 1-sigma, m.
    pub sigma_m: f64,
    /// The NIS sum's drop from the declared offset to the estimate.
    pub gain: f64,
    /// Whether the data support it (module documentation).
    pub found: bool,
}

impl LeverArm {
    /// The candidate untested, for `why`.
    pub fn untestable(why: String) -> Self {
        Self {
            untestable: Some(why),
            points: Vec::new(),
            r_x_m: f64::NAN,
            sigma_m: f64::NAN,
            gain: 0.0,
            found: false,
        }
    }

    /// The candidate from its profile's `points` (at least three distinct offsets, the
    /// declared one first), judged with `threshold` and `beyond` (as
    /// [`super::Settings::threshold`] and [`super::Settings::beyond_model`]).
    pub fn from_profile(points: Vec<Point>, threshold: f64, beyond: f64) -> Self {
        let Some(&declared) = points.first() else {
            return Self::untestable("no run".into());
        };
        let Some([c0, c1, c2]) = parabola(&points) else {
            return Self::untestable("the runs do not determine a parabola".into());
        };
        if c2 <= 0.0 {
            return Self {
                untestable: Some(
                    "the constraint's NIS has no minimum in the forward offset".into(),
                ),
                points,
                ..Self::untestable(String::new())
            };
        }
        let r_x_m = -c1 / (2.0 * c2);
        let at = |r: f64| c0 + c1 * r + c2 * r * r;
        // Innovations larger than the constraint's 1-sigma says (skid, vibration) widen the
        // estimate's 1-sigma and shrink the score by their ratio (Birge's ratio).
        let ratio = (at(r_x_m) / declared.dof).max(1.0);
        let sigma_m = (ratio / c2).sqrt();
        let gain = (at(declared.r_x_m) - at(r_x_m)) / ratio;
        let found = gain > threshold
            && (r_x_m - declared.r_x_m).abs() > beyond * sigma_m
            && r_x_m.abs() <= MAX_LEVER_ARM_M;
        Self {
            untestable: None,
            points,
            r_x_m,
            sigma_m,
            gain,
            found,
        }
    }
}

/// The least-squares parabola `c0 + c1 r + c2 r^2` through the points' NIS sums (`None`:
/// fewer than three distinct offsets).
fn parabola(points: &[Point]) -> Option<[f64; 3]> {
    let n = points.len();
    let a = nalgebra::DMatrix::from_fn(n, 3, |i, j| points[i].r_x_m.powi(j as i32));
    let b = nalgebra::DVector::from_fn(n, |i, _| points[i].chi2);
    let ata = a.transpose() * &a;
    let x = ata.try_inverse()? * a.transpose() * b;
    x.iter().all(|c| c.is_finite()).then(|| [x[0], x[1], x[2]])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(r_x_m: f64, chi2: f64) -> Point {
        Point {
            r_x_m,
            chi2,
            dof: 1000.0,
        }
    }

    #[test]
    fn a_profile_s_minimum_and_curvature_are_the_estimate_and_its_sigma() {
        // chi2(r) = 500 + ((r + 1.2) / 0.1)^2: minimum at -1.2 m, 1-sigma 0.1 m; from the
        // declared 0 the drop is 144.
        let f = |r: f64| 500.0 + ((r + 1.2) / 0.1f64).powi(2);
        let points = [0.0, -1.0, 1.0].map(|r| point(r, f(r))).to_vec();
        let lever = LeverArm::from_profile(points, 12.0, 3.0);
        assert!((lever.r_x_m + 1.2).abs() < 1e-9, "{lever:?}");
        assert!((lever.sigma_m - 0.1).abs() < 1e-9, "{lever:?}");
        assert!((lever.gain - 144.0).abs() < 1e-6, "{lever:?}");
        assert!(lever.found);
    }

    #[test]
    fn innovations_beyond_their_sigma_widen_the_estimate() {
        // The same profile with its minimum at 4 NIS per degree of freedom: sigma doubled,
        // the score a quarter.
        let f = |r: f64| 4000.0 + ((r + 1.2) / 0.1f64).powi(2);
        let points = [0.0, -1.0, 1.0].map(|r| point(r, f(r))).to_vec();
        let lever = LeverArm::from_profile(points, 12.0, 3.0);
        assert!((lever.sigma_m - 0.2).abs() < 1e-9, "{lever:?}");
        assert!((lever.gain - 36.0).abs() < 1e-6, "{lever:?}");
    }

    #[test]
    fn a_flat_profile_finds_nothing() {
        // chi2(r) = 500 + (r / 0.5)^2: the minimum at the declared offset.
        let f = |r: f64| 500.0 + (r / 0.5f64).powi(2);
        let points = [0.0, -1.0, 1.0].map(|r| point(r, f(r))).to_vec();
        let lever = LeverArm::from_profile(points, 12.0, 3.0);
        assert!(
            lever.r_x_m.abs() < 1e-9 && lever.gain.abs() < 1e-9,
            "{lever:?}"
        );
        assert!(!lever.found);
    }

    #[test]
    fn a_profile_without_a_minimum_is_untestable() {
        let points = [0.0, -1.0, 1.0].map(|r| point(r, 500.0 - r * r)).to_vec();
        let lever = LeverArm::from_profile(points, 12.0, 3.0);
        assert!(lever.untestable.is_some() && !lever.found, "{lever:?}");
    }
}
