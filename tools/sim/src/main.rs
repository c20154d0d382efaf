//! `mems-sim`: writes a simulated MPU-9250 session (quantized raw samples plus ground truth) to
//! the canonical CSV or MCAP. See `mems-sim --help`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand, ValueEnum};
use ipc_types::units::{AccelRange, GyroRange, STANDARD_GRAVITY_MPS2};
use ipc_types::{RawImuSample, RobotHint};
use mems_sim::adc::quantize_sample;
use mems_sim::defects::{LogDefects, Logger, peak_speed_time};
use mems_sim::dlpf::DlpfConfig;
use mems_sim::hints::{HintParams, RestSource, drive_hints};
use mems_sim::model::{Preset, SensorModel};
use mems_sim::mounting::Mounting;
use mems_sim::scenario::{
    Arm, ArmParams, Drive, DriveParams, Handheld, HandheldParams, PoseParams, PoseSession,
    Scenario, Walk, WalkParams, ns_from_s,
};
use mems_sim::vibration::VibrationModel;
use mems_sim::{DlpfGrid, SimSensor};
use nalgebra::{UnitQuaternion, Vector3};
use recording::Truth;
use recording::clock::WallClock;

/// Simulated MPU-9250 sessions with ground truth, written as canonical CSV (truth columns) or
/// MCAP (truth channel `mems/sim/truth`).
#[derive(Parser)]
#[command(name = "mems-sim", version)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The thesis's six-position session: +z, -z, +y, -y, +x, -x up, rotated in between.
    SixPosition {
        #[command(flatten)]
        poses: PoseArgs,
        #[command(flatten)]
        common: Common,
    },
    /// N well-spread random orientations, rotated in between.
    Orientations {
        /// Number of orientations.
        #[arg(long)]
        n: usize,
        #[command(flatten)]
        poses: PoseArgs,
        #[command(flatten)]
        common: Common,
    },
    /// A long static run, lying level (z up) unless tilted.
    Static {
        /// Length, s.
        #[arg(long)]
        duration: f64,
        /// Attitude as roll,pitch,yaw in degrees (sensor to navigation frame).
        #[arg(long, value_name = "R,P,Y", value_parser = parse_triple, default_value = "0,0,0")]
        attitude_deg: [f64; 3],
        #[command(flatten)]
        common: Common,
    },
    /// A ground robot's drive: accelerate, cruise, turn, brake, rest 1-30 s, repeat.
    Drive {
        /// Length, s.
        #[arg(long)]
        duration: f64,
        /// Vibration level while moving, relative to 0.1 m/s^2 and 0.5 deg/s RMS per axis at
        /// 1 m/s (0 turns it off).
        #[arg(long, default_value_t = 1.0)]
        vibration: f64,
        /// Vibration while the wheels turn at any speed, RMS per axis: accelerometer m/s^2,
        /// gyroscope deg/s (motors and gears; tools/sim/src/vibration.rs gives measured levels).
        #[arg(long, value_name = "MPS2,DPS", value_parser = parse_pair, default_value = "0,0")]
        vibration_floor: [f64; 2],
        /// An engine idling at the stops after the first motion: accelerometer RMS per axis,
        /// m/s^2, and firing frequency, Hz (tools/sim/src/vibration.rs gives measured levels).
        #[arg(long, value_name = "MPS2,HZ", value_parser = parse_pair, default_value = "0,23")]
        engine_idle: [f64; 2],
        /// The same engine before the first motion, accelerometer RMS per axis, m/s^2 (0:
        /// parked with the engine off).
        #[arg(long, default_value_t = 0.0)]
        engine_start: f64,
        /// The idling engine's angular vibration at the stops after the first motion, RMS
        /// per gyroscope axis, deg/s, at the --engine-idle frequency (0: none; wid-car-06
        /// shows 0.37-0.53, tools/sim/src/vibration.rs).
        #[arg(long, value_name = "DPS", default_value_t = 0.0)]
        engine_idle_gyro: f64,
        /// The same engine's angular vibration before the first motion, RMS per gyroscope
        /// axis, deg/s (0: none; wid-car-06 standing at its start shows 0.36-0.49).
        #[arg(long, value_name = "DPS", default_value_t = 0.0)]
        engine_start_gyro: f64,
        /// A road rocking a car's body while the wheels turn: accelerometer RMS per axis,
        /// m/s^2, at 1.2 Hz (tools/sim/src/vibration.rs gives measured levels).
        #[arg(long, default_value_t = 0.0)]
        road: f64,
        /// Turns between the legs of a motion.
        #[arg(long, value_enum, default_value_t = OnOff::Off)]
        turns: OnOff,
        /// In-place turns before half of the motions.
        #[arg(long, value_enum, default_value_t = OnOff::Off)]
        in_place_turns: OnOff,
        /// Rest at the start, s.
        #[arg(long, default_value_t = 10.0)]
        initial_rest: f64,
        /// IMU mounting on the robot as roll,pitch,yaw in degrees (sensor to body frame).
        #[arg(long, value_name = "R,P,Y", value_parser = parse_triple, default_value = "0,0,0")]
        mount_deg: [f64; 3],
        #[command(flatten)]
        plan: PlanArgs,
        #[command(flatten)]
        hints: HintArgs,
        #[command(flatten)]
        common: Common,
    },
    /// A pedestrian with the IMU on a foot, walking laps of a rectangle: stance 0.2-0.5 s,
    /// swing of one stride at 4-5 m/s peak foot speed, heel strikes, tremor in stance.
    Walk {
        /// Laps of the rectangle.
        #[arg(long, default_value_t = 1)]
        laps: u32,
        /// Sides of the rectangle, m.
        #[arg(long, value_name = "X,Y", value_parser = parse_pair, default_value = "12,6")]
        rectangle: [f64; 2],
        /// Stride length range, m.
        #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair, default_value = "1.0,1.6")]
        stride: [f64; 2],
        /// Still stance range, s.
        #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair, default_value = "0.2,0.5")]
        stance: [f64; 2],
        /// Peak foot speed range, m/s.
        #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair, default_value = "4,5")]
        peak_speed: [f64; 2],
        /// Standing still at the start, s.
        #[arg(long, default_value_t = 10.0)]
        initial_rest: f64,
        /// Tremor level in stance (1: about 0.05 m/s^2 and 0.3 deg/s RMS; 0: none).
        #[arg(long, default_value_t = 1.0)]
        tremor: f64,
        #[command(flatten)]
        common: Common,
    },
    /// A walker with the sensor in the hand, held in front like a phone for texting, walking
    /// laps of a circle between two rests: the hand bounces and surges once per step and sways
    /// once per stride.
    Handheld {
        #[command(flatten)]
        walk: HandheldArgs,
        #[command(flatten)]
        common: Common,
    },
    /// An industrial arm: a rest, then moves between random waypoints of its workspace with
    /// short pauses, back to the start.
    Arm {
        #[command(flatten)]
        arm: ArmArgs,
        #[command(flatten)]
        common: Common,
    },
    /// Prints a preset's error model as TOML (edit it and pass it back with --model).
    PrintModel {
        /// The preset to print.
        #[arg(long, default_value = "calibrated")]
        preset: Preset,
    },
}

