//! `mems-odometry offline`: the calibration stage and the odometry session over a raw
//! recording, in one process: the same stages `mems-calibrate serve` and `mems-odometry serve`
//! run live, chained (`mems_stage::Chain`) and run by the offline driver
//! (`mems_stage::offline`). An MCAP recording's robot hints (topic `mems/robot/hint`) go to the
//! odometry session, which orders them as it does live, unless `--no-hints`. An MCAP run is
//! streamed through the stages as it is read (`source`), its raw samples and hints put in the
//! order a live pipeline receives them (`odometry::arrival`); truth (recordings from
//! `mems-sim`) is compared as `summary` says.

mod platform;
mod source;
mod summary;
mod trust;
mod truth;

use std::path::PathBuf;

use anyhow::{Result, anyhow};
use calibrate::stage::{CalibrationStage, RefineConfig};
use ipc_types::odometry_flags;
use mems_stage::{Chain, Either};
use odometry::consistency::Scaling;
use odometry::diagnose::lag::LagShift;
use odometry::hints::ForwardAxisReport;
use odometry::profile::Profile;
use odometry::session::{NoGyro, OdometrySession};
use odometry::uncalibrated::AccelEstimate;
use odometry::velocity_axis::COARSE_MAX_SIGMA_RAD;

use crate::load::odometry_config;
use crate::out::Out;
use source::{Feed, Source};
use summary::{Read, Summary};

/// Options of `mems-odometry offline`.
#[derive(clap::Args)]
pub struct OfflineArgs {
    #[command(flatten)]
    stage: crate::load::StageArgs,
    /// Raw recording: canonical CSV, thesis CSV or MCAP.
    #[arg(long)]
    input: PathBuf,
    /// Integrate without zero-velocity updates after alignment (the rest flags still align).
    #[arg(long)]
    no_zupt: bool,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
    /// How the innovations' consistency enters (`odometry::consistency`): `report` (the
    /// published 1-sigma only), `process` (a factor on the process noise: the estimates
    /// change), `off` (the filter's covariance as is; still reported in the JSON).
    #[arg(long, value_enum, default_value_t = Scaling::Report)]
    innovation_scaling: Scaling,
    /// Ignore the recording's robot hints (IMU only).
    #[arg(long)]
    no_hints: bool,
    /// Refuse a text recording whose times do not strictly increase, instead of dropping
    /// exact repeats and rebuilding such times from the nominal rate (`recording::LogPolicy`).
    #[arg(long)]
    strict_time: bool,
    /// Repair torn high/low-byte reads first (`calibrate::repair`): for recordings made by a
    /// logger that read the two bytes of an axis in separate transactions, such as the
    /// thesis's (docs/diagnosis.md). Our driver never tears a read, so live and offline agree
    /// only without it.
    #[arg(long)]
    repair_torn_reads: bool,
    /// Weinberg's step-length constant of hand-held walking (the walking profile,
    /// `odometry::walking`), m/(m/s^2)^(1/4). Default: `odometry::walking::WEINBERG_K`.
    #[arg(long)]
    weinberg_k: Option<f64>,
    #[command(flatten)]
    hints: crate::hint_args::HintArgs,
    #[command(flatten)]
    ranges: trust::RangeArgs,
    /// Also write the run as a live run's recording to this MCAP file: raw samples and hints
    /// as read, corrected samples, odometry states (revisions included) and poses, each logged
    /// at its own time (`crate::out`).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Overwrite the recording at `--out`.
    #[arg(long, requires = "out")]
    force: bool,
    /// The accelerometer's samples lag the gyro's by this, s (what `mems-odometry diagnose`
    /// finds as `accel_lag`): each sample's specific force is read this much later, between
    /// samples (`odometry::diagnose::lag`), before the calibration stage.
    #[arg(long, allow_negative_numbers = true)]
    accel_lag_s: Option<f64>,
}

