//! The live calibration stage: raw samples in, corrected samples out, as a state machine with
//! no I/O and no allocation per sample. `mems-calibrate serve` wraps it around iceoryx2 and
//! `mems-odometry offline` runs the same code over a recording.
//!
//! Per sample (sensor frame):
//! - accelerometer: `a = S^-1 (a' - b)` in g, with the file's optional temperature, time and
//!   nonlinearity terms undone first ([`crate::terms`]; the time since power-on is taken from
//!   the first sample of the stream), times the file's local gravity -> m/s^2, minus the bias
//!   refinement (below);
//! - gyroscope: `(w' - b_file)` deg/s -> rad/s (`b_file` when the file has a gyroscope bias),
//!   minus the refined gyroscope bias;
//! - the zero-state verdict ([`crate::zero_state`]): `ZERO_STATE`, `DETECTOR_READY`, and the
//!   deciding window's mean (refinement applied) and std (see **Latency** for when it is the
//!   sample's own batch's);
//! - `BIAS_REFINED` once a refinement has been made; `calib_id` ([`calib_id`]); stamps, `seq`,
//!   temperature and the raw flags copied (`stamps.calibrated_ns` is the process wrapper's).
//!
//! **Latency.** Every corrected sample is emitted in the call that took its raw sample: output
//! keeps input order, one corrected sample per accepted raw sample, none held back. The
//! detector decides a batch of [`BATCH_LEN`] samples at its last sample, so the samples before
//! it leave with the latest verdict carried over and `PROVISIONAL` set; the batch's last sample
//! carries the batch's verdict and `settles = n`, the number of provisional samples before it
//! that the verdict is for ([`ipc_types::CorrectedImuSample::settles`]). A consumer that needs
//! final flags waits for the settling sample ([`Settler`] does that; the odometry stage
//! navigates on the provisional flags and revises what changed). A gap (lost samples, a skipped
//! sequence number), a new stream or the end of the stream leaves the partial batch's samples
//! unsettled: their provisional flags stand.
//!
//! The bias refinement (below) subtracted from a sample is the one in force when it arrives,
//! so the refinement a batch at rest makes applies from the next sample on; every sample carries
//! the accelerometer offset subtracted (`refined_accel_mps2`), so that a consumer estimating
//! the stream's residual bias follows each change exactly.
//!
//! **Bias refinement at rest.** At rest the true specific force is gravity's reaction `g u`
//! (`u` the unknown up direction in the sensor frame) and the true rate is zero. So:
//! - the gyroscope bias is observable on all three axes (the Earth's rate, at most 0.004 deg/s,
//!   is absorbed into it, which suits an odometry that neglects it);
//! - of an accelerometer bias error `e` only the component along gravity is observable from one
//!   attitude: `|g u + e| - g = e . u + O(|e|^2 / g)`, while the components across gravity are
//!   indistinguishable from a tilt of `u`. The stage corrects that component only: with rest
//!   mean `m`, `d += k (|m - d| - g) (m - d) / |m - d|`. At one attitude this is the running
//!   mean of `|m| - g` along `u`; rests at other attitudes correct other components and leave
//!   the rest of `d` as it was. A learned rest that reads gravity more than
//!   [`crate::zero_state::learn::CALIBRATED_GRAVITY_ERROR`] off (an uncalibrated part), or any
//!   learned rest of a part declared uncalibrated
//!   ([`crate::zero_state::DetectorConfig::uncalibrated`]), is taken with no prior, and every
//!   sample after it is flagged `GRAVITY_OFF`; a declared part's are flagged from the first,
//!   whether or not its detector learns a rest (SHOE learns none).
//!
//! Only a detector whose rest means still refines ([`crate::zero_state::DetectorKind::rest_is_still`]:
//! not SHOE, whose stances roll). Both are running means over rest time (the learning interval
//! first) with a memory
//! of [`RefineConfig::memory_s`] (see [`crate::zero_state::rest_gain`]); the accelerometer's
//! starts with a prior of [`RefineConfig::accel_prior_s`] seconds of rest for the file's value.
//! The gyroscope's has none: a turn-on bias of 0.3-1 deg/s that no file can know is measured to
//! 0.01 deg/s by one second of rest.

use ipc_types::stream::range::Clipping;
use ipc_types::stream::{self, Continuity, Freezes, Holes, Step, TimeLine};
use ipc_types::{CorrectedImuSample, RawImuSample, corrected_flags, limits, raw_flags};
use mems_stage::Stage;
use nalgebra::Vector3;