/// The drive's plan (a stop-and-go robot: `--rests 1,2 --legs 2,4`; a car stopping on slopes:
/// `--max-slope-deg 5`).
#[derive(Args)]
struct PlanArgs {
    /// Length of each rest between motions, s.
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair, default_value = "1,30")]
    rests: [f64; 2],
    /// Cruise speed of each leg, m/s.
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair, default_value = "0.2,1")]
    cruise: [f64; 2],
    /// Length of each constant-speed leg, s.
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair, default_value = "2,10")]
    legs: [f64; 2],
    /// Longest motion between two rests, s.
    #[arg(long, default_value_t = 30.0)]
    max_motion: f64,
    /// Largest grade of the road at each stop, degrees (0: a flat, level floor).
    #[arg(long, default_value_t = 0.0)]
    max_slope_deg: f64,
}

/// An arm's path.
/// The hand-held walk's options.
#[derive(Args)]
struct HandheldArgs {
    /// Laps of the circle (fractions allowed).
    #[arg(long, default_value_t = 2.0)]
    laps: f64,
    /// Radius of the circle, m.
    #[arg(long, default_value_t = 4.0)]
    radius: f64,
    /// Walking speed, m/s.
    #[arg(long, default_value_t = 0.8)]
    speed: f64,
    /// Steps per second.
    #[arg(long, default_value_t = 1.7)]
    step_hz: f64,
    /// Standing still at the start and at the end, s.
    #[arg(long, default_value_t = 2.0)]
    rest: f64,
}

