//! `--profile auto` offline: the platform recognized from the whole recording
//! (`odometry::platform`; up to its first 120 s of motion) before the stages run. A foot runs the pedestrian profile from the
//! start, a walker's hand the walking profile (its alignment on whole steps must see the
//! walk from its start) (its SHOE detector is the calibration stage's, which a live stack cannot change once
//! running), and so does a recording that looks like neither a foot nor a wheeled platform over
//! at least 10 s of motion (an arm, a hand-held box) with the other profile (its GLRT's
//! window is shorter, `odometry::profile::OTHER_GLRT_WINDOW_S`); any other recording runs as
//! `mems-odometry serve --profile auto` does (the GLRT, the session deciding after 10 s of
//! motion, `odometry::session`), so that offline and live give the same states.

use std::path::Path;

use anyhow::Result;
use ipc_types::{RawImuSample, raw_flags};
use odometry::platform::{Classifier, Features, Platform};
use odometry::profile::Profile;
use odometry::session::{AUTO_DECIDE_MOVING_S, AutoChoice};
use recording::mcap::run::{Item, RawRun};

/// Motion after which the look at the recording stops, s.
const PREPASS_MOVING_S: f64 = 120.0;

/// The profile a run uses and how it was chosen.
#[derive(Debug, Clone, Copy)]
pub struct Choice {
    /// The profile the stages start with: `Auto` when the session decides as live.
    pub profile: Profile,
    /// What the recognition measured, when `--profile auto` asked for it.
    pub features: Option<Features>,
}

impl Choice {
    /// The JSON record of the choice, with the session's decision `live` (the live rule's).
    pub fn json(&self, live: Option<AutoChoice>) -> serde_json::Value {
        let (profile, chosen_by) = match (self.features, self.profile, live) {
            (None, p, _) => (p, "flag"),
            (Some(_), Profile::Auto, Some(c)) => (c.profile, "auto: after 10 s of motion"),
            (Some(_), Profile::Auto, None) => (Profile::Other, "auto: undecided"),
            (Some(_), p, _) => (p, "auto: whole recording"),
        };
        serde_json::json!({
            "profile": profile.name(),
            "chosen_by": chosen_by,
            "platform": self.features,
            "decided_at_s": live.map(|c| c.at_ns as f64 * 1e-9),
            "live_rule_platform": live.map(|c| c.features),
        })
    }
}

/// The profile for `asked` at `input`: itself, or for `Auto` the pedestrian profile when the
/// whole recording is a foot's and otherwise `Auto` (the session decides as live), said on
/// stderr with the figures.
pub fn choose(asked: Profile, input: &Path, mcap: bool) -> Result<Choice> {
    if asked != Profile::Auto {
        return Ok(Choice {
            profile: asked,
            features: None,
        });
    }
    let mut c = Classifier::default();
    // Feeds a sample; `true` once enough motion has been seen.
    let mut push = |r: &RawImuSample| {
        if r.flags & raw_flags::GYRO_VALID != 0 {
            c.push(r.stamps.sample_ns, r.accel_g, r.gyro_dps);
        }
        c.moving_s() >= PREPASS_MOVING_S
    };
    // Stops at PREPASS_MOVING_S of motion: enough to tell, and a long run is not read twice.
    if mcap {
        for item in RawRun::open(input, false)? {
            if let Item::Raw(r) = item?
                && push(&r)
            {
                break;
            }
        }
    } else {
        let recording = recording::load_raw_with(input, recording::LogPolicy::Repair)?;
        for r in &recording.samples {
            if push(r) {
                break;
            }
        }
    }
    c.finish();
    let f = c.features();
    // A foot and an arm or hand-held box (after as much motion as the live rule decides on)
    // need detectors of their own (SHOE; the other profile's shorter window, which finds an
    // arm's pauses); the rest decide as live.
    let profile = match f.platform {
        Platform::Foot => Profile::Pedestrian,
        Platform::Walking => Profile::Walking,
        Platform::Other if f.moving_s >= AUTO_DECIDE_MOVING_S => Profile::Other,
        Platform::Wheeled | Platform::Other => Profile::Auto,
    };
    tracing::info!(
        "--profile auto: the whole recording looks {} ({}) (over {:.0} s of motion: tilt rate {:.1} deg/s, \
         principal-axis share {:.2} at {:.0} deg from gravity, {:.1} impacts/min)",
        f.platform.name(),
        match profile {
            Profile::Auto => "the odometry decides as live, after 10 s of motion",
            Profile::Other => "profile other",
            Profile::Walking => "profile walking",
            _ => "profile pedestrian",
        },
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
