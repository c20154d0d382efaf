//! The live driver: a stage between iceoryx2 services. It sleeps on its input's event service
//! until a publisher notifies it (or polls, [`WaitMode::Spin`](ipc_types::wake::WaitMode)),
//! hands each input to the stage as it arrives, publishes each output at once (stamped with
//! the time it leaves the process, [`Stamp`]) and wakes its subscribers, then runs the
//! stage's postprocess (work the subscribers do not wait for), counts and reports
//! what the stage refused (a live process drops a bad input and goes on), and at
//! SIGINT/SIGTERM finishes the stage. It allocates nothing per input.

use core::ops::ControlFlow;
use core::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use ipc_types::clock::monotonic_ns;
use ipc_types::service::ServiceError;
use ipc_types::wake::{self, Output};
use ipc_types::{CorrectedImuSample, OdometryState};

use crate::Stage;

/// Refusals reported one by one on stderr; later ones are only counted.
pub const REPORTED_REFUSALS: u64 = 10;

/// Longest sleep without a notification: a publisher that does not notify (an older tool) is
/// still served, with this latency.
pub const TICK: Duration = Duration::from_millis(100);

/// Where a live stage's inputs come from.
pub trait Receive<S: Stage> {
    /// The next input that has arrived and that `stage` can take now (`None`: none).
    fn receive(&mut self, stage: &S) -> Result<Option<S::Input>, ServiceError>;
}

/// One subscriber whose payloads are the stage's inputs.
impl<S, T> Receive<S> for Subscriber<ipc::Service, T, ()>
where
    S: Stage<Input = T>,
    T: core::fmt::Debug + ZeroCopySend + Copy + 'static,
{
    fn receive(&mut self, _stage: &S) -> Result<Option<T>, ServiceError> {
        Subscriber::<ipc::Service, T, ()>::receive(self)
            .map(|s| s.map(|s| *s.payload()))
            .map_err(|e| ServiceError(format!("cannot receive: {e:?}")))
    }
}

/// An output that carries the time it was published.
pub trait Stamp {
    /// Sets the publication time, ns of `CLOCK_MONOTONIC`.
    fn stamp(&mut self, now_ns: u64);
}

impl Stamp for CorrectedImuSample {
    fn stamp(&mut self, now_ns: u64) {
        self.stamps.calibrated_ns = now_ns;
    }
}

impl Stamp for OdometryState {
    fn stamp(&mut self, now_ns: u64) {
        self.stamps.odometry_ns = now_ns;
    }
}

/// What a process adds to the driver's loop (its allocation count, a state it saves).
pub trait Hooks<S> {
    /// An input was received; called before the stage takes it.
    fn input(&mut self) {}
    /// Every input that had arrived was taken; called after each drain.
    fn drained(&mut self, _stage: &S) -> anyhow::Result<()> {
        Ok(())
    }
}

impl<S> Hooks<S> for () {}

/// What a live run handled.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    /// Inputs received.
    pub received: u64,
    /// Inputs the stage refused (dropped).
    pub refused: u64,
    /// Outputs published.
    pub published: u64,
}

/// Runs `stage` on the inputs of `input`, publishing to `out`, until SIGINT/SIGTERM, then
/// finishes it. `listener` is the input's event listener (`None`: poll without sleeping).
pub fn serve<S>(
    stage: &mut S,
    input: &mut impl Receive<S>,
    out: &mut Output<S::Output>,
    listener: Option<Listener<ipc::Service>>,
    hooks: &mut impl Hooks<S>,
) -> anyhow::Result<Counts>
where
    S: Stage,
    S::Output: Stamp + core::fmt::Debug + ZeroCopySend + Copy + 'static,
{
    let mut counts = Counts::default();
    wake::serve_loop(&[listener], TICK, || -> anyhow::Result<_> {
        let mut any = false;
        while let Some(x) = input.receive(stage)? {
            any = true;
            counts.received += 1;
            hooks.input();
            let taken = stage.process(&x, &mut |o| send(out, o));
            if let Err(e) = taken {
                counts.refused += 1;
                if counts.refused <= REPORTED_REFUSALS {
                    tracing::warn!("refused: {e}");
                }
                if counts.refused == REPORTED_REFUSALS {
                    tracing::warn!("later refusals are only counted");
                }
            }
            out.end_of_input()?;
            if stage.postprocess_due() {
                // The subscribers just woken run first if one was woken onto this core.
                std::thread::yield_now();
                stage.postprocess(&mut |o| send(out, o));
                out.end_of_input()?;
            }
        }
        hooks.drained(stage)?;
        Ok(ControlFlow::Continue(any))
    })?;
    stage.finish(&mut |o| send(out, o));
    out.end_of_input()?;
    counts.published = out.sent();
    Ok(counts)
}

/// Publishes `value`, stamped with the time it leaves the process.
fn send<T: Stamp + core::fmt::Debug + ZeroCopySend + Copy + 'static>(
    out: &mut Output<T>,
    value: &T,
) {
    let mut value = *value;
    value.stamp(monotonic_ns());
    out.send(value);
}
