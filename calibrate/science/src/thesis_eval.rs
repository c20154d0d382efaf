//! Reproduction of the thesis's Table 5 / Table A-2: the displacement after 60 s of each
//! trial's static test file, uncalibrated and corrected with models 1-3 fitted (unweighted) to
//! that trial's six-position means.
//!
//! Procedure, as the thesis describes it: correct each sample (g), convert to m/s^2 with the
//! thesis's local gravity 9.797 m/s^2, subtract (0, 0, g), and integrate twice with the trapezoid
//! rule on the recorded timestamps from rest. Displacements are in metres, sensor frame.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use crate::fit::{FitError, Weighting, fit_labelled};
use crate::integrate::DoubleIntegrator;
use crate::session::poses_from_six;
use calibrate::model::{AccelModel, ModelKind};

/// The evaluated variants, in the thesis's row order.
pub const METHODS: [&str; 4] = ["none", "bias", "scale", "full"];

/// Table A-2 of the thesis (trials 1-3; rows none, model 1, 2, 3; columns x, y, z), metres.
/// Table 5 repeats trial 1 with small differences (no calibration 1731 / 1089 / -4002, model 1
/// z 413, model 3 z 25); the issue asks for Table A-2's values where they disagree.
pub const TABLE_A2_M: [[[f64; 3]; 4]; 3] = [
    [
        [1729.0, 1088.0, -3999.0],
        [115.0, 254.0, 412.0],
        [115.0, 254.0, 25.0],
        [-45.0, 66.0, 24.0],
    ],
    [
        [1705.0, 1080.0, -3961.0],
        [103.0, 255.0, 433.0],
        [103.0, 255.0, 47.0],
        [-35.0, 63.0, 46.0],
    ],
    [
        [1702.0, 1071.0, -3970.0],
        [113.0, 251.0, 404.0],
        [113.0, 251.0, 10.0],
        [-29.0, 62.0, 10.0],
    ],
];

/// Why a trial could not be evaluated.
#[derive(Debug, thiserror::Error)]
pub enum ThesisEvalError {
    /// A data file could not be read.
    #[error(transparent)]
    Read(#[from] recording::Error),
    /// A model could not be fitted.
    #[error("{}: {source}", path.display())]
    Fit {
        /// The six-position file.
        path: PathBuf,
        /// The fitting error.
        source: FitError,
    },
    /// The test file has too few samples.
    #[error("{}: fewer than 2 samples", path.display())]
    Empty {
        /// The test file.
        path: PathBuf,
    },
}

/// One trial's reproduced displacements, in [`METHODS`] order.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialResult {
    /// Trial number (1-3).
    pub trial: usize,
    /// Displacement per method, m.
    pub displacement_m: [[f64; 3]; 4],
    /// Duration of the test file, s.
    pub duration_s: f64,
}

/// Paths of trial `trial`'s six-position means and static test file under the capstone data
/// folder.
pub fn trial_paths(data_dir: &Path, trial: usize) -> (PathBuf, PathBuf) {
    let dir = data_dir
        .join("Six-Position-Test/data")
        .join(format!("trial_{trial}"));
    (
        dir.join(format!("six_position_data_{trial}.csv")),
        dir.join(format!("six_position_test_data_{trial}.csv")),
    )
}

/// Evaluates one trial from its two files (see the module documentation).
pub fn evaluate_trial(
    trial: usize,
    six_path: &Path,
    test_path: &Path,
    gravity_mps2: f64,
) -> Result<TrialResult, ThesisEvalError> {
    let six = recording::load_six_position(six_path)?;
    let test = recording::load_raw(test_path)?;
    if test.samples.len() < 2 {
        return Err(ThesisEvalError::Empty {
            path: test_path.to_path_buf(),
        });
    }
    let poses = poses_from_six(&six);
    let mut models: Vec<Option<AccelModel>> = vec![None];
    for kind in ModelKind::ALL {
        let fit = fit_labelled(&poses, kind, Weighting::Unweighted).map_err(|source| {
            ThesisEvalError::Fit {
                path: six_path.to_path_buf(),
                source,
            }
        })?;
        models.push(Some(fit.model));
    }
    let mut displacement_m = [[0.0; 3]; 4];
    for (slot, model) in displacement_m.iter_mut().zip(&models) {
        let mut integ = DoubleIntegrator::new();
        for s in &test.samples {
            let raw = Vector3::from(s.accel_g);
            let a_g = model.as_ref().map_or(raw, |m| m.correct(&raw));
            let a = a_g * gravity_mps2 - Vector3::new(0.0, 0.0, gravity_mps2);
            integ.push(s.stamps.sample_ns as f64 * 1e-9, [a.x, a.y, a.z]);
        }
        *slot = integ.displacement();
    }
    let t = |k: usize| test.samples[k].stamps.sample_ns as f64 * 1e-9;
    Ok(TrialResult {
        trial,
        displacement_m,
        duration_s: t(test.samples.len() - 1) - t(0),
    })
}

/// Evaluates trials 1-3 under the capstone data folder `data_dir`.
pub fn evaluate_all(
    data_dir: &Path,
    gravity_mps2: f64,
) -> Result<Vec<TrialResult>, ThesisEvalError> {
    (1..=3)
        .map(|trial| {
            let (six, test) = trial_paths(data_dir, trial);
            evaluate_trial(trial, &six, &test, gravity_mps2)
        })
        .collect()
}

/// The JSON document `{"table5": {"trial_N": {"none": [x, y, z], ...}}}`, metres.
pub fn to_json(results: &[TrialResult]) -> serde_json::Value {
    let mut table = serde_json::Map::new();
    for r in results {
        let mut methods = serde_json::Map::new();
        for (name, d) in METHODS.iter().zip(&r.displacement_m) {
            methods.insert((*name).into(), serde_json::json!(d));
        }
        table.insert(
            format!("trial_{}", r.trial),
            serde_json::Value::Object(methods),
        );
    }
    serde_json::json!({ "table5": table })
}

/// A side-by-side text table of the reproduced and the thesis's values.
pub fn to_text(results: &[TrialResult]) -> String {
    let mut out = String::new();
    out.push_str(
        "Thesis Table 5 / A-2: displacement after the 60 s static test (m), reproduced vs thesis\n",
    );
    for r in results {
        out.push_str(&format!("trial {} ({:.2} s)\n", r.trial, r.duration_s));
        out.push_str(
            "  method     x: ours    thesis   y: ours    thesis   z: ours    thesis   max |diff|\n",
        );
        for (k, name) in METHODS.iter().enumerate() {
            let ours = r.displacement_m[k];
            let theirs = TABLE_A2_M[r.trial - 1][k];
            let diff = (0..3)
                .map(|i| (ours[i] - theirs[i]).abs())
                .fold(0.0, f64::max);
            out.push_str(&format!(
                "  {:<6} {:>10.2} {:>8.0} {:>10.2} {:>8.0} {:>10.2} {:>8.0} {:>10.2}\n",
                name, ours[0], theirs[0], ours[1], theirs[1], ours[2], theirs[2], diff
            ));
        }
    }
    out
}
