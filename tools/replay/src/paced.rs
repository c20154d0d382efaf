//! One pass of a replay in the shape of a source (`mems_stage::source`): each message due at
//! its place in recorded time, or at once ([`Pass`]), and the replay's ports as its sink
//! ([`Published`]: each message sent and woken, its deliveries counted, the progress shown
//! after it left).

use std::time::Instant;

use ipc_types::corrected_flags;
use mems_stage::source::{Flow, Sink, Source};

use crate::deliveries::Deliveries;
use crate::pacer::Pacer;
use crate::ports::Ports;
use crate::source::Merge;
use crate::topics::Payload;
use crate::{Pace, ReplayError, ReplaySummary};

/// A message and the recorded time the pass has covered with it, ns.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Paced {
    pub payload: Payload,
    pub covered_ns: u64,
}

/// One pass over the merged messages: one message per call, due as `pace` says.
pub(crate) struct Pass<'a> {
    messages: Merge<'a>,
    pace: Pace,
    pacer: Pacer,
    next: Option<recording::Result<Paced>>,
    /// Whether the pass's first corrected sample is still to be marked as the start of a new
    /// sensor session (every pass after the first: its sequence numbers and times start over).
    mark_session: bool,
}

impl<'a> Pass<'a> {
    /// A pass over `messages` at `pace`; `again`: a pass after the first.
    pub(crate) fn new(messages: Merge<'a>, pace: Pace, again: bool) -> Self {
        Self {
            messages,
            pace,
            pacer: Pacer::default(),
            next: None,
            mark_session: again,
        }
    }
}

impl Source for Pass<'_> {
    type Output = Paced;
    type Error = ReplayError;

    /// Reads the next message and sleeps until it is due (pacing starts over with each
    /// epoch); `true` if SIGINT or SIGTERM arrived.
    fn wait_due(&mut self) -> bool {
        self.next = self.messages.next().map(|m| {
            m.map(|(place, payload)| {
                match self.pace {
                    Pace::RealTime { speed } => {
                        let due = self.pacer.due(place, speed);
                        ipc_types::stop::sleep(due.saturating_duration_since(Instant::now()));
                    }
                    Pace::Max => _ = self.pacer.place(place),
                }
                Paced {
                    payload,
                    covered_ns: self.pacer.covered_ns,
                }
            })
        });
        ipc_types::stop::requested()
    }

    fn process(&mut self, emit: &mut impl FnMut(&Paced)) -> Result<Flow, ReplayError> {
        match self.next.take() {
            None => Ok(Flow::End),
            Some(message) => {
                let mut message = message?;
                if let Payload::Corrected(s) = &mut message.payload
                    && std::mem::take(&mut self.mark_session)
                {
                    // As the calibration stage marks a new session (`ipc_types::stream`):
                    // a consumer of corrected samples follows the mark.
                    s.flags |= corrected_flags::NEW_SESSION;
                }
                emit(&message);
                Ok(Flow::Continue)
            }
        }
    }
}

/// The replay's ports, with what a pass counts and shows.
pub(crate) struct Published<'a> {
    pub ports: &'a mut Ports,
    pub deliveries: &'a mut Deliveries,
    pub summary: &'a mut ReplaySummary,
    pub start: Instant,
    pub progress: &'a mut dyn FnMut(&ReplaySummary),
}

impl Sink<Paced> for Published<'_> {
    type Error = ReplayError;

    /// Sends the message (its port wakes the subscribers) and counts its deliveries.
    fn publish(&mut self, m: &Paced) -> Result<(), ReplayError> {
        let topic = m.payload.topic();
        if let Some(delivery) = self.ports.send(&m.payload)? {
            self.deliveries
                .note(self.ports, topic, delivery, self.summary);
        }
        self.summary.sent[topic.index()] += 1;
        self.summary.pass_recorded_ns = m.covered_ns;
        Ok(())
    }

    /// After each message: the progress.
    fn end_of_input(&mut self) -> Result<(), ReplayError> {
        self.summary.elapsed = self.start.elapsed();
        (self.progress)(self.summary);
        Ok(())
    }
}
