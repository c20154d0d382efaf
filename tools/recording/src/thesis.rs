//! Readers for the capstone thesis's files (`../shared/data/capstone/`, see its README).
//!
//! All values are in g, sensor frame, as the thesis's Python scripts wrote them.
//! - Six-position means (`six_position_data_N.csv`, `trial_1_2_3_combined.csv`,
//!   `six_position_data_10_iterations.csv`): one row per pose, `x_true (g),x_mean (g),x_std,...`;
//!   read with [`load_six_position`].
//! - Time series (`six_position_test_data_N.csv`, `one_min_raw_data.csv`,
//!   `start_up_data_N.csv`): `time,x (g),y (g),z (g)`, or a title line followed by the header
//!   as published, `time (s)x (g),y (g),z (g)` (a comma missing after `time (s)`); read with
//!   [`crate::load_raw`]. `time` is seconds since the script started recording (Python
//!   `time.time()` differences, taken after each read), so `stamps.sample_ns` counts from the
//!   start of the recording, not from boot.
//! - Fitted parameters (`optim_params_N.csv`): a title line, then `b_x, b_y, b_z, Sxx, ... Szz`
//!   with one row per model; read with [`load_optim_params`].

use std::path::{Path, PathBuf};

use ::csv::StringRecord;

use crate::error::{Error, ErrorKind, Result};
use crate::text::{self, Columns, Row, Rows, SampleBuilder};
use crate::{Format, LogPolicy, Recording};

/// One orientation of a six-position session: 30 s at rest, averaged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// The gravity reaction the pose should produce, g, sensor frame (e.g. (0, 0, 1) for z up;
    /// "true" assumes a level table).
    pub true_g: [f64; 3],
    /// Mean of the accelerometer readings, g, sensor frame.
    pub mean_g: [f64; 3],
    /// Population standard deviation of the readings (numpy `std`), g, per axis.
    pub std_g: [f64; 3],
}

/// The poses of a six-position file, in file order (6 per placement; the combined and
/// 10-iteration files hold several placements one after the other).
#[derive(Debug, Clone, PartialEq)]
pub struct SixPosition {
    /// The file read.
    pub source: PathBuf,
    /// One entry per data row.
    pub poses: Vec<Pose>,
}

const SIX_POSITION_COLUMNS: [&str; 9] = [
    "x_true (g)",
    "x_mean (g)",
    "x_std",
    "y_true (g)",
    "y_mean (g)",
    "y_std",
    "z_true (g)",
    "z_mean (g)",
    "z_std",
];

/// Reads a six-position means file (`x_true (g),x_mean (g),x_std,y_true (g),...,z_std`).
///
/// Errors if the header differs, a cell is not a finite number, a pose is not one at rest
/// (true vector of magnitude 1 g, mean within 0.5..1.5 g and the sensor's range, standard
/// deviations within 0..1 g), or the file has no poses.
pub fn load_six_position(path: impl AsRef<Path>) -> Result<SixPosition> {
    let path = path.as_ref();
    let mut rows = Rows::open(path)?;
    expect_header(&mut rows, &SIX_POSITION_COLUMNS)?;
    let mut poses = Vec::new();
    while let Some((line, row)) = rows.next_row()? {
        let values = numbers(path, line, row, &SIX_POSITION_COLUMNS)?;
        let axis = |k: usize| [values[k], values[3 + k], values[6 + k]];
        let pose = Pose {
            true_g: axis(0),
            mean_g: axis(1),
            std_g: axis(2),
        };
        check_pose(path, line, &values, &pose)?;
        poses.push(pose);
    }
    if poses.is_empty() {
        return Err(Error::file(
            path,
            ErrorKind::Invalid("no poses (header only)".into()),
        ));
    }
    Ok(SixPosition {
        source: path.to_path_buf(),
        poses,
    })
}

/// Bounds on a pose at rest, g: the magnitude of its true vector (a unit gravity reaction), of
/// its mean (gravity's 1 g through an uncalibrated part: the MPU-9250's zero-g offset is
/// +-60 mg on x and y, +-80 mg on z, and its scale +-3 %, PS-MPU-9250A-01 rev 1.1 table 3.2; the thesis's
/// worst pose reads 1.27 g), and a reading's standard deviation at rest.
const POSE_TRUE_NORM_G: (f64, f64) = (0.9, 1.1);
const POSE_MEAN_NORM_G: (f64, f64) = (0.5, 1.5);
const POSE_STD_MAX_G: f64 = 1.0;

