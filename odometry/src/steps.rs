//! Steps of a walker in the specific-force magnitude, and their length (Weinberg's model):
//! what the hand-held walking mode ([`crate::walking`]) counts and the platform recognizer
//! ([`crate::platform`]) looks for.
//!
//! Method. `m = |f|` (m/s^2, specific force, any sensor frame: the magnitude needs no
//! attitude) is low-passed by two cascaded one-pole filters at [`STEP_LOWPASS_HZ`] (a
//! critically damped second-order low-pass: the step's bounce stays, the hand's tremor and a
//! phone's harmonics at 4-6 Hz go) and its baseline, a one-pole filter at
//! [`STEP_BASELINE_HZ`], is subtracted: `d = lp(m) - base(m)`, m/s^2. Each filter's gain is
//! `1 - exp(-2 pi fc dt)` with `dt` the sample's own interval, so the detector holds at any
//! rate. A step is one cycle of the bounce: `d` rises above `+`[`STEP_THRESHOLD_MPS2`], then
//! falls below `-`[`STEP_THRESHOLD_MPS2`]; it is counted at that fall, unless it comes within
//! [`STEP_MIN_INTERVAL_S`] of the previous step (a walker makes at most about 3 steps/s).
//! Its amplitude is the peak-to-peak of `d` over the cycle, `a_max - a_min`, m/s^2.
//!
//! A step is *in cadence* when it follows the previous one by [`CADENCE_S`] (1.25-2.9
//! steps/s: a walk, slow to brisk).
//!
//! Step length (H. Weinberg, "Using the ADXL202 in pedometer and personal navigation
//! applications", Analog Devices AN-602, 2002): `L = K (a_max - a_min)^(1/4)`, m, with the
//! amplitude in m/s^2 and `K` in m/(m/s^2)^(1/4) a constant of the walker and the carriage
//! (`crate::walking::WEINBERG_K` gives the one read off the corpus).

/// Cut-off of the step low-pass, Hz (two cascaded one-pole stages).
pub const STEP_LOWPASS_HZ: f64 = 3.0;
/// Cut-off of the baseline the bounce is measured from, Hz.
pub const STEP_BASELINE_HZ: f64 = 0.25;
/// Hysteresis of the step cycle, m/s^2: `d` above `+` this, then below `-` this. The Tyrex
/// phones held up for augmented reality bounce by 0.35-0.6 m/s^2 peak to peak (medians per
/// walk), held for texting by 0.7-1.8 m/s^2 (`tools/real-data/corpus.json`).
pub const STEP_THRESHOLD_MPS2: f64 = 0.08;
/// Steps closer than this are one, s.
pub const STEP_MIN_INTERVAL_S: f64 = 0.3;
/// Interval after the previous step of a step in cadence, s.
pub const CADENCE_S: (f64, f64) = (0.35, 0.8);

/// A detected step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step {
    /// Time it was counted (the bounce's fall below the threshold), ns.
    pub t_ns: u64,
    /// Time since the previous step, s; `None` for the first.
    pub interval_s: Option<f64>,
    /// Peak-to-peak of the filtered magnitude over the step, m/s^2.
    pub amplitude_mps2: f64,
}

impl Step {
    /// Whether it follows the previous step in a walking cadence ([`CADENCE_S`]).
    pub fn in_cadence(&self) -> bool {
        self.interval_s
            .is_some_and(|i| (CADENCE_S.0..=CADENCE_S.1).contains(&i))
    }

    /// Its length by Weinberg's model with constant `k`, m.
    pub fn length_m(&self, k: f64) -> f64 {
        k * self.amplitude_mps2.max(0.0).powf(0.25)
    }
}

/// The step detector of the module documentation: a few numbers, no allocation.
#[derive(Debug, Clone, Copy, Default)]
pub struct StepDetector {
    /// Time of the previous sample, ns; `None` before the first.
    prev_ns: Option<u64>,
    /// The two low-pass stages and the baseline, m/s^2.
    lp: [f64; 2],
    base: f64,
    /// Whether `d` has risen above the threshold in this cycle.
    risen: bool,
    /// Extremes of `d` over the cycle, m/s^2.
    high: f64,
    low: f64,
    last_step_ns: Option<u64>,
}

