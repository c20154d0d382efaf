//! Sample-time reconstruction for FIFO reads.
//!
//! The FIFO carries no timestamps: all the driver knows is that the samples are evenly spaced
//! at the device's output period, and, at each read, how many are waiting and when the count
//! was taken. The newest sample in the FIFO was produced within one period before the count
//! was latched, so `t_count_start - period / 2` is an unbiased but noisy (uniform, +-period/2)
//! observation of its time; read-scheduling latency adds more noise.
//!
//! The period is not the nominal one: the sample-rate generator runs on the gyro PLL or, with
//! the gyros in standby, on the internal oscillator, whose frequency varies by up to +-10 %
//! over temperature (PS-MPU-9250A-01 section 3.4.1, "Internal Clock Source": frequency
//! variation over temperature). The period is therefore *measured*, continuously, as the time
//! between two observations divided by the number of samples produced between them. The older
//! of the two is a reference that moves forward every [`WINDOW_NS`], so the baseline stays
//! between one and two windows long: long enough that the observation noise (a fraction of a
//! period) is a few ppm of it, short enough to follow the oscillator's drift with temperature
//! over hours. The estimate is bounded by the datasheet tolerance around the nominal period.
//!
//! The phase follows the observations through a proportional correction: each sample time is
//! the previous one plus the measured period, and each read's observation error moves the
//! times by a tenth of it, spread evenly over the samples of that read and bounded by a
//! quarter period, so times never go backwards and consecutive spacings stay within a few
//! percent of the period.
//!
//! Observations taken when the count read itself took unusually long (the thread was
//! preempted) are not used; the driver re-reads the count for a prompt one when such an
//! observation would be the anchor ([`SampleTimer::anchoring`]). Between two reads the FIFO cannot lose data without the driver
//! knowing (overflow is flagged), so an observation far from the prediction is treated as an
//! outlier (e.g. the device stopped, so its newest sample is old) and does not move the times;
//! only when several consecutive observations agree on it does the loop re-anchor. A known gap
//! (FIFO reset, re-initialisation) re-anchors the loop on the next observation (keeping the
//! measured period). Re-anchoring estimates how many samples were lost from the time that
//! passed.

/// Proportional gain of the phase loop, per read.
const KP: f64 = 0.1;
/// The period estimate stays within this fraction of the nominal period: the internal
/// oscillator's frequency variation over temperature, +-10 % (PS-MPU-9250A-01 section 3.4.1;
/// the gyro PLL, when a gyro is on, is within +-1 %, inside this band).
pub(crate) const CLOCK_TOLERANCE: f64 = 0.10;
/// The period reference moves forward after this much time, ns (the measured period's
/// baseline is one to two of these).
const WINDOW_NS: f64 = 30e9;
/// The period is measured only over at least this many samples (before that the nominal, or
/// previously measured, period is used): a baseline of 16 samples with +-period/2 observation
/// noise measures the period to about 3 %.
const MIN_BASELINE: u64 = 16;
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

/// An observation of the newest sample: its index in the stream since the last anchor, and
/// its observed time, ns.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Observation {
    index: u64,
    t_ns: f64,
}

/// The loop state; see the module documentation.
#[derive(Debug, Clone)]
pub(crate) struct SampleTimer {
    nominal_period_ns: f64,
    period_ns: f64,
    last_ns: Option<f64>,
    synced: bool,
    outliers: u32,
    /// Samples taken since the last anchor.
    taken: u64,
    /// The period's reference observation and the one that will replace it.
    reference: Option<Observation>,
    next_reference: Option<Observation>,
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
            taken: 0,
            reference: None,
            next_reference: None,
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

    /// Whether the next read anchors the times on its observation (a new stream, or after a
    /// gap or a period change).
    pub(crate) fn anchoring(&self) -> bool {
        !self.synced
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
        let (first_ns, step_ns, lost) = match self.last_ns {
            Some(last) if self.synced => {
                let p = self.period_ns;
                let err = newest_obs_ns - (last + available as f64 * p);
                let outlier = reliable && err.abs() > (OUTLIER_PERIODS * p).max(OUTLIER_MIN_NS);
                self.outliers = if outlier { self.outliers + 1 } else { 0 };
                if self.outliers >= OUTLIERS_TO_REANCHOR {
                    self.anchor(last, available, newest_obs_ns, reliable)
                } else {
                    let delta = if reliable && !outlier {
                        let observation = Observation {
                            index: self.taken + available as u64 - 1,
                            t_ns: newest_obs_ns,
                        };
                        self.measure_period(observation);
                        (KP * err).clamp(-p / 4.0, p / 4.0)
                    } else {
                        0.0
                    };
                    let step = self.period_ns + delta / take as f64;
                    (last + step, step, 0)
                }
            }
            Some(last) => self.anchor(last, available, newest_obs_ns, reliable),
            None => {
                let span = (available - 1) as f64 * self.period_ns;
                self.start_stream(available, newest_obs_ns, reliable);
                (newest_obs_ns - span, self.period_ns, 0)
            }
        };
        self.taken += take as u64;
        self.last_ns = Some(first_ns + (take - 1) as f64 * step_ns);
        Assignment {
            first_ns,
            step_ns,
            lost,
        }
    }

