//! What the poses of a labelled session determine: the axis directions they point up (a
//! six-position session points each axis up and down, so that every bias and scale factor is
//! seen from two sides), the parameters that rest on one pose alone, and the axes whose
//! residual-scaled 1-sigma rests on one residual. `mems-calibrate fit` warns of each.

use nalgebra::Vector3;
use statrs::distribution::{ChiSquared, ContinuousCDF};

use crate::fit::{Pose, Weighting, axis_name, axis_params, axis_problem};
use crate::session::nearest_axis;
use calibrate::model::{ModelKind, PARAM_NAMES};

/// The six directions a six-position session points up, in the order of [`direction`].
pub const DIRECTIONS: [&str; 6] = ["+x", "-x", "+y", "-y", "+z", "-z"];

/// Largest angle between a label and an axis for the label to point along it, degrees: labels
/// of axis-aligned poses are the axes themselves.
const LABEL_ON_AXIS_DEG: f64 = 1.0;

/// A leverage this close to 1 means the fit passes through the pose exactly.
const SOLE_LEVERAGE: f64 = 1.0 - 1e-9;

/// The index into [`DIRECTIONS`] of the axis `label` (g) points along, or `None` when it
/// points along none.
pub fn direction(label: &Vector3<f64>) -> Option<usize> {
    let (axis, angle_deg) = nearest_axis(label);
    let i = axis.iamax();
    (angle_deg <= LABEL_ON_AXIS_DEG).then_some(2 * i + usize::from(axis[i] < 0.0))
}

/// The directions of [`DIRECTIONS`] that no pose points up, when every label points along an
/// axis (a six-position session, complete or not); `None` for a session of other orientations.
pub fn missing_directions(poses: &[Pose]) -> Option<Vec<&'static str>> {
    let mut seen = [false; 6];
    for pose in poses {
        seen[direction(&pose.truth_g)?] = true;
    }
    Some(
        (0..6)
            .filter(|&d| !seen[d])
            .map(|d| DIRECTIONS[d])
            .collect(),
    )
}

/// A pose that alone determines some parameters: its leverage is 1, so the fit passes through
/// it exactly, no residual checks those parameters, and their 1-sigma does not hold that
/// pose's error.
#[derive(Debug, Clone, PartialEq)]
pub struct SolePose {
    /// 0-based index of the pose.
    pub pose: usize,
    /// The parameters it alone determines, by name ([`PARAM_NAMES`]).
    pub params: Vec<&'static str>,
}

/// The poses of a `kind` fit that alone determine some parameters. The design is the labels',
/// the same for every weighting; poses whose labels do not determine the model give none.
pub fn sole_poses(poses: &[Pose], kind: ModelKind) -> Vec<SolePose> {
    let mut found: Vec<SolePose> = Vec::new();
    for axis in 0..3 {
        let Ok(problem) = axis_problem(poses, kind, axis, Weighting::Unweighted, false) else {
            return Vec::new();
        };
        let cols = axis_params(kind, axis);
        let x = &problem.x;
        let Some(inverse) = (x.transpose() * x).try_inverse() else {
            return Vec::new();
        };
        for (pose, row) in x.row_iter().enumerate() {
            // The pose's leverage h = x (X^T X)^-1 x^T, and its influence on each parameter.
            let influence = &inverse * row.transpose();
            if (row * &influence)[0] < SOLE_LEVERAGE {
                continue;
            }
            let largest = influence.amax();
            let params = cols
                .iter()
                .zip(influence.iter())
                .filter(|(_, g)| g.abs() > 1e-9 * largest)
                .map(|(&k, _)| PARAM_NAMES[k]);
            match found.iter_mut().find(|s| s.pose == pose) {
                Some(sole) => sole.params.extend(params),
                None => found.push(SolePose {
                    pose,
                    params: params.collect(),
                }),
            }
        }
    }
    found
}

/// For an axis whose residual-scaled 1-sigma rests on `dof` residuals: the factor by which that
/// 1-sigma is too small one time in 20 (`sqrt(dof / q)`, `q` the 5 % quantile of chi^2 with
/// `dof` degrees of freedom): 16 for one residual, 4.4 for two, 1.9 for six.
pub fn sigma_shortfall(dof: usize) -> f64 {
    let q = ChiSquared::new(dof as f64)
        .expect("dof > 0")
        .inverse_cdf(0.05);
    (dof as f64 / q).sqrt()
}

/// The parameters of `axis` (0, 1, 2) in a `kind` fit, by name, and the axis' name.
pub fn axis_parameters(kind: ModelKind, axis: usize) -> (char, Vec<&'static str>) {
    let names = axis_params(kind, axis)
        .iter()
        .map(|&k| PARAM_NAMES[k])
        .collect();
    (axis_name(axis), names)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn poses(dirs: &[Vector3<f64>]) -> Vec<Pose> {
        dirs.iter()
            .map(|t| Pose {
                truth_g: *t,
                mean_g: *t,
                std_g: Vector3::repeat(0.002),
                n: None,
            })
            .collect()
    }

    fn six() -> Vec<Vector3<f64>> {
        vec![
            Vector3::x(),
            -Vector3::x(),
            Vector3::y(),
            -Vector3::y(),
            Vector3::z(),
            -Vector3::z(),
        ]
    }

    #[test]
    fn a_complete_session_misses_nothing_and_no_pose_stands_alone() {
        let all = poses(&six());
        assert_eq!(missing_directions(&all), Some(vec![]));
        assert_eq!(sole_poses(&all, ModelKind::Full), vec![]);
    }

    #[test]
    fn five_of_six_poses_name_the_missing_direction_and_what_rests_on_one_pose() {
        let mut dirs = six();
        dirs.remove(1); // -x
        let five = poses(&dirs);
        assert_eq!(missing_directions(&five), Some(vec!["-x"]));
        assert_eq!(
            sole_poses(&five, ModelKind::Full),
            vec![SolePose {
                pose: 0,
                params: vec!["S_xx", "S_yx", "S_zx"],
            }]
        );
        assert_eq!(
            sole_poses(&five, ModelKind::Scale),
            vec![SolePose {
                pose: 0,
                params: vec!["S_xx"],
            }]
        );
        assert_eq!(sole_poses(&five, ModelKind::Bias), vec![]);
    }

    #[test]
    fn other_orientations_are_not_a_six_position_session() {
        let tilted = Vector3::new(1.0, 1.0, 0.0).normalize();
        assert_eq!(missing_directions(&poses(&[tilted, Vector3::z()])), None);
    }

    #[test]
    fn one_residual_leaves_the_sigma_sixteen_times_too_small_one_time_in_twenty() {
        assert!((sigma_shortfall(1) - 15.95).abs() < 0.05);
        assert!((sigma_shortfall(2) - 4.42).abs() < 0.05);
    }
}
