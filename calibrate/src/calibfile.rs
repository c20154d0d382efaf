//! The calibration file (TOML): the model, its parameters and covariance, the local gravity it
//! refers to, and what it was fitted from.
//!
//! Compatibility: every field added after format version 1 must carry `#[serde(default)]` (an
//! `Option` or a section that defaults to empty), so files written by older versions still load.
//! Unknown keys are refused, in every table: a misspelt key would otherwise be a term silently
//! left out, and a reader older than a file's new key names that key. `format_version` changes
//! only when a field's *meaning* changes. Optional sections ([`NoiseSection`],
//! [`TemperatureTerms`], ...) may be absent.
//!
//! Units: parameters in g (biases) and dimensionless (`S`), see [`crate::model`]; the
//! covariance in the 12-parameter layout (`param_names`); gravity in m/s^2; temperatures in
//! degC; residuals in g.

/// The bounds [`CalibrationFile::check_plausible`] holds a file to.
pub mod plausibility;

#[cfg(test)]
mod tests;

use std::path::Path;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

pub use crate::gravity::{GRAVITY_RANGE_MPS2, check_gravity};
use crate::model::{AccelModel, ModelKind, N_PARAMS, PARAM_NAMES, ParamCovariance};
use crate::terms::{ReadingTerms, TermsError};

/// Format version written by this code.
pub const FORMAT_VERSION: u32 = 1;

/// Where the parse error at byte `span` of `text` is: `line L of [table]` (the last table
/// header before it), or `line L` at the top level.
fn parse_location(text: &str, span: Option<std::ops::Range<usize>>) -> String {
    let Some(span) = span else {
        return "the file".into();
    };
    let start = span.start.min(text.len());
    let line = text[..start].matches('\n').count() + 1;
    // Up to the end of the error's line: a table's error starts at its own header.
    let end = text[start..].find('\n').map_or(text.len(), |n| start + n);
    match text[..end].lines().rev().find_map(table_header) {
        Some(table) => format!("line {line} of [{table}]"),
        None => format!("line {line}"),
    }
}

/// The table a line such as `[noise.accel.x]` opens, or `None` for any other line (a key, or
/// a row of a multi-line array such as `[0.0, 1.0],`).
fn table_header(line: &str) -> Option<&str> {
    let (name, rest) = line.trim().strip_prefix('[')?.split_once(']')?;
    let rest = rest.trim();
    let named = name.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_' || c == '"');
    (named && !name.contains(',') && (rest.is_empty() || rest.starts_with('#'))).then_some(name)
}

/// How poses are weighted (see `calibrate_science::fit`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Weighting {
    /// Ordinary least squares.
    Unweighted,
    /// Weights `1/sigma^2` from each pose's std (standard error of the mean when `n` is known).
    PoseStd,
}

/// How the parameter covariance was obtained (see `calibrate_science::fit`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CovarianceMode {
    /// `s^2 (X^T W X)^-1` with `s^2 = chi^2 / dof` estimated from the residuals.
    ResidualScaled,
    /// `(X^T W X)^-1` with sigmas taken as known.
    Absolute,
}

/// How the parameters were estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FitMethod {
    /// Labelled linear least squares (`calibrate_science::fit`).
    Labelled,
    /// Label-free Levenberg-Marquardt on `|a| = 1 g` (`calibrate_science::labelfree`).
    LabelFree,
}

/// What the calibration was fitted from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceSection {
    /// The input file, as given on the command line.
    pub file: String,
    /// Its kind: "six_position_means", "thesis_csv", "canonical_csv" or "mcap".
    pub kind: String,
    /// Number of poses fitted.
    pub poses: usize,
    /// Torn-read repairs applied before fitting (raw inputs only).
    #[serde(default)]
    pub repaired_samples: usize,
}

