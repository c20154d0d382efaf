//! `--profile auto` offline: the platform recognized from the whole recording
//! (`odometry::platform`) before the stages run, since the profile sets the calibration stage's
//! detector as well as the odometry's rest handling.

use std::path::Path;

use anyhow::Result;
use ipc_types::{RawImuSample, raw_flags};
use odometry::platform::{Classifier, Features};
use odometry::profile::Profile;
use recording::mcap::run::{Item, RawRun};

/// The profile a run uses and how it was chosen.
#[derive(Debug, Clone, Copy)]
pub struct Choice {
    /// The profile the stages run with.
    pub profile: Profile,
    /// What the recognition measured, when `--profile auto` asked for it.
    pub features: Option<Features>,
}

impl Choice {
    /// The JSON record of the choice.
    pub fn json(&self) -> serde_json::Value {
        serde_json::json!({
            "profile": self.profile.name(),
            "chosen_by": if self.features.is_some() { "auto" } else { "flag" },
            "platform": self.features,
        })
    }
}

/// The profile for `asked` at `input`: itself, or for `Auto` the one the recognized platform
/// takes (said on stderr with its figures).
pub fn choose(asked: Profile, input: &Path, mcap: bool) -> Result<Choice> {
    if asked != Profile::Auto {
        return Ok(Choice {
            profile: asked,
            features: None,
        });
    }
    let mut c = Classifier::default();
    let mut push = |r: &RawImuSample| {
        if r.flags & raw_flags::GYRO_VALID != 0 {
            c.push(r.stamps.sample_ns, r.accel_g, r.gyro_dps);
        }
    };
    if mcap {
        for item in RawRun::open(input, false)? {
            if let Item::Raw(r) = item? {
                push(&r);
            }
        }
    } else {
        let recording = recording::load_raw_with(input, recording::LogPolicy::Repair)?;
        recording.samples.iter().for_each(&mut push);
    }
    c.finish();
    let f = c.features();
    let profile = Profile::for_platform(f.platform);
    tracing::info!(
        "--profile auto: {} platform, profile {} (over {:.0} s of motion: tilt rate {:.1} deg/s, \
         principal-axis share {:.2} at {:.0} deg from gravity, {:.1} impacts/min)",
        f.platform.name(),
        profile.name(),
        f.moving_s,
        f.tilt_rate_dps,
        f.principal_share,
        f.principal_axis_deg,
        f.impacts_per_min
    );
    Ok(Choice {
        profile,
        features: Some(f),
    })
}
