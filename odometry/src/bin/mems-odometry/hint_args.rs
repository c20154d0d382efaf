//! Command-line options for robot hints, shared by `serve` and `offline`.

use anyhow::{Result, bail};
use nalgebra::{UnitQuaternion, Vector3};
use odometry::eskf::Heading;
use odometry::hints::HintConfig;

/// How the odometry uses robot hints (`mems/robot/hint`).
#[derive(clap::Args, Clone)]
pub struct HintArgs {
    /// A hint older than this is stale and the odometry falls back to the IMU alone, s.
    #[arg(long, default_value_t = 0.25)]
    pub hint_max_age_s: f64,
    /// A hint is used by samples taken at least this long after its publication, ms.
    #[arg(long, default_value_t = 5.0)]
    pub hint_delivery_ms: f64,
    /// IMU mounting on the robot: `R,P,Y` in degrees (roll, pitch, yaw of the rotation from
    /// the sensor frame to the body frame, x forward, y left, z up), or `estimate` (from the
    /// first 3 m of forward driving after a rest; speed hints are used once it is known).
    /// Without it, the mounting is estimated from the horizontal acceleration against the
    /// speed hints' changes and turns (`odometry::cruise::ForwardAxis`; a speed hint along a
    /// wrong axis is worse than none, so they wait for it); a wheeled platform's IMU-only
    /// non-holonomic constraint estimates its own from its first drive.
    #[arg(long)]
    pub mount: Option<String>,
    /// 1-sigma of the zero lateral and vertical body velocity (non-holonomic constraint), m/s.
    #[arg(long, default_value_t = 0.02)]
    pub nonholonomic_sigma: f64,
    /// 1-sigma of the wheel-speed scale error (prior of the filter's scale state), fraction.
    #[arg(long, default_value_t = 0.02)]
    pub speed_scale_sigma: f64,
    /// Let the speed hints' updates turn the heading (the filter's optimal gain), which
    /// body-frame velocities do not observe: for comparison (`odometry::eskf::Heading`).
    #[arg(long)]
    pub speed_hints_turn_heading: bool,
    /// The speed source's lag behind the IMU, ms: added to each speed hint's time before it
    /// is compared with the filter's velocity (`tools/real-data/hint_lag.py` measures it).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub hint_speed_lag_ms: f64,
    /// The lever arm from the IMU to the rear axle, the point the non-holonomic constraint
    /// and the wheel speed describe: `X,Y,Z` in metres, body frame (x forward, y left, z up;
    /// an IMU 1.2 m ahead of the axle is `-1.2,0,0`). Default: the IMU on the axle.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true, value_parser = parse_xyz_m)]
    pub lever_arm: Option<[f64; 3]>,
}

/// Parses `X,Y,Z` (m): a lever arm or a point (`diagnose --end`).
pub fn parse_xyz_m(text: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|x| {
            x.trim()
                .parse::<f64>()
                .map_err(|e| format!("{text:?}: {x:?} is not a number: {e}"))
        })
        .collect::<Result<_, _>>()?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(format!("{text:?}: three finite numbers X,Y,Z (m) expected")),
    }
}

impl HintArgs {
    /// The stage's hint configuration; an error names the option.
    pub fn config(&self) -> Result<HintConfig> {
        let given = self.mount.as_deref();
        let mounting = match given.map(str::trim) {
            None | Some("estimate") => None,
            Some(text) => Some(parse_mount(text)?),
        };
        let config = HintConfig {
            max_age_s: self.hint_max_age_s,
            delivery_s: self.hint_delivery_ms * 1e-3,
            mounting,
            imu_mounting: given.and(mounting),
            mounting_from_turns: given.is_none(),
            nonholonomic_sigma_mps: self.nonholonomic_sigma,
            speed_scale_sigma: self.speed_scale_sigma,
            speed_heading: if self.speed_hints_turn_heading {
                Heading::Corrected
            } else {
                Heading::Kept
            },
            speed_time_offset_s: self.hint_speed_lag_ms * 1e-3,
            lever_arm_m: self.lever_arm.map_or_else(Vector3::zeros, Vector3::from),
            ..HintConfig::default()
        };
        config.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
        Ok(config)
    }
}

/// `R,P,Y` in degrees as the rotation from the sensor frame to the body frame.
fn parse_mount(mount: &str) -> Result<UnitQuaternion<f64>> {
    let parts: Vec<&str> = mount.split(',').collect();
    let [r, p, y] = parts.as_slice() else {
        bail!(
            "--mount {mount:?}: expected `estimate` or three comma-separated angles R,P,Y in degrees"
        );
    };
    let mut angles = [0.0; 3];
    for (a, text) in angles.iter_mut().zip([r, p, y]) {
        *a = text
            .trim()
            .parse::<f64>()
            .map_err(|e| anyhow::anyhow!("--mount {mount:?}: {text:?} is not a number: {e}"))?;
    }
    let [r, p, y] = angles.map(f64::to_radians);
    Ok(UnitQuaternion::from_euler_angles(r, p, y))
}
