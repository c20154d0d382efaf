//! The loop that feeds the view from the stack's services and publishes the app's hints.

use std::ops::ControlFlow;
use std::time::Duration;

use anyhow::Result;
use ipc_types::clock::monotonic_ns;
use ipc_types::wake::{self, WaitMode};
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint, service};

use crate::View;
use crate::hints::Inbox;

/// The longest a hint from the app waits for the loop when no sample wakes it.
pub const TICK: Duration = Duration::from_millis(20);

/// Serves `view` from the services of `namespace` and publishes what arrives in `inbox` on
/// its hint service, until SIGINT/SIGTERM.
pub fn serve(view: &mut View, inbox: &Inbox, namespace: &str) -> Result<()> {
    let node = service::node()?;
    let name = |base| service::full_name(namespace, base);
    let raw = service::subscriber(&service::open::<RawImuSample>(&node, &name(service::RAW))?)?;
    let corrected = service::subscriber(&service::open::<CorrectedImuSample>(
        &node,
        &name(service::CORRECTED),
    )?)?;
    let odometry = service::subscriber(&service::open::<OdometryState>(
        &node,
        &name(service::ODOMETRY),
    )?)?;
    let hint_service = service::open::<RobotHint>(&node, &name(service::HINT))?;
    let hints = service::subscriber(&hint_service)?;
    let hint_publisher = service::hint_publisher(&hint_service)?;
    let listeners = [
        wake::listener(&node, &name(service::RAW), WaitMode::Event)?,
        wake::listener(&node, &name(service::CORRECTED), WaitMode::Event)?,
        wake::listener(&node, &name(service::ODOMETRY), WaitMode::Event)?,
    ];
    let mut seq = 0u64;
    let step = || -> Result<ControlFlow<(), bool>> {
        let mut any = false;
        for hint in inbox.drain() {
            hint_publisher.send_copy(hint.stamped(monotonic_ns(), seq))?;
            seq += 1;
        }
        while let Some(r) = raw.receive()? {
            view.raw(&r);
            any = true;
        }
        while let Some(c) = corrected.receive()? {
            view.corrected(&c);
            any = true;
        }
        while let Some(s) = odometry.receive()? {
            view.state(&s);
            any = true;
        }
        while let Some(h) = hints.receive()? {
            view.hint(&h);
            any = true;
        }
        Ok(ControlFlow::Continue(any))
    };
    wake::serve_loop(&listeners, TICK, step)?;
    Ok(())
}
