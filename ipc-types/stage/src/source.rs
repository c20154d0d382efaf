//! The shape of a source, beside [`crate::Stage`]: what brings samples into the pipeline (a
//! sensor read, a recording replayed), and its live driver ([`produce`]).
//!
//! The model is Copper's source task, `CuSrcTask` (copper-project/copper-rs,
//! `core/cu29_runtime/src/cutask.rs`): the runtime, not the task, owns the loop; `process`
//! makes the output as soon as possible, and `postprocess`, called after it, is "a chance for
//! the task to update some state after process is out of the way", for statistics and other
//! work nobody waits for. Here the driver waits until the source is due
//! ([`Source::wait_due`]), has it make what is due ([`Source::process`]), publishes each output
//! at once and wakes the subscribers, then calls [`Source::postprocess`]. A source does no
//! publishing of its own, so every source leaves through the same send path and its outputs
//! are counted one way.

/// What a source's live run published.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Produced {
    /// Calls of [`Source::process`] (reads of a sensor, messages of a replay).
    pub rounds: u64,
    /// Outputs published.
    pub published: u64,
}

/// Whether a source has more to make.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    /// More will be due.
    Continue,
    /// The source has ended (its input is exhausted, or its time is up).
    End,
}

/// A source: outputs made from outside the pipeline, on a schedule of its own. No publishing,
/// and no allocation per output.
pub trait Source {
    /// What it makes.
    type Output;
    /// Why it cannot go on (fatal; what a source survives, it counts and reports itself).
    type Error;

    /// Returns once the next outputs are due (sleeps on the source's clock, or at once).
    /// `true`: SIGINT/SIGTERM arrived meanwhile, and the driver stops.
    fn wait_due(&mut self) -> bool;

    /// Makes what is due; each output is passed to `emit`, in order, before the call returns.
    fn process(&mut self, emit: &mut impl FnMut(&Self::Output)) -> Result<Flow, Self::Error>;

    /// After the outputs of [`Self::process`] were published and their subscribers woken: the
    /// work they do not wait for (statistics, progress).
    fn postprocess(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// Where a driver puts a source's outputs: publishes each, then wakes the subscribers once
/// per call of [`Source::process`].
pub trait Sink<T> {
    /// Why a publication failed (fatal).
    type Error;
    /// Publishes `value`.
    fn publish(&mut self, value: &T) -> Result<(), Self::Error>;
    /// The outputs of one call were all published: wake the subscribers.
    fn end_of_input(&mut self) -> Result<(), Self::Error>;
}

/// A source's live driver: until the source ends or SIGINT/SIGTERM arrives, waits until it is
/// due, publishes what it makes to `sink` and wakes the subscribers, then lets it postprocess.
/// Returns what was published; the first error of the source or the sink stops it.
pub fn produce<S, K, E>(source: &mut S, sink: &mut K) -> Result<Produced, E>
where
    S: Source,
    K: Sink<S::Output>,
    E: From<S::Error> + From<K::Error>,
{
    let mut counts = Produced::default();
    loop {
        if source.wait_due() {
            break;
        }
        let mut failed = None;
        let flow = source.process(&mut |o| {
            if failed.is_none() {
                match sink.publish(o) {
                    Ok(()) => counts.published += 1,
                    Err(e) => failed = Some(e),
                }
            }
        })?;
        if let Some(e) = failed {
            return Err(e.into());
        }
        sink.end_of_input()?;
        source.postprocess()?;
        counts.rounds += 1;
        if flow == Flow::End {
            break;
        }
    }
    Ok(counts)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Counts down from `n`, two outputs per call; notes each postprocess.
    struct Countdown {
        n: u32,
        log: Vec<String>,
    }

    impl Source for Countdown {
        type Output = u32;
        type Error = String;

        fn wait_due(&mut self) -> bool {
            false
        }

        fn process(&mut self, emit: &mut impl FnMut(&u32)) -> Result<Flow, String> {
            for _ in 0..2 {
                emit(&self.n);
                self.n -= 1;
            }
            Ok(if self.n == 0 {
                Flow::End
            } else {
                Flow::Continue
            })
        }

        fn postprocess(&mut self) -> Result<(), String> {
            self.log.push(format!("post {}", self.n));
            Ok(())
        }
    }

    /// Records publications and wake-ups; fails on 3.
    #[derive(Default)]
    struct Recorder(Vec<String>);

    impl Sink<u32> for Recorder {
        type Error = String;

        fn publish(&mut self, value: &u32) -> Result<(), String> {
            if *value == 3 {
                return Err("cannot publish 3".into());
            }
            self.0.push(format!("pub {value}"));
            Ok(())
        }

        fn end_of_input(&mut self) -> Result<(), String> {
            self.0.push("wake".into());
            Ok(())
        }
    }

    #[test]
    fn outputs_are_published_and_woken_before_the_postprocess() {
        let mut source = Countdown { n: 6, log: vec![] };
        let mut sink = Recorder::default();
        let stop = produce::<_, _, String>(&mut source, &mut sink);
        assert_eq!(stop, Err("cannot publish 3".to_string()));
        assert_eq!(sink.0, ["pub 6", "pub 5", "wake", "pub 4"]);
        assert_eq!(source.log, ["post 4"]);

        let mut source = Countdown { n: 2, log: vec![] };
        let mut sink = Recorder::default();
        let counts = produce::<_, _, String>(&mut source, &mut sink).unwrap();
        assert_eq!((counts.rounds, counts.published), (1, 2));
        assert_eq!(sink.0, ["pub 2", "pub 1", "wake"]);
        assert_eq!(source.log, ["post 0"]);
    }
}
