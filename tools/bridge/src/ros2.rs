//! `mems-bridge ros2`: our services as ROS 2 topics on Zenoh, the way rmw_zenoh publishes
//! them, so that a ROS 2 node on `rmw_zenoh_cpp` subscribes to `/odom` and `/imu/data` as to
//! any ROS 2 publisher.
//!
//! Everything here follows rmw_zenoh's design document, `docs/design.md` of ros2/rmw_zenoh at
//! commit 99a6a2bd10b949052f4f12c5854825dc005e95a5 (the Zenoh-cpp era of rmw_zenoh_cpp, the one
//! ROS 2 Jazzy and Kilted ship), sections "Topic and Service name mapping to Zenoh key
//! expressions", "Graph Cache" and "Publishers":
//!
//! - a message is a Zenoh `put` on `<domain_id>/<fully_qualified_name>/<type_name>/<type_hash>`
//!   ([`topic_key`]; the name without its leading `/`, the DDS type name, the RIHS01 hash), its
//!   payload the CDR message ([`mems_ros2::cdr`]), with an attachment ([`attachment`]): the
//!   sequence number (`i64`, little-endian), the source timestamp (ns since the Unix epoch,
//!   `i64`, little-endian), the GID's length (one byte, 16) and the publisher's 16-byte GID;
//! - the node and each publisher declare a liveliness token ([`node_token`],
//!   [`publisher_token`]): `@ros2_lv/<domain_id>/<session_id>/<node_id>/<entity_id>/<kind>/
//!   <enclave>/<namespace>/<node_name>[/<topic>/<type_name>/<type_hash>/<qos>]`, names mangled
//!   (`/` -> `%`, `%` for an empty enclave or namespace), the QoS in rmw_zenoh's compact form
//!   with every default left empty ([`QOS`]).
//!
//! The GID's derivation is left open by the document (rmw_zenoh hashes the token with XXH3):
//! ours is the first 16 bytes of the SHA-256 of the publisher's token ([`gid`]), unique per
//! publisher and session.

use anyhow::{Result, anyhow};
use ipc_types::{CorrectedImuSample, Message, OdometryState};
use mems_ros2::convert;
use mems_ros2::export::{IMU_TOPIC, ODOM_TOPIC};
use mems_ros2::msg::{Imu, Odometry, RosMessage, Time};
use recording::clock::WallClock;
use sha2::{Digest, Sha256};
use zenoh::Wait;
use zenoh::liveliness::LivelinessToken;

use crate::{Counts, relay};

/// The admin space of rmw_zenoh's liveliness tokens.
const ADMIN_SPACE: &str = "@ros2_lv";
/// Our publishers' QoS in rmw_zenoh's compact form: reliable, volatile, keep last (rmw_zenoh's
/// defaults, left empty) with a depth of 10 (`rclcpp::SensorDataQoS` aside, what a ROS 2 node
/// subscribes with by default; rmw_zenoh's own default depth is 42); deadline, lifespan and
/// liveliness the defaults.
pub const QOS: &str = "::,10:,:,:,,";

/// A service carried as a ROS 2 topic.
pub trait Ros2Topic: Message {
    /// The ROS 2 message it becomes.
    type Ros: RosMessage;
    /// The topic's fully qualified name.
    const TOPIC: &'static str;
    /// The message stamped on `clock`; `None` when the topic does not take it (a revision:
    /// `/odom` carries the live states, whose times only go forward) or its stamp does not fit.
    fn to_ros(&self, clock: &WallClock) -> Option<Self::Ros>;
}

fn stamp(clock: &WallClock, sample_ns: u64) -> Option<Time> {
    Time::from_ns(clock.unix_ns(sample_ns))
}

impl Ros2Topic for CorrectedImuSample {
    type Ros = Imu;
    const TOPIC: &'static str = IMU_TOPIC;

    fn to_ros(&self, clock: &WallClock) -> Option<Imu> {
        Some(convert::imu(self, stamp(clock, self.stamps.sample_ns)?))
    }
}

impl Ros2Topic for OdometryState {
    type Ros = Odometry;
    const TOPIC: &'static str = ODOM_TOPIC;

    fn to_ros(&self, clock: &WallClock) -> Option<Odometry> {
        let stamp = stamp(clock, self.stamps.sample_ns)?;
        (!self.is_revision()).then(|| convert::odometry(self, stamp))
    }
}

/// `/` -> `%`, and `%` for an empty name.
fn mangle(name: &str) -> String {
    if name.is_empty() {
        "%".into()
    } else {
        name.replace('/', "%")
    }
}

/// The key expression of topic `name` carrying `M` in domain `domain`.
pub fn topic_key<M: RosMessage>(domain: u32, name: &str) -> String {
    let name = name.trim_matches('/');
    format!("{domain}/{name}/{}/{}", M::DDS_TYPE_NAME, M::TYPE_HASH)
}

/// The liveliness token of node `node` (id 0, no namespace, no enclave) of session `zid`.
pub fn node_token(domain: u32, zid: &str, node: &str) -> String {
    format!("{ADMIN_SPACE}/{domain}/{zid}/0/0/NN/%/%/{}", mangle(node))
}

/// The liveliness token of publisher `entity` of node `node` (id 0) on topic `name` carrying
/// `M`.
pub fn publisher_token<M: RosMessage>(
    domain: u32,
    zid: &str,
    node: &str,
    entity: u32,
    name: &str,
) -> String {
    format!(
        "{ADMIN_SPACE}/{domain}/{zid}/0/{entity}/MP/%/%/{}/{}/{}/{}/{QOS}",
        mangle(node),
        mangle(name),
        mangle(M::DDS_TYPE_NAME),
        mangle(M::TYPE_HASH),
    )
}

