//! A robot process's view of mems-odometry: subscribe, zero-copy, to the odometry state and
//! print position with its 1-sigma ("not aligned yet" before the odometry's gravity
//! alignment, when the position is held at zero). Event-driven: it sleeps on the state
//! service's event (the odometry notifies it after each send) and drains the subscriber when
//! woken (`ipc_types::wake`), so a state is handled as soon as it is published and an idle
//! client uses no CPU.
//!
//! `cargo run --release -p ipc-types --example subscribe_odometry -- [COUNT] [--namespace NS]`
//! (stops after COUNT live states, or on Ctrl-C). It says once on stderr which service and
//! namespace it waits on, so a client started without a stack does not wait silently.

use clap::Parser;
use ipc_types::wake::{self, WaitMode};
use ipc_types::{OdometryState, odometry_flags, service};
use std::ops::ControlFlow;
use std::time::Duration;

/// Prints the live odometry states of a running mems-odometry stack.
#[derive(Parser)]
struct Cli {
    /// Stop after this many live states (default: until Ctrl-C).
    count: Option<u64>,
    /// iceoryx2 service namespace (default: $MEMS_NAMESPACE, else none).
    #[arg(long)]
    namespace: Option<String>,
}

/// The line printed for a live state.
fn line(state: &OdometryState) -> String {
    let head = format!(
        "seq {} t {:.3} s:",
        state.seq,
        state.stamps.sample_ns as f64 * 1e-9
    );
    if state.flags & odometry_flags::ALIGNED == 0 {
        return format!("{head} not aligned yet");
    }
    let (p, s) = (state.position_m, state.position_sigma_m);
    let rest = if state.flags & odometry_flags::ZERO_VELOCITY != 0 {
        ", at rest"
    } else {
        ""
    };
    format!(
        "{head} position ({:+.3}, {:+.3}, {:+.3}) m +- ({:.3}, {:.3}, {:.3}){rest}",
        p[0], p[1], p[2], s[0], s[1], s[2]
    )
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let cli = Cli::parse();
    // Before any port exists: a SIGINT/SIGTERM is kept from then on.
    ipc_types::stop::install()?;
    let node = service::node()?;
    let namespace = service::namespace(cli.namespace.as_deref());
    let name = service::full_name(&namespace, service::ODOMETRY);
    let odometry = service::open::<OdometryState>(&node, &name)?;
    let subscriber = service::subscriber(&odometry)?;
    let listener = wake::listener(&node, &name, WaitMode::Event)?;
    eprintln!(
        "subscribe_odometry: waiting for states on {name} (namespace {namespace:?}; \
         start mems-stack with the same namespace)"
    );
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
            println!("{}", line(&sample));
            seen += 1;
            if cli.count.is_some_and(|c| seen >= c) {
                return Ok(ControlFlow::Break(()));
            }
        }
        Ok(ControlFlow::Continue(any))
    };
    wake::serve_loop(&[listener], Duration::from_millis(100), step)?;
    Ok(())
}
