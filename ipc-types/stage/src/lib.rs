//! The one shape of every mems-odometry stage, and the two drivers that run any stage: live
//! ([`live::serve`]: iceoryx2 in, iceoryx2 out, woken by events) and offline ([`offline::run`]:
//! inputs from a file, outputs to a sink); beside it the shape of a source, which brings the
//! samples in, and its live driver ([`source`]).
//!
//! A stage is a pure state machine, Copper's task discipline without its code generation: it
//! takes one input at a time and emits its outputs through a callback, with no I/O, no clock
//! and no allocation per input. Every policy that decides its outputs (a new sensor session,
//! the order of its inputs, what a sample without a gyroscope gives) lives inside it; a driver
//! only moves inputs in and outputs out, and counts. Given the same inputs in the same order,
//! the live process and the offline run therefore emit the same outputs, by construction.

pub mod live;
pub mod offline;
pub mod source;

/// A stage: inputs in, outputs out, no I/O.
pub trait Stage {
    /// What the stage takes.
    type Input;
    /// What it emits.
    type Output;
    /// Why it refused an input (the message names the input); a refused input changes nothing.
    type Refusal: core::fmt::Display;

    /// Takes one input; every output it causes is passed to `emit`, in order, before the call
    /// returns.
    fn process(
        &mut self,
        input: &Self::Input,
        emit: &mut impl FnMut(&Self::Output),
    ) -> Result<(), Self::Refusal>;

    /// The end of the input: emits what was held back for inputs that will not come.
    fn finish(&mut self, emit: &mut impl FnMut(&Self::Output));

    /// Whether the last input left work its outputs' subscribers do not wait for
    /// ([`Stage::postprocess`]).
    fn postprocess_due(&self) -> bool {
        false
    }

    /// Does the work the last input left that its outputs' subscribers do not wait for
    /// (Copper's `postprocess`: the odometry's revisions of earlier states). The live driver
    /// calls it after the input's outputs are published and their subscribers woken, the
    /// offline driver right after [`Stage::process`]. A stage whose `postprocess` was not
    /// called does that work first in the next `process` or `finish`, so the outputs and their
    /// order do not depend on the driver.
    fn postprocess(&mut self, _emit: &mut impl FnMut(&Self::Output)) {}
}

/// Two stages in one, the first's outputs the second's inputs; an input may go to either (a
/// robot hint bypasses the calibration stage). Emits what both emit, in order.
pub struct Chain<A, B> {
    /// The first stage.
    pub first: A,
    /// The second stage.
    pub second: B,
}

/// An input of a [`Chain`], its output, or its refusal: the first stage's or the second's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Either<A, B> {
    /// The first stage's.
    First(A),
    /// The second stage's.
    Second(B),
}

impl<A: core::fmt::Display, B: core::fmt::Display> core::fmt::Display for Either<A, B> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::First(a) => a.fmt(f),
            Self::Second(b) => b.fmt(f),
        }
    }
}

