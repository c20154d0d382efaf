//! The defects of real logs, applied to a simulated session row by row: a logger that polls
//! faster than the sensor (exact repeats of a row), host timestamps (Gaussian jitter, then
//! quantisation, e.g. to 1 ms, which produces equal timestamps), and where the recording starts
//! ([`peak_speed_time`]: in the middle of the first motion, with no rest before it).
//!
//! Each output row's time is the host timestamp, `stamps.sample_ns` (the only time such a log
//! holds); its truth is the truth of the measurement the row carries (at the instant the sensor
//! took it; a repeated row repeats its original's truth), with `Truth::t_ns` set to the row's
//! time so that rows and truth pair one to one. The host time of row `i` is
//! `max(host[i-1], t_i + jitter_i)` floored to the quantum: a logger stamps rows in the order
//! it reads them, so times never decrease, but they can be equal.

use ipc_types::RawImuSample;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use recording::Truth;

use crate::scenario::{Scenario, ScenarioError, ns_from_s};
use crate::{stream_rng, streams};

/// How a logger mangles the rows it writes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogDefects {
    /// Fraction of rows followed by an exact repeat (0-1): the logger polled again before the
    /// sensor had a new sample.
    pub repeat_fraction: f64,
    /// Whether a repeat carries its original's timestamp (`true`) or the time of the second
    /// poll (`false`: uniformly between the original and the next sample).
    pub repeat_same_time: bool,
    /// Standard deviation of the host timestamp jitter, s (Gaussian, >= 0).
    pub jitter_std_s: f64,
    /// Timestamp quantum, s (>= 0; 0 keeps whole nanoseconds): times floor to a multiple.
    pub quantum_s: f64,
}

impl LogDefects {
    /// No defect at all: every row as sampled.
    pub fn none() -> Self {
        Self {
            repeat_fraction: 0.0,
            repeat_same_time: false,
            jitter_std_s: 0.0,
            quantum_s: 0.0,
        }
    }

    /// Whether any defect is on.
    pub fn any(&self) -> bool {
        self.repeat_fraction > 0.0 || self.jitter_std_s > 0.0 || self.quantum_s > 0.0
    }

    fn validate(&self) -> Result<(), ScenarioError> {
        let err = |field: &str, reason: String| {
            Err(ScenarioError {
                field: field.into(),
                reason,
            })
        };
        let r = self.repeat_fraction;
        if !(0.0..=1.0).contains(&r) {
            return err("repeat_fraction", format!("must be in [0, 1], got {r}"));
        }
        for (field, x) in [
            ("jitter_std_s", self.jitter_std_s),
            ("quantum_s", self.quantum_s),
        ] {
            if !(x.is_finite() && x >= 0.0) {
                return err(field, format!("must be finite and >= 0, got {x}"));
            }
        }
        Ok(())
    }
}

/// A logger writing rows with [`LogDefects`]: feed it the session's rows in order.
pub struct Logger {
    defects: LogDefects,
    period_s: f64,
    rng: ChaCha8Rng,
    last_ns: u64,
}

impl Logger {
    /// A logger of a session sampled at `rate_hz`, its random choices drawn from `seed`.
    pub fn new(defects: &LogDefects, rate_hz: f64, seed: u64) -> Result<Self, ScenarioError> {
        defects.validate()?;
        Ok(Self {
            defects: *defects,
            period_s: 1.0 / rate_hz,
            rng: stream_rng(seed, streams::LOG_DEFECTS),
            last_ns: 0,
        })
    }

    /// The host timestamp of a read at `t_s`, ns.
    fn host_ns(&mut self, t_s: f64) -> u64 {
        let d = &self.defects;
        let jitter = if d.jitter_std_s > 0.0 {
            d.jitter_std_s * self.rng.sample::<f64, _>(StandardNormal)
        } else {
            0.0
        };
        let mut ns = ns_from_s((t_s + jitter).max(0.0)).max(self.last_ns);
        if d.quantum_s > 0.0 {
            let q = ns_from_s(d.quantum_s).max(1);
            ns = ns / q * q;
        }
        self.last_ns = ns;
        ns
    }

    /// Logs one sampled row (the sample at its true time `stamps.sample_ns`, its truth at that
    /// time): emits it with its host time and, for a fraction of rows, an exact repeat.
    pub fn log(
        &mut self,
        sample: RawImuSample,
        truth: Truth,
        mut emit: impl FnMut(RawImuSample, Truth),
    ) {
        let t_s = sample.stamps.sample_ns as f64 * 1e-9;
        let ns = self.host_ns(t_s);
        let row = |ns: u64| {
            let mut s = sample;
            s.stamps.sample_ns = ns;
            let mut t = truth;
            t.t_ns = ns;
            (s, t)
        };
        let (s, t) = row(ns);
        emit(s, t);
        let r = self.defects.repeat_fraction;
        if r > 0.0 && self.rng.random_bool(r) {
            let repeat_ns = if self.defects.repeat_same_time {
                ns
            } else {
                let poll = t_s + self.rng.random_range(0.0..1.0) * self.period_s;
                self.host_ns(poll)
            };
            let (s, t) = row(repeat_ns);
            emit(s, t);
        }
    }
}

/// The sample time (on the grid of `rate_hz`) of the highest speed in the first motion of
/// `scenario`, s: a start in motion, with no rest before it. `None` when the scenario never
/// moves.
pub fn peak_speed_time(scenario: &impl Scenario, rate_hz: f64) -> Option<f64> {
    let n = (scenario.duration_s() * rate_hz).floor() as u64;
    let mut best: Option<(f64, f64)> = None;
    for k in 0..=n {
        let t = k as f64 / rate_hz;
        let truth = scenario.truth(t);
        if truth.at_rest {
            if best.is_some() {
                break;
            }
            continue;
        }
        let v = truth.velocity_mps;
        let speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if best.is_none_or(|(s, _)| speed > s) {
            best = Some((speed, t));
        }
    }
    best.map(|(_, t)| t)
}
