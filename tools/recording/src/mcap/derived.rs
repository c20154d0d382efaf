//! The Foxglove messages derived from odometry states, one mapping for the recording
//! (`mems-record`) and the live view (`mems-foxglove`), in Foxglove's protobuf schemas (its
//! SDK's messages):
//! - the pose ([`POSE_TOPIC`], `foxglove.PoseInFrame`, frame [`NAV_FRAME`]) of the first live
//!   state in each [`DISPLAY_STEP_NS`] of sample time (50 Hz: these topics are for display;
//!   every state, at full rate, is on the state topic);
//! - the revised pose ([`REVISED_POSE_TOPIC`], `foxglove.PoseInFrame`) of states republished
//!   with `REVISION` (history corrected in hindsight), likewise the first in each
//!   [`DISPLAY_STEP_NS`] of a run of revisions, apart, so the live pose's times never go back;
//! - the transform ([`TF_TOPIC`], `foxglove.FrameTransform`) [`NAV_FRAME`] -> [`BODY_FRAME`]
//!   with each pose, for the 3D panel;
//! - the path ([`PATH_TOPIC`], `foxglove.PosesInFrame`): the aligned track, one pose per
//!   [`PATH_STEP_NS`] of sample time, the last [`PATH_LEN`] of them, sent every
//!   [`PATH_EVERY_NS`].
//!
//! None of these schemas has a covariance: the 1-sigma of position and velocity is on the
//! state topic (`position_sigma_m`, `velocity_sigma_mps`). Position in m, navigation frame
//! (z up, origin and heading fixed at alignment); the orientation rotates body-frame vectors
//! into the navigation frame. The messages' timestamps are the state's sample time on the
//! [`WallClock`] given (Unix time, as Foxglove places messages), or `CLOCK_MONOTONIC` without
//! one.
//!
//! Each message is kept and rewritten in place (its strings and the path's poses keep their
//! storage): deriving allocates nothing per state once the path is full.

use std::collections::VecDeque;

use foxglove::messages::{
    FrameTransform, Pose, PoseInFrame, PosesInFrame, Quaternion, Timestamp, Vector3,
};
use ipc_types::{OdometryState, odometry_flags};

use super::{FoxgloveChannel, Topic, Writer};
use crate::clock::WallClock;

/// Topic of the live states' poses.
pub const POSE_TOPIC: &str = super::POSE_TOPIC;
/// Topic of the revised states' poses.
pub const REVISED_POSE_TOPIC: &str = "mems/odometry/revised_pose";
/// Topic of the `nav` -> `body` transform.
pub const TF_TOPIC: &str = "mems/odometry/tf";
/// Topic of the path.
pub const PATH_TOPIC: &str = "mems/odometry/path";
/// The navigation frame's id.
pub const NAV_FRAME: &str = super::NAV_FRAME;
/// The sensor body's frame id.
pub const BODY_FRAME: &str = "body";
/// The display step of the pose, revised pose and transform: one per this much sample
/// time, ns (50 Hz, above the rate at which Foxglove redraws a panel and a twentieth of
/// the 1 kHz state rate).
pub const DISPLAY_STEP_NS: u64 = 20_000_000;
/// Sample time between two poses of the path, ns (4 Hz: 0.25-0.5 m apart at a robot's
/// 1-2 m/s, enough to draw its track; the pose and transform carry the live position).
pub const PATH_STEP_NS: u64 = 250_000_000;
/// Poses kept in the path (the last 5 minutes at [`PATH_STEP_NS`]).
pub const PATH_LEN: usize = 1200;
/// Sample time between two path messages, ns. Each message repeats the whole path, so this
/// and [`PATH_LEN`] set its share of a long recording: 1200 poses every 2 s are 34 kB/s
/// before compression, a tenth of what the other topics take at 1 kHz (300 kB/s).
pub const PATH_EVERY_NS: u64 = 2_000_000_000;