/// Residual statistics of the fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResidualSection {
    /// Root-mean-square residual per axis (labelled) or of the magnitude (label-free, all three
    /// entries equal), g.
    pub rms_g: [f64; 3],
    /// Largest absolute residual, g.
    pub max_abs_g: f64,
    /// Degrees of freedom per axis (label-free: the same number three times).
    pub dof: [usize; 3],
    /// Weighted sum of squared residuals per axis.
    pub chi2: [f64; 3],
    /// Residual per pose, g: `[x, y, z]` (labelled: measured minus predicted) or
    /// `[|a| - 1, 0, 0]` (label-free).
    pub per_pose_g: Vec<[f64; 3]>,
}

/// The `[noise]` table: the sensor's noise parameters from an Allan analysis of a static
/// recording (`mems-calibrate allan --into`), per axis in SI units with their 1-sigma (see
/// [`crate::noise_params`]). The one source of truth for the zero-state detectors' noise levels, the
/// odometry filter's noise model and `mems-eval static`'s uncertainty propagation.
pub type NoiseSection = crate::noise_params::NoiseParams;

/// Keys of the `[noise]` table written by format-1 files before the Allan analysis existed (a
/// per-sample sigma from static-segment detection); such a table is read as "no noise
/// parameters".
const LEGACY_NOISE_KEYS: [&str; 2] = ["white_sigma_g", "sample_rate_hz"];

/// Reads the `[noise]` table: absent, empty or legacy-only means `None`; anything else must be
/// a complete [`NoiseSection`] (values are checked by [`CalibrationFile::load`]).
fn deserialize_noise<'de, D>(deserializer: D) -> Result<Option<NoiseSection>, D::Error>
where
    D: serde::Deserializer<'de>,
{
    use serde::de::Error as _;
    let table = toml::Table::deserialize(deserializer)?;
    if table
        .keys()
        .all(|k| LEGACY_NOISE_KEYS.contains(&k.as_str()))
    {
        return Ok(None);
    }
    toml::Value::Table(table.clone())
        .try_into::<NoiseSection>()
        .map(Some)
        .map_err(|e| {
            D::Error::custom(format!(
                "in [{}]: {}",
                failing_noise_table(&table),
                e.message()
            ))
        })
}

/// The innermost table of a `[noise]` table that fails to read on its own, as a TOML path
/// (`noise.accel.z`): the one an error of the whole table is about.
fn failing_noise_table(table: &toml::Table) -> String {
    use crate::noise_params::{AxisNoise, SensorNoise};
    for sensor in ["accel", "gyro"] {
        let Some(toml::Value::Table(t)) = table.get(sensor) else {
            continue;
        };
        for axis in ["x", "y", "z"] {
            if let Some(v) = t.get(axis)
                && v.clone().try_into::<AxisNoise>().is_err()
            {
                return format!("noise.{sensor}.{axis}");
            }
        }
        if toml::Value::Table(t.clone())
            .try_into::<SensorNoise>()
            .is_err()
        {
            return format!("noise.{sensor}");
        }
    }
    "noise".into()
}

/// Temperature terms of the model (empty until a fit estimates them, e.g. `mems-calibrate
/// diagnose --out`): with `dT = T_die - reference_c`, the reading is
/// `a' = (S + diag(scale_per_c) dT) a + b + bias_g_per_c dT` (see [`crate::terms`]).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TemperatureTerms {
    /// Reference temperature of the terms, degC.
    #[serde(default)]
    pub reference_c: Option<f64>,
    /// Bias change per degC, g/degC.
    #[serde(default)]
    pub bias_g_per_c: Option<[f64; 3]>,
    /// Change of the diagonal of `S` per degC, 1/degC.
    #[serde(default)]
    pub scale_per_c: Option<[f64; 3]>,
}

/// Bias terms in the time since power-on `t` (s, from the first sample of a stream): the
/// reading gains `drift_g_per_s min(t, drift_max_s) + warm_up_g exp(-t / warm_up_time_constant_s)`
/// (see [`crate::terms`]). The drift is held at its value at `drift_max_s`, the longest time the
/// fit saw, rather than extrapolated.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeTerms {
    /// Linear bias drift, g/s.
    #[serde(default)]
    pub drift_g_per_s: Option<[f64; 3]>,
    /// Time since power-on after which the drift term stays constant, s.
    #[serde(default)]
    pub drift_max_s: Option<f64>,
    /// Warm-up transient at power-on, g.
    #[serde(default)]
    pub warm_up_g: Option<[f64; 3]>,
    /// Time constant of the warm-up transient, s.
    #[serde(default)]
    pub warm_up_time_constant_s: Option<f64>,
}

