//! What an offline run knows of its input's ranges, and what it reports of the samples it did
//! not take at their word: the full-scale ranges (given on the command line, else inferred
//! from a text recording's samples stuck at its extreme, `ipc_types::stream::range`), the
//! clipped samples per axis and the implausible ones (`odometry::session::SessionStats`).

use std::path::Path;

use ipc_types::RawImuSample;
use ipc_types::stream::range::{self, AXES, Range, RangeSource, Ranges};
use odometry::clip::ClipStats;
use odometry::session::SessionStats;
use serde_json::json;

/// The ranges and trust options of `mems-odometry offline`.
#[derive(clap::Args)]
pub struct RangeArgs {
    /// The accelerometer's full-scale range, g (e.g. 2 for +-2 g): a reading at its end is
    /// clipped. Without it, a text recording's range is inferred from readings stuck at its
    /// extreme; an MCAP recording's samples carry their driver's flags.
    #[arg(long, value_name = "G")]
    accel_range_g: Option<f64>,
    /// The gyroscope's full-scale range, deg/s (e.g. 250), as `--accel-range-g`.
    #[arg(long, value_name = "DPS")]
    gyro_range_dps: Option<f64>,
    /// Integrate clipped and implausible samples as measured (they are still flagged and
    /// counted): the behaviour without the checks, for comparison.
    #[arg(long)]
    pub trust_clipped: bool,
    /// Bridge clipped runs only (widen the 1-sigma for what they hid) instead of
    /// reconstructing them once they have ended and predicting them again: for comparison.
    #[arg(long)]
    pub bridge_clipped: bool,
}

impl RangeArgs {
    /// The ranges given, with those a text recording's `samples` show for the others.
    pub fn ranges(&self, samples: Option<&[RawImuSample]>) -> anyhow::Result<Ranges> {
        for (name, v) in [
            ("--accel-range-g", self.accel_range_g),
            ("--gyro-range-dps", self.gyro_range_dps),
        ] {
            if v.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
                anyhow::bail!(
                    "{name} {}: not a full-scale range (a positive number)",
                    v.unwrap()
                );
            }
        }
        let mut ranges = Ranges {
            accel_g: Range::given(self.accel_range_g),
            gyro_dps: Range::given(self.gyro_range_dps),
        };
        let Some(samples) = samples else {
            return Ok(ranges);
        };
        let inferred = |value: Option<f64>| Range {
            value,
            source: value.map_or(RangeSource::Unknown, |_| RangeSource::Inferred),
        };
        if ranges.accel_g.value.is_none() {
            let axes: Vec<[f64; 3]> = samples.iter().map(|s| s.accel_g).collect();
            ranges.accel_g = inferred(range::infer_range(&axes, range::MIN_ACCEL_RANGE_G));
        }
        if ranges.gyro_dps.value.is_none() {
            let axes: Vec<[f64; 3]> = samples.iter().map(|s| s.gyro_dps).collect();
            ranges.gyro_dps = inferred(range::infer_range(&axes, range::MIN_GYRO_RANGE_DPS));
        }
        Ok(ranges)
    }
}

/// Marks `raw`'s axes at the end of `ranges` clipped.
pub fn mark(raw: &mut RawImuSample, ranges: &Ranges) {
    range::mark_clipped(raw, ranges.clipped_axes(raw));
}

/// The JSON fields: `ranges`, `clipped_samples`, `clipped_per_axis`, `clipped_runs`
/// (`reconstructed` and `bridged`, `odometry::clip`), `implausible_samples` and
/// `first_implausible` (seq, time from the first sample, s).
pub fn json(
    ranges: &Ranges,
    stats: &SessionStats,
    t0_ns: u64,
    clip: ClipStats,
) -> serde_json::Value {
    let per_axis: serde_json::Map<String, serde_json::Value> = AXES
        .iter()
        .zip(stats.clipped.per_axis)
        .map(|(a, n)| ((*a).to_string(), json!(n)))
        .collect();
    json!({
        "ranges": ranges,
        "clipped_samples": stats.clipped.samples,
        "clipped_per_axis": per_axis,
        "clipped_runs": json!({"reconstructed": clip.reconstructed, "bridged": clip.bridged}),
        "implausible_samples": stats.implausible,
        "first_implausible": stats.first_implausible.map(|(seq, t)| json!({
            "seq": seq,
            "t_s": t.saturating_sub(t0_ns) as f64 * 1e-9,
        })),
    })
}

/// What the run did with clipped and implausible samples (`--trust-clipped`,
/// `--bridge-clipped` or neither).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Treatment {
    /// Integrated as measured.
    Trusted,
    /// Bridged only: the 1-sigma widened for what they hid.
    Bridged,
    /// Bridged, and a clipped gyroscope's motion reconstructed at the rest after it.
    Reconstructed,
}

impl Treatment {
    /// The treatment `args` ask for.
    pub fn of(args: &RangeArgs) -> Self {
        if args.trust_clipped {
            Self::Trusted
        } else if args.bridge_clipped {
            Self::Bridged
        } else {
            Self::Reconstructed
        }
    }
}

/// Says on stderr which ranges the run used and what it did not take at its word.
pub fn report(input: &Path, ranges: &Ranges, stats: &SessionStats, t0_ns: u64, how: Treatment) {
    let input = input.display();
    for (name, unit, r) in [
        ("accelerometer", "g", ranges.accel_g),
        ("gyroscope", "deg/s", ranges.gyro_dps),
    ] {
        if let (Some(v), RangeSource::Inferred) = (r.value, r.source) {
            tracing::info!(
                "{input}: {name} range +-{v} {unit} inferred (readings stuck at the file's \
                 extreme); pass the range flag to state it"
            );
        }
    }
    let what = if how == Treatment::Trusted {
        "integrated as measured (--trust-clipped)"
    } else {
        "bridged as unobserved and counted in the 1-sigma"
    };
    if stats.clipped.samples > 0 {
        tracing::warn!(
            "{input}: {} samples clipped at the end of their range ({}); {}",
            stats.clipped.samples,
            stats.clipped.per_axis_text(),
            match how {
                Treatment::Trusted => what,
                Treatment::Bridged => {
                    "bridged and counted in the 1-sigma, not reconstructed (--bridge-clipped)"
                }
                Treatment::Reconstructed => {
                    "bridged and counted in the 1-sigma; a clipped gyroscope's motion \
                     reconstructed at the rest after it (unless --bridge-clipped; \
                     `clipped_runs` in --json)"
                }
            }
        );
    }
    if let Some((seq, t)) = stats.first_implausible {
        tracing::warn!(
            "{input}: {} samples beyond what the profile's platforms do (the first: seq {seq}, \
             t {:.3} s); {what}",
            stats.implausible,
            t.saturating_sub(t0_ns) as f64 * 1e-9
        );
    }
}