/// Checks that a pose is one at rest (see [`POSE_MEAN_NORM_G`]); `values` are its cells in
/// [`SIX_POSITION_COLUMNS`] order, the first offending one is named.
fn check_pose(path: &Path, line: u64, values: &[f64], pose: &Pose) -> Result<()> {
    let fail = |column: usize, message: String| {
        let column = SIX_POSITION_COLUMNS[column];
        Error::line(path, line, Some(column), ErrorKind::Invalid(message))
    };
    for axis in 0..3 {
        let (mean, std) = (values[3 * axis + 1], values[3 * axis + 2]);
        if mean.abs() > ipc_types::limits::ACCEL_LIMIT_G {
            let limit = ipc_types::limits::ACCEL_LIMIT_G;
            return Err(fail(
                3 * axis + 1,
                format!("mean {mean:?} g is beyond the sensor's range (limit {limit} g)"),
            ));
        }
        if !(0.0..=POSE_STD_MAX_G).contains(&std) {
            return Err(fail(
                3 * axis + 2,
                format!(
                    "standard deviation {std:?} g is not in 0..={POSE_STD_MAX_G} g (a pose at rest)"
                ),
            ));
        }
    }
    let norm = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let (t, m) = (norm(pose.true_g), norm(pose.mean_g));
    if !(POSE_TRUE_NORM_G.0..=POSE_TRUE_NORM_G.1).contains(&t) {
        let (lo, hi) = POSE_TRUE_NORM_G;
        return Err(fail(
            0,
            format!("the true vector's magnitude is {t:?} g, not gravity's 1 g ({lo}..={hi})"),
        ));
    }
    if !(POSE_MEAN_NORM_G.0..=POSE_MEAN_NORM_G.1).contains(&m) {
        let (lo, hi) = POSE_MEAN_NORM_G;
        return Err(fail(
            1,
            format!("the mean's magnitude is {m:?} g: not a pose at rest ({lo}..={hi} g)"),
        ));
    }
    Ok(())
}

/// One of the thesis's accelerometer models, `a' = S a + b`: `a'` the measured and `a` the true
/// specific force, both in g, sensor frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThesisModel {
    /// Bias `b`, g.
    pub bias_g: [f64; 3],
    /// `S`, row-major (`s[0][1]` is `Sxy`), dimensionless. Identity for the bias-only model.
    pub s: [[f64; 3]; 3],
}

/// The three models fitted by the thesis for one trial (unweighted least squares on that
/// trial's six-position means).
#[derive(Debug, Clone, PartialEq)]
pub struct OptimParams {
    /// The file read.
    pub source: PathBuf,
    /// The file's title line, e.g. "Accelerometer Model Parameters Optimized - Trial 1.".
    pub title: String,
    /// Model 1: bias only (`S` = identity; the file stores zeros).
    pub bias_only: ThesisModel,
    /// Model 2: bias and per-axis scale (`S` diagonal; the file stores the diagonal in the
    /// `Sxx, Sxy, Sxz` columns and zeros in the rest).
    pub scale: ThesisModel,
    /// Model 3: bias, scale and misalignment (full `S`).
    pub full: ThesisModel,
}

const OPTIM_COLUMNS: [&str; 12] = [
    "b_x", "b_y", "b_z", "Sxx", "Sxy", "Sxz", "Syx", "Syy", "Syz", "Szx", "Szy", "Szz",
];

/// Reads an `optim_params_N.csv` file: a title line, the header, and rows for models 1, 2, 3.
///
/// Errors if the layout differs, a cell is not a finite number, or a model stores a non-zero
/// value where its structure requires a zero (model 1's `S` columns, model 2's last six).
pub fn load_optim_params(path: impl AsRef<Path>) -> Result<OptimParams> {
    let path = path.as_ref();
    let mut rows = Rows::open(path)?;
    let title = match rows.next_row()? {
        Some((_, row)) if row.len() == 1 => row[0].to_owned(),
        Some((line, _)) => {
            let kind = ErrorKind::Invalid("expected a one-field title line".into());
            return Err(Error::line(path, line, None, kind));
        }
        None => return Err(Error::file(path, ErrorKind::Invalid("empty file".into()))),
    };
    expect_header(&mut rows, &OPTIM_COLUMNS)?;
    let mut models = Vec::with_capacity(3);
    while let Some((line, row)) = rows.next_row()? {
        if models.len() == 3 {
            let kind = ErrorKind::Invalid("more than three model rows".into());
            return Err(Error::line(path, line, None, kind));
        }
        let values = numbers(path, line, row, &OPTIM_COLUMNS)?;
        // Columns that the model's structure requires to be zero.
        let zeros = match models.len() {
            0 => 3..12,
            1 => 6..12,
            _ => 12..12,
        };
        if let Some(k) = zeros.clone().find(|&k| values[k] != 0.0) {
            let message = format!(
                "model {} stores {} here; its structure needs 0",
                models.len() + 1,
                values[k]
            );
            return Err(Error::line(
                path,
                line,
                Some(OPTIM_COLUMNS[k]),
                ErrorKind::Invalid(message),
            ));
        }
        let bias_g = [values[0], values[1], values[2]];
        let s = match models.len() {
            0 => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            1 => [
                [values[3], 0.0, 0.0],
                [0.0, values[4], 0.0],
                [0.0, 0.0, values[5]],
            ],
            _ => [
                [values[3], values[4], values[5]],
                [values[6], values[7], values[8]],
                [values[9], values[10], values[11]],
            ],
        };
        models.push(ThesisModel { bias_g, s });
    }
    let [bias_only, scale, full] = models.try_into().map_err(|models: Vec<_>| {
        let message = format!("{} model rows, expected 3", models.len());
        Error::file(path, ErrorKind::Invalid(message))
    })?;
    Ok(OptimParams {
        source: path.to_path_buf(),
        title,
        bias_only,
        scale,
        full,
    })
}

