//! The live view: mems topics turned into Foxglove channels, for the WebSocket server of
//! Foxglove's official SDK (`mems-foxglove`, started by `mems-stack --foxglove ADDR`), as
//! foxglove_bridge does for ROS.
//!
//! Channels (Foxglove's well-known schemas are protobuf; ours are JSON with the JSON Schema
//! the recordings use, so a panel reads the same fields live and from an MCAP file):
//! - `/mems/odometry/pose` (`foxglove.PoseInFrame`, frame `nav`): each live state's pose;
//! - `/mems/odometry/revised_pose` (`foxglove.PoseInFrame`): states republished with
//!   `REVISION` (history corrected in hindsight), apart, so the live pose's times never go back;
//! - `/tf` (`foxglove.FrameTransform`): `nav` -> `body` at each live state, for the 3D panel;
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

use foxglove::messages::{
    FrameTransform, Pose, PoseInFrame, PosesInFrame, Quaternion, Timestamp, Vector3,
};
use foxglove::{Channel, ChannelBuilder, Context, PartialMetadata, RawChannel, Schema};
use ipc_types::{CorrectedImuSample, OdometryState, odometry_flags};
use recording::mcap::Topic;

/// The navigation frame's id (z up, origin and heading fixed at alignment).
pub const NAV_FRAME: &str = "nav";
/// The sensor body's frame id.
pub const BODY_FRAME: &str = "body";
/// Sample time between two poses of the path, ns.
pub const PATH_STEP_NS: u64 = 100_000_000;
/// Poses kept in the path.
pub const PATH_LEN: usize = 3000;
/// Sample time between two path messages, ns.
pub const PATH_EVERY_NS: u64 = 500_000_000;

pub use recording::clock::WallClock;

/// Foxglove's timestamp of monotonic time `t_ns` on `clock`.
fn timestamp(clock: &WallClock, t_ns: u64) -> Timestamp {
    let unix = clock.unix_ns(t_ns);
    Timestamp::new(
        u32::try_from(unix / 1_000_000_000).unwrap_or(u32::MAX),
        (unix % 1_000_000_000) as u32,
    )
}

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
    pose: Channel<PoseInFrame>,
    revised: Channel<PoseInFrame>,
    tf: Channel<FrameTransform>,
    path: Channel<PosesInFrame>,
    state: Arc<RawChannel>,
    corrected: Arc<RawChannel>,
    poses: std::collections::VecDeque<Pose>,
    last_path_pose_ns: Option<u64>,
    last_path_sent_ns: Option<u64>,
    json: Vec<u8>,
}

fn pose_of(s: &OdometryState) -> Pose {
    let [x, y, z] = s.position_m;
    let [w, qx, qy, qz] = s.attitude_wxyz;
    Pose {
        position: Some(Vector3 { x, y, z }),
        orientation: Some(Quaternion {
            x: qx,
            y: qy,
            z: qz,
            w,
        }),
    }
}

impl View {
    /// Creates the channels in `ctx`.
    pub fn new(ctx: &Arc<Context>, clock: WallClock) -> anyhow::Result<Self> {
        let typed = |topic: &str| ChannelBuilder::new(topic).context(ctx);
        Ok(Self {
            clock,
            pose: typed("/mems/odometry/pose").build(),
            revised: typed("/mems/odometry/revised_pose").build(),
            tf: typed("/tf").build(),
            path: typed("/mems/odometry/path").build(),
            state: json_channel::<OdometryState>(ctx)?,
            corrected: json_channel::<CorrectedImuSample>(ctx)?,
            poses: std::collections::VecDeque::with_capacity(PATH_LEN),
            last_path_pose_ns: None,
            last_path_sent_ns: None,
            json: Vec::new(),
        })
    }

    /// Logs one odometry state on its channels, at its sample time.
    pub fn state(&mut self, s: &OdometryState) -> anyhow::Result<()> {
        let t_ns = s.stamps.sample_ns;
        let meta = PartialMetadata::with_log_time(self.clock.unix_ns(t_ns));
        self.json.clear();
        serde_json::to_writer(&mut self.json, s)?;
        self.state.log_with_meta(&self.json, meta);
        let pose = pose_of(s);
        let stamped = PoseInFrame {
            timestamp: Some(timestamp(&self.clock, t_ns)),
            frame_id: NAV_FRAME.into(),
            pose: Some(pose),
        };
        if s.flags & odometry_flags::REVISION != 0 {
            self.revised.log_with_meta(&stamped, meta);
            return Ok(());
        }
        self.pose.log_with_meta(&stamped, meta);
        self.tf.log_with_meta(
            &FrameTransform {
                timestamp: stamped.timestamp,
                parent_frame_id: NAV_FRAME.into(),
                child_frame_id: BODY_FRAME.into(),
                translation: pose.position,
                rotation: pose.orientation,
            },
            meta,
        );
        if s.flags & odometry_flags::ALIGNED == 0 {
            return Ok(());
        }
        if self
            .last_path_pose_ns
            .is_none_or(|t| t_ns >= t + PATH_STEP_NS)
        {
            if self.poses.len() == PATH_LEN {
                self.poses.pop_front();
            }
            self.poses.push_back(pose);
            self.last_path_pose_ns = Some(t_ns);
        }
        if self
            .last_path_sent_ns
            .is_none_or(|t| t_ns >= t + PATH_EVERY_NS)
        {
            self.path.log_with_meta(
                &PosesInFrame {
                    timestamp: stamped.timestamp,
                    frame_id: NAV_FRAME.into(),
                    poses: self.poses.iter().cloned().collect(),
                },
                meta,
            );
            self.last_path_sent_ns = Some(t_ns);
        }
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