impl HandheldArgs {
    fn params(&self, gravity_mps2: f64) -> HandheldParams {
        HandheldParams {
            radius_m: self.radius,
            speed_mps: self.speed,
            step_hz: self.step_hz,
            rest_s: self.rest,
            gravity_mps2,
            ..HandheldParams::new(self.laps)
        }
    }
}

#[derive(Args)]
struct ArmArgs {
    /// Moves (the last one returns to the start).
    #[arg(long, default_value_t = 12)]
    moves: usize,
    /// Pause after each move, s.
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair, default_value = "0.2,0.6")]
    pauses: [f64; 2],
    /// Length of each move, s.
    #[arg(long = "move-s", value_name = "MIN,MAX", value_parser = parse_pair, default_value = "0.8,2")]
    move_s: [f64; 2],
    /// Rest at the start, s.
    #[arg(long, default_value_t = 1.6)]
    initial_rest: f64,
    /// Half-width of the workspace, m.
    #[arg(long, default_value_t = 0.5)]
    reach: f64,
}

impl ArmArgs {
    fn params(&self, gravity_mps2: f64) -> ArmParams {
        ArmParams {
            pause_s: self.pauses,
            move_s: self.move_s,
            initial_rest_s: self.initial_rest,
            reach_m: self.reach,
            gravity_mps2,
            ..ArmParams::new(self.moves)
        }
    }
}

impl PlanArgs {
    /// `params` with this plan.
    fn apply(&self, params: DriveParams) -> DriveParams {
        DriveParams {
            rest_s: self.rests,
            cruise_speed_mps: self.cruise,
            leg_s: self.legs,
            max_motion_s: self.max_motion,
            max_slope_deg: self.max_slope_deg,
            ..params
        }
    }
}

/// Options of every scenario.
#[derive(Args)]
struct Common {
    /// Output file: `.csv` (canonical CSV with truth columns) or `.mcap`; private (0600),
    /// written when the scenario is complete. An existing file there is refused unless
    /// `--force` is given.
    #[arg(long)]
    out: PathBuf,
    /// Replace the file at `--out` (atomically; a symbolic link there is replaced, never
    /// followed).
    #[arg(long)]
    force: bool,
    /// Seed of every random choice (scenario, sensor, vibration).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output data rate, Hz.
    #[arg(long, default_value_t = 1000.0)]
    rate: f64,
    /// Error model preset.
    #[arg(long, default_value = "calibrated")]
    preset: Preset,
    /// Error model from a TOML file (see `print-model`); replaces --preset.
    #[arg(long, conflicts_with = "preset")]
    model: Option<PathBuf>,
    /// Accelerometer white-noise density, ug/sqrt(Hz), all axes (overrides the model's).
    #[arg(long)]
    accel_noise_ug: Option<f64>,
    /// Gyroscope white-noise density, deg/s/sqrt(Hz), all axes (overrides the model's).
    #[arg(long)]
    gyro_noise_dps: Option<f64>,
    /// Accelerometer full-scale range, g.
    #[arg(long, value_enum, default_value_t = AccelFullScale::G2)]
    accel_range: AccelFullScale,
    /// Gyroscope full-scale range, deg/s.
    #[arg(long, value_enum, default_value_t = GyroFullScale::Dps250)]
    gyro_range: GyroFullScale,
    /// Local gravity, m/s^2.
    #[arg(long, default_value_t = STANDARD_GRAVITY_MPS2)]
    gravity: f64,
    /// Digital low-pass filter: `driver` (what our driver configures for --rate, as the real
    /// part then filters: DLPF_CFG = A_DLPF_CFG picked from the rate at 1000/n Hz, 1 (184 Hz)
    /// at 1000 and 500 Hz, 2 (92 Hz) at 200 Hz, see `mems_sim::dlpf::cfg_for_rate`; the
    /// accelerometer bypassed at 4000 Hz), `off` (white noise at the output rate, no part
    /// produces it), or the gyro bandwidth in Hz of DLPF_CFG 0-7 (250, 184, 92, 41, 20, 10, 5,
    /// 3600; the accelerometer gets the same A_DLPF_CFG).
    #[arg(long, default_value = "driver")]
    dlpf: DlpfChoice,
    /// The recording starts this late into the scenario: seconds, or `motion` (at the highest
    /// speed of the first motion: a start in motion, no rest before it).
    #[arg(long, default_value = "0")]
    start_at: StartAt,
    /// The accelerometer's samples lag the gyro's by this, s: each holds the specific force
    /// this long before its time (`mems_sim::mounting`).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    accel_lag_s: f64,
    /// The sensor sits this far from the point the scenario moves (the arm's tool point, the
    /// robot's rear axle), sensor frame, m; the truth stays that point's (`mems_sim::mounting`).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_triple, default_value = "0,0,0",
          allow_hyphen_values = true)]
    lever_arm_m: [f64; 3],
    #[command(flatten)]
    log: LogArgs,
}

