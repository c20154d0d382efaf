//! The candidate effects: each a term the model can gain (a column per axis of the linear
//! models, a reading term of the label-free one) or a fix of the acquisition.

use serde::Serialize;

use super::data::{Obs, class_axis};

/// A candidate effect (names as in the JSON output and on the command line).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
#[value(rename_all = "snake_case")]
pub enum Effect {
    /// Bias linear in the die temperature: `c_b (T - T_ref)` per axis (3 parameters).
    TemperatureBias,
    /// Scale factor linear in the die temperature: `c_s,i (T - T_ref) a_i` on axis `i`, with
    /// `a` the specific force (3 parameters).
    TemperatureScale,
    /// Bias linear in the elapsed time since the time origin (the session's first sample, or
    /// the first of its power-on with `--same-power-on`): `r t` (3).
    BiasDrift,
    /// Warm-up transient after power-on: `w exp(-t / tau)` (3 + the time constant, chosen
    /// on the training data from a grid).
    WarmUp,
    /// Quadratic scale nonlinearity: `k_i a_i^2` on axis `i` (3).
    ScaleNonlinearity,
    /// The gravity labels are off: each orientation class has its own small tilt, i.e. an
    /// offset on the two axes across its label (2 per class; labelled data only).
    ReferenceTilt,
    /// The bias steps at each gap in the samples (the acquisition restarted): a free constant
    /// for each stretch between gaps (3 per gap).
    Gaps,
    /// Torn high/low-byte reads (values off by +-256 counts near a byte boundary), undone by
    /// the torn-read repair (`calibrate::repair`).
    TornReads,
    /// Samples that repeat the previous one exactly more often than noise allows (the driver
    /// read faster than the sensor converts), left out.
    RepeatedSamples,
}

impl Effect {
    /// Every candidate, in the order they are reported.
    pub const ALL: [Effect; 9] = [
        Effect::TemperatureBias,
        Effect::TemperatureScale,
        Effect::BiasDrift,
        Effect::WarmUp,
        Effect::ScaleNonlinearity,
        Effect::ReferenceTilt,
        Effect::Gaps,
        Effect::TornReads,
        Effect::RepeatedSamples,
    ];

    /// The name used in the JSON output and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Effect::TemperatureBias => "temperature_bias",
            Effect::TemperatureScale => "temperature_scale",
            Effect::BiasDrift => "bias_drift",
            Effect::WarmUp => "warm_up",
            Effect::ScaleNonlinearity => "scale_nonlinearity",
            Effect::ReferenceTilt => "reference_tilt",
            Effect::Gaps => "gaps",
            Effect::TornReads => "torn_reads",
            Effect::RepeatedSamples => "repeated_samples",
        }
    }

    /// Whether the effect changes the data (a fix of the acquisition) rather than the model.
    pub fn is_fix(self) -> bool {
        matches!(self, Effect::TornReads | Effect::RepeatedSamples)
    }
}

impl std::fmt::Display for Effect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Where a column of a linear design comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Tag {
    /// Model 3: `S[axis][j]` (j < 3) or the bias (j = 3).
    Base(usize),
    /// An effect's column; the index distinguishes several columns of one effect on one axis
    /// (the orientation class of a tilt column).
    Effect(Effect, usize),
}

/// The direction the scale terms refer to for an observation: its label, else its orientation
/// class's axis (a single-orientation session), else the corrected direction estimate.
pub(crate) fn direction(o: &Obs, estimate: Option<&[f64; 3]>) -> [f64; 3] {
    match (o.label, estimate) {
        (Some(l), _) => l,
        (None, Some(e)) => *e,
        (None, None) => class_axis(o.class).into(),
    }
}

/// The regressor of a single-column effect on `axis` for observation `o` (`t_ref_c` the
/// reference temperature, `tau_s` the warm-up time constant, `dir` from [`direction`]).
pub(crate) fn regressor(
    effect: Effect,
    o: &Obs,
    axis: usize,
    t_ref_c: f64,
    tau_s: f64,
    dir: &[f64; 3],
) -> f64 {
    match effect {
        Effect::TemperatureBias => o.temp_c.expect("checked: temperature present") - t_ref_c,
        Effect::TemperatureScale => {
            (o.temp_c.expect("checked: temperature present") - t_ref_c) * dir[axis]
        }
        Effect::BiasDrift => o.t_s.expect("checked: times present"),
        Effect::WarmUp => (-o.t_s.expect("checked: times present") / tau_s).exp(),
        Effect::ScaleNonlinearity => dir[axis] * dir[axis],
        Effect::ReferenceTilt | Effect::Gaps | Effect::TornReads | Effect::RepeatedSamples => {
            unreachable!("{effect} has no single regressor")
        }
    }
}

/// Whether an effect adds columns (as opposed to groups or a data fix).
pub(crate) fn has_columns(effect: Effect) -> bool {
    !matches!(
        effect,
        Effect::Gaps | Effect::TornReads | Effect::RepeatedSamples
    )
}
