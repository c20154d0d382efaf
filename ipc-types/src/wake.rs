//! Event-driven waking: every data service has an iceoryx2 event service of the same name.
//! A publisher notifies it after each send ([`Waker`]); a subscribing process sleeps in epoll
//! on its listeners until a notification (or its periodic tick) arrives, then drains its
//! subscribers ([`serve_loop`]). An idle process makes no system call and uses no CPU between
//! ticks; a notification that arrives between the last drain and the wait wakes the next wait
//! at once (iceoryx2's listener counts notifications), so no sample waits for a tick.
//!
//! The wait is iceoryx2's own epoll reactor (`iceoryx2_cal::reactor`, what its WaitSet is
//! built on), not the WaitSet: iceoryx2 0.10's `WaitSet::wait_and_process_once*` collect the
//! triggered file descriptors in two new `Vec`s on every wake-up (`waitset.rs`,
//! `wait_and_process_once_with_timeout` and `handle_all_attachments`), that is two heap
//! allocations per sample; the reactor waits on a stack array and allocates nothing.
//!
//! [`WaitMode::Spin`] polls instead, for a process pinned to an isolated core: no listener is
//! created (a notifier without listeners costs no system call) and the loop never sleeps.

use core::ops::ControlFlow;
use core::time::Duration;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use iceoryx2_cal::reactor::{Reactor, ReactorBuilder, ReactorWaitError};

use crate::service::{MAX_NODES, MAX_SUBSCRIBERS, ServiceError, patiently};
use iceoryx2::service::builder::event::{EventOpenError, EventOpenOrCreateError};

/// Notifiers per event service: the data service's publishers and the robot controllers that
/// publish hints.
pub const MAX_NOTIFIERS: usize = 8;

/// How a process waits for input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WaitMode {
    /// Sleep on the input's event service until a publisher notifies it.
    #[default]
    Event,
    /// Poll without sleeping (for a core of its own: `--spin`).
    Spin,
}

