//! The live view: mems topics turned into Foxglove channels, for the WebSocket server of
//! Foxglove's official SDK (`mems-foxglove`, started by `mems-stack --foxglove ADDR`), as
//! foxglove_bridge does for ROS.
//!
//! Channels (Foxglove's well-known schemas are protobuf; ours are JSON with the JSON Schema
//! the recordings use, so a panel reads the same fields live and from an MCAP file):
//! - `/mems/odometry/pose` (`foxglove.PoseInFrame`, frame `nav`): the pose of the first live
//!   state in each [`DISPLAY_STEP_NS`] of sample time (50 Hz, as the recording has it);
//! - `/mems/odometry/revised_pose` (`foxglove.PoseInFrame`): states republished with
//!   `REVISION` (history corrected in hindsight), likewise at most one per
//!   [`DISPLAY_STEP_NS`], apart, so the live pose's times never go back;
//! - `/tf` (`foxglove.FrameTransform`): `nav` -> `body` with each pose, for the 3D panel;
//! - `/mems/odometry/path` (`foxglove.PosesInFrame`): the live track, one pose per
//!   [`PATH_STEP_NS`] of sample time, the last [`PATH_LEN`] of them, sent every
//!   [`PATH_EVERY_NS`];
//! - `/mems/odometry/state`, `/mems/imu/corrected` (JSON, `mems.OdometryState`,
//!   `mems.CorrectedImuSample`): every message as published, sigma included.
//!
//! Times: our messages carry `CLOCK_MONOTONIC` ns; Foxglove places messages by Unix time, so
//! each time is shifted by `CLOCK_REALTIME - CLOCK_MONOTONIC` measured once at start
//! ([`WallClock`], the recorder's too). The JSON messages keep their own monotonic stamps.

use std::sync::Arc;

use foxglove::messages::{FrameTransform, PoseInFrame, PosesInFrame};
use foxglove::{Channel, ChannelBuilder, Context, PartialMetadata, RawChannel, Schema};
use ipc_types::{CorrectedImuSample, OdometryState};
use recording::mcap::Topic;
use recording::mcap::derived::{Derived, Out};

pub use recording::mcap::derived::{
    BODY_FRAME, DISPLAY_STEP_NS, NAV_FRAME, PATH_EVERY_NS, PATH_LEN, PATH_STEP_NS,
};

pub use recording::clock::WallClock;

/// A JSON channel whose schema is the recording's for `T`.
fn json_channel<T: Topic>(ctx: &Arc<Context>) -> anyhow::Result<Arc<RawChannel>> {
    let schema = serde_json::to_vec(&T::json_schema())?;
    Ok(ChannelBuilder::new(format!("/{}", T::TOPIC))
        .context(ctx)
        .message_encoding("json")
        .schema(Schema::new(T::SCHEMA_NAME, "jsonschema", schema))
        .build_raw()?)
}

/// The channels of the live view and the path it keeps.
pub struct View {
    clock: WallClock,
    derived: Derived,
    pose: Channel<PoseInFrame>,
    revised: Channel<PoseInFrame>,
    tf: Channel<FrameTransform>,
    path: Channel<PosesInFrame>,
    state: Arc<RawChannel>,
    corrected: Arc<RawChannel>,
    json: Vec<u8>,
}

impl View {
    /// Creates the channels in `ctx`.
    pub fn new(ctx: &Arc<Context>, clock: WallClock) -> anyhow::Result<Self> {
        let typed = |topic: &str| ChannelBuilder::new(topic).context(ctx);
        Ok(Self {
            clock,
            derived: Derived::new(Some(clock)),
            pose: typed("/mems/odometry/pose").build(),
            revised: typed("/mems/odometry/revised_pose").build(),
            tf: typed("/tf").build(),
            path: typed("/mems/odometry/path").build(),
            state: json_channel::<OdometryState>(ctx)?,
            corrected: json_channel::<CorrectedImuSample>(ctx)?,
            json: Vec::new(),
        })
    }

    /// Logs one odometry state on its channels, at its sample time (the derived messages of
    /// `recording::mcap::derived`, as the recorder writes them).
    pub fn state(&mut self, s: &OdometryState) -> anyhow::Result<()> {
        let t_ns = s.stamps.sample_ns;
        let meta = PartialMetadata::with_log_time(self.clock.unix_ns(t_ns));
        self.json.clear();
        serde_json::to_writer(&mut self.json, s)?;
        self.state.log_with_meta(&self.json, meta);
        let Self {
            derived,
            pose,
            revised,
            tf,
            path,
            ..
        } = self;
        derived.state(s, |out| {
            match out {
                Out::Pose(m) => pose.log_with_meta(m, meta),
                Out::RevisedPose(m) => revised.log_with_meta(m, meta),
                Out::Tf(m) => tf.log_with_meta(m, meta),
                Out::Path(m) => path.log_with_meta(m, meta),
            }
            Ok::<(), std::convert::Infallible>(())
        })?;
        Ok(())
    }

    /// Logs one corrected sample, at its sample time.
    pub fn corrected(&mut self, c: &CorrectedImuSample) -> anyhow::Result<()> {
        self.json.clear();
        serde_json::to_writer(&mut self.json, c)?;
        let meta = PartialMetadata::with_log_time(self.clock.unix_ns(c.stamps.sample_ns));
        self.corrected.log_with_meta(&self.json, meta);
        Ok(())
    }
}
