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

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::model::{AccelModel, ModelKind, N_PARAMS, PARAM_NAMES, ParamCovariance};

/// Format version written by this code.
pub const FORMAT_VERSION: u32 = 1;

/// The local gravity a file may state, m/s^2: every place on the Earth's surface. Normal
/// gravity at sea level runs from 9.7803 (equator) to 9.8322 (poles) (WGS 84, Somigliana's
/// formula) and falls by 3.1e-6 m/s^2 per metre of height; the lowest surface value, on the
/// summit of Huascaran (6768 m, 9 deg S), is 9.7639 and the highest, on the Arctic Ocean, 9.8337.
/// A value outside is a typo or a damaged file (1e6, 9.81e3 in mm/s^2, 1.0 in g).
pub const GRAVITY_RANGE_MPS2: (f64, f64) = (9.76, 9.84);

/// Checks that `value` (a local gravity, m/s^2) is within [`GRAVITY_RANGE_MPS2`]; the error
/// says what is wrong with the value, for the caller to name where it came from.
pub fn check_gravity(value: f64) -> Result<(), String> {
    let (lo, hi) = GRAVITY_RANGE_MPS2;
    if value >= lo && value <= hi {
        return Ok(());
    }
    Err(format!(
        "{value:?} m/s^2 is not the gravity of any place on Earth ({lo} to {hi} m/s^2)"
    ))
}

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
        crate::terms::ReadingTerms::from_file(&file).map_err(|e| invalid(e.to_string()))?;
        file.check_plausible().map_err(invalid)?;
        if let Some(noise) = &file.noise {
            noise
                .validate()
                .map_err(|e| invalid(format!("noise.{}: {}", e.field, e.problem)))?;
        }
        Ok(file)
    }
}

/// The bounds [`CalibrationFile::check_plausible`] holds a file to.
pub mod plausibility {
    use nalgebra::{DMatrix, Matrix3};

    use crate::model::PARAM_NAMES;