/// Opens (or creates) the event service that goes with the data service `name`.
pub fn open_event(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<ipc::Service>, ServiceError> {
    let service_name: ServiceName = name
        .try_into()
        .map_err(|e| ServiceError(format!("invalid service name {name:?}: {e:?}")))?;
    patiently(&format!("event service {name:?}"), event_in_flux, || {
        node.service_builder(&service_name)
            .event()
            .max_notifiers(MAX_NOTIFIERS)
            .max_listeners(MAX_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .open_or_create()
    })
}

/// Whether an event open-or-create failed only because another process was creating or
/// removing the service at that moment (or a signal interrupted the wait).
fn event_in_flux(e: &EventOpenOrCreateError) -> bool {
    matches!(
        e,
        EventOpenOrCreateError::SystemInFlux
            | EventOpenOrCreateError::EventOpenError(
                EventOpenError::HangsInCreation
                    | EventOpenError::IsMarkedForDestruction
                    | EventOpenError::Interrupt
            )
    )
}

/// The event a woken [`Output`] notifies when it is dropped: its publisher leaves cleanly,
/// having sent everything. A process that dies notifies nothing, so a listener (the recorder)
/// tells a stopped publisher from a lost one. Samples notify iceoryx2's default event id, 0.
pub const LEAVING: EventId = EventId::new(1);

/// The notifier a publisher on the data service `name` wakes its subscribers with.
pub struct Waker {
    notifier: Notifier<ipc::Service>,
    name: String,
}

impl Waker {
    /// A notifier on the event service of the data service `name`.
    pub fn new(node: &Node<ipc::Service>, name: &str) -> Result<Self, ServiceError> {
        let notifier = open_event(node, name)?
            .notifier_builder()
            .create()
            .map_err(|e| ServiceError(format!("cannot create notifier on {name:?}: {e:?}")))?;
        Ok(Self {
            notifier,
            name: name.to_string(),
        })
    }

    /// Wakes every listener of the service; call it after the sends of one input.
    pub fn notify(&self) -> Result<(), ServiceError> {
        self.notifier
            .notify()
            .map(|_| ())
            .map_err(|e| ServiceError(format!("cannot notify {:?}: {e:?}", self.name)))
    }

    /// Tells every listener of the service that its publisher leaves ([`LEAVING`]).
    pub fn leave(&self) -> Result<(), ServiceError> {
        self.notifier
            .notify_with_custom_event_id(LEAVING)
            .map(|_| ())
            .map_err(|e| ServiceError(format!("cannot notify {:?}: {e:?}", self.name)))
    }
}

/// A publisher that wakes its subscribers (unless made [`Output::unwoken`]): the first sample
/// sent for an input is notified at once (the live output reaches its subscribers without
/// waiting for the rest), the others together by [`Output::end_of_input`]. A send error is
/// kept (a stage's emit callback cannot return one) and returned by [`Output::end_of_input`];
/// nothing is sent after it. `mems-replay` publishes through it too, each replayed message an
/// input of its own.
pub struct Output<T: core::fmt::Debug + ZeroCopySend + 'static> {
    publisher: Publisher<ipc::Service, T, ()>,
    /// `None` for a publisher that wakes nobody ([`Output::unwoken`]).
    waker: Option<Waker>,
    error: Option<ServiceError>,
    /// Whether the current input's first sample was notified.
    notified: bool,
    /// Samples sent since the last notification.
    unnotified: bool,
    sent: u64,
}

impl<T: core::fmt::Debug + ZeroCopySend + Copy + 'static> Output<T> {
    /// The lossless publisher of [`crate::service::publisher`] on the data service `name`
    /// (opened in `service`) with its [`Waker`].
    pub fn new(
        node: &Node<ipc::Service>,
        service: &iceoryx2::service::port_factory::publish_subscribe::PortFactory<
            ipc::Service,
            T,
            (),
        >,
        name: &str,
    ) -> Result<Self, ServiceError> {
        Self::with_publisher(node, crate::service::publisher(service)?, name)
    }

    /// `publisher` (on the data service `name`) with its [`Waker`]: for a publisher made with
    /// other settings, such as [`crate::service::publisher_waiting_at_most`]'s.
    pub fn with_publisher(
        node: &Node<ipc::Service>,
        publisher: Publisher<ipc::Service, T, ()>,
        name: &str,
    ) -> Result<Self, ServiceError> {
        Ok(Self::woken_by(publisher, Some(Waker::new(node, name)?)))
    }

    /// `publisher` without a [`Waker`]: for a service whose subscribers are not woken by its
    /// samples. The robot hints are one: only samples wake the odometry, which takes the hints
    /// that arrived when it wakes (`mems-replay` publishes them so).
    pub fn unwoken(publisher: Publisher<ipc::Service, T, ()>) -> Self {
        Self::woken_by(publisher, None)
    }

    fn woken_by(publisher: Publisher<ipc::Service, T, ()>, waker: Option<Waker>) -> Self {
        Self {
            publisher,
            waker,
            error: None,
            notified: false,
            unnotified: false,
            sent: 0,
        }
    }

    /// Sends `value` and returns how many subscribers it reached (iceoryx2's count: a
    /// subscriber whose buffer stayed full past the publisher's backpressure handling, or that
    /// is gone, is not one); 0 if it was not sent (an error, now or since the last
    /// [`Output::end_of_input`]).
    pub fn send(&mut self, value: T) -> usize {
        if self.error.is_some() {
            return 0;
        }
        let sent = self
            .publisher
            .loan_uninit()
            .map_err(|e| ServiceError(format!("cannot loan a sample: {e:?}")))
            .and_then(|s| {
                s.write_payload(value)
                    .send()
                    .map_err(|e| ServiceError(format!("cannot send a sample: {e:?}")))
            });
        let recipients = match sent {
            Ok(n) => n,
            Err(e) => {
                self.error = Some(e);
                return 0;
            }
        };
        self.sent += 1;
        if let Some(waker) = &self.waker {
            if self.notified {
                self.unnotified = true;
            } else if let Err(e) = waker.notify() {
                self.error = Some(e);
            } else {
                self.notified = true;
            }
        }
        recipients
    }

    /// The input is done: notifies what was sent since its first sample, and returns the
    /// error met since the last call, if any.
    pub fn end_of_input(&mut self) -> Result<(), ServiceError> {
        if self.unnotified
            && self.error.is_none()
            && let Some(waker) = &self.waker
            && let Err(e) = waker.notify()
        {
            self.error = Some(e);
        }
        self.notified = false;
        self.unnotified = false;
        self.error.take().map_or(Ok(()), Err)
    }

    /// Samples sent so far.
    pub fn sent(&self) -> u64 {
        self.sent
    }

    /// The publisher (for its service's state).
    pub fn publisher(&self) -> &Publisher<ipc::Service, T, ()> {
        &self.publisher
    }
}