    /// Updates the period from an observation against the reference, and moves the reference
    /// forward once a window has passed.
    fn measure_period(&mut self, observation: Observation) {
        let Some(reference) = self.reference else {
            self.reference = Some(observation);
            return;
        };
        let samples = observation.index.saturating_sub(reference.index);
        if samples >= MIN_BASELINE {
            let bound = CLOCK_TOLERANCE * self.nominal_period_ns;
            self.period_ns = ((observation.t_ns - reference.t_ns) / samples as f64).clamp(
                self.nominal_period_ns - bound,
                self.nominal_period_ns + bound,
            );
        }
        match self.next_reference {
            None if observation.t_ns - reference.t_ns >= WINDOW_NS => {
                self.next_reference = Some(observation);
            }
            Some(next) if observation.t_ns - next.t_ns >= WINDOW_NS => {
                self.reference = Some(next);
                self.next_reference = Some(observation);
            }
            _ => {}
        }
    }

    /// Starts a new stream of sample indices at an anchor whose newest sample (index
    /// `available - 1`) is observed at `newest_obs_ns`.
    fn start_stream(&mut self, available: usize, newest_obs_ns: f64, reliable: bool) {
        self.synced = true;
        self.outliers = 0;
        self.taken = 0;
        self.next_reference = None;
        self.reference = reliable.then_some(Observation {
            index: available as u64 - 1,
            t_ns: newest_obs_ns,
        });
    }

    /// Re-anchors after a discontinuity: the oldest new sample is at the observation minus
    /// the span of the available samples, but never earlier than one period after the `last`
    /// sample; returns (first, step, lost).
    fn anchor(
        &mut self,
        last: f64,
        available: usize,
        newest_obs_ns: f64,
        reliable: bool,
    ) -> (f64, f64, u64) {
        let p = self.period_ns;
        let first_obs_ns = newest_obs_ns - (available - 1) as f64 * p;
        self.start_stream(available, newest_obs_ns, reliable);
        let first = first_obs_ns.max(last + p);
        let lost = ((first - last) / p).round() as u64 - 1;
        (first, p, lost)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Drives the timer with a device whose sample `k` is produced at `time(k)` ns (nominal
    /// period 250 us), reading every `read_every` ns for `reads` reads; returns (worst |time
    /// error| over the second half, worst over the whole run, min and max spacing).
    fn run_with(
        nominal: f64,
        time: impl Fn(u64) -> f64,
        read_every: f64,
        reads: usize,
    ) -> (f64, f64, f64, f64) {
        let mut timer = SampleTimer::new(nominal);
        let mut delivered = 0u64;
        let (mut worst_late, mut worst) = (0.0f64, 0.0f64);
        let (mut min_step, mut max_step) = (f64::MAX, f64::MIN);
        let mut prev: Option<f64> = None;
        let mut produced = 0u64;
        for r in 1..=reads {
            let now = r as f64 * read_every;
            while time(produced) <= now {
                produced += 1;
            }
            let available = (produced - delivered) as usize;
            if available == 0 {
                continue;
            }
            let a = timer.assign(available, available, now - nominal / 2.0, true);
            for i in 0..available {
                let t = a.first_ns + i as f64 * a.step_ns;
                let err = (t - time(delivered + i as u64)).abs();
                if let Some(p) = prev {
                    min_step = min_step.min(t - p);
                    max_step = max_step.max(t - p);
                }
                prev = Some(t);
                worst = worst.max(err);
                if r > reads / 2 {
                    worst_late = worst_late.max(err);
                }
            }
            delivered += available as u64;
            assert_eq!(a.lost, 0, "read {r}");
        }
        (worst_late, worst, min_step, max_step)
    }

    /// [`run_with`] for a device of constant period `true_p`, nominal 250 us.
    fn run(true_p: f64, read_every: f64, reads: usize) -> (f64, f64, f64) {
        let (worst, _, min_step, max_step) = run_with(
            250_000.0,
            |k| 123_456.0 + k as f64 * true_p,
            read_every,
            reads,
        );
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
    fn tracks_the_internal_oscillator_eight_percent_off_from_the_first_read() {
        // 1 kHz read every 4.5 ms, the part's clock 8 % slow and 8 % fast: never a false gap
        // (asserted in run_with), within 2 ms of the truth from the first sample, within a
        // quarter period once the period is measured.
        for rate_error in [-0.08, 0.08] {
            let true_p = 1_000_000.0 / (1.0 + rate_error);
            let (late, worst, _, _) = run_with(
                1_000_000.0,
                |k| 777.0 + k as f64 * true_p,
                4_500_000.0,
                4000,
            );
            assert!(worst < 2e6, "{rate_error}: worst error {worst} ns");
            assert!(late < 250_000.0, "{rate_error}: error {late} ns after 9 s");
        }
    }

    #[test]
    fn follows_an_oscillator_drifting_over_hours() {
        // The part's clock swings between 8 % fast and 8 % slow over two hours (a temperature
        // cycle): sample times stay within half a period of the truth throughout.
        let nominal = 1_000_000.0;
        let hour = 3600e9;
        let period =
            |t: f64| nominal / (1.0 + 0.08 * (2.0 * std::f64::consts::PI * t / (2.0 * hour)).sin());
        let mut times = vec![0.0];
        while *times.last().unwrap() < 2.0 * hour + 1e9 {
            let t = *times.last().unwrap();
            times.push(t + period(t));
        }
        let reads = (2.0 * hour / 4_500_000.0) as usize;
        let (late, worst, _, _) = run_with(nominal, |k| times[k as usize], 4_500_000.0, reads);
        assert!(worst < 2e6, "worst error {worst} ns");
        assert!(late < nominal / 2.0, "error {late} ns in the second hour");
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
