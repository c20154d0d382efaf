//! Calibration inputs: a thesis six-position means file, or a raw recording (canonical CSV,
//! thesis time series, or MCAP, all read by the `recording` crate) whose static segments
//! become the poses; and the automatic gravity labels of axis-aligned poses.

use std::path::{Path, PathBuf};

use ipc_types::RawImuSample;
use nalgebra::Vector3;
use recording::thesis::SixPosition;
use recording::{Format, Recording};

use crate::fit::Pose;
use crate::segments::{Detection, SegmentConfig, SegmentError, detect_static_segments};
use calibrate::repair::{RepairConfig, TornReport, repair_torn_reads};

/// Largest angle (degrees) between a pose's mean reading and the nearest axis for the pose to
/// count as axis aligned. Generous on purpose: the thesis's sensor has a 0.25 g bias on z,
/// which tilts the reading of an x-up or y-up pose by up to 14 degrees.
pub const AXIS_ALIGNED_MAX_DEG: f64 = 25.0;

/// A loaded calibration input.
#[derive(Debug, Clone)]
pub enum Input {
    /// A six-position means file.
    SixPosition(SixPosition),
    /// A raw time series.
    Raw(Recording),
}

/// Why an input could not be loaded or turned into poses.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// The file is neither kind of input.
    #[error(
        "{}: neither a six-position means file ({six}) nor a raw recording ({raw})",
        path.display()
    )]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// Why it is not a means file.
        six: Box<recording::Error>,
        /// Why it is not a raw recording.
        raw: Box<recording::Error>,
    },
    /// Static-segment detection failed.
    #[error("{}: {source}", path.display())]
    Segments {
        /// The file.
        path: PathBuf,
        /// The detector's error.
        source: SegmentError,
    },
    /// A static segment is not near any axis, so it cannot be labelled automatically.
    #[error(
        "{}: static segment {index} (t = {t_s:.1} s, mean {mean:?} g) is {angle_deg:.0} degrees from the nearest axis; \
         automatic labels need axis-aligned poses (use --labels none for a label-free fit)",
        path.display()
    )]
    NotAxisAligned {
        /// The file.
        path: PathBuf,
        /// 0-based segment index.
        index: usize,
        /// Segment start, s.
        t_s: f64,
        /// Segment mean, g.
        mean: [f64; 3],
        /// Angle to the nearest axis, degrees.
        angle_deg: f64,
    },
}

impl Input {
    /// Short name of the input kind, as written to calibration files.
    pub fn kind_name(&self) -> &'static str {
        match self {
            Input::SixPosition(_) => "six_position_means",
            Input::Raw(r) => match r.format {
                Format::CanonicalCsv => "canonical_csv",
                Format::ThesisCsv => "thesis_csv",
                Format::Mcap => "mcap",
            },
        }
    }
}

/// Loads a calibration input, trying the six-position means format first and then the raw
/// formats; the error names the file and says why each reading failed.
pub fn load_input(path: &Path) -> Result<Input, InputError> {
    match recording::load_six_position(path) {
        Ok(six) => Ok(Input::SixPosition(six)),
        Err(six) => match recording::load_raw(path) {
            Ok(rec) => Ok(Input::Raw(rec)),
            Err(raw) => Err(InputError::Unreadable {
                path: path.to_path_buf(),
                six: Box::new(six),
                raw: Box::new(raw),
            }),
        },
    }
}

/// The poses of a six-position file with their labels. The file stores neither sample counts
/// nor the samples, so `n` is unknown (weights are then relative, see [`crate::fit`]).
pub fn poses_from_six(six: &SixPosition) -> Vec<Pose> {
    six.poses
        .iter()
        .map(|p| Pose {
            truth_g: Vector3::from(p.true_g),
            mean_g: Vector3::from(p.mean_g),
            std_g: Vector3::from(p.std_g),
            n: None,
        })
        .collect()
}

/// Static poses found in a raw recording, after torn-read repair.
#[derive(Debug, Clone)]
pub struct RawPoses {
    /// The repaired samples.
    pub samples: Vec<RawImuSample>,
    /// What the repair changed.
    pub repair: TornReport,
    /// The static-segment detection.
    pub detection: Detection,
}

/// Repairs torn reads and detects the static segments of a raw recording.
pub fn raw_poses(rec: &Recording, segment_cfg: &SegmentConfig) -> Result<RawPoses, InputError> {
    let mut samples = rec.samples.clone();
    let repair = repair_torn_reads(&mut samples, &RepairConfig::default());
    let detection =
        detect_static_segments(&samples, segment_cfg).map_err(|source| InputError::Segments {
            path: rec.source.clone(),
            source,
        })?;
    Ok(RawPoses {
        samples,
        repair,
        detection,
    })
}

/// The nearest signed axis to a reading (unit vector, g) and the angle to it in degrees.
pub fn nearest_axis(mean_g: &Vector3<f64>) -> (Vector3<f64>, f64) {
    let i = mean_g.iamax();
    let mut axis = Vector3::zeros();
    axis[i] = mean_g[i].signum();
    let cos = (mean_g.dot(&axis) / mean_g.norm()).clamp(-1.0, 1.0);
    (axis, cos.acos().to_degrees())
}

/// Labels every segment of `raw` with its nearest axis, or says which segment is not axis
/// aligned (see [`AXIS_ALIGNED_MAX_DEG`]).
pub fn label_axis_aligned(path: &Path, raw: &RawPoses) -> Result<Vec<Pose>, InputError> {
    let t0 = raw.samples.first().map_or(0, |s| s.stamps.sample_ns);
    raw.detection
        .segments
        .iter()
        .enumerate()
        .map(|(index, seg)| {
            let mean = Vector3::from(seg.mean_g);
            let (axis, angle_deg) = nearest_axis(&mean);
            if angle_deg > AXIS_ALIGNED_MAX_DEG {
                return Err(InputError::NotAxisAligned {
                    path: path.to_path_buf(),
                    index,
                    t_s: (seg.t_start_ns - t0) as f64 * 1e-9,
                    mean: seg.mean_g,
                    angle_deg,
                });
            }
            Ok(raw.detection.pose(seg, axis))
        })
        .collect()
}

/// Whether every segment lies within [`AXIS_ALIGNED_MAX_DEG`] of an axis.
pub fn all_axis_aligned(raw: &RawPoses) -> bool {
    raw.detection
        .segments
        .iter()
        .all(|s| nearest_axis(&Vector3::from(s.mean_g)).1 <= AXIS_ALIGNED_MAX_DEG)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_axis_of_a_biased_x_up_reading() {
        // The thesis's x-up pose: 1.09 g on x with -0.26 g on z from the z bias.
        let (axis, angle) = nearest_axis(&Vector3::new(1.092, 0.038, -0.259));
        assert_eq!(axis, Vector3::x());
        assert!(angle > 13.0 && angle < 14.0, "{angle}");
        let (axis, _) = nearest_axis(&Vector3::new(0.08, 0.04, -1.27));
        assert_eq!(axis, -Vector3::z());
    }
}