use crate::calibfile::CalibrationFile;
use crate::model::AccelModel;
use crate::terms::ReadingTerms;
use crate::zero_state::{
    BATCH_LEN, DetectorConfig, NoiseFloor, StaticReference, Verdict, ZeroStateDetector,
    batch_duration_s, rest_gain,
};

/// Settings of the bias refinement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefineConfig {
    /// Weight of the calibration file's accelerometer bias, as seconds of rest (1 s of rest at
    /// the MPU-9250's noise density, 300 ug/sqrt(Hz), measures a bias to about 3 mm/s^2, the
    /// order of the turn-on repeatability a calibration cannot know).
    pub accel_prior_s: f64,
    /// Memory of the running means, seconds of rest.
    pub memory_s: f64,
}

impl Default for RefineConfig {
    /// An accelerometer prior of 1 s and a memory of 60 s.
    fn default() -> Self {
        Self {
            accel_prior_s: 1.0,
            memory_s: 60.0,
        }
    }
}

/// Why a raw sample was refused. The sample is not consumed; the stage's state is unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StageError {
    /// A field that must be finite is not.
    #[error("raw sample seq {seq} (t {t_ns} ns): {field} is not finite ({value})")]
    NotFinite {
        /// Sequence number of the sample.
        seq: u64,
        /// Its sample time, ns.
        t_ns: u64,
        /// The field, e.g. `accel_g[2]`.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// The sample time did not increase within a stream.
    #[error(
        "raw sample seq {seq}: sample time {t_ns} ns is not after the previous sample's \
         ({prev_ns} ns, seq {prev_seq})"
    )]
    TimeNotIncreasing {
        /// Sequence number of the sample.
        seq: u64,
        /// Its sample time, ns.
        t_ns: u64,
        /// Sequence number of the previous sample.
        prev_seq: u64,
        /// Its sample time, ns.
        prev_ns: u64,
    },
    /// A value the sensor cannot produce (beyond its largest range).
    #[error("raw sample seq {seq} (t {t_ns} ns): {bad}")]
    OutOfRange {
        /// Sequence number of the sample.
        seq: u64,
        /// Its sample time, ns.
        t_ns: u64,
        /// The field, its value and the bound.
        bad: limits::OutOfBounds,
    },
    /// The sample time is further after the previous sample's than
    /// [`limits::MAX_STEP_S`] (a corrupted stamp; a second such step in a row starts a new
    /// stream instead).
    #[error(
        "raw sample seq {seq}: sample time {t_ns} ns is more than {} s after the previous \
         sample's ({prev_ns} ns); dropped",
        limits::MAX_STEP_S
    )]
    TimeStep {
        /// Sequence number of the sample.
        seq: u64,
        /// Its sample time, ns.
        t_ns: u64,
        /// The previous sample's time, ns.
        prev_ns: u64,
    },
    /// The detector needs the gyroscope but the sample has none.
    #[error(
        "raw sample seq {seq} has no gyroscope measurement (GYRO_VALID clear) but the {detector} \
         detector needs one: use the glrt-accel detector or an acquisition rate with the gyroscope"
    )]
    NoGyro {
        /// Sequence number of the sample.
        seq: u64,
        /// The detector's name.
        detector: &'static str,
    },
    /// The calibration has temperature terms but the sample has no temperature.
    #[error(
        "raw sample seq {seq} has no temperature (TEMP_VALID clear) but the calibration's \
         temperature terms need one"
    )]
    NoTemperature {
        /// Sequence number of the sample.
        seq: u64,
    },
}

/// Why a calibration file cannot drive the stage.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("calibration: {0}")]
pub struct StageSetupError(String);

/// Counters of the stage since it started.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StageStats {
    /// Raw samples accepted.
    pub accepted: u64,
    /// Corrected samples emitted.
    pub released: u64,
    /// Samples whose batch was decided at rest.
    pub rest: u64,
    /// Gaps seen (the partial batch's samples stay unsettled).
    pub gaps: u64,
    /// New streams seen (sequence number not increasing).
    pub restarts: u64,
    /// Holes in the time line that nothing marked ([`ipc_types::stream`]), each a gap too.
    pub holes: Holes,
    /// Runs of samples repeating one reading for longer than a hole (a sensor that stopped
    /// updating, [`Freezes`]), each counted once it ends; the samples pass on unchanged.
    pub frozen: Holes,
    /// Samples with an axis at the end of its range (`raw_flags::SATURATED`, passed on as
    /// `corrected_flags::CLIPPED`), per axis.
    pub clipped: Clipping,
}

