//! The baseline the calibration data allow ([`BaselineKind`]), and the test data it can be
//! judged on.

use nalgebra::Vector3;

use super::data::Session;
use super::{BaselineKind, DiagnoseError};
use crate::labelfree::distinct_orientations;
use crate::session::{AXIS_ALIGNED_MAX_DEG, nearest_axis};

/// Whether every pose of a raw session lies in one orientation.
fn single_orientation(s: &Session) -> bool {
    match s {
        Session::Means { .. } => false,
        Session::Raw(r) => {
            let first = Vector3::from(r.segments[0].mean_g).normalize();
            r.segments
                .iter()
                .all(|g| Vector3::from(g.mean_g).normalize().dot(&first) > 10f64.to_radians().cos())
        }
    }
}

pub(super) fn choose_kind(calib: &[Session]) -> Result<BaselineKind, DiagnoseError> {
    if calib.iter().all(single_orientation) {
        return Ok(BaselineKind::SessionMean);
    }
    let mut labels: Vec<Vector3<f64>> = Vec::new();
    let mut aligned = true;
    for s in calib {
        match s {
            Session::Means { poses, .. } => labels.extend(poses.iter().map(|p| p.truth_g)),
            Session::Raw(_) => {
                for m in s.pose_means() {
                    let (axis, angle) = nearest_axis(&m);
                    aligned &= angle <= AXIS_ALIGNED_MAX_DEG;
                    labels.push(axis);
                }
            }
        }
    }
    if aligned {
        // Model 3 needs [a_x, a_y, a_z, 1] of rank 4.
        let x = nalgebra::DMatrix::from_fn(
            labels.len(),
            4,
            |r, c| {
                if c < 3 { labels[r][c] } else { 1.0 }
            },
        );
        let sv = x.svd(false, false).singular_values;
        if sv.len() == 4 && sv.min() > 1e-6 * sv.max() {
            return Ok(BaselineKind::Full);
        }
    }
    if calib.iter().any(|s| matches!(s, Session::Means { .. })) {
        return Err(DiagnoseError::NoBaseline(
            "a means file's labels do not determine model 3".into(),
        ));
    }
    let poses: Vec<crate::fit::Pose> = calib
        .iter()
        .flat_map(|s| s.pose_means())
        .map(|m| crate::fit::Pose {
            truth_g: Vector3::zeros(),
            mean_g: m,
            std_g: Vector3::repeat(1e-3),
            n: None,
        })
        .collect();
    let distinct = distinct_orientations(&poses);
    if distinct >= crate::labelfree::MIN_POSES {
        return Ok(BaselineKind::LabelFree);
    }
    Err(DiagnoseError::NoBaseline(format!(
        "{} static poses in {distinct} distinct orientations, {}",
        poses.len(),
        if aligned {
            "axis aligned but not covering every axis"
        } else {
            "not all axis aligned"
        }
    )))
}

pub(super) fn check_test(kind: BaselineKind, test: &[Session]) -> Result<(), DiagnoseError> {
    for s in test {
        let err = |reason: String| DiagnoseError::Test {
            name: s.name().to_string(),
            reason,
        };
        match (kind, s) {
            (BaselineKind::SessionMean, Session::Means { .. }) => {
                return Err(err(
                    "a static baseline is tested on static recordings, not on a means file".into(),
                ));
            }
            (BaselineKind::SessionMean, _) if !single_orientation(s) => {
                return Err(err(
                    "a static baseline is tested on static recordings in one orientation".into(),
                ));
            }
            (BaselineKind::Full, Session::Raw(_)) => {
                for (k, m) in s.pose_means().iter().enumerate() {
                    let (_, angle) = nearest_axis(m);
                    if angle > AXIS_ALIGNED_MAX_DEG {
                        return Err(err(format!(
                            "static segment {k} is {angle:.0} degrees from the nearest axis; model 3 \
                             is tested on axis-aligned poses"
                        )));
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}