/// The defects of a real logger (see `mems_sim::defects`).
#[derive(Args)]
struct LogArgs {
    /// Fraction of rows followed by an exact repeat (a logger polling faster than the sensor).
    #[arg(long, default_value_t = 0.0)]
    repeat_fraction: f64,
    /// Repeats carry their original's timestamp (otherwise the time of the second poll).
    #[arg(long)]
    repeat_same_time: bool,
    /// Host timestamp jitter, ms (Gaussian standard deviation).
    #[arg(long, default_value_t = 0.0)]
    jitter_ms: f64,
    /// Host timestamp quantum, ms (0: none), e.g. 1 for a millisecond clock.
    #[arg(long, default_value_t = 0.0)]
    quantum_ms: f64,
}

/// The `--dlpf` choice.
#[derive(Clone, Copy, PartialEq)]
enum DlpfChoice {
    Off,
    Driver,
    /// DLPF_CFG = A_DLPF_CFG = this.
    Cfg(u8),
}

impl std::str::FromStr for DlpfChoice {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "off" => return Ok(Self::Off),
            "driver" => return Ok(Self::Driver),
            _ => {}
        }
        mems_sim::dlpf::GYRO_DLPF
            .iter()
            .position(|g| g.bandwidth_hz.to_string() == s)
            .map(|cfg| Self::Cfg(cfg as u8))
            .ok_or_else(|| {
                format!(
                    "unknown DLPF {s:?}: expected off, driver or a gyro bandwidth (250, 184, 92, \
                     41, 20, 10, 5, 3600)"
                )
            })
    }
}

/// The `--start-at` choice.
#[derive(Clone, Copy, PartialEq)]
enum StartAt {
    Seconds(f64),
    Motion,
}

impl std::str::FromStr for StartAt {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s == "motion" {
            return Ok(Self::Motion);
        }
        match s.parse::<f64>() {
            Ok(x) if x.is_finite() && x >= 0.0 => Ok(Self::Seconds(x)),
            _ => Err(format!("expected seconds >= 0 or `motion`, got {s:?}")),
        }
    }
}

/// The robot controller's hints during a drive (MCAP topic `mems/robot/hint`, see
/// `mems_sim::hints`).
#[derive(Args)]
struct HintArgs {
    /// Emit robot hints with this source of the stationary flag (MCAP output only).
    #[arg(long, value_enum, default_value_t = HintSource::Off)]
    hints: HintSource,
    /// Hints per second.
    #[arg(long, default_value_t = 50.0)]
    hint_rate: f64,
    /// Fraction of hints lost independently.
    #[arg(long, default_value_t = 0.02)]
    hint_drop: f64,
    /// Loss bursts (0.2-2 s each) per minute.
    #[arg(long, default_value_t = 0.5)]
    hint_bursts_per_min: f64,
    /// Publication latency range after the encoder window, ms.
    #[arg(long, value_name = "MIN,MAX", value_parser = parse_pair, default_value = "5,30")]
    hint_latency_ms: [f64; 2],
    /// How long a velocity command precedes the motion (commanded source), ms.
    #[arg(long, default_value_t = 75.0)]
    hint_command_lead_ms: f64,
}

impl HintArgs {
    /// The hints of `drive` that reach the odometry (none when hints are off), with what was
    /// published and lost printed.
    fn received(&self, drive: &Drive, seed: u64) -> Result<Vec<RobotHint>> {
        let source = match self.hints {
            HintSource::Off => return Ok(Vec::new()),
            HintSource::Commanded => RestSource::Commanded,
            HintSource::Encoders => RestSource::Encoders,
        };
        let p = HintParams {
            rate_hz: self.hint_rate,
            drop_fraction: self.hint_drop,
            bursts_per_min: self.hint_bursts_per_min,
            latency_s: self.hint_latency_ms.map(|ms| ms * 1e-3),
            command_lead_s: self.hint_command_lead_ms * 1e-3,
            ..HintParams::new(source)
        };
        let stream = drive_hints(drive, &p, seed, 0.0)?;
        println!(
            "robot hints: {} published, {} lost, encoder scale error {:+.2}%",
            stream.hints.len() + stream.lost,
            stream.lost,
            100.0 * stream.speed_scale
        );
        Ok(stream.hints)
    }
}

