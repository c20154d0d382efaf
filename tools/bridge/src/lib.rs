//! Carries mems services off the robot: `mems-bridge out` takes chosen iceoryx2 services of this
//! machine and puts each message on Zenoh (the transport of ROS 2's rmw_zenoh); `mems-bridge
//! in`, on another machine, subscribes to them and publishes them on its own iceoryx2
//! services, where the same clients (Rust, Python, C, `mems-record`, `mems-foxglove`) read them.
//!
//! Wire: each Zenoh sample is one message's `#[repr(C)]` bytes as `ipc-types` lays it out
//! (no implicit padding: every gap is a named reserved field, pinned by its layout tests),
//! so both machines must be little-endian with the same `ipc-types` (the key expression carries
//! the type name with its version, [`key`], so a mismatch never decodes). Key expressions:
//! `PREFIX/SERVICE/TYPE`, e.g. `robot1/mems/odometry/state/mems::OdometryState.v2`.
//!
//! `mems-bridge ros2` publishes the corrected samples and the odometry as ROS 2 topics in
//! rmw_zenoh's layout instead ([`ros2`]), for ROS 2 nodes on `rmw_zenoh_cpp`.
//!
//! The robot is never held back by the network: `out` and `ros2` drain their subscriber at once
//! into a bounded queue that a sender thread empties onto Zenoh (reliable, blocking congestion
//! control; [`relay`]); a message that finds the queue full is dropped and counted ([`Counts`]). `in`
//! counts the sequence numbers that never arrived.

pub mod relay;
pub mod ros2;

use std::sync::atomic::{AtomicU64, Ordering};

use iceoryx2::prelude::ZeroCopySend;
use ipc_types::{Message, service};

/// The services the bridge can carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Carried {
    /// `mems/imu/raw`.
    Raw,
    /// `mems/imu/corrected`.
    Corrected,
    /// `mems/odometry/state`.
    Odometry,
    /// `mems/robot/hint`.
    Hint,
}

impl Carried {
    /// The service's base name.
    pub fn base(self) -> &'static str {
        match self {
            Self::Raw => service::RAW,
            Self::Corrected => service::CORRECTED,
            Self::Odometry => service::ODOMETRY,
            Self::Hint => service::HINT,
        }
    }
}

/// The Zenoh key expression of service `base` carrying `T`, under `prefix` (a robot's name).
pub fn key<T: Message>(prefix: &str, base: &str) -> String {
    // SAFETY: reading the name is harmless; the trait is unsafe to implement, not to call.
    let type_name = unsafe { <T as ZeroCopySend>::type_name() }.replace("::", "-");
    if prefix.is_empty() {
        format!("{base}/{type_name}")
    } else {
        format!("{prefix}/{base}/{type_name}")
    }
}

/// The message's bytes as they travel.
pub fn to_bytes<T: Message>(message: &T) -> &[u8] {
    // SAFETY: `T` is one of the `#[repr(C)]` payloads of ipc-types, plain data without implicit
    // padding (ipc-types' layout tests), so all `size_of::<T>()` bytes are initialised.
    unsafe {
        std::slice::from_raw_parts(
            std::ptr::from_ref(message).cast::<u8>(),
            std::mem::size_of::<T>(),
        )
    }
}

/// The message in `bytes`, or `None` if their length is not `T`'s.
pub fn from_bytes<T: Message>(bytes: &[u8]) -> Option<T> {
    (bytes.len() == std::mem::size_of::<T>()).then(|| {
        // SAFETY: the length is checked; every bit pattern is a valid `T` (integers, floats and
        // arrays of them); `read_unaligned` needs no alignment.
        unsafe { std::ptr::read_unaligned(bytes.as_ptr().cast::<T>()) }
    })
}

/// The endpoint `out` listens on and `in` connects to when given neither `--listen` nor
/// `--connect`: this machine only.
pub const DEFAULT_ENDPOINT: &str = "tcp/127.0.0.1:7447";

