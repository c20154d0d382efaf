//! Sample-time reconstruction for FIFO reads.
//!
//! The FIFO carries no timestamps: all the driver knows is that the samples are evenly spaced
//! at the device's output period, and, at each read, how many are waiting and when the count
//! was taken. The newest sample in the FIFO was produced within one period before the count
//! was latched, so `t_count_start - period / 2` is an unbiased but noisy (uniform, +-period/2)
//! observation of its time; read-scheduling latency adds more noise. Stamping samples from
//! that observation directly would put the noise into every sample time, so a
//! second-order phase-locked loop (proportional phase correction plus a period estimate that
//! absorbs the device clock's tolerance) predicts each sample time from the previous one and
//! moves only slowly towards the observations. Each read's phase correction is spread evenly
//! over the samples of that read and bounded by a quarter period, so times never go backwards
//! and consecutive spacings stay within a few percent of the period.
//!
//! Observations taken when the count read itself took unusually long (the thread was
//! preempted) are not used for the loop. Between two reads the FIFO cannot lose data without
//! the driver knowing (overflow is flagged), so an observation far from the prediction is
//! treated as an outlier (e.g. the device stopped, so its newest sample is old) and does not
//! move the times; only when several consecutive observations agree on it does the loop
//! re-anchor. A known gap (FIFO reset, re-initialisation) re-anchors the loop on the next
//! observation. Re-anchoring estimates how many samples were lost from the time that passed.

/// Proportional gain of the phase loop, per read.
const KP: f64 = 0.1;
/// Integral (period) gain, per read; KP / (2 sqrt(KI)) = 1 gives critical damping.
const KI: f64 = 0.0025;
/// The period estimate stays within this fraction of the nominal period (the MPU-9250's clock
/// is specified to about +-1 %; a wider band leaves room for the internal oscillator).
const MAX_PERIOD_DEVIATION: f64 = 0.05;
/// An observation further than this many periods from the prediction is an outlier.
const OUTLIER_PERIODS: f64 = 4.0;
/// An observation further than this from the prediction, ns, is an outlier too (covers host
/// latency at high rates).
const OUTLIER_MIN_NS: f64 = 2e6;
/// This many consecutive outliers re-anchor the loop.
const OUTLIERS_TO_REANCHOR: u32 = 5;

/// Times assigned to the samples of one read: sample `i` (oldest first) is at
/// `first_ns + i * step_ns`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Assignment {
    /// Time of the oldest sample taken, ns.
    pub first_ns: f64,
    /// Spacing of the samples taken, ns.
    pub step_ns: f64,
    /// Samples estimated lost between the previous sample and this read's first one.
    pub lost: u64,
}

/// The loop state; see the module documentation.
#[derive(Debug, Clone)]
pub(crate) struct SampleTimer {
    nominal_period_ns: f64,
    period_ns: f64,
    last_ns: Option<f64>,
    synced: bool,
    outliers: u32,
}

impl SampleTimer {
    /// A timer for an output period of `period_ns`, with no sample seen yet.
    pub(crate) fn new(period_ns: f64) -> Self {
        Self {
            nominal_period_ns: period_ns,
            period_ns,
            last_ns: None,
            synced: false,
            outliers: 0,
        }
    }

    /// Starts over at a new nominal period, keeping the last sample time (so later times stay
    /// after it and the gap can be estimated).
    pub(crate) fn set_period(&mut self, period_ns: f64) {
        self.nominal_period_ns = period_ns;
        self.period_ns = period_ns;
        self.synced = false;
    }

    /// Marks a discontinuity: the next read re-anchors on its observation.
    pub(crate) fn resync(&mut self) {
        self.synced = false;
    }

    /// The current period estimate, ns.
    pub(crate) fn period_ns(&self) -> f64 {
        self.period_ns
    }

    /// Assigns times to the `take` oldest of `available` samples (`take <= available`,
    /// `available > 0`), where the newest available sample is observed at `newest_obs_ns`;
    /// `reliable` says whether the observation may steer the loop.
    pub(crate) fn assign(
        &mut self,
        take: usize,
        available: usize,
        newest_obs_ns: f64,
        reliable: bool,
    ) -> Assignment {
        debug_assert!(take >= 1 && take <= available);
        let p = self.period_ns;
        let span = (available - 1) as f64 * p;
        let (first_ns, step_ns, lost) = match self.last_ns {
            Some(last) if self.synced => {
                let err = newest_obs_ns - (last + available as f64 * p);
                let outlier = reliable && err.abs() > (OUTLIER_PERIODS * p).max(OUTLIER_MIN_NS);
                self.outliers = if outlier { self.outliers + 1 } else { 0 };
                if self.outliers >= OUTLIERS_TO_REANCHOR {
                    self.anchor(last, newest_obs_ns - span)
                } else {
                    let delta = if reliable && !outlier {
                        let bound = MAX_PERIOD_DEVIATION * self.nominal_period_ns;
                        self.period_ns = (p + KI * err / available as f64).clamp(
                            self.nominal_period_ns - bound,
                            self.nominal_period_ns + bound,
                        );
                        (KP * err).clamp(-p / 4.0, p / 4.0)
                    } else {
                        0.0
                    };
                    let step = p + delta / take as f64;
                    (last + step, step, 0)
                }
            }
            Some(last) => self.anchor(last, newest_obs_ns - span),
            None => {
                self.synced = true;
                (newest_obs_ns - span, p, 0)
            }
        };
        self.last_ns = Some(first_ns + (take - 1) as f64 * step_ns);
        Assignment {
            first_ns,
            step_ns,
            lost,
        }
    }

