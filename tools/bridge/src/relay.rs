//! `out` and `ros2`: an iceoryx2 service drained at once into a bounded queue, so that the
//! robot is never held back by the network, and a sender thread that puts each message on
//! Zenoh through a reliable publisher that blocks when the network is congested.

use std::ops::ControlFlow;
use std::time::Duration;

use anyhow::{Result, anyhow};
use ipc_types::wake::{self, WaitMode};
use ipc_types::{Message, service};
use zenoh::Wait;
use zenoh::qos::CongestionControl;

use crate::Counts;

/// Messages buffered per service between iceoryx2 and Zenoh: 16 s at 1 kHz.
pub const QUEUE: usize = 16_384;
/// Longest wait between two checks for SIGINT/SIGTERM.
pub const TICK: Duration = Duration::from_millis(100);

/// A reliable Zenoh publisher on `key` that blocks when the network is congested.
pub fn publisher<'a>(
    session: &'a zenoh::Session,
    key: &str,
) -> Result<zenoh::pubsub::Publisher<'a>> {
    session
        .declare_publisher(key.to_string())
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| anyhow!("cannot declare a Zenoh publisher on {key}: {e}"))
}

/// Drains iceoryx2 service `name` at once into a bounded queue (a message that finds it full is
/// lost and counted) and hands each message to `send` on a thread of its own, until
/// SIGINT/SIGTERM; a message `send` says it put on Zenoh is counted carried.
pub fn drain<T: Message + Send>(
    name: &str,
    counts: &Counts,
    mut send: impl FnMut(T) -> Result<bool> + Send,
) -> Result<()> {
    let node = service::node()?;
    let subscriber = service::subscriber(&service::open::<T>(&node, name)?)?;
    let listener = wake::listener(&node, name, WaitMode::Event)?;
    let (tx, rx) = std::sync::mpsc::sync_channel::<T>(QUEUE);
    std::thread::scope(|scope| {
        let sender = scope.spawn(move || -> Result<()> {
            for message in rx {
                if send(message)? {
                    counts.carry();
                }
            }
            Ok(())
        });
        let step = || -> Result<ControlFlow<(), bool>> {
            let mut any = false;
            while let Some(sample) = subscriber.receive()? {
                any = true;
                if tx.try_send(*sample).is_err() {
                    counts.lose(1);
                }
            }
            Ok(ControlFlow::Continue(any))
        };
        let served = wake::serve_loop(&[listener], TICK, step);
        drop(tx);
        let sent = sender.join().map_err(|_| anyhow!("the sender panicked"))?;
        served.and(sent).map(|_| ())
    })
}