/// Source of the hints' stationary flag on the command line.
#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum HintSource {
    /// No hints.
    Off,
    /// The controller's velocity command (leads the motion).
    Commanded,
    /// The wheel encoders (no tick in the window).
    Encoders,
}

/// Parses `a,b` into two numbers.
fn parse_pair(s: &str) -> Result<[f64; 2], String> {
    let parts: Vec<&str> = s.split(',').collect();
    let [a, b] = parts.as_slice() else {
        return Err(format!("expected two comma-separated numbers, got {s:?}"));
    };
    let num = |x: &str| {
        x.trim()
            .parse::<f64>()
            .map_err(|e| format!("{x:?} in {s:?}: {e}"))
    };
    Ok([num(a)?, num(b)?])
}

/// Timing of pose sessions.
#[derive(Args)]
struct PoseArgs {
    /// How long each pose is held, s (default 30 for six-position, 10 for orientations).
    #[arg(long)]
    hold: Option<f64>,
    /// How long each rotation between poses takes, s.
    #[arg(long, default_value_t = 4.0)]
    rotate: f64,
    /// 1-sigma random tilt of each placement, degrees.
    #[arg(long, default_value_t = 0.0)]
    tilt_deg: f64,
}

/// Accelerometer full-scale range on the command line, in g.
#[derive(Clone, Copy, ValueEnum)]
enum AccelFullScale {
    #[value(name = "2")]
    G2,
    #[value(name = "4")]
    G4,
    #[value(name = "8")]
    G8,
    #[value(name = "16")]
    G16,
}

/// Gyroscope full-scale range on the command line, in deg/s.
#[derive(Clone, Copy, ValueEnum)]
enum GyroFullScale {
    #[value(name = "250")]
    Dps250,
    #[value(name = "500")]
    Dps500,
    #[value(name = "1000")]
    Dps1000,
    #[value(name = "2000")]
    Dps2000,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum OnOff {
    On,
    Off,
}

/// Parses `a,b,c` into three numbers.
fn parse_triple(s: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = s.split(',').collect();
    let [a, b, c] = parts.as_slice() else {
        return Err(format!("expected three comma-separated numbers, got {s:?}"));
    };
    let num = |x: &str| {
        x.trim()
            .parse::<f64>()
            .map_err(|e| format!("{x:?} in {s:?}: {e}"))
    };
    Ok([num(a)?, num(b)?, num(c)?])
}

/// The attitude for roll, pitch, yaw in degrees.
fn rotation_deg([r, p, y]: [f64; 3]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(r.to_radians(), p.to_radians(), y.to_radians())
}

impl Common {
    /// The mounting effects of `--accel-lag-s` and `--lever-arm-m`, checked.
    fn mounting(&self) -> Result<Mounting> {
        let mounting = Mounting {
            accel_lag_s: self.accel_lag_s,
            lever_arm_m: self.lever_arm_m,
        };
        mounting
            .validate()
            .map_err(|e| anyhow::anyhow!("--accel-lag-s / --lever-arm-m: {e}"))?;
        Ok(mounting)
    }

