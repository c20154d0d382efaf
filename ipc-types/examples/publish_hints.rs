//! A robot controller's side of mems-odometry: publish what the controller knows (rest and
//! forward speed) as hints on `mems/robot/hint`, without ever blocking the control loop.
//!
//! `cargo run --release -p ipc-types --example publish_hints -- [DURATION_S] [SPEED_MPS]`
//!
//! Publishes at 50 Hz for DURATION_S seconds (default 10; until Ctrl-C with 0). With
//! SPEED_MPS 0 (the default) every hint says the robot is stationary, commanded and measured
//! by the encoders, with a zero forward speed; otherwise it says the robot moves forward at
//! SPEED_MPS (body frame x forward, m/s, 1-sigma 0.02 m/s). Honours `MEMS_NAMESPACE`. Each
//! hint's `stamps.sample_ns` is the time it describes, on the IMU samples' clock
//! (`CLOCK_MONOTONIC`); `stamps.acquired_ns` is when it was published.

use std::time::{Duration, Instant};

use ipc_types::clock::monotonic_ns;
use ipc_types::{RobotHint, Stamps, hint_flags, service};

/// Control loop period: 50 Hz, a typical wheel-odometry rate.
const PERIOD: Duration = Duration::from_millis(20);

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let duration_s: f64 = args.next().map_or(Ok(10.0), |s| s.parse())?;
    let speed_mps: f64 = args.next().map_or(Ok(0.0), |s| s.parse())?;
    // Before any port exists: a SIGINT/SIGTERM is kept from then on.
    ipc_types::stop::install()?;
    let node = service::node()?;
    let name = service::full_name(&service::namespace(None), service::HINT);
    let hints = service::open::<RobotHint>(&node, &name)?;
    // Never blocks: a hint the odometry cannot take is dropped (and treated there as stale).
    let publisher = service::hint_publisher(&hints)?;
    let start = Instant::now();
    let mut seq = 0u64;
    while !ipc_types::stop::sleep(PERIOD) {
        if duration_s > 0.0 && start.elapsed().as_secs_f64() >= duration_s {
            break;
        }
        let now = monotonic_ns();
        let flags = if speed_mps == 0.0 {
            hint_flags::STATIONARY
                | hint_flags::SOURCE_COMMANDED
                | hint_flags::SOURCE_ENCODERS
                | hint_flags::SPEED_VALID
        } else {
            hint_flags::SPEED_VALID
        };
        let hint = RobotHint {
            stamps: Stamps {
                sample_ns: now,
                acquired_ns: monotonic_ns(),
                ..Stamps::default()
            },
            seq,
            forward_speed_mps: speed_mps,
            forward_speed_sigma_mps: 0.02,
            flags,
            ..RobotHint::default()
        };
        publisher.send_copy(hint)?;
        seq += 1;
    }
    println!("published {seq} hints on {name}");
    Ok(())
}