/// The stable identifier of a calibration: 64-bit FNV-1a over the model name and the
/// little-endian bytes of the local gravity, the 12 parameters, the temperature bias terms and
/// the gyroscope bias (absent terms hash as a marker byte), then, only when any is present (so
/// that files without them keep their identifier), the temperature scale, time and
/// nonlinearity terms. FNV-1a is written out here because std's `DefaultHasher` may change
/// between Rust releases and the identifier must not.
pub fn calib_id(file: &CalibrationFile) -> u64 {
    let mut h = Fnv1a::new();
    h.bytes(file.model.name().as_bytes());
    h.f64s(Some(&[file.gravity_mps2]));
    h.f64s(Some(&file.bias_g));
    for row in &file.scale {
        h.f64s(Some(row));
    }
    h.f64s(
        file.temperature
            .reference_c
            .as_ref()
            .map(std::slice::from_ref),
    );
    h.f64s(file.temperature.bias_g_per_c.as_ref().map(|v| &v[..]));
    h.f64s(file.gyro.bias_dps.as_ref().map(|v| &v[..]));
    let time = &file.time;
    let later: [Option<Vec<f64>>; 6] = [
        file.temperature.scale_per_c.map(|v| v.to_vec()),
        time.drift_g_per_s.map(|v| v.to_vec()),
        time.drift_max_s.map(|v| vec![v]),
        time.warm_up_g.map(|v| v.to_vec()),
        time.warm_up_time_constant_s.map(|v| vec![v]),
        file.nonlinearity.quadratic_g_per_g2.map(|v| v.to_vec()),
    ];
    if later.iter().any(Option::is_some) {
        for term in &later {
            h.f64s(term.as_deref());
        }
    }
    h.0
}

/// 64-bit FNV-1a state.
struct Fnv1a(u64);

impl Fnv1a {
    fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }

    fn bytes(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 ^= u64::from(*b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    /// A marker byte (0 absent, 1 present), then each value's little-endian bytes.
    fn f64s(&mut self, xs: Option<&[f64]>) {
        match xs {
            None => self.bytes(&[0]),
            Some(xs) => {
                self.bytes(&[1]);
                for x in xs {
                    self.bytes(&x.to_le_bytes());
                }
            }
        }
    }
}

/// The running bias refinement (see the module documentation).
#[derive(Debug, Clone, Copy)]
struct Refinement {
    config: RefineConfig,
    /// Accelerometer offset subtracted from the output, m/s^2.
    accel_mps2: Vector3<f64>,
    /// Gyroscope bias subtracted from the output, rad/s.
    gyro_rps: Vector3<f64>,
    /// Rest time the accelerometer offset was refined from, s (the prior included).
    accel_seen_s: f64,
    /// Rest time the gyroscope bias was refined from, s.
    gyro_seen_s: f64,
    refined: bool,
}

impl Refinement {
    fn new(config: RefineConfig) -> Self {
        Self {
            config,
            accel_mps2: Vector3::zeros(),
            gyro_rps: Vector3::zeros(),
            accel_seen_s: config.accel_prior_s,
            gyro_seen_s: 0.0,
            refined: false,
        }
    }

    /// Refines with a rest mean `accel` (m/s^2, file-corrected) and `gyro` (rad/s) over
    /// `duration_s`; `gyro` is `None` when the samples carry no gyroscope.
    fn update(&mut self, accel: [f64; 3], gyro: Option<[f64; 3]>, duration_s: f64, gravity: f64) {
        let memory = self.config.memory_s;
        let gain = rest_gain(duration_s, self.accel_seen_s, memory);
        self.accel_seen_s += duration_s;
        let c = Vector3::from(accel) - self.accel_mps2;
        let magnitude = c.norm();
        if magnitude > 0.0 {
            self.accel_mps2 += gain * (magnitude - gravity) * (c / magnitude);
        }
        if let Some(g) = gyro {
            let gain = rest_gain(duration_s, self.gyro_seen_s, memory);
            self.gyro_seen_s += duration_s;
            self.gyro_rps += gain * (Vector3::from(g) - self.gyro_rps);
        }
        self.refined = true;
    }
}

/// What a restarted calibration process needs to go on where its predecessor stopped, on the
/// same sensor stream: the detector's references and the bias refinement (so the corrected
/// stream neither changes its bias nor waits for a new rest to learn, and a moving robot is not
/// learned as rest), the stream's start (for the time terms) and the last sample seen. Written
/// by `mems-calibrate serve --state`; a new stream (sequence numbers starting again) discards it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WarmState {
    /// The calibration the state was made with ([`calib_id`]).
    pub calib_id: u64,
    /// The detector's reference (`None`: not learned yet, or SHOE).
    pub reference: Option<StaticReference>,
    /// Rest time the reference has been kept current over, s.
    pub rest_seen_s: f64,
    /// Accelerometer offset subtracted from the output, m/s^2.
    pub refine_accel_mps2: [f64; 3],
    /// Gyroscope bias subtracted from the output, rad/s.
    pub refine_gyro_rps: [f64; 3],
    /// Rest time the accelerometer offset was refined from, s.
    pub accel_seen_s: f64,
    /// Rest time the gyroscope bias was refined from, s.
    pub gyro_seen_s: f64,
    /// Whether a refinement was made.
    pub refined: bool,
    /// Sample time of the stream's first sample, ns.
    pub stream_start_ns: u64,
    /// Sequence number and sample time of the last sample taken, ns.
    pub last_seq: u64,
    /// Sample time of the last sample taken, ns.
    pub last_ns: u64,
}