    /// The error model: the preset or the TOML file, with the noise overrides applied.
    fn sensor_model(&self) -> Result<SensorModel> {
        let mut model = match &self.model {
            Some(path) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("reading the model file {}", path.display()))?;
                toml::from_str(&text)
                    .with_context(|| format!("parsing the model file {}", path.display()))?
            }
            None => self.preset.model(),
        };
        if let Some(ug) = self.accel_noise_ug {
            model.accel.noise_density = [ug * 1e-6; 3];
        }
        if let Some(dps) = self.gyro_noise_dps {
            model.gyro.noise_density = [dps; 3];
        }
        model.validate().with_context(|| match &self.model {
            Some(path) => format!("in the model file {}", path.display()),
            None => "in the model".into(),
        })?;
        Ok(model)
    }

    /// The DLPF for the output rate, checked against it: the output rate must be the internal
    /// rate divided by 1 + SMPLRT_DIV (0-255) where the register map allows a divider, and the
    /// internal rate itself where it does not (DLPF_CFG 0 and 7, the 4 kHz accelerometer).
    fn dlpf_config(&self) -> Result<Option<DlpfConfig>> {
        let config = match self.dlpf {
            DlpfChoice::Off => return Ok(None),
            DlpfChoice::Driver => DlpfConfig::driver(self.rate),
            DlpfChoice::Cfg(cfg) => DlpfConfig::both(cfg),
        };
        let fast = config.fast_rate_hz();
        let divided = fast == 1000.0;
        let n = fast / self.rate;
        let ok = if divided {
            n.fract() == 0.0 && (1.0..=256.0).contains(&n)
        } else {
            n == 1.0
        };
        if !ok {
            let allowed = if divided {
                "1000/n Hz (n = 1..256)".to_string()
            } else {
                format!("{fast} Hz")
            };
            bail!(
                "--rate {}: with this --dlpf the part samples at {fast} Hz internally and can \
                 output {allowed} (--dlpf off gives white samples at any rate)",
                self.rate
            );
        }
        Ok(Some(config))
    }

    /// The logger's defects from the command line.
    fn log_defects(&self) -> LogDefects {
        LogDefects {
            repeat_fraction: self.log.repeat_fraction,
            repeat_same_time: self.log.repeat_same_time,
            jitter_std_s: self.log.jitter_ms * 1e-3,
            quantum_s: self.log.quantum_ms * 1e-3,
        }
    }

    fn ranges(&self) -> (AccelRange, GyroRange) {
        let accel = match self.accel_range {
            AccelFullScale::G2 => AccelRange::G2,
            AccelFullScale::G4 => AccelRange::G4,
            AccelFullScale::G8 => AccelRange::G8,
            AccelFullScale::G16 => AccelRange::G16,
        };
        let gyro = match self.gyro_range {
            GyroFullScale::Dps250 => GyroRange::Dps250,
            GyroFullScale::Dps500 => GyroRange::Dps500,
            GyroFullScale::Dps1000 => GyroRange::Dps1000,
            GyroFullScale::Dps2000 => GyroRange::Dps2000,
        };
        (accel, gyro)
    }
}

/// The wall clock of a simulated MCAP recording. Its stamps are scenario time (ns from the
/// scenario's start), not `CLOCK_MONOTONIC`; the file is anchored with scenario time 0 at the
/// moment it is written, so that Foxglove and `mems-info` place the run at that date. The
/// stamps inside the messages are unchanged, so results do not depend on it.
fn wall_clock_now_at_scenario_start() -> WallClock {
    WallClock {
        realtime_ns: WallClock::now().realtime_ns,
        monotonic_ns: 0,
    }
}

/// Where samples go: MCAP is written as it is produced; the canonical CSV writer takes the
/// whole session at once.
enum Sink {
    Csv {
        path: PathBuf,
        samples: Vec<RawImuSample>,
        truth: Vec<Truth>,
    },
    Mcap {
        writer: Box<recording::mcap::Writer>,
        raw: recording::mcap::Channel<RawImuSample>,
        truth: recording::mcap::Channel<Truth>,
        hint: Option<recording::mcap::Channel<RobotHint>>,
    },
}

impl Sink {
    fn create(path: &Path, hints: bool) -> Result<Self> {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
        match ext.to_ascii_lowercase().as_str() {
            "csv" if hints => bail!(
                "--out {}: robot hints need an .mcap output (the canonical CSV has no hint columns)",
                path.display()
            ),
            "csv" => Ok(Self::Csv {
                path: path.to_path_buf(),
                samples: Vec::new(),
                truth: Vec::new(),
            }),
            "mcap" => {
                let mut writer = recording::mcap::Writer::create(path)?;
                writer.anchor(wall_clock_now_at_scenario_start())?;
                let raw = writer.add_channel()?;
                let truth = writer.add_channel()?;
                let hint = if hints {
                    Some(writer.add_channel()?)
                } else {
                    None
                };
                Ok(Self::Mcap {
                    writer: Box::new(writer),
                    raw,
                    truth,
                    hint,
                })
            }
            _ => bail!(
                "--out {}: the file name must end in .csv or .mcap",
                path.display()
            ),
        }
    }

    fn push(&mut self, sample: RawImuSample, truth: Truth) -> Result<()> {
        match self {
            Self::Csv {
                samples, truth: t, ..
            } => {
                samples.push(sample);
                t.push(truth);
            }
            Self::Mcap {
                writer,
                raw,
                truth: channel,
                ..
            } => {
                let time = sample.stamps.sample_ns;
                writer.write(*raw, &sample, time)?;
                writer.write(*channel, &truth, time)?;
            }
        }
        Ok(())
    }

