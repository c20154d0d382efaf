//! The live view: mems topics turned into Foxglove channels, for the WebSocket server of
//! Foxglove's official SDK (`mems-foxglove`, started by `mems-stack --foxglove ADDR`), as
//! foxglove_bridge does for ROS.
//!
//! Every channel has the topic, message encoding and schema its recording has, so one
//! Foxglove layout opens the live view and a recorded file alike (`tests/tests/stack_foxglove.rs`
//! compares the two):
//! - `mems/imu/raw`, `mems/imu/corrected`, `mems/odometry/state`, `mems/robot/hint`:
//!   every message as published, protobuf with the recording's schemas
//!   (`recording::mcap::proto`, sigmas included);
//! - `mems/odometry/pose` (`foxglove.PoseInFrame`, frame `nav`): the pose of the first live
//!   state in each [`DISPLAY_STEP_NS`] of sample time (50 Hz);
//! - `mems/odometry/revised_pose` (`foxglove.PoseInFrame`): states republished with
//!   `REVISION` (history corrected in hindsight), likewise at most one per
//!   [`DISPLAY_STEP_NS`], apart, so the live pose's times never go back;
//! - `mems/odometry/tf` (`foxglove.FrameTransform`): `nav` -> `body` with each pose, for the
//!   3D panel (which takes transforms from every `foxglove.FrameTransform` topic);
//! - `mems/odometry/path` (`foxglove.PosesInFrame`): the live track, one pose per
//!   [`PATH_STEP_NS`] of sample time, the last [`PATH_LEN`] of them, sent every
//!   [`PATH_EVERY_NS`].
//!
//! The derived messages are `recording::mcap::derived`'s, as the recorder writes them.
//!
//! Times: our messages carry `CLOCK_MONOTONIC` ns; Foxglove places messages by Unix time, so
//! each message is logged at its own time ([`Topic::publish_time_ns`]) shifted by
//! `CLOCK_REALTIME - CLOCK_MONOTONIC` measured once at start ([`WallClock`], the recorder's
//! too); the messages keep their own monotonic stamps.

pub mod hints;
pub mod live;
pub mod parameters;
pub mod subprotocol;

use std::sync::Arc;

use foxglove::messages::{FrameTransform, PoseInFrame, PosesInFrame};
use foxglove::{Channel, ChannelBuilder, Context, PartialMetadata, RawChannel, Schema};
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint};
use recording::mcap::derived::{
    Derived, Out, PATH_TOPIC, POSE_TOPIC, REVISED_POSE_TOPIC, TF_TOPIC,
};
use recording::mcap::{MessageEncoding, Topic};

pub use recording::mcap::derived::{
    BODY_FRAME, DISPLAY_STEP_NS, NAV_FRAME, PATH_EVERY_NS, PATH_LEN, PATH_STEP_NS,
};

pub use recording::clock::WallClock;

/// The channel of one of our message types, protobuf as its recording has it.
pub struct Proto<T: Topic> {
    channel: Arc<RawChannel>,
    proto: T::Proto,
    buf: Vec<u8>,
}

impl<T: Topic> Proto<T> {
    /// Creates the channel `T::TOPIC` in `ctx`, with the recording's schema for `T`.
    pub fn new(ctx: &Arc<Context>) -> anyhow::Result<Self> {
        let encoding = MessageEncoding::Protobuf;
        let schema = Schema::new(T::SCHEMA_NAME, encoding.schema(), T::proto_schema());
        let channel = ChannelBuilder::new(T::TOPIC)
            .context(ctx)
            .message_encoding(encoding.message())
            .schema(schema)
            .build_raw()?;
        Ok(Self {
            channel,
            proto: T::Proto::default(),
            buf: Vec::new(),
        })
    }

    /// Logs `m` at its own time on `clock`; nothing is encoded while no client subscribes.
    pub fn log(&mut self, m: &T, clock: &WallClock) {
        if !self.channel.has_sinks() {
            return;
        }
        m.fill_proto(&mut self.proto);
        self.buf.clear();
        prost::Message::encode(&self.proto, &mut self.buf).expect("a Vec grows to any message");
        let meta = PartialMetadata::with_log_time(clock.unix_ns(m.publish_time_ns()));
        self.channel.log_with_meta(&self.buf, meta);
    }
}

/// The channels of the live view and the path it keeps.
pub struct View {
    clock: WallClock,
    derived: Derived,
    pose: Channel<PoseInFrame>,
    revised: Channel<PoseInFrame>,
    tf: Channel<FrameTransform>,
    path: Channel<PosesInFrame>,
    state: Proto<OdometryState>,
    corrected: Proto<CorrectedImuSample>,
    raw: Proto<RawImuSample>,
    hint: Proto<RobotHint>,
}

impl View {
    /// Creates the channels in `ctx`.
    pub fn new(ctx: &Arc<Context>, clock: WallClock) -> anyhow::Result<Self> {
        let typed = |topic: &str| ChannelBuilder::new(topic).context(ctx);
        Ok(Self {
            clock,
            derived: Derived::new(Some(clock)),
            pose: typed(POSE_TOPIC).build(),
            revised: typed(REVISED_POSE_TOPIC).build(),
            tf: typed(TF_TOPIC).build(),
            path: typed(PATH_TOPIC).build(),
            state: Proto::new(ctx)?,
            corrected: Proto::new(ctx)?,
            raw: Proto::new(ctx)?,
            hint: Proto::new(ctx)?,
        })
    }

    /// Logs one odometry state and the messages derived from it, at its sample time.
    pub fn state(&mut self, s: &OdometryState) {
        self.state.log(s, &self.clock);
        let meta = PartialMetadata::with_log_time(self.clock.unix_ns(s.stamps.sample_ns));
        let Self {
            derived,
            pose,
            revised,
            tf,
            path,
            ..
        } = self;
        let logged = derived.state(s, |out| {
            match out {
                Out::Pose(m) => pose.log_with_meta(m, meta),
                Out::RevisedPose(m) => revised.log_with_meta(m, meta),
                Out::Tf(m) => tf.log_with_meta(m, meta),
                Out::Path(m) => path.log_with_meta(m, meta),
            }
            Ok::<(), std::convert::Infallible>(())
        });
        let Ok(()) = logged;
    }

    /// Logs one corrected sample, at its sample time.
    pub fn corrected(&mut self, c: &CorrectedImuSample) {
        self.corrected.log(c, &self.clock);
    }

    /// Logs one raw sample, at its sample time.
    pub fn raw(&mut self, r: &RawImuSample) {
        self.raw.log(r, &self.clock);
    }

    /// Logs one robot hint, at the time it describes.
    pub fn hint(&mut self, h: &RobotHint) {
        self.hint.log(h, &self.clock);
    }
}