/// Scale nonlinearity: the reading gains `quadratic_g_per_g2 * a_i^2` on each axis `i`, with
/// `a` the true specific force in g (see [`crate::terms`]).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NonlinearityTerms {
    /// Quadratic coefficient per axis, g/g^2.
    #[serde(default)]
    pub quadratic_g_per_g2: Option<[f64; 3]>,
}

/// Gyroscope terms (optional: present once a gyroscope calibration estimates them).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GyroSection {
    /// Zero-rate bias, deg/s, sensor frame: subtracted from every reading.
    #[serde(default)]
    pub bias_dps: Option<[f64; 3]>,
    /// Scale and misalignment correction `C`, row-major, dimensionless: the angular rate is
    /// `omega = C w` with `w` the bias-free reading, sensor frame (as
    /// `odometry::config::OdometryConfig::gyro_correction`; `mems-odometry gyrocal --into`).
    #[serde(default)]
    pub correction: Option<[[f64; 3]; 3]>,
    /// 1-sigma of each entry of `correction`, row-major, dimensionless.
    #[serde(default)]
    pub correction_sigma: Option<[[f64; 3]; 3]>,
}

/// The calibration file's contents.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationFile {
    /// File format version ([`FORMAT_VERSION`]).
    pub format_version: u32,
    /// Model kind.
    pub model: ModelKind,
    /// Estimation method.
    pub method: FitMethod,
    /// Weighting of the poses.
    pub weighting: Weighting,
    /// How the covariance was obtained.
    pub covariance_mode: CovarianceMode,
    /// Local gravity the g units refer to, m/s^2.
    pub gravity_mps2: f64,
    /// Bias `b`, g.
    pub bias_g: [f64; 3],
    /// `S`, row-major.
    pub scale: [[f64; 3]; 3],
    /// Parameter names in covariance order.
    pub param_names: Vec<String>,
    /// 12 x 12 parameter covariance, rows in `param_names` order.
    pub covariance: Vec<Vec<f64>>,
    /// 1-sigma per parameter (square root of the diagonal).
    pub sigma: Vec<f64>,
    /// Die temperature range seen in the fitted data, degC (absent when unknown).
    #[serde(default)]
    pub temperature_range_c: Option<[f64; 2]>,
    /// What was fitted.
    pub source: SourceSection,
    /// Residual statistics.
    pub residuals: ResidualSection,
    /// Noise parameters (the `[noise]` table), when an Allan analysis has been stored.
    #[serde(
        default,
        deserialize_with = "deserialize_noise",
        skip_serializing_if = "Option::is_none"
    )]
    pub noise: Option<NoiseSection>,
    /// Temperature terms, when fitted.
    #[serde(default)]
    pub temperature: TemperatureTerms,
    /// Terms in the time since power-on, when fitted.
    #[serde(default)]
    pub time: TimeTerms,
    /// Scale nonlinearity, when fitted.
    #[serde(default)]
    pub nonlinearity: NonlinearityTerms,
    /// Gyroscope terms, when calibrated.
    #[serde(default)]
    pub gyro: GyroSection,
}

/// Why a calibration file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum CalibFileError {
    /// The file could not be read or written.
    // The cause is part of the message, not a `source()`: an error chain prints it once.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: String,
        /// The OS error.
        error: std::io::Error,
    },
    /// The TOML is malformed, misses a key or has one this reader does not know.
    #[error("{path}: {location}: {message}")]
    Parse {
        /// The file.
        path: String,
        /// Where: the line and the table (`line 12 of [gyro]`).
        location: String,
        /// The parser's message.
        message: String,
    },
    /// The contents are inconsistent.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: String,
        /// What is wrong.
        message: String,
    },
}