/// Runs the pipeline and prints the result. A part whose accelerometer the run found
/// uncalibrated (`odometry::uncalibrated`) is run a second time with the bias the first run
/// estimated removed from its samples (or, where its rests at several attitudes gave a
/// per-axis fit, `odometry::attitudes`, with that fit's bias and scale applied), and only the
/// second run's result is printed and written; should the second run move the bias further than an uncalibrated part's bias
/// sigma, or fail (never align, say), the first estimate was not one, and the recording is run
/// once more as the first run was, that result standing.
///
/// A calibrated part whose speed hints' forward axis (the IMU's mounting) was estimated, no
/// `--mount` given, to a whole yaw 1-sigma of at most 20 deg ([`Pass::First`]), is run a
/// second time with the first run's last fit taken from the start
/// (`odometry::hints::HintConfig::mounting_fit`: its yaw 1-sigmas and speed scale carried):
/// live, the hints wait for it, and what the platform drove meanwhile on the IMU alone is lost.
///
/// A first run that never aligned although its GLRT was ready, with a calibration file that
/// has no fit of the part's accelerometer and a learned rest that read gravity like a
/// calibrated part's, is made again with the part declared uncalibrated (`--uncalibrated`):
/// an offset across gravity barely moves the magnitude, and turned with the gravity reference
/// it calls every later window motion (the comma2k19 drive with 0.15 g on x alone never
/// aligned).
pub fn run(args: OfflineArgs) -> Result<()> {
    let is_mcap = recording::mcap::has_magic(&args.input)?;
    let choice = platform::choose(args.stage.profile, &args.input, is_mcap)?;
    let (file, mut detector) = args.stage.load(choice.profile)?;
    let early = match pass(&args, &choice, &file, detector, Pass::First) {
        Err(e) if e.is::<NotAligned>() => {
            tracing::warn!(
                "{e:#}; the calibration file has no fit of this part's accelerometer: running \
                 it again as an uncalibrated part (as --uncalibrated)"
            );
            detector.offset_unknown = true;
            pass(&args, &choice, &file, detector, Pass::First)?
        }
        other => other?,
    };
    let first = match early {
        None => return Ok(()),
        Some(Early::Mounting(axis)) => {
            tracing::info!(
                "first pass: the speed hints' forward axis at {}; running the recording again \
                 with it from the first hint",
                summary::describe_fit(&axis.fit)
            );
            return pass(&args, &choice, &file, detector, Pass::Mounted(&axis)).map(|_| ());
        }
        Some(Early::Accel { estimate, .. }) => estimate,
    };
    let removed = match &first.per_axis {
        Some(fit) => {
            tracing::info!(
                "first pass: {first}; running the recording again with that per-axis bias and \
                 scale applied"
            );
            odometry::uncalibrated::apply_fit(&file, fit)
        }
        None => {
            tracing::info!(
                "first pass: {first}; running the recording again with that bias removed"
            );
            odometry::uncalibrated::remove_bias(&file, &first.bias_mps2)
        }
    };
    match pass(&args, &choice, &removed, detector, Pass::Second(&first)) {
        Ok(None) => return Ok(()),
        Ok(Some(Early::Accel {
            estimate,
            limit_mps2,
        })) => tracing::warn!(
            "second pass: {estimate}: further than {limit_mps2:.2} m/s^2 from the first pass's, \
             which is no estimate; the result is the first pass's"
        ),
        Ok(Some(Early::Mounting(_))) => unreachable!("only a first pass ends for its mounting"),
        // The samples with that bias removed are no recording of this part (a first pass that
        // diverged can estimate tens of m/s^2): the same evidence.
        Err(e) => tracing::warn!(
            "second pass with the first pass's estimate applied failed ({e:#}), so that estimate \
             is no estimate; the result is the first pass's"
        ),
    }
    pass(&args, &choice, &file, detector, Pass::Only).map(|_| ())
}

/// A run that ended early, and what for.
enum Early {
    /// What the filter estimated of the accelerometer, and how far the bias may move between
    /// passes (the run's configured `uncalibrated.bias_sigma_mps2`, m/s^2).
    Accel {
        estimate: AccelEstimate,
        limit_mps2: f64,
    },
    /// The speed hints' forward axis the run ended with (a mounting not given).
    Mounting(ForwardAxisReport),
}

