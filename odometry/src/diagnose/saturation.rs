//! The saturation candidate: the motions during which the gyro clipped, tested apart from the
//! others because no calibration term restores what a clip hid (the remedy is a wider range,
//! the driver's `GYRO_CONFIG` `FS_SEL`, or a reconstruction in the filter).
//!
//! Their tilt rows ([`Kind::ClippedTilt`]), with the effect the main selection fitted taken
//! out, are fitted with one rate per gyro axis that every clipped sample hid beyond the range
//! (rad/s, added with the sample's sign; `rows`): the rate a clip hides grows with the motion,
//! so one rate per axis is the mean over the run's clips, and what it leaves is reported. It
//! is scored held out, one clipped motion at a time, as the other candidates are
//! ([`super::fit`]), and found when its gain passes the threshold, some axis's rate is above
//! [`Settings::beyond_model`] of its own 1-sigma, and none is below minus that (a clip cannot
//! hide a rate of the opposite sign).

use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF};

use super::Settings;
use super::fit::Fit;
use super::rows::{Candidate, Kind, Row};

/// What the saturation candidate found.
#[derive(Debug, Clone, Serialize)]
pub struct Saturation {
    /// Motions between rests during which the gyro clipped.
    pub motions: usize,
    /// The gyro axes that clipped in them (x, y, z): the others' rates are not determined.
    pub clipped_axes: [bool; 3],
    /// Why it could not be tested, if so.
    pub untestable: Option<String>,
    /// Held-out chi-square gain.
    pub gain: f64,
    /// The rate each clipped sample hid beyond the range, rad/s per sensor axis (0 on an axis
    /// that never clipped).
    pub hidden_rps: [f64; 3],
    /// Its 1-sigma (0 on an axis that never clipped).
    pub sigma_rps: [f64; 3],
    /// Whether the data support it.
    pub found: bool,
    /// Rms of the clipped motions' tilt rows before the fit, rad.
    pub rms_before: f64,
    /// Rms after it (before, when not found).
    pub rms_after: f64,
    /// Rms their noise predicts, rad.
    pub rms_noise: f64,
    /// p-value of what remains on them (noise and the model's 1-sigma): below
    /// [`Settings::unexplained_p`], the clips hid more than one rate per axis describes.
    pub p_after: f64,
}

fn rms(x: impl ExactSizeIterator<Item = f64>) -> f64 {
    let n = x.len().max(1) as f64;
    (x.map(|v| v * v).sum::<f64>() / n).sqrt()
}

/// Tests saturation on the clipped rows of `all`, from which the main selection's effect
/// (`chosen`, fitted as `fitted`) is first taken out.
pub fn test(all: &[Row], chosen: &[Candidate], fitted: Option<&Fit>, s: &Settings) -> Saturation {
    let slot = |c: &Candidate| Candidate::ALL.iter().position(|a| a == c).unwrap_or(0);
    let clipped: Vec<Row> = all
        .iter()
        .filter(|r| r.kind == Kind::ClippedTilt)
        .cloned()
        .collect();
    let rows = super::without(&clipped, chosen, fitted);
    let mut groups: Vec<usize> = rows.iter().map(|r| r.group).collect();
    groups.dedup();
    // Axes that clipped: the parameters the rows determine.
    let clipped_axes: [bool; 3] = std::array::from_fn(|i| {
        rows.iter()
            .any(|r| r.design[slot(&Candidate::GyroSaturation)][i] != 0.0)
    });
    let axes = clipped_axes.iter().filter(|&&c| c).count();
    let needed = (axes * s.min_rows_per_param).div_ceil(2) + 1;
    let before = rms(rows.iter().map(|r| r.r));
    let mut out = Saturation {
        motions: groups.len(),
        clipped_axes,
        untestable: None,
        gain: 0.0,
        hidden_rps: [0.0; 3],
        sigma_rps: [0.0; 3],
        found: false,
        rms_before: before,
        rms_after: before,
        rms_noise: rms(rows.iter().map(|r| r.sigma)),
        p_after: 1.0,
    };
    let fit = (groups.len() >= needed.max(2))
        .then(|| super::fit::fit(&rows, &[Candidate::GyroSaturation]))
        .flatten();
    let Some(f) = fit else {
        out.untestable = Some(format!(
            "{} motions between rests with the gyro clipped (needs {})",
            groups.len(),
            needed.max(2)
        ));
        return out;
    };
    out.gain = f.gain;
    out.hidden_rps = std::array::from_fn(|i| f.theta[i]);
    out.sigma_rps = std::array::from_fn(|i| if clipped_axes[i] { f.sigma[i] } else { 0.0 });
    let (h, sd) = (out.hidden_rps, out.sigma_rps);
    out.found = f.gain > s.threshold
        && (0..3).any(|i| clipped_axes[i] && h[i] > s.beyond_model * sd[i])
        && (0..3).all(|i| !clipped_axes[i] || h[i] > -s.beyond_model * sd[i]);
    let after: Vec<f64> = if out.found {
        f.residuals.clone()
    } else {
        rows.iter().map(|r| r.r).collect()
    };
    out.rms_after = rms(after.iter().copied());
    let chi2: f64 = rows
        .iter()
        .zip(&after)
        .map(|(r, e)| e * e / (r.sigma.powi(2) + r.floor.powi(2)))
        .sum();
    let dof = rows
        .len()
        .saturating_sub(if out.found { axes } else { 0 })
        .max(1);
    out.p_after = ChiSquared::new(dof as f64).map_or(1.0, |d| d.sf(chi2));
    out
}
