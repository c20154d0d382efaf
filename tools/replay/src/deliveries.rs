//! Why a message reached fewer subscribers than [`crate::ReplayOptions::wait_subscribers`]
//! (see [`ReplaySummary`]): a subscriber left (it ended, or its process died), the publisher
//! gave the message up for a stalled subscriber, or it was lost for a subscriber that had
//! not connected yet (the only replay fault).
//!
//! A message that reached too few while that many subscribers were registered, and was not
//! given up for a stalled one, is not told apart at once: a SIGKILLed subscriber's dead node is
//! removed (by the replay's [`ipc_types::service::DeadNodeCleanup`] or by any other iceoryx2
//! process) in two steps, its connections first and its registration after, and between the
//! two the publisher already skips it (a full buffer that no receiver holds is not waited
//! for). Such messages wait until the subscribers registered when the first of them was sent
//! are not all there any more (a departure), or a later message reaches enough subscribers
//! with all of them still there (a loss for one that had not connected); at the end of the
//! replay, a subscriber of a dead node counts as gone. Telling them apart so needs neither a
//! time limit nor a node listing per message.

use ipc_types::service;

use crate::ReplaySummary;
use crate::ports::{Delivery, Ports, SubscriberPort};
use crate::topics::Replayable;

/// Messages of one topic that reached too few subscribers while enough were registered.
#[derive(Debug)]
struct Undecided {
    messages: u64,
    /// The subscribers registered when the first of them was sent.
    registered: Vec<SubscriberPort>,
}

/// Counts the messages that reached fewer than the subscribers waited for, by cause.
#[derive(Debug)]
pub(crate) struct Deliveries {
    wanted: usize,
    /// Per topic ([`Replayable::index`]).
    undecided: [Option<Undecided>; 4],
}

impl Deliveries {
    /// For a replay that waited for `wanted` subscribers per service.
    pub(crate) fn new(wanted: usize) -> Self {
        Self {
            wanted,
            undecided: Default::default(),
        }
    }

    /// Counts a message of `topic` sent through `ports` as `delivery` says, in `summary`.
    pub(crate) fn note(
        &mut self,
        ports: &Ports,
        topic: Replayable,
        delivery: Delivery,
        summary: &mut ReplaySummary,
    ) {
        let undecided = &mut self.undecided[topic.index()];
        if let Some(u) = undecided {
            let now = ports.subscriber_ports(topic);
            if u.registered.iter().any(|s| !now.contains(s)) {
                summary.after_subscriber_left += u.messages;
                *undecided = None;
            } else if delivery.recipients >= self.wanted {
                summary.short_deliveries += u.messages;
                *undecided = None;
            }
        }
        if delivery.recipients >= self.wanted {
            return;
        }
        if delivery.given_up {
            summary.given_up_stalled += 1;
        } else if ports.subscribers(topic) < self.wanted {
            summary.after_subscriber_left += 1;
        } else {
            undecided
                .get_or_insert_with(|| Undecided {
                    messages: 0,
                    registered: ports.subscriber_ports(topic),
                })
                .messages += 1;
        }
    }

    /// The replay is over: counts the messages not told apart yet, a subscriber of a dead
    /// node counting as gone.
    pub(crate) fn finish(&mut self, ports: &Ports, summary: &mut ReplaySummary) {
        if self.undecided.iter().all(Option::is_none) {
            return;
        }
        let dead = service::dead_nodes().unwrap_or_else(|e| {
            tracing::warn!("{e}: subscribers of dead processes are taken for live ones");
            Vec::new()
        });
        for topic in Replayable::ALL {
            let Some(u) = self.undecided[topic.index()].take() else {
                continue;
            };
            let now = ports.subscriber_ports(topic);
            if u.registered
                .iter()
                .any(|s| !now.contains(s) || dead.contains(&s.node))
            {
                summary.after_subscriber_left += u.messages;
            } else {
                summary.short_deliveries += u.messages;
            }
        }
    }
}