/// A first run that never aligned while its part, with no fit in its calibration file, was
/// taken for a calibrated one ([`summary::may_be_uncalibrated`]): [`run`] makes it again as
/// an uncalibrated part's.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct NotAligned(String);

/// Which run of the recording [`pass`] makes.
#[derive(Clone, Copy)]
enum Pass<'a> {
    /// The first: it ends early, with the accelerometer's estimate, when that is uncalibrated,
    /// else with the speed hints' forward axis, when one was estimated and its whole yaw
    /// 1-sigma is within the least the live rule takes a path's axis with
    /// (`odometry::velocity_axis::COARSE_MAX_SIGMA_RAD`, 20 deg): from the start, a worse one
    /// would turn the whole track by more than a third of its distance.
    First,
    /// The second, with the first's estimated bias removed (or its per-axis fit applied): it
    /// ends early, with its estimate,
    /// when that moved the bias further than the uncalibrated prior's sigma.
    Second(&'a AccelEstimate),
    /// The second of a calibrated part, with the first's forward-axis fit from the start.
    Mounted(&'a ForwardAxisReport),
    /// The only one whose result stands whatever it estimates.
    Only,
}

impl Pass<'_> {
    /// Why the run ends early instead of reporting, if it does: the accelerometer's
    /// `estimate`, or the forward-axis `fit`.
    fn ends_early(
        self,
        estimate: Option<AccelEstimate>,
        axis: Option<ForwardAxisReport>,
        config: &odometry::config::OdometryConfig,
    ) -> Option<Early> {
        let limit_mps2 = config.uncalibrated.bias_sigma_mps2;
        let accel = |estimate| Early::Accel {
            estimate,
            limit_mps2,
        };
        match self {
            Self::First => match estimate {
                Some(e) if e.uncalibrated => Some(accel(e)),
                _ => axis
                    .filter(|a| a.fit.systematic_sigma_rad() <= COARSE_MAX_SIGMA_RAD)
                    .map(Early::Mounting),
            },
            Self::Second(first) => {
                let removed = first.per_axis.map_or(first.bias_mps2, |f| f.bias_mps2);
                estimate
                    .filter(|e| (0..3).any(|i| (e.bias_mps2[i] - removed[i]).abs() > limit_mps2))
                    .map(accel)
            }
            Self::Mounted(_) | Self::Only => None,
        }
    }
}

/// The odometry's configuration for the calibration `file`, the `detector` and the options
/// `args`, before the profile's, with what an earlier pass estimated for `which`.
fn base_config(
    args: &OfflineArgs,
    file: &calibrate::calibfile::CalibrationFile,
    detector: &calibrate::zero_state::DetectorConfig,
    which: Pass<'_>,
) -> Result<odometry::config::OdometryConfig> {
    let mut base = odometry_config(file);
    if let Pass::Second(first) = which {
        match first.per_axis {
            Some(fit) => base.uncalibrated.fitted = Some(fit),
            None => base.uncalibrated.removed_bias_mps2 = Some(first.bias_mps2),
        }
    }
    base.rest_updates = !args.no_zupt;
    // The alignment may stand on the whole first learning window (`--learn-s`, at most the
    // robot's half second when it learns again from a longer rest): the learner judged all of
    // it still.
    base.learned_rest_s = detector.learn.first_window_s();
    base.consistency.scaling = args.innovation_scaling;
    if let Some(k) = args.weinberg_k {
        if !(k.is_finite() && k > 0.0) {
            return Err(anyhow!(
                "--weinberg-k {k}: expected a positive step-length constant"
            ));
        }
        base.walking = Some(odometry::walking::WalkingConfig {
            weinberg_k: k,
            ..Default::default()
        });
    }
    base.trust_untrusted = args.ranges.trust_clipped;
    base.reconstruct_clipped = !args.ranges.bridge_clipped;
    Ok(base)
}