/// The column names the time-series readers report errors under.
const SERIES_COLUMNS: [&str; 4] = ["time", "x (g)", "y (g)", "z (g)"];

/// [`SERIES_COLUMNS`] as the sample builder names them (the files have no gyroscope or
/// temperature).
const SERIES_NAMES: Columns = Columns {
    time: SERIES_COLUMNS[0],
    accel: [SERIES_COLUMNS[1], SERIES_COLUMNS[2], SERIES_COLUMNS[3]],
    gyro: ["", "", ""],
    temp: "",
};

/// Whether a row is one of the thesis's time-series headers: `time,x (g),y (g),z (g)`,
/// `time (s),x (g),y (g),z (g)`, or the published malformed `time (s)x (g),y (g),z (g)`.
pub(crate) fn is_series_header(row: &StringRecord) -> bool {
    let fields: Vec<&str> = row.iter().collect();
    matches!(
        fields.as_slice(),
        ["time" | "time (s)", "x (g)", "y (g)", "z (g)"] | ["time (s)x (g)", "y (g)", "z (g)"]
    )
}

/// Reads the rows after a time-series header into a recording (accelerometer only).
pub(crate) fn read_series_body(rows: &mut Rows, policy: LogPolicy) -> Result<Recording> {
    let path = rows.path().to_path_buf();
    let mut samples = SampleBuilder::new(policy);
    while let Some((line, row)) = rows.next_row()? {
        text::check_width(&path, line, row, &SERIES_COLUMNS)?;
        let t_ns = text::parse_seconds(&path, line, SERIES_COLUMNS[0], &row[0])?;
        let mut accel_g = [0.0; 3];
        for (k, value) in accel_g.iter_mut().enumerate() {
            *value = text::parse_f64(&path, line, SERIES_COLUMNS[k + 1], &row[k + 1])?;
        }
        let parsed = Row {
            t_ns,
            accel_g,
            gyro_dps: None,
            temp_c: None,
            flags: None,
            lost_before: 0,
        };
        samples.push(&path, line, &SERIES_NAMES, parsed)?;
    }
    let (samples, repairs) = samples.finish(&path, None)?;
    Ok(Recording {
        source: path,
        format: Format::ThesisCsv,
        samples,
        truth: None,
        truncation: None,
        repairs,
    })
}

/// Reads the next row and checks that it is exactly `columns`.
fn expect_header(rows: &mut Rows, columns: &[&str]) -> Result<()> {
    let path = rows.path().to_path_buf();
    match rows.next_row()? {
        Some((_, row)) if row.iter().eq(columns.iter().copied()) => Ok(()),
        Some((line, row)) => {
            let found: Vec<&str> = row.iter().collect();
            let message = format!(
                "header {:?}, expected {:?}",
                found.join(","),
                columns.join(",")
            );
            Err(Error::line(&path, line, None, ErrorKind::Invalid(message)))
        }
        None => Err(Error::file(&path, ErrorKind::Invalid("no header".into()))),
    }
}

/// Parses a row of numbers, one per column.
fn numbers(path: &Path, line: u64, row: &StringRecord, columns: &[&str]) -> Result<Vec<f64>> {
    text::check_width(path, line, row, columns)?;
    columns
        .iter()
        .zip(row.iter())
        .map(|(column, text)| text::parse_f64(path, line, column, text))
        .collect()
}
