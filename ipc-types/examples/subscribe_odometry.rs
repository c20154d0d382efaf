//! A robot process's view of mems-odometry: subscribe, zero-copy, to the odometry state and
//! print position with its 1-sigma. Event-driven: it sleeps on the state service's event (the
//! odometry notifies it after each send) and drains the subscriber when woken
//! (`ipc_types::wake`), so a state is handled as soon as it is published and an idle client
//! uses no CPU.
//!
//! `cargo run --release -p ipc-types --example subscribe_odometry -- [COUNT]`
//! (honours `MEMS_NAMESPACE`; stops after COUNT live states, or on Ctrl-C).

use ipc_types::wake::{self, WaitMode};
use ipc_types::{OdometryState, odometry_flags, service};
use std::ops::ControlFlow;
use std::time::Duration;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let count: Option<u64> = std::env::args().nth(1).map(|s| s.parse()).transpose()?;
    // Before any port exists: a SIGINT/SIGTERM is kept from then on.
    ipc_types::stop::install()?;
    let node = service::node()?;
    let name = service::full_name(&service::namespace(None), service::ODOMETRY);
    let odometry = service::open::<OdometryState>(&node, &name)?;
    let subscriber = service::subscriber(&odometry)?;
    let listener = wake::listener(&node, &name, WaitMode::Event)?;
    let mut seen = 0;
    // Woken by each notification, and at least every 100 ms; returns on Ctrl-C.
    let step = || -> Result<ControlFlow<(), bool>, Box<dyn std::error::Error>> {
        let mut any = false;
        while let Some(sample) = subscriber.receive()? {
            any = true;
            // Revisions re-publish past states after drift removal; a controller that only
            // wants the latest estimate skips them.
            if sample.flags & odometry_flags::REVISION != 0 {
                continue;
            }
            let p = sample.position_m;
            let s = sample.position_sigma_m;
            println!(
                "seq {} t {:.3} s: position ({:+.3}, {:+.3}, {:+.3}) m +- ({:.3}, {:.3}, {:.3}){}",
                sample.seq,
                sample.stamps.sample_ns as f64 * 1e-9,
                p[0],
                p[1],
                p[2],
                s[0],
                s[1],
                s[2],
                if sample.flags & odometry_flags::ZERO_VELOCITY != 0 {
                    ", at rest"
                } else {
                    ""
                }
            );
            seen += 1;
            if count.is_some_and(|c| seen >= c) {
                return Ok(ControlFlow::Break(()));
            }
        }
        Ok(ControlFlow::Continue(any))
    };
    wake::serve_loop(&[listener], Duration::from_millis(100), step)?;
    Ok(())
}