/// Whether Zenoh endpoint `endpoint` (`PROTO/HOST:PORT[?...][#...]`) names this machine only:
/// a loopback address or `localhost`. An unspecified address (`0.0.0.0`, `[::]`) or any other
/// host is reachable from other machines.
pub fn is_loopback(endpoint: &str) -> bool {
    let address = endpoint.split_once('/').map_or(endpoint, |(_, a)| a);
    let address = address.split(['?', '#']).next().unwrap_or_default();
    let host = address.rsplit_once(':').map_or(address, |(h, _)| h);
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host == "localhost"
        || host
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// Zenoh's user-password authentication from a credentials file: one `USER:PASSWORD` line per
/// accepted user (Zenoh's dictionary format), the first being the one this end presents.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Credentials {
    /// The file, the dictionary of accepted users.
    pub file: std::path::PathBuf,
    /// The user this end presents.
    pub user: String,
    /// Its password.
    pub password: String,
}

impl Credentials {
    /// Reads the credentials file `file`; the error names the file and what is wrong.
    pub fn load(file: &std::path::Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(file)
            .map_err(|e| anyhow::anyhow!("--auth {}: {e}", file.display()))?;
        let first = text.lines().find(|l| !l.trim().is_empty()).unwrap_or("");
        let (user, password) = first
            .split_once(':')
            .map(|(u, p)| (u.trim(), p.trim()))
            .filter(|(u, p)| !u.is_empty() && !p.is_empty())
            .ok_or_else(|| {
                anyhow::anyhow!(
                    "--auth {}: the first line must be USER:PASSWORD (both non-empty)",
                    file.display()
                )
            })?;
        Ok(Self {
            file: file.to_path_buf(),
            user: user.to_owned(),
            password: password.to_owned(),
        })
    }
}

/// A Zenoh peer configuration: listening on and connecting to the given endpoints (e.g.
/// `tcp/127.0.0.1:7447`), multicast scouting off so that only the named peers connect, and
/// with `auth` Zenoh's user-password authentication: this end presents the credentials' user,
/// and a peer that presents none of the file's users is refused.
pub fn zenoh_config(
    listen: &[String],
    connect: &[String],
    auth: Option<&Credentials>,
) -> anyhow::Result<zenoh::Config> {
    let list = |eps: &[String]| {
        let quoted: Vec<String> = eps.iter().map(|e| format!("{e:?}")).collect();
        format!("[{}]", quoted.join(","))
    };
    let mut config = zenoh::Config::default();
    let set = |config: &mut zenoh::Config, key: &str, value: &str| {
        config
            .insert_json5(key, value)
            .map_err(|e| anyhow::anyhow!("zenoh config {key}: {e}"))
    };
    set(&mut config, "mode", "\"peer\"")?;
    set(&mut config, "scouting/multicast/enabled", "false")?;
    set(&mut config, "listen/endpoints", &list(listen))?;
    set(&mut config, "connect/endpoints", &list(connect))?;
    if let Some(auth) = auth {
        let usrpwd = "transport/auth/usrpwd";
        set(
            &mut config,
            &format!("{usrpwd}/user"),
            &format!("{:?}", auth.user),
        )?;
        set(
            &mut config,
            &format!("{usrpwd}/password"),
            &format!("{:?}", auth.password),
        )?;
        let dictionary = format!("{:?}", auth.file.display().to_string());
        set(
            &mut config,
            &format!("{usrpwd}/dictionary_file"),
            &dictionary,
        )?;
    }
    Ok(config)
}

/// What one direction of one service did, shared between its threads.
#[derive(Debug, Default)]
pub struct Counts {
    /// Messages carried (put on Zenoh, or published on iceoryx2).
    pub carried: AtomicU64,
    /// `out`: messages dropped because the queue to Zenoh was full. `in`: sequence numbers
    /// that never arrived (revisions excluded).
    pub lost: AtomicU64,
}