impl WarmState {
    /// Whether the two hold the same learning (references and refinement): the stream
    /// position alone changing is no reason to write the state again.
    pub fn same_learning(&self, other: &Self) -> bool {
        self.reference == other.reference
            && self.refine_accel_mps2 == other.refine_accel_mps2
            && self.refine_gyro_rps == other.refine_gyro_rps
    }
}

/// A [`WarmState`] that does not fit the stage.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the state was made with calibration {state:016x}, the stage has {stage:016x}")]
pub struct ResumeError {
    /// The state's calibration.
    pub state: u64,
    /// The stage's.
    pub stage: u64,
}

/// The calibration stage (see the module documentation).
#[derive(Debug, Clone)]
pub struct CalibrationStage {
    model: AccelModel,
    gravity_mps2: f64,
    terms: ReadingTerms,
    /// Sample time of the first sample of the current stream (power-on for the time terms), ns.
    stream_start_ns: Option<u64>,
    gyro_bias_dps: [f64; 3],
    calib_id: u64,
    detector: ZeroStateDetector,
    refine_config: RefineConfig,
    refine: Refinement,
    /// Samples emitted in the current batch (all but the newest provisional).
    batch_len: usize,
    /// Whether the batch's samples all carry a gyroscope measurement.
    batch_gyro: bool,
    /// The latest verdict's flags and `zs_*` fields, carried over to provisional samples.
    carried: Carried,
    last: Option<(u64, u64)>,
    /// The stream's time line (its nominal period and holes, [`ipc_types::stream`]).
    time: TimeLine,
    /// Runs of repeated readings ([`StageStats::frozen`]).
    freezes: Freezes,
    /// Whether `last` comes from [`CalibrationStage::resume`] and no sample has confirmed it.
    resumed: bool,
    /// Whether the previous sample was dropped for a time step beyond the bound.
    jumped: bool,
    stats: StageStats,
}

impl CalibrationStage {
    /// A stage applying `file` with the zero-state detector `detector` (its local gravity
    /// should be the file's; without a noise floor of its own it gets the file's `[noise]`
    /// table as one) and the bias refinement `refine`.
    pub fn new(
        file: &CalibrationFile,
        mut detector: DetectorConfig,
        refine: RefineConfig,
    ) -> Result<Self, StageSetupError> {
        if detector.noise.is_none() {
            detector.noise = file
                .noise
                .as_ref()
                .map(|p| NoiseFloor::from_params(p, file.gravity_mps2));
        }
        let model = file
            .accel_model()
            .map_err(|e| StageSetupError(e.to_string()))?;
        let terms = ReadingTerms::from_file(file).map_err(|e| StageSetupError(e.to_string()))?;
        Ok(Self {
            model,
            gravity_mps2: file.gravity_mps2,
            terms,
            stream_start_ns: None,
            gyro_bias_dps: file.gyro.bias_dps.unwrap_or([0.0; 3]),
            calib_id: calib_id(file),
            detector: ZeroStateDetector::new(detector),
            refine_config: refine,
            refine: Refinement::new(refine),
            batch_len: 0,
            batch_gyro: true,
            carried: Carried::default(),
            last: None,
            time: TimeLine::default(),
            freezes: Freezes::default(),
            resumed: false,
            jumped: false,
            stats: StageStats::default(),
        })
    }

