//! What `mems-calibrate serve` adds to the live driver's loop (the steady-state allocation
//! count, the `--state` file kept up to date) and its summary at the end.

use std::path::Path;
use std::time::{Duration, Instant};

use alloc_count::steady::SteadyState;
use anyhow::Result;
use calibrate::stage::{CalibrationStage, WarmState};
use ipc_types::stream::Freezes;
use mems_stage::live::Hooks;

/// The summary on stderr: the stage's counts, what it learned and refined, and the
/// steady-state allocations.
pub fn report(stage: &CalibrationStage, refused: u64, steady: &SteadyState) {
    let s = stage.stats();
    let (learn_restarts, _) = stage.detector().learn_rejections();
    let (accel, gyro, refined) = stage.refinement();
    tracing::info!(
        "accepted {}, published {}, at rest {}, refused {refused}, gaps {}, \
         stream restarts {}, learning restarts {learn_restarts}, detector ready {}, gravity \
         reference lost and measured anew {}, rests held against a gravity magnitude it does \
         not hold {}, refined {refined} (accel {:.4?} m/s^2, gyro {:.5?} rad/s)",
        s.accepted,
        s.released,
        s.rest,
        s.gaps,
        s.restarts,
        stage.detector().is_ready(),
        stage.detector().gravity_reanchored(),
        stage.detector().gravity_held(),
        accel,
        gyro
    );
    if let Some(r) = stage.detector().relearned() {
        tracing::info!(
            "the detector learned again from {:.1} s of rest (--learn-s), at most half as noisy \
             as its first window",
            r.duration_s
        );
    }
    if let Some(holes) = s.holes.describe(0) {
        tracing::warn!("{holes}; each bridged as a gap (GAP_BEFORE and HOLE_BEFORE)");
    }
    if let Some(frozen) = Freezes::describe(&s.frozen, 0) {
        tracing::warn!(
            "{frozen}: the sensor stopped updating while it was read; passed on as measured"
        );
    }
    if s.clipped.samples > 0 {
        tracing::warn!(
            "clipped {} samples at the end of their range ({}); marked CLIPPED",
            s.clipped.samples,
            s.clipped.per_axis_text()
        );
    }
    tracing::info!("{}; {}", steady.summary(), crate::ALLOCATOR.summary());
}

/// The steady-state allocation count, and the `--state` file kept up to date.
pub struct Watch<'a> {
    /// Steady-state allocations.
    pub steady: SteadyState,
    state_file: Option<&'a Path>,
    /// The state as last written, and when (not per sample: at most once a second).
    saved: Option<(WarmState, Instant)>,
}

impl<'a> Watch<'a> {
    /// Counting allocations from now on, and writing the state to `state_file` if given.
    pub fn new(state_file: Option<&'a Path>) -> Result<Self> {
        Ok(Self {
            steady: SteadyState::from_env(|| crate::ALLOCATOR.counts())
                .map_err(anyhow::Error::msg)?,
            state_file,
            saved: None,
        })
    }
}

impl Hooks<CalibrationStage> for Watch<'_> {
    fn input(&mut self) {
        self.steady.inputs(1);
    }

    fn drained(&mut self, stage: &CalibrationStage) -> Result<()> {
        if let Some(path) = self.state_file
            && let Some(state) = stage.warm_state()
            && state.reference.is_some()
            && self.saved.as_ref().is_none_or(|(s, at)| {
                at.elapsed() >= Duration::from_secs(1) && !s.same_learning(&state)
            })
        {
            calibrate::warm_file::save(path, &state)?;
            self.saved = Some((state, Instant::now()));
        }
        Ok(())
    }
}