/// One derived message, borrowed from [`Derived`] until its next state.
#[derive(Debug, Clone, Copy)]
pub enum Out<'a> {
    /// On [`POSE_TOPIC`].
    Pose(&'a PoseInFrame),
    /// On [`REVISED_POSE_TOPIC`].
    RevisedPose(&'a PoseInFrame),
    /// On [`TF_TOPIC`].
    Tf(&'a FrameTransform),
    /// On [`PATH_TOPIC`].
    Path(&'a PosesInFrame),
}

/// The pose of a state: its position and attitude as a recording holds them
/// ([`Topic::as_recorded`]: the pose shows the state topic's values), `attitude_wxyz`
/// reordered to Foxglove's x, y, z, w.
pub fn pose_of(s: &OdometryState) -> Pose {
    let s = s.as_recorded();
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

/// The derived messages of a stream of states, and the path they keep.
pub struct Derived {
    clock: Option<WallClock>,
    pose: PoseInFrame,
    tf: FrameTransform,
    path: PosesInFrame,
    poses: VecDeque<Pose>,
    last_path_pose_ns: Option<u64>,
    last_path_sent_ns: Option<u64>,
    /// The display step ([`DISPLAY_STEP_NS`]) of the last pose and of the last revised pose.
    last_pose_step: Option<u64>,
    last_revised_step: Option<u64>,
}

impl Derived {
    /// Derives with timestamps on `clock` (`None`: `CLOCK_MONOTONIC`).
    pub fn new(clock: Option<WallClock>) -> Self {
        Self {
            clock,
            pose: PoseInFrame {
                frame_id: NAV_FRAME.into(),
                ..PoseInFrame::default()
            },
            tf: FrameTransform {
                parent_frame_id: NAV_FRAME.into(),
                child_frame_id: BODY_FRAME.into(),
                ..FrameTransform::default()
            },
            path: PosesInFrame {
                frame_id: NAV_FRAME.into(),
                poses: Vec::with_capacity(PATH_LEN),
                ..PosesInFrame::default()
            },
            poses: VecDeque::with_capacity(PATH_LEN),
            last_path_pose_ns: None,
            last_path_sent_ns: None,
            last_pose_step: None,
            last_revised_step: None,
        }
    }

    /// Foxglove's timestamp of monotonic time `t_ns` (seconds saturated at `u32::MAX`).
    pub fn timestamp(&self, t_ns: u64) -> Timestamp {
        let t = self.clock.map_or(t_ns, |c| c.unix_ns(t_ns));
        super::FoxgloveTime::from_ns(t).foxglove()
    }

    /// Gives `emit` the messages derived from state `s`: if it is a revision, its revised
    /// pose when it is the first in its display step; otherwise its pose and its transform
    /// when it is the first in its display step and, once aligned, the path when it is due.
    pub fn state<E>(
        &mut self,
        s: &OdometryState,
        mut emit: impl FnMut(Out<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        let t_ns = s.stamps.sample_ns;
        let pose = pose_of(s);
        let timestamp = Some(self.timestamp(t_ns));
        let step = t_ns / DISPLAY_STEP_NS;
        let revision = s.flags & odometry_flags::REVISION != 0;
        let last_step = if revision {
            &mut self.last_revised_step
        } else {
            &mut self.last_pose_step
        };
        let shown = last_step.replace(step) != Some(step);
        if shown {
            self.pose.timestamp = timestamp;
            self.pose.pose = Some(pose);
        }
        if revision {
            return if shown {
                emit(Out::RevisedPose(&self.pose))
            } else {
                Ok(())
            };
        }
        if shown {
            emit(Out::Pose(&self.pose))?;
            self.tf.timestamp = timestamp;
            self.tf.translation = pose.position;
            self.tf.rotation = pose.orientation;
            emit(Out::Tf(&self.tf))?;
        }
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
            self.path.timestamp = timestamp;
            self.path.poses.clear();
            self.path.poses.extend(self.poses.iter().copied());
            self.last_path_sent_ns = Some(t_ns);
            return emit(Out::Path(&self.path));
        }
        Ok(())
    }
}

/// The channels of the Foxglove messages derived from each odometry state
/// in a recording (pose, revised pose, transform, path), as `mems-record` and
/// `mems-odometry offline --out` write them.
pub struct DerivedChannels {
    derived: Derived,
    pose: FoxgloveChannel<PoseInFrame>,
    revised: FoxgloveChannel<PoseInFrame>,
    tf: FoxgloveChannel<FrameTransform>,
    path: FoxgloveChannel<PosesInFrame>,
}

impl DerivedChannels {
    /// Adds the channels to `writer`; timestamps on its wall clock.
    pub fn add(writer: &mut Writer) -> crate::Result<Self> {
        Ok(Self {
            derived: Derived::new(writer.clock()),
            pose: writer.add_foxglove_channel(POSE_TOPIC)?,
            revised: writer.add_foxglove_channel(REVISED_POSE_TOPIC)?,
            tf: writer.add_foxglove_channel(TF_TOPIC)?,
            path: writer.add_foxglove_channel(PATH_TOPIC)?,
        })
    }

    /// Writes what `state` (received at `log_ns`) derives, published at its sample time.
    pub fn write(
        &mut self,
        w: &mut Writer,
        state: &OdometryState,
        log_ns: u64,
    ) -> crate::Result<()> {
        let t = state.stamps.sample_ns;
        let Self {
            derived,
            pose,
            revised,
            tf,
            path,
        } = self;
        derived.state(state, |out| match out {
            Out::Pose(m) => w.write_foxglove(*pose, m, t, log_ns),
            Out::RevisedPose(m) => w.write_foxglove(*revised, m, t, log_ns),
            Out::Tf(m) => w.write_foxglove(*tf, m, t, log_ns),
            Out::Path(m) => w.write_foxglove(*path, m, t, log_ns),
        })
    }
}
