//! The lever-arm candidate of `mems-odometry diagnose` (`odometry::diagnose::lever`): the
//! run made again with the IMU-only non-holonomic constraint at the declared forward offset
//! plus and minus `lever::PROBE_M`, the profile of its NIS sum fitted, and, when the data
//! support an offset, the run made once more with it and its figures compared with the
//! declared run's.

use std::path::Path;

use anyhow::Result;
use nalgebra::Vector3;
use odometry::config::OdometryConfig;
use odometry::diagnose::Settings;
use odometry::diagnose::lever::{LeverArm, PROBE_M, Point};
use serde_json::{Value, json};

use super::{Declared, DiagnoseArgs, Run, offline, offline_json};

/// Fewest degrees of freedom of the constraint's updates the candidate needs (a second of
/// driving at the propagation interval's rate is tens).
const MIN_DOF: f64 = 100.0;

/// The constraint's NIS sum and degrees of freedom in an offline run's JSON (`None`: no
/// IMU-only constraint ran).
fn point(json: &Value, r_x_m: f64) -> Option<Point> {
    let w = &json["wheeled"];
    Some(Point {
        r_x_m,
        chi2: w["nonholonomic_nis_sum"].as_f64()?,
        dof: w["nonholonomic_dof_sum"].as_f64()?,
    })
}

/// Tests the lever-arm candidate on the run `before`, made as `declared` says; `end` is the
/// known end point, if any. Returns the candidate and, when found, the rerun's figures
/// beside the declared run's, as JSON.
pub fn test(
    args: &DiagnoseArgs,
    declared: Declared,
    before: &Run,
    dir: &Path,
    config: &OdometryConfig,
    end: Option<Vector3<f64>>,
) -> Result<Value> {
    let r0 = declared.lever_arm_m;
    let Some(first) = point(&before.json, r0[0]) else {
        let why =
            "no IMU-only non-holonomic constraint ran (a wheeled profile without speed hints)";
        return Ok(json!({ "candidate": LeverArm::untestable(why.into()) }));
    };
    if first.dof < MIN_DOF {
        let why = format!(
            "{:.0} degrees of freedom of the constraint's updates (needs {MIN_DOF})",
            first.dof
        );
        return Ok(json!({ "candidate": LeverArm::untestable(why) }));
    }
    let mut points = vec![first];
    for (k, dx) in [-PROBE_M, PROBE_M].into_iter().enumerate() {
        let r = [r0[0] + dx, r0[1], r0[2]];
        let probe = Declared {
            lever_arm_m: r,
            ..declared
        };
        let json = offline_json(args, probe, &format!("lever probe {k}"), None)?;
        if let Some(p) = point(&json, r[0]) {
            points.push(p);
        }
    }
    let s = Settings::default();
    let lever = LeverArm::from_profile(points, s.threshold, s.beyond_model);
    if !lever.found {
        return Ok(json!({ "candidate": lever }));
    }
    let fitted = Declared {
        lever_arm_m: [lever.r_x_m, r0[1], r0[2]],
        ..declared
    };
    let after = offline(args, fitted, dir, "lever", config)?;
    let nis_after = point(&after.json, lever.r_x_m);
    // The rerun confirms the offset when its constraint's NIS sum is no larger.
    let confirmed = nis_after.map(|p| p.chi2 <= first.chi2);
    Ok(json!({
        "candidate": lever,
        "lever_arm_m": fitted.lever_arm_m,
        "nis_sum_after": nis_after.map(|p| p.chi2),
        "confirmed": confirmed,
        "before": before.figures(end),
        "after": after.figures(end),
    }))
}