    /// Writes a robot hint at its publication time (MCAP only; `create` refuses hints for CSV).
    fn push_hint(&mut self, h: &RobotHint) -> Result<()> {
        if let Self::Mcap {
            writer,
            hint: Some(channel),
            ..
        } = self
        {
            writer.write(*channel, h, h.stamps.acquired_ns)?;
        }
        Ok(())
    }

    fn finish(self) -> Result<()> {
        match self {
            Self::Csv {
                path,
                samples,
                truth,
            } => {
                let increasing = samples
                    .windows(2)
                    .all(|w| w[1].stamps.sample_ns > w[0].stamps.sample_ns);
                if increasing {
                    recording::csv::write_raw(&path, &samples, Some(&truth))?
                } else {
                    recording::csv::write_log(&path, &samples, Some(&truth))?;
                    println!(
                        "{}: timestamps repeat, so this is a logger's CSV (the canonical \
                         columns, times non-decreasing), not the canonical CSV",
                        path.display()
                    );
                }
            }
            Self::Mcap { writer, .. } => writer.finish()?,
        }
        Ok(())
    }
}

/// `model`, built on the `--vibration` `level`, if both are valid, else an error naming the
/// options that set them.
fn checked(level: f64, model: VibrationModel) -> anyhow::Result<VibrationModel> {
    if !(level.is_finite() && level >= 0.0) {
        bail!("--vibration {level}: the level must be finite and >= 0");
    }
    model.validate().map_err(|e| {
        anyhow::anyhow!(
            "--vibration-floor, --engine-idle, --engine-start, --engine-idle-gyro, \
             --engine-start-gyro or --road: {e}"
        )
    })?;
    Ok(model)
}

/// Samples `scenario` from 0 to its duration at the common rate, quantizes, and writes, with
/// `hints` interleaved by publication time.
fn simulate(
    scenario: impl Scenario,
    vibration: &VibrationModel,
    common: &Common,
    hints: &[RobotHint],
) -> Result<()> {
    let rate = common.rate;
    if !(rate.is_finite() && (1.0..=32_000.0).contains(&rate)) {
        bail!("--rate {rate}: the output rate must be between 1 and 32000 Hz");
    }
    let model = common.sensor_model()?;
    let dlpf = common.dlpf_config()?;
    let (accel_range, gyro_range) = common.ranges();
    let duration = scenario.duration_s();
    let count = (duration * rate).floor() as u64 + 1;
    let start_s = match common.start_at {
        StartAt::Seconds(s) => s,
        StartAt::Motion => peak_speed_time(&scenario, rate)
            .context("--start-at motion: the scenario never moves")?,
    };
    let first = (start_s * rate).ceil() as u64;
    if first >= count {
        bail!("--start-at {start_s}: the scenario ends at {duration} s");
    }
    let defects = common.log_defects();
    let is_mcap = common
        .out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"));
    if defects.any() && is_mcap {
        bail!(
            "--out {}: a logger's defects (--repeat-fraction, --jitter-ms, --quantum-ms) can repeat \
             timestamps, which MCAP recordings refuse; write a .csv",
            common.out.display()
        );
    }
    let mut logger = defects
        .any()
        .then(|| Logger::new(&defects, rate, common.seed))
        .transpose()?;
    let mounting = common.mounting()?;
    let mut sim = SimSensor::new(scenario, &model, vibration, common.seed)?;
    sim.set_dlpf(dlpf.map(DlpfGrid::from_power_on));
    sim.set_mounting(mounting);
    if !common.force {
        mems_files::refuse_existing(&common.out, Some("--out"))?;
    }
    let mut sink = Sink::create(&common.out, !hints.is_empty())?;
    let mut next_hint = 0;
    let (mut distance, mut saturated, mut rest, mut rows) = (0.0, 0u64, 0u64, 0u64);
    let mut last: Option<Vector3<f64>> = None;
    let mut logged = Vec::with_capacity(2);
    let progress = mems_log::progress::bar(Some(count - first), "mems-sim", "samples");
    for k in first..count {
        progress.inc(1);
        let t_s = k as f64 / rate;
        let (analog, truth) = sim.sample_with_truth(t_s, rate);
        let raw = quantize_sample(&analog, accel_range, gyro_range, ns_from_s(t_s), k);
        let p = Vector3::from(truth.position_m);
        if let Some(q) = last {
            distance += (p - q).norm();
        }
        last = Some(p);
        saturated += u64::from(raw.flags & ipc_types::raw_flags::SATURATED != 0);
        rest += u64::from(truth.at_rest);
        while let Some(h) = hints.get(next_hint)
            && h.stamps.acquired_ns <= raw.stamps.sample_ns
        {
            sink.push_hint(h)?;
            next_hint += 1;
        }
        match logger.as_mut() {
            Some(l) => l.log(raw, truth, |s, t| logged.push((s, t))),
            None => logged.push((raw, truth)),
        }
        for (s, t) in logged.drain(..) {
            sink.push(s, t)?;
            rows += 1;
        }
    }
    progress.finish_and_clear();
    let count = count - first;
    for h in &hints[next_hint..] {
        sink.push_hint(h)?;
    }
    sink.finish()
        .with_context(|| format!("writing {}", common.out.display()))?;
    println!(
        "{}: {count} samples ({rows} rows) from {start_s} s to {duration} s at {rate} Hz, \
         {distance:.3} m travelled, {:.1}% at rest, {saturated} saturated",
        common.out.display(),
        100.0 * rest as f64 / count as f64
    );
    Ok(())
}

