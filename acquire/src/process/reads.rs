//! `mems-acquire` in the shape of a source (`mems_stage::source`): the acquisition loop's
//! FIFO reads as a [`Source`] ([`Reads`]: due on the read schedule, each read's samples its
//! outputs, a failed read reported after the samples left) and `mems/imu/raw` as its sink
//! ([`RawOut`]: each sample stamped with what the publisher gave up so far, the subscribers
//! woken once per read).

use std::convert::Infallible;
use std::time::{Duration, Instant};

use embedded_hal::i2c::I2c;
use ipc_types::RawImuSample;
use ipc_types::service::{ServiceError, Undelivered};
use ipc_types::wake::Output;
use mems_stage::source::{Flow, Sink, Source};

use crate::acquisition::Acquisition;
use crate::clock::Clock;
use crate::driver;

/// The acquisition loop as a source: one FIFO read per call, until `deadline` after `start`
/// (if any).
pub struct Reads<I2C: I2c, C: Clock> {
    /// The loop.
    pub acq: Acquisition<I2C, C>,
    /// When the loop started.
    pub start: Instant,
    /// How long it runs (`None`: until SIGINT/SIGTERM).
    pub deadline: Option<Duration>,
    /// The last read's failure, reported in the postprocess.
    failed: Option<driver::Error<I2C::Error>>,
}

impl<I2C: I2c, C: Clock> Reads<I2C, C> {
    /// Reads with `acq` from now, for `deadline` if given.
    pub fn new(acq: Acquisition<I2C, C>, deadline: Option<Duration>) -> Self {
        Self {
            acq,
            start: Instant::now(),
            deadline,
            failed: None,
        }
    }
}

impl<I2C: I2c, C: Clock> Source for Reads<I2C, C> {
    type Output = RawImuSample;
    type Error = Infallible;

    /// An absolute-deadline sleep until the next read (a relative one would add any
    /// preemption between reading the clock and sleeping); then SIGINT/SIGTERM stops: the
    /// clean way out.
    fn wait_due(&mut self) -> bool {
        self.acq.clock().sleep_until(self.acq.next_read_ns());
        ipc_types::stop::requested()
    }

    fn process(&mut self, emit: &mut impl FnMut(&RawImuSample)) -> Result<Flow, Infallible> {
        let Ok(read) = self.acq.read_and_publish(&mut |s| {
            emit(s);
            Ok::<_, Infallible>(())
        });
        self.failed = read.err();
        let over = self.deadline.is_some_and(|d| self.start.elapsed() >= d);
        Ok(if over { Flow::End } else { Flow::Continue })
    }

    /// A failed read (the driver re-initialises the device) is said after the samples left.
    fn postprocess(&mut self) -> Result<(), Infallible> {
        if let Some(e) = self.failed.take() {
            tracing::warn!("read failed, device re-initialising: {e}");
        }
        Ok(())
    }
}

/// `mems/imu/raw`: each sample stamped with the samples the publisher gave up so far for
/// stalled subscribers.
pub struct RawOut {
    /// The output, which wakes the subscribers.
    pub out: Output<RawImuSample>,
    /// What the publisher gave up.
    pub undelivered: Undelivered,
}

impl Sink<RawImuSample> for RawOut {
    type Error = ServiceError;

    fn publish(&mut self, s: &RawImuSample) -> Result<(), ServiceError> {
        self.out.send(RawImuSample {
            undelivered: u32::try_from(self.undelivered.total()).unwrap_or(u32::MAX),
            ..*s
        });
        Ok(())
    }

    fn end_of_input(&mut self) -> Result<(), ServiceError> {
        self.out.end_of_input()
    }
}
