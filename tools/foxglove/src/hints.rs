//! Robot hints published from the Foxglove app (the protocol's `clientPublish` capability:
//! a client advertises a channel, then sends messages on it).
//!
//! A client publishes hints on topic `mems/robot/hint` with message encoding `json`
//! ([`ENCODING`]; Foxglove's Publish panel sends JSON). Each message is a JSON object
//! ([`AppHint`], schema [`app_hint_schema`]) holding the fields of `ipc_types::RobotHint`
//! that the robot knows, in its units and frames (body frame x forward, y left, z up):
//! `flags` (`ipc_types::hint_flags` bits; `1` with a source bit says "stationary"), and,
//! with their bits, `forward_speed_mps`, `forward_speed_sigma_mps`, `yaw_rate_rps`,
//! `yaw_rate_sigma_rps` (absent: 0). The server stamps it: `stamps.sample_ns` and
//! `stamps.acquired_ns` are its arrival time (`CLOCK_MONOTONIC`), `seq` the server's own
//! count. It is published on the stack's `mems/robot/hint` service as a controller's hint
//! would be (never blocking; the odometry treats a missing hint as stale). A message that is
//! not such an object, or a channel of another topic or encoding, is refused, counted and
//! answered with an error status naming the problem.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError};

use foxglove::websocket::{Client, ClientChannel, ServerListener, Status};
use ipc_types::{RobotHint, Stamps};
use serde::Deserialize;
use serde_json::{Value, json};

/// The topic a client publishes hints on: the hint service's.
pub const TOPIC: &str = ipc_types::service::HINT;
/// The message encoding accepted.
pub const ENCODING: &str = "json";
/// Hints queued between the server's threads and the publishing loop; more are dropped.
pub const QUEUE: usize = 256;

/// One hint as a client sends it.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AppHint {
    /// `ipc_types::hint_flags` bits.
    pub flags: u16,
    /// Forward speed along body x, m/s.
    #[serde(default)]
    pub forward_speed_mps: f64,
    /// 1-sigma of `forward_speed_mps`, m/s.
    #[serde(default)]
    pub forward_speed_sigma_mps: f64,
    /// Yaw rate about body z (counter-clockwise positive seen from above), rad/s.
    #[serde(default)]
    pub yaw_rate_rps: f64,
    /// 1-sigma of `yaw_rate_rps`, rad/s.
    #[serde(default)]
    pub yaw_rate_sigma_rps: f64,
}

impl AppHint {
    /// The hint to publish: this one, received at `now_ns` (`CLOCK_MONOTONIC`), number `seq`.
    pub fn stamped(&self, now_ns: u64, seq: u64) -> RobotHint {
        RobotHint {
            stamps: Stamps {
                sample_ns: now_ns,
                acquired_ns: now_ns,
                ..Stamps::default()
            },
            seq,
            forward_speed_mps: self.forward_speed_mps,
            forward_speed_sigma_mps: self.forward_speed_sigma_mps,
            yaw_rate_rps: self.yaw_rate_rps,
            yaw_rate_sigma_rps: self.yaw_rate_sigma_rps,
            flags: self.flags,
            ..RobotHint::default()
        }
    }
}

/// The JSON Schema of [`AppHint`], for a client's advertisement (`schemaEncoding`
/// `jsonschema`, schema name `mems.AppHint`).
pub fn app_hint_schema() -> Value {
    let number = |d: &str| json!({"type": "number", "description": d});
    json!({
        "title": "mems.AppHint",
        "description": "A robot hint from the app; the server stamps it on arrival.",
        "type": "object",
        "properties": {
            "flags": {"type": "integer", "minimum": 0, "maximum": u16::MAX,
                      "description": "ipc-types hint_flags bits (1 stationary, 2 commanded, 4 encoders, 8 speed valid, 16 yaw rate valid)."},
            "forward_speed_mps": number("Forward speed along body x, m/s."),
            "forward_speed_sigma_mps": number("1-sigma of forward_speed_mps, m/s."),
            "yaw_rate_rps": number("Yaw rate about body z, counter-clockwise positive, rad/s."),
            "yaw_rate_sigma_rps": number("1-sigma of yaw_rate_rps, rad/s."),
        },
        "required": ["flags"],
        "additionalProperties": false,
    })
}

/// The server's listener: decodes the hints clients publish and queues them for
/// [`Inbox::drain`].
pub struct Listener {
    queue: SyncSender<AppHint>,
    refused: AtomicU64,
}

/// The receiving end of the queue, in the loop that publishes on iceoryx2.
pub struct Inbox {
    queue: Receiver<AppHint>,
}

/// A listener and its inbox.
pub fn channel() -> (Listener, Inbox) {
    let (queue, rx) = std::sync::mpsc::sync_channel(QUEUE);
    let listener = Listener {
        queue,
        refused: AtomicU64::new(0),
    };
    (listener, Inbox { queue: rx })
}

impl Listener {
    /// Hints refused so far (bad channel, bad message, full queue).
    pub fn refused(&self) -> u64 {
        self.refused.load(Ordering::Relaxed)
    }

    fn refuse(&self, client: &Client, why: String) {
        let n = self.refused.fetch_add(1, Ordering::Relaxed) + 1;
        tracing::warn!("warning: client hint refused ({n} so far): {why}");
        client.send_status(Status::error(why));
    }
}

/// Why a client channel cannot carry hints, if it cannot.
fn unsupported(channel: &ClientChannel) -> Option<String> {
    (channel.topic != TOPIC || channel.encoding != ENCODING).then(|| {
        format!(
            "client channel {:?} ({}): only {TOPIC:?} with encoding {ENCODING:?} is accepted",
            channel.topic, channel.encoding
        )
    })
}

impl ServerListener for Listener {
    fn on_client_advertise(&self, client: Client, channel: &ClientChannel) {
        if let Some(why) = unsupported(channel) {
            tracing::warn!("warning: {why}");
            client.send_status(Status::warning(why));
        }
    }

    fn on_message_data(&self, client: Client, channel: &ClientChannel, payload: &[u8]) {
        if let Some(why) = unsupported(channel) {
            return self.refuse(&client, why);
        }
        let hint = match serde_json::from_slice::<AppHint>(payload) {
            Ok(h) => h,
            Err(e) => return self.refuse(&client, format!("{TOPIC}: not a hint: {e}")),
        };
        match self.queue.try_send(hint) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => self.refuse(&client, format!("{TOPIC}: queue full")),
            Err(TrySendError::Disconnected(_)) => {}
        }
    }
}

impl Inbox {
    /// Takes every queued hint.
    pub fn drain(&self) -> impl Iterator<Item = AppHint> + '_ {
        self.queue.try_iter()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hint_is_stamped_and_unknown_fields_refused() {
        let h: AppHint = serde_json::from_str(r#"{"flags": 7}"#).unwrap();
        let r = h.stamped(5, 9);
        assert_eq!(
            (r.flags, r.seq, r.stamps.sample_ns, r.stamps.acquired_ns),
            (7, 9, 5, 5)
        );
        assert!(serde_json::from_str::<AppHint>(r#"{"flags": 1, "speed": 2}"#).is_err());
        assert!(serde_json::from_str::<AppHint>(r#"{"forward_speed_mps": 2}"#).is_err());
    }
}