impl CalibrationFile {
    /// Builds the file contents from a fitted model and its covariance.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        model: &AccelModel,
        covariance: &ParamCovariance,
        method: FitMethod,
        weighting: Weighting,
        covariance_mode: CovarianceMode,
        gravity_mps2: f64,
        source: SourceSection,
        residuals: ResidualSection,
    ) -> Self {
        let mut file = Self {
            format_version: FORMAT_VERSION,
            model: model.kind(),
            method,
            weighting,
            covariance_mode,
            gravity_mps2,
            bias_g: [0.0; 3],
            scale: [[0.0; 3]; 3],
            param_names: PARAM_NAMES.iter().map(|s| s.to_string()).collect(),
            covariance: Vec::new(),
            sigma: Vec::new(),
            temperature_range_c: None,
            source,
            residuals,
            noise: None,
            temperature: TemperatureTerms::default(),
            time: TimeTerms::default(),
            nonlinearity: NonlinearityTerms::default(),
            gyro: GyroSection::default(),
        };
        file.set_accel_model(model, covariance);
        file
    }

    /// Replaces the accelerometer model (its kind, bias and `S`) and the parameter covariance
    /// (and so the sigmas), keeping the rest of the file. With [`CalibrationFile::identity`],
    /// the one way to build a file around a model of one's own, as tests do.
    pub fn set_accel_model(&mut self, model: &AccelModel, covariance: &ParamCovariance) {
        let s = model.scale();
        self.model = model.kind();
        self.bias_g = [model.bias_g().x, model.bias_g().y, model.bias_g().z];
        self.scale = std::array::from_fn(|r| std::array::from_fn(|c| s[(r, c)]));
        self.covariance = (0..N_PARAMS)
            .map(|r| (0..N_PARAMS).map(|c| covariance[(r, c)]).collect())
            .collect();
        self.sigma = (0..N_PARAMS)
            .map(|k| covariance[(k, k)].max(0.0).sqrt())
            .collect();
    }

    /// An identity model-3 calibration (S = I, b = 0, zero covariance, no fit behind it) at
    /// local gravity `gravity_mps2` (m/s^2): for a sensor whose output is already calibrated,
    /// such as the simulator's calibrated part, so that the live stage only converts units,
    /// detects rest and refines the biases.
    pub fn identity(gravity_mps2: f64) -> Self {
        Self::new(
            &AccelModel::identity(ModelKind::Full),
            &ParamCovariance::zeros(),
            FitMethod::Labelled,
            Weighting::Unweighted,
            CovarianceMode::ResidualScaled,
            gravity_mps2,
            SourceSection {
                file: "identity".into(),
                kind: "none".into(),
                poses: 0,
                repaired_samples: 0,
            },
            ResidualSection {
                rms_g: [0.0; 3],
                max_abs_g: 0.0,
                dof: [0; 3],
                chi2: [0.0; 3],
                per_pose_g: Vec::new(),
            },
        )
    }

    /// Whether the accelerometer model was fitted to poses: `false` for
    /// [`CalibrationFile::identity`] (no fit behind it), whose part may read gravity several
    /// percent off (`zero_state::learn::UNCALIBRATED_GRAVITY_ERROR`).
    pub fn accel_fitted(&self) -> bool {
        self.source.poses > 0
    }

    /// An error seen in the corrected output, `error_mps2` (m/s^2, sensor frame), as the raw
    /// reading's bias it comes from: the stage corrects `a = g S^-1 (a' - b)`, so an output
    /// reading `error_mps2` too much is a raw bias of `S error_mps2 / g` (g).
    pub fn raw_bias_g(&self, error_mps2: &Vector3<f64>) -> Vector3<f64> {
        let s = nalgebra::Matrix3::from_fn(|r, c| self.scale[r][c]);
        s * error_mps2 / self.gravity_mps2
    }

    /// The model described by the file.
    pub fn accel_model(&self) -> Result<AccelModel, crate::model::ModelError> {
        let s = nalgebra::Matrix3::from_fn(|r, c| self.scale[r][c]);
        AccelModel::new(self.model, s, nalgebra::Vector3::from(self.bias_g))
    }

    /// The parameter covariance as a matrix.
    pub fn covariance_matrix(&self) -> ParamCovariance {
        ParamCovariance::from_fn(|r, c| self.covariance[r][c])
    }

    /// Serialises to TOML text.
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("every field is serialisable")
    }

    /// Writes the file.
    pub fn save(&self, path: &Path) -> Result<(), CalibFileError> {
        std::fs::write(path, self.to_toml()).map_err(|error| CalibFileError::Io {
            path: path.display().to_string(),
            error,
        })
    }

    /// Checks that the parameters describe a real MEMS part (see [`plausibility`]): `S` and
    /// the gyroscope correction near the identity and well conditioned, biases within a few
    /// times the datasheet's tolerances, covariance and sigmas finite and non-negative. The
    /// message names the field.
    pub fn check_plausible(&self) -> Result<(), String> {
        let p = plausibility::PLAUSIBLE;
        plausibility::near_identity("scale", &self.scale, &p)?;
        for (i, b) in self.bias_g.iter().enumerate() {
            if !plausibility::within(*b, p.accel_bias_g) {
                return Err(format!(
                    "bias_g[{i}] = {b:?} g is not a MEMS accelerometer's bias (limit {} g)",
                    p.accel_bias_g
                ));
            }
        }
        for (i, v) in self.sigma.iter().enumerate() {
            if !(v.is_finite() && *v >= 0.0) {
                return Err(format!("sigma[{i}] = {v:?} must be finite and >= 0"));
            }
        }
        for (r, row) in self.covariance.iter().enumerate() {
            if let Some(c) = row.iter().position(|v| !v.is_finite()) {
                return Err(format!("covariance[{r}][{c}] = {:?} is not finite", row[c]));
            }
            if row[r] < 0.0 {
                return Err(format!(
                    "covariance[{r}][{r}] = {} is a negative variance",
                    row[r]
                ));
            }
        }
        plausibility::covariance(&self.covariance)?;
        if let Some(bias) = self.gyro.bias_dps
            && let Some(i) = bias
                .iter()
                .position(|b| !plausibility::within(*b, p.gyro_bias_dps))
        {
            return Err(format!(
                "gyro.bias_dps[{i}] = {:?} deg/s is not a MEMS gyroscope's bias (limit {} deg/s)",
                bias[i], p.gyro_bias_dps
            ));
        }
        if let Some(c) = &self.gyro.correction {
            plausibility::near_identity("gyro.correction", c, &p)?;
        }
        Ok(())
    }

    /// Checks the format version, the covariance's shape and the gravity.
    fn check_layout(&self) -> Result<(), String> {
        if self.format_version > FORMAT_VERSION {
            return Err(format!(
                "format_version {} is newer than this program understands ({FORMAT_VERSION})",
                self.format_version
            ));
        }
        if self.covariance.len() != N_PARAMS || self.covariance.iter().any(|r| r.len() != N_PARAMS)
        {
            return Err(format!(
                "covariance must be {N_PARAMS} rows of {N_PARAMS} values"
            ));
        }
        check_gravity(self.gravity_mps2)
            .map_err(|e| format!("gravity_mps2 = {e}: set it to your site's gravity"))
    }

    /// Checks that the optional terms are finite (and the gyro correction's sigmas >= 0).
    fn check_terms_finite(&self) -> Result<(), String> {
        let t = &self.temperature;
        let time = &self.time;
        let extra = [
            ("temperature.reference_c", t.reference_c.map(|r| [r; 3])),
            ("temperature.bias_g_per_c", t.bias_g_per_c),
            ("temperature.scale_per_c", t.scale_per_c),
            ("time.drift_g_per_s", time.drift_g_per_s),
            ("time.drift_max_s", time.drift_max_s.map(|r| [r; 3])),
            ("time.warm_up_g", time.warm_up_g),
            (
                "time.warm_up_time_constant_s",
                time.warm_up_time_constant_s.map(|r| [r; 3]),
            ),
            (
                "nonlinearity.quadratic_g_per_g2",
                self.nonlinearity.quadratic_g_per_g2,
            ),
            ("gyro.bias_dps", self.gyro.bias_dps),
        ];
        for (name, values) in extra {
            if let Some(v) = values
                && v.iter().any(|x| !x.is_finite())
            {
                return Err(format!("{name} must be finite, got {v:?}"));
            }
        }
        let matrices = [
            ("gyro.correction", self.gyro.correction, "finite", f64::MIN),
            (
                "gyro.correction_sigma",
                self.gyro.correction_sigma,
                "finite and >= 0",
                0.0,
            ),
        ];
        for (name, rows, what, min) in matrices {
            if let Some(m) = rows
                && m.iter().flatten().any(|x| !(x.is_finite() && *x >= min))
            {
                return Err(format!("{name} must be {what}, got {m:?}"));
            }
        }
        Ok(())
    }

    /// Reads and checks a file: parses, then checks the version, the covariance shape, that
    /// the parameters form a valid model of the stated kind, and that they are plausible
    /// ([`Self::check_plausible`]).
    pub fn load(path: &Path) -> Result<Self, CalibFileError> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|error| CalibFileError::Io {
            path: name.clone(),
            error,
        })?;
        let file: Self = toml::from_str(&text).map_err(|error| CalibFileError::Parse {
            path: name.clone(),
            location: parse_location(&text, error.span()),
            message: error.message().to_owned(),
        })?;
        let invalid = |message: String| CalibFileError::Invalid {
            path: name.clone(),
            message,
        };
        file.check_layout().map_err(invalid)?;
        file.accel_model().map_err(|e| invalid(e.to_string()))?;
        file.check_terms_finite().map_err(invalid)?;
        ReadingTerms::from_file(&file).map_err(|e| invalid(e.to_string()))?;
        file.check_plausible().map_err(invalid)?;
        if let Some(noise) = &file.noise {
            noise
                .validate()
                .map_err(|e| invalid(format!("noise.{}: {}", e.field, e.problem)))?;
        }
        Ok(file)
    }
}

