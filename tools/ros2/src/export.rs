//! `mems-ros2 export`: a recorded run (all its segment files) rewritten as a ROS 2 bag.
//!
//! | topic | type | from |
//! |---|---|---|
//! | [`IMU_TOPIC`] | `sensor_msgs/msg/Imu` | each corrected sample |
//! | [`ODOM_TOPIC`] | `nav_msgs/msg/Odometry` | each live odometry state |
//! | [`REVISED_TOPIC`] | `nav_msgs/msg/Odometry` | each revised state (`REVISION`), stamped with the sample time it revises |
//! | [`TF_TOPIC`] | `tf2_msgs/msg/TFMessage` | each live state: `odom` -> `base_link` once aligned, `base_link` -> `imu_link` |
//!
//! Times: a header's stamp is the message's sample time (`stamps.sample_ns`) on the
//! recording's wall clock (its `mems.clock` anchor, the one of the segment file the message is
//! in), as a ROS driver stamps a measurement; the MCAP log (and publish) time is the
//! recording's log time, which is the recorder's receive time on the same clock, as
//! `ros2 bag record` logs the time it received each message. A recording without an anchor
//! gives `CLOCK_MONOTONIC` times (said once on stderr).

use std::path::Path;

use anyhow::{Context, Result, bail};
use ipc_types::{CorrectedImuSample, Message as _, OdometryState};
use recording::clock::WallClock;
use recording::mcap::run::RunReader;

use crate::bag::{Bag, Topic};
use crate::convert;
use crate::msg::{Imu, Odometry, TfMessage, Time};

/// Topic of the IMU's samples.
pub const IMU_TOPIC: &str = "/imu/data";
/// Topic of the live odometry.
pub const ODOM_TOPIC: &str = "/odom";
/// Topic of the odometry's revisions of past states.
pub const REVISED_TOPIC: &str = "/odom/revised";
/// Topic of the transforms.
pub const TF_TOPIC: &str = "/tf";

/// How many messages went to each topic.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct Counts {
    /// On [`IMU_TOPIC`].
    pub imu: u64,
    /// On [`ODOM_TOPIC`].
    pub odom: u64,
    /// On [`REVISED_TOPIC`].
    pub revised: u64,
    /// On [`TF_TOPIC`].
    pub tf: u64,
}

/// The bag's topics.
struct Topics {
    imu: Topic<Imu>,
    odom: Topic<Odometry>,
    revised: Topic<Odometry>,
    tf: Topic<TfMessage>,
}

/// Writes the run `reader` reads (whose first file is `input`) as a ROS 2 bag at `out`, which
/// must not exist (see [`Bag::create_new`]); the bag is removed if the export fails.
pub fn export(mut reader: RunReader, input: &Path, out: &Path) -> Result<Counts> {
    let mut bag = Bag::create_new(out)?;
    let result = write_run(&mut reader, &mut bag).and_then(|counts| {
        bag.finish()?;
        Ok(counts)
    });
    if result.is_err() {
        // Best effort: the error being reported matters more than a failed removal.
        let _ = std::fs::remove_file(out);
    }
    for segment in reader.segments() {
        if let Some(cut) = &segment.truncation {
            tracing::warn!("{} ends early: {cut}", segment.path.display());
        }
    }
    let counts = result?;
    if counts.imu + counts.odom + counts.revised == 0 {
        let _ = std::fs::remove_file(out);
        bail!(
            "{} holds no corrected samples and no odometry states (a raw recording: \
             `mems-odometry offline --input {0} --out F.mcap` computes them)",
            input.display()
        );
    }
    Ok(counts)
}

fn write_run(reader: &mut RunReader, bag: &mut Bag) -> Result<Counts> {
    let topics = Topics {
        imu: bag.add_topic(IMU_TOPIC)?,
        odom: bag.add_topic(ODOM_TOPIC)?,
        revised: bag.add_topic(REVISED_TOPIC)?,
        tf: bag.add_topic(TF_TOPIC)?,
    };
    let mut counts = Counts::default();
    let mut warned = false;
    while let Some(message) = reader.next() {
        let message = message?;
        let log_ns = message.log_time_ns;
        let item = match (
            message.decode::<CorrectedImuSample>(),
            message.decode::<OdometryState>(),
        ) {
            (Some(sample), _) => Item::Sample(sample?),
            (_, Some(state)) => Item::State(state?),
            _ => continue,
        };
        let clock = reader.clock();
        if clock.is_none() && !warned {
            warned = true;
            tracing::warn!("the recording has no wall-clock anchor: times are CLOCK_MONOTONIC");
        }
        item.write(
            bag,
            &topics,
            stamp(clock, item.sample_ns())?,
            log_ns,
            &mut counts,
        )?;
    }
    Ok(counts)
}

/// A message the bag takes.
#[derive(Clone, Copy)]
enum Item {
    Sample(CorrectedImuSample),
    State(OdometryState),
}

impl Item {
    fn sample_ns(&self) -> u64 {
        match self {
            Self::Sample(s) => s.stamps.sample_ns,
            Self::State(s) => s.stamps.sample_ns,
        }
    }

    fn write(
        &self,
        bag: &mut Bag,
        topics: &Topics,
        stamp: Time,
        log_ns: u64,
        counts: &mut Counts,
    ) -> Result<()> {
        match self {
            Self::Sample(sample) => {
                counts.imu += 1;
                bag.write(topics.imu, &convert::imu(sample, stamp), log_ns)
            }
            Self::State(state) if state.is_revision() => {
                counts.revised += 1;
                bag.write(topics.revised, &convert::odometry(state, stamp), log_ns)
            }
            Self::State(state) => {
                counts.odom += 1;
                counts.tf += 1;
                bag.write(topics.odom, &convert::odometry(state, stamp), log_ns)?;
                bag.write(topics.tf, &convert::transforms(state, stamp), log_ns)
            }
        }
    }
}

/// The header stamp of sample time `sample_ns` on `clock` (`CLOCK_MONOTONIC` without one).
fn stamp(clock: Option<WallClock>, sample_ns: u64) -> Result<Time> {
    let ns = clock.map_or(sample_ns, |c| c.unix_ns(sample_ns));
    Time::from_ns(ns).with_context(|| format!("a stamp of {ns} ns is past 2038 (int32 seconds)"))
}