/// The GID of the publisher whose liveliness token is `token`.
pub fn gid(token: &str) -> [u8; 16] {
    let digest = Sha256::digest(token.as_bytes());
    digest[..16].try_into().expect("SHA-256 has 32 bytes")
}

/// A message's attachment: sequence number, source timestamp (ns since the Unix epoch), the
/// GID's length and the GID.
pub fn attachment(sequence: i64, timestamp_ns: i64, gid: &[u8; 16]) -> [u8; 33] {
    let mut out = [0; 33];
    out[..8].copy_from_slice(&sequence.to_le_bytes());
    out[8..16].copy_from_slice(&timestamp_ns.to_le_bytes());
    out[16] = 16;
    out[17..].copy_from_slice(gid);
    out
}

/// The ROS 2 node of `mems-bridge ros2`: its liveliness token, declared for as long as it
/// lives, and what its publishers need.
pub struct Node {
    domain: u32,
    /// The Zenoh session's id, as rmw_zenoh writes it in tokens.
    zid: String,
    name: String,
    /// Shifts the samples' `CLOCK_MONOTONIC` times to the Unix times of their header stamps.
    clock: WallClock,
    _token: LivelinessToken,
}

impl Node {
    /// Declares node `name` of domain `domain` on `session`; its header stamps use the wall
    /// clock read now.
    pub fn declare(session: &zenoh::Session, domain: u32, name: &str) -> Result<Self> {
        let zid = session.zid().to_string();
        let token = node_token(domain, &zid, name);
        Ok(Self {
            domain,
            _token: declare_token(session, token)?,
            zid,
            name: name.into(),
            clock: WallClock::now(),
        })
    }
}

fn declare_token(session: &zenoh::Session, token: String) -> Result<LivelinessToken> {
    session
        .liveliness()
        .declare_token(token.clone())
        .wait()
        .map_err(|e| anyhow!("cannot declare the liveliness token {token}: {e}"))
}

/// iceoryx2 service `name` -> ROS 2 topic `T::TOPIC` as publisher `entity` of `node`
/// until SIGINT/SIGTERM: each message converted, CDR-encoded and put with its attachment.
pub fn publish<T: Ros2Topic + Send>(
    session: &zenoh::Session,
    node: &Node,
    entity: u32,
    name: &str,
    counts: &Counts,
) -> Result<()> {
    let key = topic_key::<T::Ros>(node.domain, T::TOPIC);
    let token = publisher_token::<T::Ros>(node.domain, &node.zid, &node.name, entity, T::TOPIC);
    let gid = gid(&token);
    let publisher = relay::publisher(session, &key)?;
    let _token = declare_token(session, token)?;
    let (mut sequence, mut buf) = (0i64, Vec::new());
    relay::drain::<T>(name, counts, |message| {
        let Some(ros) = message.to_ros(&node.clock) else {
            return Ok(false);
        };
        mems_ros2::cdr::encode(&ros, &mut buf).map_err(|e| anyhow!("{key}: {e}"))?;
        sequence += 1;
        let now = WallClock::now().realtime_ns;
        let attachment = attachment(sequence, now as i64, &gid);
        publisher
            .put(buf.clone())
            .attachment(attachment.to_vec())
            .wait()
            .map_err(|e| anyhow!("cannot put on {key}: {e}"))?;
        Ok(true)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The design document's examples, with our types.
    #[test]
    fn keys_and_tokens_are_laid_out_as_the_design_document_shows() {
        assert_eq!(
            topic_key::<Odometry>(0, "/odom"),
            format!(
                "0/odom/nav_msgs::msg::dds_::Odometry_/{}",
                Odometry::TYPE_HASH
            )
        );
        assert_eq!(
            topic_key::<Imu>(2, "/robot1/imu/data"),
            format!(
                "2/robot1/imu/data/sensor_msgs::msg::dds_::Imu_/{}",
                Imu::TYPE_HASH
            )
        );
        assert_eq!(
            node_token(2, "aac3178e146ba6f1fc6e6a4085e77f21", "listener"),
            "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
        );
        assert_eq!(
            publisher_token::<Odometry>(
                0,
                "8b20917502ee955ac4476e0266340d5c",
                "talker",
                10,
                "/odom"
            ),
            format!(
                "@ros2_lv/0/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%odom/\
                 nav_msgs::msg::dds_::Odometry_/{}/::,10:,:,:,,",
                Odometry::TYPE_HASH
            )
        );
    }

    #[test]
    fn an_attachment_is_33_bytes_little_endian() {
        let gid = std::array::from_fn(|i| i as u8);
        let a = attachment(0x0102, -2, &gid);
        assert_eq!(a[..8], [2, 1, 0, 0, 0, 0, 0, 0]);
        assert_eq!(a[8..16], [0xfe, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff]);
        assert_eq!(a[16], 16);
        assert_eq!(a[17..], gid);
    }

    #[test]
    fn revisions_stay_off_odom() {
        let clock = WallClock {
            realtime_ns: 1_795_935_601_000_000_000,
            monotonic_ns: 0,
        };
        let live = OdometryState::default();
        assert!(live.to_ros(&clock).is_some());
        let revision = OdometryState {
            flags: ipc_types::odometry_flags::REVISION,
            ..live
        };
        assert!(revision.to_ros(&clock).is_none());
    }
}