    /// The identifier written into every output sample.
    pub fn calib_id(&self) -> u64 {
        self.calib_id
    }

    /// The detector (for its state and references).
    pub fn detector(&self) -> &ZeroStateDetector {
        &self.detector
    }

    /// What a restarted process would need to go on from here (`None` before the first
    /// sample).
    pub fn warm_state(&self) -> Option<WarmState> {
        let (last_seq, last_ns) = self.last?;
        let r = &self.refine;
        Some(WarmState {
            calib_id: self.calib_id,
            reference: self.detector.reference(),
            rest_seen_s: self.detector.rest_seen_s(),
            refine_accel_mps2: r.accel_mps2.into(),
            refine_gyro_rps: r.gyro_rps.into(),
            accel_seen_s: r.accel_seen_s,
            gyro_seen_s: r.gyro_seen_s,
            refined: r.refined,
            stream_start_ns: self.stream_start_ns.unwrap_or(last_ns),
            last_seq,
            last_ns,
        })
    }

    /// Goes on from `state` (a fresh stage, before its first sample): the references,
    /// the refinement and the stream as they were. The next sample is a gap after
    /// `state.last_seq`; one that is not later in sequence and time belongs to another stream
    /// (a new power-on), and the stage starts over.
    pub fn resume(&mut self, state: &WarmState) -> Result<(), ResumeError> {
        if state.calib_id != self.calib_id {
            return Err(ResumeError {
                state: state.calib_id,
                stage: self.calib_id,
            });
        }
        if let Some(reference) = &state.reference {
            self.detector.resume(reference, state.rest_seen_s);
        }
        let r = &mut self.refine;
        r.accel_mps2 = state.refine_accel_mps2.into();
        r.gyro_rps = state.refine_gyro_rps.into();
        r.accel_seen_s = state.accel_seen_s;
        r.gyro_seen_s = state.gyro_seen_s;
        r.refined = state.refined;
        self.stream_start_ns = Some(state.stream_start_ns);
        self.last = Some((state.last_seq, state.last_ns));
        self.time.accept(state.last_ns);
        self.resumed = true;
        Ok(())
    }

    /// The current refinement: accelerometer offset (m/s^2) and gyroscope bias (rad/s)
    /// subtracted from the output, and whether any refinement was made.
    pub fn refinement(&self) -> ([f64; 3], [f64; 3], bool) {
        let r = &self.refine;
        (r.accel_mps2.into(), r.gyro_rps.into(), r.refined)
    }

    /// Counters since the stage was created.
    pub fn stats(&self) -> StageStats {
        StageStats {
            frozen: self.freezes.frozen,
            ..self.stats
        }
    }

    /// Number of provisional samples emitted in the current batch, which its verdict will
    /// settle.
    pub fn unsettled(&self) -> usize {
        self.batch_len
    }

    /// A new sensor session: everything learned and refined is forgotten.
    fn start_over(&mut self) {
        self.cut_batch();
        self.carried = Carried::default();
        self.detector.reset();
        self.refine = Refinement::new(self.refine_config);
        self.stream_start_ns = None;
        self.stats.restarts += 1;
    }

    /// Starts a new batch.
    fn cut_batch(&mut self) {
        self.batch_len = 0;
        self.batch_gyro = true;
    }

    /// Validates a sample before anything changes.
    fn check(&self, raw: &RawImuSample, has_gyro: bool, has_temp: bool) -> Result<(), StageError> {
        let err = |field, value| StageError::NotFinite {
            seq: raw.seq,
            t_ns: raw.stamps.sample_ns,
            field,
            value,
        };
        const ACCEL: [&str; 3] = ["accel_g[0]", "accel_g[1]", "accel_g[2]"];
        const GYRO: [&str; 3] = ["gyro_dps[0]", "gyro_dps[1]", "gyro_dps[2]"];
        for (i, x) in raw.accel_g.iter().enumerate() {
            if !x.is_finite() {
                return Err(err(ACCEL[i], *x));
            }
        }
        if has_gyro {
            for (i, x) in raw.gyro_dps.iter().enumerate() {
                if !x.is_finite() {
                    return Err(err(GYRO[i], *x));
                }
            }
        } else if self.detector.config().kind.needs_gyro() {
            return Err(StageError::NoGyro {
                seq: raw.seq,
                detector: self.detector.config().kind.name(),
            });
        }
        if self.terms.needs_temperature() && !has_temp {
            return Err(StageError::NoTemperature { seq: raw.seq });
        }
        if has_temp && !raw.temp_c.is_finite() {
            return Err(err("temp_c", raw.temp_c));
        }
        let gyro = has_gyro.then_some(&raw.gyro_dps);
        limits::check_raw(&raw.accel_g, gyro, has_temp.then_some(raw.temp_c)).map_err(|bad| {
            StageError::OutOfRange {
                seq: raw.seq,
                t_ns: raw.stamps.sample_ns,
                bad,
            }
        })
    }