    /// Bounds on the parameters of a real part.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct Bounds {
        /// Largest distance of a diagonal entry of `S` (or the gyroscope correction) from 1.
        pub scale_error: f64,
        /// Largest magnitude of an off-diagonal entry (cross-axis sensitivity, misalignment).
        pub cross_axis: f64,
        /// Largest condition number (largest over smallest singular value).
        pub condition: f64,
        /// Largest accelerometer bias per axis, g.
        pub accel_bias_g: f64,
        /// Largest gyroscope bias per axis, deg/s.
        pub gyro_bias_dps: f64,
    }

    /// The MPU-9250's tolerances (PS-MPU-9250A-01 rev 1.1, tables 3.1 and 3.2: sensitivity
    /// +-3 %, cross-axis sensitivity +-2 %, zero-g offset +-60/+-80 mg, zero-rate offset
    /// +-5 deg/s) widened several times for other parts, temperature and mounting: a file
    /// beyond them holds a fit that failed or a damaged value.
    pub const PLAUSIBLE: Bounds = Bounds {
        scale_error: 0.2,
        cross_axis: 0.1,
        condition: 1.5,
        accel_bias_g: 0.5,
        gyro_bias_dps: 50.0,
    };

    /// Relative tolerance of the covariance checks, as a fraction of its largest variance:
    /// far above the rounding of a fit's `V diag(1/s^2) V^T` (1e-16) and of a TOML round trip
    /// (exact), far below any real correlation.
    const COVARIANCE_TOLERANCE: f64 = 1e-9;

    /// Checks that the parameter covariance `c` (square, finite, rows in `PARAM_NAMES` order)
    /// is symmetric and positive semi-definite, as every covariance is: a damaged or hand-made
    /// one would give some combination of parameters a negative variance. The zero matrix of
    /// an identity calibration passes.
    pub fn covariance(c: &[Vec<f64>]) -> Result<(), String> {
        let n = c.len();
        let m = DMatrix::from_fn(n, n, |r, k| c[r][k]);
        let tol = COVARIANCE_TOLERANCE * m.diagonal().amax();
        for r in 0..n {
            for k in r + 1..n {
                if (m[(r, k)] - m[(k, r)]).abs() > tol {
                    return Err(format!(
                        "covariance is not symmetric: covariance[{r}][{k}] = {:?} but \
                         covariance[{k}][{r}] = {:?}",
                        m[(r, k)],
                        m[(k, r)]
                    ));
                }
            }
        }
        let eigen = m.symmetric_eigen();
        let (i, smallest) = eigen.eigenvalues.argmin();
        if smallest < -tol {
            let v = eigen.eigenvectors.column(i);
            let along: Vec<&str> = (0..n)
                .filter(|&k| v[k].abs() > 0.3)
                .map(|k| PARAM_NAMES.get(k).copied().unwrap_or("?"))
                .collect();
            return Err(format!(
                "covariance is not positive semi-definite: a combination of {} has the variance \
                 {smallest:.3e} (no variance is negative)",
                along.join(" and ")
            ));
        }
        Ok(())
    }

    /// Whether `v` is a number of magnitude at most `limit` (false for NaN).
    pub fn within(v: f64, limit: f64) -> bool {
        v.abs() <= limit
    }

    /// Checks that `m` (named `name`, row-major) is near the identity and well conditioned.
    pub fn near_identity(name: &str, m: &[[f64; 3]; 3], b: &Bounds) -> Result<(), String> {
        for (r, row) in m.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                let (off, limit, what) = if r == c {
                    (
                        (v - 1.0).abs(),
                        b.scale_error,
                        "a scale factor farther than",
                    )
                } else {
                    (v.abs(), b.cross_axis, "a cross-axis term larger than")
                };
                if !within(off, limit) {
                    return Err(format!(
                        "{name}[{r}][{c}] = {v:?} is not plausible ({what} {limit} from the identity)"
                    ));
                }
            }
        }
        let sv = Matrix3::from_fn(|r, c| m[r][c]).singular_values();
        let condition = sv.max() / sv.min();
        if !within(condition, b.condition) {
            return Err(format!(
                "{name} has condition number {condition:.3}, more than {}",
                b.condition
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, Vector3};

    /// The identity file round-trips through TOML and its model leaves a reading unchanged.
    #[test]
    fn identity_file_leaves_readings_unchanged() {
        let file = CalibrationFile::identity(9.797);
        assert_eq!(file.gravity_mps2, 9.797);
        assert!(file.sigma.iter().all(|&s| s == 0.0));
        let path = std::env::temp_dir().join(format!("identity-{}.toml", std::process::id()));
        file.save(&path).unwrap();
        let back = CalibrationFile::load(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        let reading = Vector3::new(0.01, -0.98, 0.2);
        assert_eq!(back.accel_model().unwrap().correct(&reading), reading);
    }

    fn example() -> CalibrationFile {
        let s = Matrix3::new(
            1.0, 0.008, 0.009, -0.006, 1.0004, 0.0106, -0.0102, -0.0044, 1.022,
        );
        let m = AccelModel::new(ModelKind::Full, s, Vector3::new(0.0916, 0.0473, -0.2502)).unwrap();
        let mut cov = ParamCovariance::identity() * 1e-8;
        cov[(0, 3)] = 2e-9;
        cov[(3, 0)] = 2e-9;
        let source = SourceSection {
            file: "six.csv".into(),
            kind: "six_position_means".into(),
            poses: 6,
            repaired_samples: 0,
        };
        let residuals = ResidualSection {
            rms_g: [1e-3, 2e-3, 3e-3],
            max_abs_g: 4e-3,
            dof: [2, 2, 2],
            chi2: [1e-6, 2e-6, 3e-6],
            per_pose_g: vec![[1e-3, -1e-3, 0.0]; 6],
        };
        CalibrationFile::new(
            &m,
            &cov,
            FitMethod::Labelled,
            Weighting::Unweighted,
            CovarianceMode::ResidualScaled,
            9.797,
            source,
            residuals,
        )
    }

    #[test]
    fn round_trips_through_toml() {
        let f = example();
        let back: CalibrationFile = toml::from_str(&f.to_toml()).unwrap();
        assert_eq!(back, f);
        assert_eq!(back.accel_model().unwrap(), f.accel_model().unwrap());
        assert_eq!(back.covariance_matrix()[(0, 3)], 2e-9);
    }

    #[test]
    fn fitted_terms_round_trip_and_incomplete_ones_are_refused() {
        let dir = std::env::temp_dir().join(format!("calibfile-terms-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("terms.toml");
        let mut f = example();
        f.temperature.reference_c = Some(27.5);
        f.temperature.scale_per_c = Some([2e-4, -1e-4, 3e-4]);
        f.time.drift_g_per_s = Some([1e-6, -2e-6, 3e-6]);
        f.time.drift_max_s = Some(60.0);
        f.time.warm_up_g = Some([1e-3, 0.0, -2e-3]);
        f.time.warm_up_time_constant_s = Some(12.0);
        f.nonlinearity.quadratic_g_per_g2 = Some([0.002, -0.001, 0.003]);
        f.save(&path).unwrap();
        assert_eq!(CalibrationFile::load(&path).unwrap(), f);
        type Spoil = fn(&mut CalibrationFile);
        let cases: [(&str, Spoil); 4] = [
            ("drift_max_s", |f| f.time.drift_max_s = None),
            ("warm_up_time_constant_s", |f| {
                f.time.warm_up_time_constant_s = Some(0.0)
            }),
            ("reference_c", |f| f.temperature.reference_c = None),
            ("nonlinearity.quadratic_g_per_g2", |f| {
                f.nonlinearity.quadratic_g_per_g2 = Some([f64::NAN, 0.0, 0.0])
            }),
        ];
        for (name, spoil) in cases {
            let mut g = f.clone();
            spoil(&mut g);
            g.save(&path).unwrap();
            let err = CalibrationFile::load(&path).unwrap_err().to_string();
            assert!(err.contains("terms.toml") && err.contains(name), "{err}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_gyro_correction_round_trips_and_is_checked_on_load() {
        let dir = std::env::temp_dir().join(format!("calibfile-gyro-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("gyro.toml");
        let mut f = example();
        f.gyro.bias_dps = Some([0.5, -0.2, 0.1]);
        f.gyro.correction = Some([
            [0.99, -0.005, 0.005],
            [0.005, 1.01, -0.005],
            [-0.005, 0.005, 0.99],
        ]);
        f.gyro.correction_sigma = Some([[1e-4, 2e-4, 3e-4]; 3]);
        f.save(&path).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let table: toml::Table = toml::from_str(&text).unwrap();
        assert_eq!(
            table["gyro"]["correction"][1][1].as_float(),
            Some(1.01),
            "row-major under [gyro]: {text}"
        );
        assert_eq!(CalibrationFile::load(&path).unwrap(), f);

        // A [gyro] table written before the correction existed (bias only) loads without one.
        let mut older = table.clone();
        let gyro = older["gyro"].as_table_mut().unwrap();
        gyro.remove("correction");
        gyro.remove("correction_sigma");
        std::fs::write(&path, toml::to_string(&older).unwrap()).unwrap();
        let back = CalibrationFile::load(&path).unwrap();
        assert_eq!(back.gyro.bias_dps, f.gyro.bias_dps);
        assert_eq!(
            (back.gyro.correction, back.gyro.correction_sigma),
            (None, None)
        );

        type Spoil = fn(&mut CalibrationFile);
        let cases: [(&str, Spoil); 3] = [
            ("gyro.correction must be finite", |f| {
                f.gyro.correction.as_mut().unwrap()[2][0] = f64::INFINITY
            }),
            ("gyro.correction_sigma must be finite and >= 0", |f| {
                f.gyro.correction_sigma.as_mut().unwrap()[0][1] = f64::NAN
            }),
            ("gyro.correction_sigma must be finite and >= 0", |f| {
                f.gyro.correction_sigma.as_mut().unwrap()[1][2] = -1e-4
            }),
        ];
        for (message, spoil) in cases {
            let mut g = f.clone();
            spoil(&mut g);
            g.save(&path).unwrap();
            let err = CalibrationFile::load(&path).unwrap_err().to_string();
            assert!(err.contains("gyro.toml") && err.contains(message), "{err}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn older_files_without_optional_sections_load_and_unknown_keys_are_refused() {
        let mut value: toml::Table = toml::from_str(&example().to_toml()).unwrap();
        value.remove("noise");
        value.remove("temperature");
        value.remove("temperature_range_c");
        value.remove("gyro");
        value.remove("time");
        value.remove("nonlinearity");
        let text = toml::to_string(&value).unwrap();
        let back: CalibrationFile = toml::from_str(&text).unwrap();
        assert_eq!(back.noise, None);
        assert_eq!(back.temperature_range_c, None);
        assert_eq!(back.gyro, GyroSection::default());
        assert_eq!(back.time, TimeTerms::default());
        assert_eq!(back.nonlinearity, NonlinearityTerms::default());

        // A key no table has, at the top, in a table, and deep in [noise]: refused naming the
        // file, the line, the table and the key.
        let dir = std::env::temp_dir().join(format!("calibfile-keys-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("keys.toml");
        let mut with_noise = example();
        with_noise.noise = Some(crate::noise_params::tests::sample());
        let good = with_noise.to_toml();
        let cases = [
            (
                good.replacen("gravity_mps2 =", "gravity = 9.8\ngravity_mps2 =", 1),
                "keys.toml: line 6: unknown field `gravity`",
            ),
            (
                good.replacen("[source]\n", "[source]\nfiles = 2\n", 1),
                "of [source]: unknown field `files`",
            ),
            (
                good.replacen(
                    "[noise.accel.y.white_noise_density]\n",
                    "[noise.accel.y.white_noise_density]\nvalu = 1.0\n",
                    1,
                ),
                "of [noise]: in [noise.accel.y]: unknown field `valu`",
            ),
        ];
        for (text, expected) in cases {
            std::fs::write(&path, text).unwrap();
            let err = CalibrationFile::load(&path).unwrap_err().to_string();
            assert!(err.contains(expected), "{err}");
        }
        std::fs::write(&path, good).unwrap();
        assert_eq!(CalibrationFile::load(&path).unwrap(), with_noise);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn gravity_and_covariance_are_checked_on_load() {
        let dir = std::env::temp_dir().join(format!("calibfile-cov-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("cov.toml");
        type Spoil = fn(&mut CalibrationFile);
        let cases: [(&str, Spoil); 5] = [
            ("gravity_mps2 = 1000000.0 m/s^2 is not the gravity", |f| {
                f.gravity_mps2 = 1e6
            }),
            ("gravity_mps2 = 9.7 m/s^2", |f| f.gravity_mps2 = 9.7),
            ("gravity_mps2 = 1.0 m/s^2", |f| f.gravity_mps2 = 1.0),
            ("covariance[1][5] = 1e-9 but covariance[5][1] = 0.0", |f| {
                f.covariance[1][5] = 1e-9
            }),
            // Each variance positive, the correlation of b_x and b_y beyond 1.
            (
                "a combination of b_x and b_y has the variance -1.010e-8",
                |f| {
                    f.covariance[0][1] = 2e-8;
                    f.covariance[1][0] = 2e-8;
                },
            ),
        ];
        for (expected, spoil) in cases {
            let mut f = example();
            spoil(&mut f);
            f.save(&path).unwrap();
            let err = CalibrationFile::load(&path).unwrap_err().to_string();
            assert!(
                err.contains("cov.toml: ") && err.contains(expected),
                "{err}"
            );
        }
        // The sites at the ends of the range, and a fitted covariance with its rounding, load.
        for g in [9.7639, 9.8337] {
            let mut f = example();
            f.gravity_mps2 = g;
            f.covariance[0][3] *= 1.0 + 1e-15;
            f.save(&path).unwrap();
            CalibrationFile::load(&path).unwrap();
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn load_names_the_file_and_the_problem() {
        let dir = std::env::temp_dir().join(format!("calibfile-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("bad.toml");
        let mut f = example();
        f.covariance.pop();
        std::fs::write(&path, f.to_toml()).unwrap();
        let err = CalibrationFile::load(&path).unwrap_err().to_string();
        assert!(
            err.contains("bad.toml") && err.contains("covariance"),
            "{err}"
        );
        std::fs::write(&path, "model = \"full\"\n").unwrap();
        let err = CalibrationFile::load(&path).unwrap_err().to_string();
        assert!(
            err.contains("bad.toml") && err.contains("missing field"),
            "{err}"
        );
        let mut f = example();
        f.temperature.bias_g_per_c = Some([1e-4, 0.0, 0.0]);
        std::fs::write(&path, f.to_toml()).unwrap();
        let err = CalibrationFile::load(&path).unwrap_err().to_string();
        assert!(
            err.contains("bad.toml") && err.contains("reference_c"),
            "{err}"
        );
        let mut f = example();
        f.gyro.bias_dps = Some([0.1, f64::NAN, 0.0]);
        std::fs::write(&path, f.to_toml()).unwrap();
        let err = CalibrationFile::load(&path).unwrap_err().to_string();
        assert!(
            err.contains("bad.toml") && err.contains("gyro.bias_dps"),
            "{err}"
        );
        // Implausible values: each is refused naming the file and the field.
        type Spoil = fn(&mut CalibrationFile);
        let cases: [(&str, Spoil); 7] = [
            ("scale[0][0]", |f| f.scale[0][0] = 1e300),
            ("scale[0][0]", |f| f.scale[0][0] = -1.0),
            ("scale[1][2]", |f| f.scale[1][2] = 0.5),
            ("bias_g[2]", |f| f.bias_g[2] = 3.0),
            ("gyro.correction[0][0]", |f| {
                f.gyro.correction = Some([[0.0; 3]; 3])
            }),
            ("gyro.bias_dps[1]", |f| {
                f.gyro.bias_dps = Some([0.0, 400.0, 0.0])
            }),
            ("covariance[4][4]", |f| f.covariance[4][4] = -1e-6),
        ];
        for (field, spoil) in cases {
            let mut f = example();
            spoil(&mut f);
            std::fs::write(&path, f.to_toml()).unwrap();
            let err = CalibrationFile::load(&path).unwrap_err().to_string();
            assert!(
                err.contains("bad.toml") && err.contains(field),
                "{field}: {err}"
            );
        }
        // Entries each within bounds that together make a badly conditioned matrix.
        let mut f = example();
        f.gyro.correction = Some([[0.8, 0.1, 0.1], [0.1, 0.8, -0.1], [0.1, 0.1, 1.2]]);
        let b = plausibility::PLAUSIBLE;
        let m = f.gyro.correction.unwrap();
        let err = plausibility::near_identity("m", &m, &b).unwrap_err();
        assert!(err.contains("condition number"), "{err}");
        let good = dir.join("good.toml");
        example().save(&good).unwrap();
        assert_eq!(CalibrationFile::load(&good).unwrap(), example());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