    /// Re-anchors after a discontinuity: the oldest new sample is at `first_obs_ns` but never
    /// earlier than one period after the `last` sample; returns (first, step, lost).
    fn anchor(&mut self, last: f64, first_obs_ns: f64) -> (f64, f64, u64) {
        self.synced = true;
        self.outliers = 0;
        let p = self.period_ns;
        let first = first_obs_ns.max(last + p);
        let lost = ((first - last) / p).round() as u64 - 1;
        (first, p, lost)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Drives the timer with a device whose true period is `true_p` (nominal 250 us) and reads
    /// every `read_every` ns; returns (worst |time error| after settling, min and max spacing).
    fn run(true_p: f64, read_every: f64, reads: usize) -> (f64, f64, f64) {
        let nominal = 250_000.0;
        let mut timer = SampleTimer::new(nominal);
        let t0 = 123_456.0; // first sample time
        let mut delivered = 0u64;
        let mut worst = 0.0f64;
        let (mut min_step, mut max_step) = (f64::MAX, f64::MIN);
        let mut prev: Option<f64> = None;
        for r in 1..=reads {
            let now = r as f64 * read_every;
            let produced = ((now - t0) / true_p).floor() as u64 + 1;
            let available = (produced - delivered) as usize;
            if available == 0 {
                continue;
            }
            let a = timer.assign(available, available, now - nominal / 2.0, true);
            for i in 0..available {
                let t = a.first_ns + i as f64 * a.step_ns;
                let truth = t0 + (delivered + i as u64) as f64 * true_p;
                if let Some(p) = prev {
                    min_step = min_step.min(t - p);
                    max_step = max_step.max(t - p);
                }
                prev = Some(t);
                if r > reads / 2 {
                    worst = worst.max((t - truth).abs());
                }
            }
            delivered += available as u64;
            assert_eq!(a.lost, 0);
        }
        (worst, min_step, max_step)
    }

    #[test]
    fn locks_to_exact_rate_with_bounded_error_and_smooth_spacing() {
        // Reads every 5.03 ms: the read phase walks over the sample grid.
        let (worst, min_step, max_step) = run(250_000.0, 5_030_000.0, 2000);
        assert!(worst < 125_000.0, "worst error {worst} ns");
        assert!(
            min_step > 0.9 * 250_000.0 && max_step < 1.1 * 250_000.0,
            "{min_step} {max_step}"
        );
    }

    #[test]
    fn tracks_a_device_clock_one_percent_fast() {
        let true_p = 250_000.0 / 1.01;
        let (worst, min_step, max_step) = run(true_p, 4_970_000.0, 3000);
        assert!(worst < 125_000.0, "worst error {worst} ns");
        assert!(
            min_step > 0.9 * true_p && max_step < 1.1 * true_p,
            "{min_step} {max_step}"
        );
    }

    #[test]
    fn gap_reanchors_and_counts_lost_samples() {
        let p = 1_000_000.0;
        let mut timer = SampleTimer::new(p);
        // 10 samples, newest at 9.5 ms + half a period of latch uncertainty.
        let a = timer.assign(10, 10, 9.0e6, true);
        assert_eq!((a.first_ns, a.step_ns, a.lost), (0.0, p, 0));
        timer.resync();
        // After the gap, 5 samples with the newest observed at 30 ms: first at 26 ms, so the
        // samples at 10..=25 ms (16 of them) were lost.
        let a = timer.assign(5, 5, 30.0e6, true);
        assert_eq!((a.first_ns, a.lost), (26.0e6, 16));
        // A resync whose observation would go backwards still moves forward by a period.
        timer.resync();
        let a = timer.assign(3, 3, 10.0e6, true);
        assert_eq!((a.first_ns, a.lost), (31.0e6, 0));
    }

    #[test]
    fn outliers_are_ignored_until_they_persist() {
        let p = 1_000_000.0;
        let mut timer = SampleTimer::new(p);
        timer.assign(4, 4, 3.0e6, true);
        // The device paused for 20 ms: its next sample looks 20 ms late. Not followed...
        for k in 0..OUTLIERS_TO_REANCHOR - 1 {
            let last = 3.0e6 + f64::from(k) * 2.0 * p;
            let a = timer.assign(2, 2, last + 2.0 * p + 20e6, true);
            assert_eq!((a.first_ns, a.step_ns, a.lost), (last + p, p, 0));
        }
        // ...until enough consecutive observations agree: then it re-anchors, counting the gap.
        let last = 3.0e6 + f64::from(OUTLIERS_TO_REANCHOR - 1) * 2.0 * p;
        let a = timer.assign(2, 2, last + 2.0 * p + 20e6, true);
        assert_eq!((a.first_ns, a.lost), (last + p + 20e6, 20));
        assert_eq!(timer.period_ns(), p);
    }

    #[test]
    fn unreliable_observations_do_not_steer() {
        let p = 1_000_000.0;
        let mut timer = SampleTimer::new(p);
        timer.assign(4, 4, 3.0e6, true);
        let a = timer.assign(4, 4, 50.0e6, false);
        assert_eq!((a.first_ns, a.step_ns, a.lost), (4.0e6, p, 0));
        assert_eq!(timer.period_ns(), p);
    }
}