    /// Refines at rest with the batch's `verdict` and carries the verdict over.
    fn decide(&mut self, v: &Verdict) {
        let gyro = self.batch_gyro.then_some(v.gyro.mean);
        if let Some(learned) = &v.learned {
            // The start-up interval was at rest by assumption: the first refinement. A part
            // that reads gravity further off than a calibrated one is not what the file says:
            // its bias is worth nothing against the rest, which is taken whole.
            if self.detector.config().uncalibrated(learned) {
                self.refine.accel_seen_s = 0.0;
            }
            let gyro = self.batch_gyro.then_some(learned.gyro_mean_rps);
            self.refine.update(
                learned.accel_mean_mps2,
                gyro,
                learned.duration_s,
                self.gravity_mps2,
            );
        } else if v.rest && self.detector.config().kind.rest_is_still() {
            self.refine.update(
                v.accel.mean,
                gyro,
                batch_duration_s(&v.accel),
                self.gravity_mps2,
            );
        }
        let config = self.detector.config();
        self.carried = Carried {
            ready: v.ready,
            // A part declared uncalibrated is flagged whether or not its detector learns a
            // reference (the stance detector of a foot learns none).
            gravity_off: config.offset_unknown
                || self
                    .detector
                    .reference()
                    .is_some_and(|r| config.uncalibrated(&r)),
            rest: v.rest,
            zs_mean_mps2: std::array::from_fn(|i| {
                v.decided_mean_mps2[i] - self.refine.accel_mps2[i]
            }),
            zs_std_mps2: v.decided_std_mps2,
        };
    }

    /// Follows the runs of repeated readings ([`StageStats::frozen`]): a gap or a new session
    /// ends the current one.
    fn watch_freezes(&mut self, raw: &RawImuSample, has_gyro: bool, continuity: Continuity) {
        if continuity != Continuity::Next {
            self.freezes.end(&self.time);
        }
        let gyro = has_gyro.then_some(raw.gyro_dps);
        self.freezes
            .push(&self.time, raw.seq, raw.stamps.sample_ns, raw.accel_g, gyro);
    }

    /// Places `raw` in the stream by the stream contract ([`stream::continuity`]): a resumed
    /// state that `raw` does not continue, a sequence that starts again or a confirmed time
    /// jump start a new session; a time that does not increase or a first jump is refused.
    /// Returns how `raw` continues the stream (a gap: samples are missing before it, marked
    /// or a hole in the time line).
    #[inline]
    fn sequence(&mut self, raw: &RawImuSample) -> Result<Continuity, StageError> {
        let t_ns = raw.stamps.sample_ns;
        if std::mem::take(&mut self.resumed)
            && self
                .last
                .is_some_and(|(seq, ns)| raw.seq <= seq || t_ns <= ns)
        {
            // Not the stream the resumed state was made on (a new power-on): start over.
            self.start_over();
            self.last = None;
            self.time.restart();
            return Ok(Continuity::NewSession);
        }
        let step = self.time.step(t_ns);
        if step == Step::Beyond && !self.jumped {
            // One stamp far ahead is a corrupted stamp until the next one agrees.
            self.jumped = true;
            return Err(StageError::TimeStep {
                seq: raw.seq,
                t_ns,
                prev_ns: self.last.map_or(0, |(_, ns)| ns),
            });
        }
        self.jumped = false;
        let marked = raw.lost_before > 0 || raw.flags & raw_flags::GAP_BEFORE != 0;
        let continuity = stream::continuity(self.last.map(|(seq, _)| seq), raw.seq, marked, step);
        match (continuity, self.last) {
            (Continuity::NewSession, _) => {
                self.start_over();
                self.time.restart();
            }
            (_, Some((prev_seq, prev_ns))) if matches!(step, Step::Back | Step::Repeat) => {
                return Err(StageError::TimeNotIncreasing {
                    seq: raw.seq,
                    t_ns,
                    prev_seq,
                    prev_ns,
                });
            }
            (Continuity::Gap, _) => {
                if let Step::Hole { dt_ns } = step {
                    self.stats.holes.record(raw.seq, t_ns, dt_ns);
                }
                self.cut_batch();
                self.detector.interrupt();
                self.stats.gaps += 1;
            }
            (Continuity::Next, _) => {}
        }
        Ok(continuity)
    }