fn pose_params(args: &PoseArgs, default_hold: f64, common: &Common) -> PoseParams {
    PoseParams {
        rotate_s: args.rotate,
        gravity_mps2: common.gravity,
        placement_tilt_std_deg: args.tilt_deg,
        ..PoseParams::new(args.hold.unwrap_or(default_hold))
    }
}

fn run(cli: Cli) -> Result<()> {
    let still = VibrationModel::moderate(0.0);
    match cli.command {
        Command::SixPosition { poses, common } => {
            let params = pose_params(&poses, 30.0, &common);
            simulate(
                PoseSession::six_position(&params, common.seed)?,
                &still,
                &common,
                &[],
            )
        }
        Command::Orientations { n, poses, common } => {
            let params = pose_params(&poses, 10.0, &common);
            simulate(
                PoseSession::orientations(n, &params, common.seed)?,
                &still,
                &common,
                &[],
            )
        }
        Command::Static {
            duration,
            attitude_deg,
            common,
        } => {
            let s = PoseSession::static_pose(rotation_deg(attitude_deg), duration, common.gravity)?;
            simulate(s, &still, &common, &[])
        }
        Command::Drive {
            duration,
            vibration,
            vibration_floor,
            engine_idle,
            engine_start,
            engine_idle_gyro,
            engine_start_gyro,
            road,
            turns,
            in_place_turns,
            initial_rest,
            mount_deg,
            plan,
            hints,
            common,
        } => {
            let params = plan.apply(DriveParams {
                initial_rest_s: initial_rest,
                turns: turns == OnOff::On,
                in_place_turns: in_place_turns == OnOff::On,
                mounting: rotation_deg(mount_deg),
                gravity_mps2: common.gravity,
                ..DriveParams::new(duration)
            });
            let drive = Drive::new(&params, common.seed)?;
            let hint_list = hints.received(&drive, common.seed)?;
            let model = VibrationModel::moderate(vibration)
                .with_floor(vibration_floor[0], vibration_floor[1])
                .with_engine_idle(engine_idle[0], engine_idle[1], engine_start)
                .with_engine_idle_gyro(engine_idle_gyro)
                .with_engine_start_gyro(engine_start_gyro)
                .with_road(road);
            simulate(drive, &checked(vibration, model)?, &common, &hint_list)
        }
        Command::Walk {
            laps,
            rectangle,
            stride,
            stance,
            peak_speed,
            initial_rest,
            tremor,
            common,
        } => {
            let params = WalkParams {
                rectangle_m: rectangle,
                stride_m: stride,
                stance_s: stance,
                peak_speed_mps: peak_speed,
                initial_rest_s: initial_rest,
                tremor,
                gravity_mps2: common.gravity,
                ..WalkParams::new(laps)
            };
            simulate(Walk::new(&params, common.seed)?, &still, &common, &[])
        }
        Command::Handheld { walk, common } => {
            let params = walk.params(common.gravity);
            simulate(Handheld::new(&params)?, &still, &common, &[])
        }
        Command::Arm { arm, common } => {
            let params = arm.params(common.gravity);
            simulate(Arm::new(&params, common.seed)?, &still, &common, &[])
        }
        Command::PrintModel { preset } => {
            print!("{}", toml::to_string(&preset.model())?);
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    mems_log::init("mems-sim");
    mems_log::exit(run(Cli::parse()))
}