impl ReadingTerms {
    /// The terms of a calibration file, checking that the parts of each term come together
    /// (a temperature term with its `reference_c`, the drift with `drift_max_s`, the warm-up
    /// with a positive time constant).
    pub fn from_file(file: &CalibrationFile) -> Result<Self, TermsError> {
        let t = &file.temperature;
        let any_temperature = t.bias_g_per_c.is_some() || t.scale_per_c.is_some();
        if any_temperature != t.reference_c.is_some() {
            return Err(TermsError(
                "temperature: bias_g_per_c or scale_per_c and reference_c must be given together"
                    .into(),
            ));
        }
        let time = &file.time;
        let drift = match (time.drift_g_per_s, time.drift_max_s) {
            (None, None) => None,
            (Some(r), Some(t_max)) if t_max > 0.0 => Some((Vector3::from(r), t_max)),
            _ => {
                return Err(TermsError(
                    "time: drift_g_per_s and drift_max_s (> 0 s) must be given together".into(),
                ));
            }
        };
        let warm_up = match (time.warm_up_g, time.warm_up_time_constant_s) {
            (None, None) => None,
            (Some(w), Some(tau)) if tau > 0.0 => Some((Vector3::from(w), tau)),
            _ => {
                return Err(TermsError(
                    "time: warm_up_g and warm_up_time_constant_s (> 0 s) must be given together"
                        .into(),
                ));
            }
        };
        Ok(Self {
            reference_c: t.reference_c,
            temp_bias_g_per_c: t.bias_g_per_c.map(Vector3::from),
            temp_scale_per_c: t.scale_per_c.map(Vector3::from),
            drift,
            warm_up,
            quadratic_g_per_g2: file.nonlinearity.quadratic_g_per_g2.map(Vector3::from),
        })
    }
}