    /// The corrected sample of `raw` (flagged by the detector later), the corrected
    /// acceleration m/s^2 and the bias-free rate rad/s the detector takes (before refinement).
    #[inline]
    fn correct(
        &self,
        raw: &RawImuSample,
        has_gyro: bool,
        has_temp: bool,
        gap: bool,
    ) -> (CorrectedImuSample, Vector3<f64>, [f64; 3]) {
        let start_ns = self.stream_start_ns.unwrap_or(raw.stamps.sample_ns);
        let t_s = (raw.stamps.sample_ns - start_ns) as f64 * 1e-9;
        let a = self.terms.correct(
            &self.model,
            &Vector3::from(raw.accel_g),
            has_temp.then_some(raw.temp_c),
            t_s,
        ) * self.gravity_mps2;
        let w: [f64; 3] = if has_gyro {
            std::array::from_fn(|i| (raw.gyro_dps[i] - self.gyro_bias_dps[i]).to_radians())
        } else {
            [0.0; 3]
        };
        let (da, dw) = (self.refine.accel_mps2, self.refine.gyro_rps);
        let out = CorrectedImuSample {
            stamps: raw.stamps,
            seq: raw.seq,
            accel_mps2: std::array::from_fn(|i| a[i] - da[i]),
            gyro_rps: if has_gyro {
                std::array::from_fn(|i| w[i] - dw[i])
            } else {
                w
            },
            temp_c: raw.temp_c,
            calib_id: self.calib_id,
            raw_flags: raw.flags | if gap { raw_flags::GAP_BEFORE } else { 0 },
            refined_accel_mps2: da.into(),
            refined_gyro_rps: if has_gyro { dw.into() } else { [0.0; 3] },
            ..CorrectedImuSample::default()
        };
        (out, a, w)
    }

    /// Gives the sample to the zero-state detector; a verdict settles the batch it ends
    /// (`out.settles`). Returns whether `out` is provisional (its batch not yet decided).
    #[inline]
    fn detect(
        &mut self,
        t_ns: u64,
        a: Vector3<f64>,
        w: [f64; 3],
        out: &mut CorrectedImuSample,
    ) -> bool {
        match self.detector.push(t_ns, a.into(), w) {
            Some(verdict) => {
                self.decide(&verdict);
                out.settles = self.batch_len as u32;
                self.stats.rest += u64::from(verdict.rest) * (self.batch_len as u64 + 1);
                self.cut_batch();
                false
            }
            None => {
                self.batch_len += 1;
                true
            }
        }
    }
}

impl Stage for CalibrationStage {
    type Input = RawImuSample;
    type Output = CorrectedImuSample;
    type Refusal = StageError;

    /// Takes one raw sample and emits its corrected sample (see the module documentation for
    /// its flags). A sample whose sequence number does not increase starts a new stream (a
    /// restarted publisher): the time check and the detector and refinement start over (a new
    /// sensor session has a new turn-on bias, and a stale gyroscope reference would hold every
    /// later window in "motion").
    ///
    /// A refused sample (see [`StageError`]: not finite, beyond the sensor's range
    /// ([`limits::check_raw`]), time not increasing or more than [`limits::MAX_STEP_S`] ahead)
    /// changes nothing; the caller counts it. The next sample then skips a sequence number: a
    /// gap, and its corrected sample carries [`raw_flags::GAP_BEFORE`] (as every sample after a
    /// gap does). A second step beyond the bound in a row is a new time base: a new stream, as
    /// for a restarted publisher.
    fn process(
        &mut self,
        raw: &RawImuSample,
        emit: &mut impl FnMut(&CorrectedImuSample),
    ) -> Result<(), StageError> {
        let has_gyro = raw.flags & raw_flags::GYRO_VALID != 0;
        let has_temp = raw.flags & raw_flags::TEMP_VALID != 0;
        self.check(raw, has_gyro, has_temp)?;
        let continuity = self.sequence(raw)?;
        let gap = continuity == Continuity::Gap;
        let hole = gap && matches!(self.time.step(raw.stamps.sample_ns), Step::Hole { .. });
        self.watch_freezes(raw, has_gyro, continuity);
        self.last = Some((raw.seq, raw.stamps.sample_ns));
        self.time.accept(raw.stamps.sample_ns);
        self.stats.accepted += 1;
        self.stream_start_ns.get_or_insert(raw.stamps.sample_ns);

        let (mut out, a, w) = self.correct(raw, has_gyro, has_temp, gap);
        self.batch_gyro &= has_gyro;
        let provisional = self.detect(raw.stamps.sample_ns, a, w, &mut out);
        self.carried.apply(&mut out, self.refine.refined);
        if provisional {
            out.flags |= corrected_flags::PROVISIONAL;
        }
        if continuity == Continuity::NewSession {
            out.flags |= corrected_flags::NEW_SESSION;
        }
        if hole {
            out.flags |= corrected_flags::HOLE_BEFORE;
        }
        if raw.flags & raw_flags::SATURATED != 0 {
            out.flags |= corrected_flags::CLIPPED;
        }
        self.stats.clipped.count(raw.flags);
        self.stats.released += 1;
        emit(&out);
        Ok(())
    }