impl<T: core::fmt::Debug + ZeroCopySend + 'static> Drop for Output<T> {
    /// Announces the clean departure ([`LEAVING`]) before the publisher is released.
    fn drop(&mut self) {
        if let Some(waker) = &self.waker
            && let Err(e) = waker.leave()
        {
            tracing::warn!("{e}");
        }
    }
}

/// A listener on the event service of the data service `name` (none in [`WaitMode::Spin`]).
pub fn listener(
    node: &Node<ipc::Service>,
    name: &str,
    mode: WaitMode,
) -> Result<Option<Listener<ipc::Service>>, ServiceError> {
    if mode == WaitMode::Spin {
        return Ok(None);
    }
    open_event(node, name)?
        .listener_builder()
        .create()
        .map(Some)
        .map_err(|e| ServiceError(format!("cannot create listener on {name:?}: {e:?}")))
}

/// Why [`serve_loop`] returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Exit {
    /// SIGINT or SIGTERM arrived ([`crate::stop`]).
    Signal,
    /// The step broke the loop.
    Done,
}

/// The epoll reactor iceoryx2 uses for `ipc::Service` listeners.
type IpcReactor = <ipc::Service as iceoryx2::service::Service>::Reactor;

/// Calls `step` whenever input may have arrived on one of `listeners` (at once at the start,
/// then after every notification), and at least every `tick`, until SIGINT/SIGTERM (the flag of
/// [`crate::stop`], installed here if it was not) or `step` breaks. `step` drains its
/// subscribers and returns whether it found anything (`Continue(true)`): without listeners
/// ([`WaitMode::Spin`]) it is called in a loop that never sleeps. Any other signal that
/// interrupts the wait (a SIGCONT after a SIGSTOP) only wakes it. Allocates nothing per wake-up
/// once running.
pub fn serve_loop<E: From<ServiceError>>(
    listeners: &[Option<Listener<ipc::Service>>],
    tick: Duration,
    step: impl FnMut() -> Result<ControlFlow<(), bool>, E>,
) -> Result<Exit, E> {
    serve_loop_with_events(listeners, tick, |_, _| {}, step)
}

/// [`serve_loop`], which also passes every event id it consumes to `on_event`, with the index
/// of its listener in `listeners` (such as [`LEAVING`]).
pub fn serve_loop_with_events<E: From<ServiceError>>(
    listeners: &[Option<Listener<ipc::Service>>],
    tick: Duration,
    mut on_event: impl FnMut(usize, EventId),
    mut step: impl FnMut() -> Result<ControlFlow<(), bool>, E>,
) -> Result<Exit, E> {
    crate::stop::install()?;
    let listeners: Vec<(usize, &Listener<ipc::Service>)> = listeners
        .iter()
        .enumerate()
        .filter_map(|(i, l)| Some((i, l.as_ref()?)))
        .collect();
    if listeners.is_empty() {
        return spin(step);
    }
    let err = |what: &str, e: &dyn core::fmt::Debug| ServiceError(format!("{what}: {e:?}"));
    // Through the reactor traits (the epoll type has inherent methods of the same names).
    let builder = <<IpcReactor as Reactor>::Builder as ReactorBuilder<IpcReactor>>::new();
    let reactor =
        ReactorBuilder::create(builder).map_err(|e| err("cannot create an epoll reactor", &e))?;
    let _guards = listeners
        .iter()
        .map(|(_, l)| Reactor::attach(&reactor, *l))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| err("cannot attach a listener to the reactor", &e))?;
    loop {
        // A SIGINT/SIGTERM during the wait interrupts it (epoll_wait is never restarted).
        if crate::stop::requested() {
            return Ok(Exit::Signal);
        }
        // Consume the notifications first: a sample sent after this is notified again.
        for (i, l) in &listeners {
            l.try_wait(|a| on_event(*i, a.id))
                .map_err(|e| err("cannot read a listener", &e))?;
        }
        if step()?.is_break() {
            return Ok(Exit::Done);
        }
        match Reactor::timed_wait(&reactor, |_| {}, tick) {
            Ok(_) | Err(ReactorWaitError::Interrupt) => {}
            Err(e) => return Err(err("epoll wait", &e).into()),
        }
    }
}

/// [`serve_loop`] without listeners: polls `step` without sleeping.
fn spin<E: From<ServiceError>>(
    mut step: impl FnMut() -> Result<ControlFlow<(), bool>, E>,
) -> Result<Exit, E> {
    loop {
        // One atomic load: cheap enough to check on every poll.
        if crate::stop::requested() {
            return Ok(Exit::Signal);
        }
        if step()?.is_break() {
            return Ok(Exit::Done);
        }
    }
}