impl Counts {
    /// Adds one carried message.
    pub fn carry(&self) {
        self.carried.fetch_add(1, Ordering::Relaxed);
    }

    /// Adds `n` lost messages.
    pub fn lose(&self, n: u64) {
        self.lost.fetch_add(n, Ordering::Relaxed);
    }

    /// (carried, lost).
    pub fn get(&self) -> (u64, u64) {
        (
            self.carried.load(Ordering::Relaxed),
            self.lost.load(Ordering::Relaxed),
        )
    }
}

/// The sequence numbers missing before `seq`, given the last one seen (`None` at the start: a
/// bridge that joins late misses nothing it was not there for). A number that goes back is a
/// restarted publisher, not a loss.
pub fn missing(last: Option<u64>, seq: u64) -> u64 {
    match last {
        Some(last) if seq > last => seq - last - 1,
        _ => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_types::{OdometryState, RawImuSample};

    #[test]
    fn bytes_round_trip_every_field() {
        let state = OdometryState {
            seq: 7,
            position_m: [1.5, -2.25, 1e-9],
            attitude_wxyz: [0.5, -0.5, 0.5, -0.5],
            flags: 0xA5A5,
            rest_count: u32::MAX,
            ..OdometryState::default()
        };
        let bytes = to_bytes(&state).to_vec();
        assert_eq!(from_bytes::<OdometryState>(&bytes), Some(state));
        assert_eq!(from_bytes::<OdometryState>(&bytes[1..]), None);
        assert_eq!(from_bytes::<RawImuSample>(&bytes), None, "another size");
    }

    #[test]
    fn keys_carry_the_versioned_type() {
        assert_eq!(
            key::<OdometryState>("robot1", service::ODOMETRY),
            "robot1/mems/odometry/state/mems-OdometryState.v2"
        );
        assert_eq!(
            key::<RawImuSample>("", service::RAW),
            "mems/imu/raw/mems-RawImuSample.v1"
        );
    }

    #[test]
    fn only_loopback_endpoints_are_this_machine_only() {
        for local in [
            "tcp/127.0.0.1:7447",
            "tcp/127.0.0.2:1",
            "tcp/[::1]:7447",
            "tcp/localhost:7447",
            "tcp/127.0.0.1:7447?so_sndbuf=65000",
        ] {
            assert!(is_loopback(local), "{local}");
        }
        for open in [
            "tcp/0.0.0.0:7447",
            "tcp/[::]:7447",
            "tcp/192.168.1.20:7447",
            "tcp/robot.local:7447",
            "tcp/localhost.example.com:7447",
        ] {
            assert!(!is_loopback(open), "{open}");
        }
    }

    #[test]
    fn credentials_take_the_first_line_and_name_a_bad_file() {
        let dir = std::env::temp_dir().join(format!("bridge-auth-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("bridge.auth");
        std::fs::write(&file, "\nrobot:s3cret:x\nstation:other\n").unwrap();
        let c = Credentials::load(&file).unwrap();
        assert_eq!(
            (c.user.as_str(), c.password.as_str()),
            ("robot", "s3cret:x")
        );
        for bad in ["robot\n", "robot:\n", ":pw\n", ""] {
            std::fs::write(&file, bad).unwrap();
            let err = Credentials::load(&file).unwrap_err().to_string();
            assert!(
                err.contains("bridge.auth") && err.contains("USER:PASSWORD"),
                "{err}"
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn only_skipped_numbers_are_missing() {
        assert_eq!(missing(None, 100), 0);
        assert_eq!(missing(Some(4), 5), 0);
        assert_eq!(missing(Some(4), 9), 4);
        assert_eq!(missing(Some(9), 0), 0, "a restarted publisher");
        assert_eq!(missing(Some(9), 9), 0, "a revision repeats a number");
    }
}