    /// End of the stream: the detector's partial batch is dropped (its samples stay unsettled;
    /// nothing is emitted; learned references stay). The last sequence number is kept, so a later stream that
    /// starts again from 0 is still recognised as a new session.
    fn finish(&mut self, _emit: &mut impl FnMut(&CorrectedImuSample)) {
        self.cut_batch();
        self.detector.interrupt();
        self.freezes.end(&self.time);
    }
}

/// The latest verdict as it is written into samples.
#[derive(Debug, Clone, Copy, Default)]
struct Carried {
    ready: bool,
    /// The learned rest read gravity off, or the part was declared uncalibrated
    /// (`corrected_flags::GRAVITY_OFF`).
    gravity_off: bool,
    rest: bool,
    zs_mean_mps2: [f64; 3],
    zs_std_mps2: [f64; 3],
}

impl Carried {
    /// Writes the verdict's flags (and `BIAS_REFINED` when `refined`) and window statistics.
    fn apply(&self, s: &mut CorrectedImuSample, refined: bool) {
        let mut flags = 0;
        if refined {
            flags |= corrected_flags::BIAS_REFINED;
        }
        if self.ready {
            flags |= corrected_flags::DETECTOR_READY;
        }
        if self.gravity_off {
            flags |= corrected_flags::GRAVITY_OFF;
        }
        if self.rest {
            flags |= corrected_flags::ZERO_STATE;
        }
        s.flags = flags;
        s.zs_mean_mps2 = self.zs_mean_mps2;
        s.zs_std_mps2 = self.zs_std_mps2;
    }
}

/// Holds provisional corrected samples back until their verdict is known and emits them with
/// their final flags, in order: for consumers that need every sample's own batch verdict (the
/// detector evaluations, the gyroscope calibration) rather than the earliest sample. Storage
/// for two batches is allocated once; should more samples stay unsettled (not possible with a
/// [`CalibrationStage`]'s output), the oldest is emitted as it is.
#[derive(Debug, Clone)]
pub struct Settler {
    held: [CorrectedImuSample; 2 * BATCH_LEN],
    len: usize,
}

impl Default for Settler {
    fn default() -> Self {
        Self {
            held: [CorrectedImuSample::default(); 2 * BATCH_LEN],
            len: 0,
        }
    }
}

impl Settler {
    /// Takes the next sample of a calibration stage's output; emits every sample whose flags
    /// are now final.
    pub fn push(&mut self, s: &CorrectedImuSample, emit: &mut impl FnMut(&CorrectedImuSample)) {
        if s.flags & corrected_flags::PROVISIONAL != 0 {
            if self.len == self.held.len() {
                emit(&self.held[0]);
                self.held.copy_within(1.., 0);
                self.len -= 1;
            }
            self.held[self.len] = *s;
            self.len += 1;
            return;
        }
        // Samples older than those settled were cut from their batch: final as they are.
        let cut = self.len - stream::settled_by(s, self.len);
        for h in &self.held[..cut] {
            emit(h);
        }
        for h in &mut self.held[cut..self.len] {
            stream::settle(h, s);
            emit(h);
        }
        self.len = 0;
        emit(s);
    }

    /// End of the stream: the samples held are final as they are.
    pub fn finish(&mut self, emit: &mut impl FnMut(&CorrectedImuSample)) {
        for h in &self.held[..self.len] {
            emit(h);
        }
        self.len = 0;
    }
}
