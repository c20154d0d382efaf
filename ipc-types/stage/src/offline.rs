//! The offline driver: a stage over inputs read from a file, its outputs to a sink ([`run`]),
//! or with a context both take in turn ([`run_with`]).

use crate::Stage;

/// Why [`run`] stopped before the end of its inputs.
#[derive(Debug)]
pub enum Stop<R, E> {
    /// The stage refused the input at this index (0 for the first): offline, a bad input is
    /// fatal (the caller names the file).
    Refused {
        /// Index of the refused input.
        index: u64,
        /// The stage's refusal.
        refusal: R,
    },
    /// The inputs could not be read.
    Input(E),
}

impl<R: core::fmt::Display, E: core::fmt::Display> core::fmt::Display for Stop<R, E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Refused { refusal, .. } => refusal.fmt(f),
            Self::Input(e) => e.fmt(f),
        }
    }
}

impl<R, E> core::error::Error for Stop<R, E>
where
    R: core::fmt::Display + core::fmt::Debug,
    E: core::fmt::Display + core::fmt::Debug,
{
}

/// Runs `stage` over `inputs`, in order, every output to `sink`, then finishes it. Returns the
/// number of inputs taken. The first refusal or read error stops the run (the stage is not
/// finished then).
pub fn run<S: Stage, E>(
    stage: &mut S,
    inputs: impl IntoIterator<Item = Result<S::Input, E>>,
    sink: &mut impl FnMut(&S::Output),
) -> Result<u64, Stop<S::Refusal, E>> {
    let mut inputs = inputs.into_iter();
    run_with(stage, &mut inputs, Iterator::next, &mut |_, o| sink(o))
}

/// [`run`] with a context that the inputs and the sink take in turn, for what both use (an
/// output file both write to, truth the inputs read and the sink compares against) without
/// shared cells: `next` gives the next input (`None`: the end), `sink` takes each output.
pub fn run_with<S: Stage, C, E>(
    stage: &mut S,
    context: &mut C,
    mut next: impl FnMut(&mut C) -> Option<Result<S::Input, E>>,
    sink: &mut impl FnMut(&mut C, &S::Output),
) -> Result<u64, Stop<S::Refusal, E>> {
    let mut index = 0;
    while let Some(input) = next(context) {
        let input = input.map_err(Stop::Input)?;
        stage
            .process(&input, &mut |o| sink(context, o))
            .map_err(|refusal| Stop::Refused { index, refusal })?;
        stage.postprocess(&mut |o| sink(context, o));
        index += 1;
    }
    stage.finish(&mut |o| sink(context, o));
    Ok(index)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Emits each input twice; refuses zero.
    struct Twice;

    impl Stage for Twice {
        type Input = u32;
        type Output = u32;
        type Refusal = &'static str;

        fn process(&mut self, x: &u32, emit: &mut impl FnMut(&u32)) -> Result<(), &'static str> {
            if *x == 0 {
                return Err("zero");
            }
            emit(x);
            emit(x);
            Ok(())
        }

        fn finish(&mut self, emit: &mut impl FnMut(&u32)) {
            emit(&99);
        }
    }

    #[test]
    fn every_input_in_order_then_the_finish() {
        let mut out = Vec::new();
        let n = run(&mut Twice, [1, 2].map(Ok::<_, ()>), &mut |o| out.push(*o)).unwrap();
        assert_eq!((n, out), (2, vec![1, 1, 2, 2, 99]));
    }

    #[test]
    fn a_refusal_or_a_read_error_stops_the_run_where_it_happened() {
        let mut out = Vec::new();
        let stop = run(&mut Twice, [1, 0, 3].map(Ok::<_, ()>), &mut |o| {
            out.push(*o)
        });
        assert!(matches!(
            stop,
            Err(Stop::Refused {
                index: 1,
                refusal: "zero"
            })
        ));
        assert_eq!(out, [1, 1]);
        let stop = run(&mut Twice, [Ok(1), Err("unreadable")], &mut |_| {});
        assert_eq!(stop.unwrap_err().to_string(), "unreadable");
    }

    #[test]
    fn the_inputs_and_the_sink_take_the_context_in_turn() {
        // The context: inputs still to come, and a log both write to.
        let mut context = (vec![2, 1], Vec::new());
        let n = run_with(
            &mut Twice,
            &mut context,
            |(inputs, log): &mut (Vec<u32>, Vec<String>)| {
                let x = inputs.pop()?;
                log.push(format!("in {x}"));
                Some(Ok::<_, ()>(x))
            },
            &mut |(_, log), o| log.push(format!("out {o}")),
        )
        .unwrap();
        assert_eq!(n, 2);
        assert_eq!(
            context.1,
            ["in 1", "out 1", "out 1", "in 2", "out 2", "out 2", "out 99"]
        );
    }
}