impl<A, B> Stage for Chain<A, B>
where
    A: Stage,
    A::Output: Clone,
    B: Stage,
    B::Input: From<A::Output>,
    B::Output: Clone,
{
    type Input = Either<A::Input, B::Input>;
    type Output = Either<A::Output, B::Output>;
    type Refusal = Either<A::Refusal, B::Refusal>;

    /// A first-stage input goes through both; the second stage's first refusal of what the
    /// first emitted is returned (it still takes the rest of that call's outputs).
    fn process(
        &mut self,
        input: &Self::Input,
        emit: &mut impl FnMut(&Self::Output),
    ) -> Result<(), Self::Refusal> {
        let second = &mut self.second;
        match input {
            Either::First(a) => {
                let mut refused = None;
                self.first
                    .process(a, &mut |out: &A::Output| {
                        emit(&Either::First(out.clone()));
                        let result = second.process(&B::Input::from(out.clone()), &mut |b| {
                            emit(&Either::Second(b.clone()))
                        });
                        if let Err(e) = result {
                            refused.get_or_insert(e);
                        }
                    })
                    .map_err(Either::First)?;
                refused.map_or(Ok(()), |e| Err(Either::Second(e)))
            }
            Either::Second(b) => second
                .process(b, &mut |out| emit(&Either::Second(out.clone())))
                .map_err(Either::Second),
        }
    }

    fn postprocess_due(&self) -> bool {
        self.first.postprocess_due() || self.second.postprocess_due()
    }

    /// The first's postprocess (its outputs going through the second), then the second's.
    fn postprocess(&mut self, emit: &mut impl FnMut(&Self::Output)) {
        let second = &mut self.second;
        self.first.postprocess(&mut |out: &A::Output| {
            emit(&Either::First(out.clone()));
            // Work left from an input already taken: a refusal has no input left to stop.
            let _ = second.process(&B::Input::from(out.clone()), &mut |b| {
                emit(&Either::Second(b.clone()))
            });
        });
        second.postprocess(&mut |out| emit(&Either::Second(out.clone())));
    }

    fn finish(&mut self, emit: &mut impl FnMut(&Self::Output)) {
        let second = &mut self.second;
        self.first.finish(&mut |out: &A::Output| {
            emit(&Either::First(out.clone()));
            // The end of the input: a refusal has no input left to stop.
            let _ = second.process(&B::Input::from(out.clone()), &mut |b| {
                emit(&Either::Second(b.clone()))
            });
        });
        second.finish(&mut |out| emit(&Either::Second(out.clone())));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Emits the running sum of its inputs; refuses negative ones.
    struct Sum(i64);

    impl Stage for Sum {
        type Input = i64;
        type Output = i64;
        type Refusal = String;

        fn process(&mut self, x: &i64, emit: &mut impl FnMut(&i64)) -> Result<(), String> {
            if *x < 0 {
                return Err(format!("negative input {x}"));
            }
            self.0 += x;
            emit(&self.0);
            Ok(())
        }

        fn finish(&mut self, emit: &mut impl FnMut(&i64)) {
            emit(&-1);
        }
    }

    #[test]
    fn a_chain_feeds_the_first_stages_outputs_to_the_second() {
        let mut chain = Chain {
            first: Sum(0),
            second: Sum(100),
        };
        let mut out = Vec::new();
        for x in [1, 2, 3] {
            chain
                .process(&Either::First(x), &mut |o| out.push(*o))
                .unwrap();
        }
        chain
            .process(&Either::Second(10), &mut |o| out.push(*o))
            .unwrap();
        use Either::{First as F, Second as S};
        // Running sums 1, 3, 6 of the first; 101, 104, 110, then 120 of the second.
        assert_eq!(
            out,
            [F(1), S(101), F(3), S(104), F(6), S(110), S(120)],
            "{out:?}"
        );
    }

    #[test]
    fn a_chain_names_which_stage_refused() {
        let mut chain = Chain {
            first: Sum(0),
            second: Sum(-10),
        };
        let refused = chain.process(&Either::First(-1), &mut |_| {});
        assert_eq!(refused, Err(Either::First("negative input -1".to_string())));
        // What the first emits goes on to the second, whose sum starts below zero.
        let mut out = Vec::new();
        let refused = chain.process(&Either::First(3), &mut |o| out.push(*o));
        assert_eq!(refused, Ok(()));
        assert_eq!(out, [Either::First(3), Either::Second(-7)]);
        let refused = chain.process(&Either::Second(-3), &mut |_| {});
        assert_eq!(refused.unwrap_err().to_string(), "negative input -3");
    }

    #[test]
    fn finishing_a_chain_finishes_both_in_order() {
        let mut chain = Chain {
            first: Sum(0),
            second: Sum(0),
        };
        let mut out = Vec::new();
        chain.finish(&mut |o| out.push(*o));
        // The first's -1 is refused by the second; then the second's own -1.
        assert_eq!(out, [Either::First(-1), Either::Second(-1)]);
    }
}