/// The hints' configuration of `args` for the run `which`: a [`Pass::Mounted`] takes the first
/// run's forward-axis fit from the start.
fn hint_config(args: &OfflineArgs, which: Pass<'_>) -> Result<odometry::hints::HintConfig> {
    let mut hints = args.hints.config()?;
    if let Pass::Mounted(axis) = which {
        hints.mounting_fit = Some(axis.fit);
        hints.mounting_from_turns = false;
    }
    Ok(hints)
}

/// One run of the pipeline over the recording with the calibration `file` (see [`Pass`]).
/// Returns what the filter estimated of the accelerometer, without printing or writing
/// anything, when the run ends early; else prints the result and writes `--out`.
fn pass(
    args: &OfflineArgs,
    choice: &platform::Choice,
    file: &calibrate::calibfile::CalibrationFile,
    detector: calibrate::zero_state::DetectorConfig,
    which: Pass<'_>,
) -> Result<Option<Early>> {
    let (source, repairs, ranges) = Source::open(args)?;
    let base = base_config(args, file, &detector, which)?;
    let calibration = CalibrationStage::new(file, detector, RefineConfig::default())
        .map_err(|e| anyhow!("{}: {e}", args.stage.calib_name()))?;
    let hints = hint_config(args, which)?;
    let (config, session) = match choice.profile {
        Profile::Auto => (
            Profile::Auto.odometry(base),
            OdometrySession::auto(base, hints, NoGyro::HoldAttitude)?,
        ),
        p => {
            let config = p.odometry(base);
            (
                config,
                OdometrySession::new(config, hints, NoGyro::HoldAttitude)?,
            )
        }
    };
    let mut chain = Chain {
        first: calibration,
        second: session,
    };
    let out = Out::for_input(args.out.as_deref(), &args.input, args.force)?;
    let shift = args
        .accel_lag_s
        .map(LagShift::new)
        .transpose()
        .map_err(|e| anyhow!("--accel-lag-s: {e}"))?;
    let mut feed = Feed::new(source, out, ranges, shift);
    let mut summary = Summary::default();
    let progress = mems_log::progress::bar(None, "mems-odometry offline", "states");
    let ran =
        mems_stage::offline::run_with(&mut chain, &mut feed, Feed::next_input, &mut |feed, o| {
            feed.write(o);
            if let Either::Second(s) = o {
                if s.flags & odometry_flags::REVISION == 0 {
                    progress.inc(1);
                    summary.state(*s, &mut feed.truth);
                } else {
                    summary.revise(s);
                }
            }
        });
    progress.finish_and_clear();
    if matches!(which, Pass::First)
        && ran.is_ok()
        && !file.accel_fitted()
        && !summary.aligned()
        && summary::may_be_uncalibrated(&chain.first)
    {
        return Err(NotAligned(format!(
            "{}: never aligned: {}",
            args.input.display(),
            summary::why_never_aligned(&chain.first, config.align_s)
        ))
        .into());
    }
    let stage = chain.second.stage();
    let early = ran
        .is_ok()
        .then(|| which.ends_early(stage.accel_estimate(), stage.forward_axis(), &config))
        .flatten();
    if early.is_some() {
        return Ok(early);
    }
    let mut read = Read::new(&args.input, &feed, repairs, config.align_s, *choice);
    if read.holes.count == 0 {
        read.holes = chain.first.stats().holes;
    }
    read.frozen = chain.first.stats().frozen;
    if let Pass::Mounted(axis) = which {
        read.first_pass_axis = Some(*axis);
    }
    let no_gyro = chain.second.stats().first_no_gyro_seq;
    read.segments = summary::report_input(&read, &mut feed.source, no_gyro);
    let t0 = read.first_ns.unwrap_or(0);
    let stats = chain.second.stats();
    trust::report(
        &args.input,
        &ranges,
        &stats,
        t0,
        trust::Treatment::of(&args.ranges),
    );
    read.trust = trust::json(&ranges, &stats, t0, chain.second.stage().clip_stats());
    summary.finish(ran, &read, &chain, &mut feed.truth, args.json)?;
    // Only a run that succeeded leaves its --out file (a failed one drops it unwritten).
    match feed.out {
        Some(out) => out.finish().map(|_| None),
        None => Ok(None),
    }
}