impl StepDetector {
    /// Takes one sample's specific-force magnitude `norm_mps2` at `t_ns` (increasing); returns
    /// the step it ends, if any.
    pub fn push(&mut self, t_ns: u64, norm_mps2: f64) -> Option<Step> {
        let Some(prev_ns) = self.prev_ns.replace(t_ns) else {
            self.lp = [norm_mps2; 2];
            self.base = norm_mps2;
            self.reset_cycle();
            return None;
        };
        let dt = t_ns.saturating_sub(prev_ns) as f64 * 1e-9;
        let gain = |fc: f64| 1.0 - (-2.0 * std::f64::consts::PI * fc * dt).exp();
        let a = gain(STEP_LOWPASS_HZ);
        self.lp[0] += a * (norm_mps2 - self.lp[0]);
        self.lp[1] += a * (self.lp[0] - self.lp[1]);
        self.base += gain(STEP_BASELINE_HZ) * (norm_mps2 - self.base);
        let d = self.lp[1] - self.base;
        self.high = self.high.max(d);
        self.low = self.low.min(d);
        if !self.risen {
            self.risen = d > STEP_THRESHOLD_MPS2;
            return None;
        }
        if d >= -STEP_THRESHOLD_MPS2 {
            return None;
        }
        let amplitude_mps2 = self.high - self.low;
        self.reset_cycle();
        let interval_s = self
            .last_step_ns
            .map(|l| t_ns.saturating_sub(l) as f64 * 1e-9);
        if interval_s.is_some_and(|i| i < STEP_MIN_INTERVAL_S) {
            return None;
        }
        self.last_step_ns = Some(t_ns);
        Some(Step {
            t_ns,
            interval_s,
            amplitude_mps2,
        })
    }

    /// Time of the last step, ns.
    pub fn last_step_ns(&self) -> Option<u64> {
        self.last_step_ns
    }

    fn reset_cycle(&mut self) {
        self.risen = false;
        self.high = f64::NEG_INFINITY;
        self.low = f64::INFINITY;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Steps of a bounce of `amp` m/s^2 peak to peak at `hz` steps/s, 100 Hz, for `s` seconds.
    fn walk(amp: f64, hz: f64, s: f64) -> Vec<Step> {
        let mut d = StepDetector::default();
        (0..(s * 100.0) as u64)
            .filter_map(|i| {
                let t = i as f64 * 0.01;
                let m = 9.81 + amp / 2.0 * (2.0 * std::f64::consts::PI * hz * t).sin();
                d.push(i * 10_000_000, m)
            })
            .collect()
    }

    #[test]
    fn a_walk_at_two_steps_per_second_gives_two_steps_per_second_in_cadence() {
        let steps = walk(1.0, 2.0, 20.0);
        assert!((38..=40).contains(&steps.len()), "{}", steps.len());
        assert!(steps.iter().skip(1).all(Step::in_cadence));
        // The two 3 Hz stages pass 1 / (1 + (2/3)^2) = 0.69 of a 2 Hz bounce (the baseline's
        // lag takes a little more).
        let amp = steps[10].amplitude_mps2;
        assert!((0.5..=0.72).contains(&amp), "{amp}");
        let l = steps[10].length_m(0.4);
        assert!((l - 0.4 * amp.powf(0.25)).abs() < 1e-12);
    }

    #[test]
    fn a_still_sensor_and_a_tremor_give_no_step() {
        assert!(walk(0.0, 2.0, 20.0).is_empty());
        assert!(walk(0.1, 2.0, 20.0).is_empty());
        // A 10 Hz buzz is filtered out.
        assert!(walk(1.0, 10.0, 20.0).is_empty());
    }
}
