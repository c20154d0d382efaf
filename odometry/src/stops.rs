//! What tells a wheeled platform's stop from its driving when its vibration does not: the
//! low-frequency part of the specific force and the angular rate.
//!
//! A car stopped with its engine running vibrates, but does not move. Its vibration is the
//! engine's: narrowband, at the firing frequency and its harmonics (an inline four-cylinder
//! engine's second order, twice the crankshaft's rate: 20-30 Hz at 600-900 rpm of idle), with
//! nothing below a few hertz, because the body stands on its tyres. Driving puts power where
//! standing has none: the road's undulations through the suspension (body modes at 1-2 Hz),
//! speed changes and steering. On the corpus's wid-car-06 (an Xsens DOT at 120 Hz; 1 s
//! windows, standard deviation of the three axes together, 10-90 %) the stop with the engine
//! running shows 52.1-55.4 mg in all against 41.9-45.6 mg standing at the start, so the
//! zero-state detector's scatter test calls it motion, but below 2 Hz it shows 0.7-2.0 mg, as
//! at the start (0.9-2.6 mg), against 10.3-42.3 mg while it drives. wid-car-10 is the other
//! way round: its engine shook it more standing (101-125 mg) than cruising (53-95 mg), so the
//! detector took stretches of its cruise for rest, while below 2 Hz the cruise shows
//! 10.6-38.5 mg against 0.5-2.2 mg standing. (The figures: `python3
//! tools/real-data/low_frequency.py`, with the spans of docs/odometry.md.)
//!
//! [`StopTest`] runs every channel through a second-order Butterworth low-pass at
//! [`CUTOFF_HZ`] (bilinear transform; an engine's 20 Hz leaks through at 1 %, aliased or
//! not, at 40 Hz and above) and keeps the spread of its output over the last second
//! ([`WINDOW_BLOCKS`] blocks of [`BLOCK_S`]): the variance summed over the three axes of the
//! accelerometer (m/s^2)^2 and of the gyroscope (rad/s)^2, and the gyroscope's mean. The
//! reference is the same spread, and the mean rate, over the standing before the platform's
//! first motion (it aligns standing): the median over its windows (the newest
//! [`REFERENCE_WINDOWS`] of them), not their mean, because a standing holds moments that are
//! no standing and that the detector may still flag rest (a door closed, someone getting in,
//! a creep of a few decimetres): on wid-car-10 of docs/real-data.md the car moves 0.4 m in
//! its first 6 s, which a 2 s GLRT window took for rest, and those 12 windows of 14-39 mg
//! below 2 Hz among 112 of 2-4 mg made the mean's reference 9.1 mg instead of 2.2 mg, so that
//! a smooth stretch of its cruise at 3.9 m/s was quiet and taken for a stop. The median of a
//! window's variance, a chi-squared of about 12 degrees of freedom (three axes, 2 Hz over
//! 1 s), lies 5 % below its mean: 3 % on the standard deviation. A window is *quiet* when both spreads are within
//! [`FACTOR`] times the reference's standard deviation (floored at [`FLOOR_ACCEL_MPS2`] and
//! [`FLOOR_GYRO_RPS`]), and its mean rate within [`TURN_RPS`] of the reference's (no steady
//! turn).
//!
//! That tells a stop from driving only where driving is never that quiet: a road's
//! undulations always show, a smooth floor's or a simulator's perfectly smooth road need not,
//! and there a cruise at constant speed is as quiet as a stop (the filter's velocity, whose
//! along-track 1-sigma grows between stops, refuses it only at first). So the test takes
//! windows for stops only where the platform's driving has been told from them: of its first
//! [`MIN_DRIVING_S`] of windows in motion, at most [`QUIET_DRIVING_SHARE`] quiet, decided
//! then once and for all ([`StopTest::driving_told`]; counted on, the windows it then takes
//! for stops would no longer count as driving's, and a simulated robot's cruise, quiet below
//! 2 Hz once its wheel's frequency is above it, was taken for stops). And only where an
//! engine runs: the platform stood before its first motion shaking by more than [`FACTOR`]
//! times the sensor's white noise at its rate (the profile's noise density; wid-car-06: 42-46
//! mg against 4 mg for the MPU-9250's datasheet density at 120 Hz), or its stops are no
//! different from its standing and the detector finds them (a simulated robot standing in
//! its sensor's noise alone, docs/odometry.md's wheeled-sim drives, took cruising at 1-2 m/s
//! for stops without this). The navigator
//! (`navigator::wheeled`) takes a quiet window the detector calls motion as a stop once the
//! windows have been quiet for a window's length ([`StopTest::quiet_for_s`]) and when the
//! filter's velocity does not contradict it (flagged `VIBRATING_STOP`), whatever the velocity
//! once they have been quiet for [`CERTAIN_S`], and refuses a rest the detector flags in a
//! window that is not quiet (flagged `REST_VIBRATING`).

use nalgebra::Vector3;

/// Cut-off of the low-pass, Hz: below a car's engine orders (20 Hz and above at idle) and
/// above its body's modes on the suspension (1-2 Hz).
pub const CUTOFF_HZ: f64 = 2.0;
/// Length of one block of the window, s.
pub const BLOCK_S: f64 = 0.25;
/// Blocks in the window (1 s): a body mode at 1 Hz completes a cycle in it.
pub const WINDOW_BLOCKS: usize = 4;
/// A window is quiet within this many times the standing reference's standard deviation: the
/// factor of the wheeled profile's vibration check (`profile::WHEELED_REST_VIBRATION_FACTOR`).
pub const FACTOR: f64 = 3.0;
/// Floor of the accelerometer reference's standard deviation, m/s^2 (1 mg: a quantised part
/// can show no variance at all standing).
pub const FLOOR_ACCEL_MPS2: f64 = 1e-3 * 9.80665;
/// Floor of the gyroscope reference's standard deviation, rad/s (0.05 deg/s).
pub const FLOOR_GYRO_RPS: f64 = 0.05 * std::f64::consts::PI / 180.0;
/// Standing windows the reference is the median of (the newest): 30 s of them.
pub const REFERENCE_WINDOWS: usize = 120;
/// Windows in motion the test must have seen before it tells a stop, s of windows.
pub const MIN_DRIVING_S: f64 = 30.0;
/// The largest share of windows in motion that may be quiet for the test to tell a stop:
/// wid-car-06 drives 43 s with 1 quiet window in 40 at most (the one at 40 s, 2.5 mg below
/// 2 Hz).
pub const QUIET_DRIVING_SHARE: f64 = 0.1;
/// Quiet for this long without a break, a stop is certain, s: the filter's velocity no longer
/// decides ([`StopTest::quiet_for_s`]). The corpus's two engine cars (wid-car-06 and -10, a
/// 2 Hz decision of 1 s windows) drive with at most 0.5 s of quiet in a row (wid-car-06
/// creeping to its stop at 0.3-0.5 m/s by its GNSS), and stand quiet for 1.8-44 s.
pub const CERTAIN_S: f64 = 2.0;
/// A window whose mean rate is further than this from the standing one turns, rad/s
/// (0.5 deg/s): a car in a steady turn turns at degrees a second (5 m/s on a 50 m radius:
/// 5.7 deg/s), a gyroscope's bias moves by hundredths of a degree a second between rests.
pub const TURN_RPS: f64 = 0.5 * std::f64::consts::PI / 180.0;

/// One channel's second-order Butterworth low-pass (direct form II transposed). Written here
/// rather than taken from the `biquad` crate: the filter must start (and restart, when the
/// sample interval changes) at the steady state of its input, which that crate's
/// `DirectForm2Transposed` cannot be set to; started from zero, a 2 Hz low-pass rings through
/// its first second with a gravity-sized step, and the standing reference would be learned
/// from the ringing.
#[derive(Debug, Clone, Copy, Default)]
struct Biquad {
    s1: f64,
    s2: f64,
}

/// The low-pass's coefficients at one sample interval.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Coefficients {
    dt_s: f64,
    b: [f64; 3],
    a: [f64; 2],
}

impl Coefficients {
    /// Butterworth at [`CUTOFF_HZ`] (at most 0.4 times the rate) by the bilinear transform
    /// with pre-warping.
    fn new(dt_s: f64) -> Self {
        let fc = CUTOFF_HZ.min(0.4 / dt_s);
        let k = (std::f64::consts::PI * fc * dt_s).tan();
        let q = std::f64::consts::FRAC_1_SQRT_2;
        let norm = 1.0 / (1.0 + k / q + k * k);
        let b0 = k * k * norm;
        Self {
            dt_s,
            b: [b0, 2.0 * b0, b0],
            a: [2.0 * (k * k - 1.0) * norm, (1.0 - k / q + k * k) * norm],
        }
    }
}

impl Biquad {
    /// Starts at the steady state of a constant input `x`.
    fn settle(&mut self, c: &Coefficients, x: f64) {
        self.s2 = (c.b[2] - c.a[1]) * x;
        self.s1 = (c.b[1] - c.a[0]) * x + self.s2;
    }

    fn step(&mut self, c: &Coefficients, x: f64) -> f64 {
        let y = c.b[0] * x + self.s1;
        self.s1 = c.b[1] * x - c.a[0] * y + self.s2;
        self.s2 = c.b[2] * x - c.a[1] * y;
        y
    }
}

/// Sums of one block of low-passed samples (accelerometer x, y, z, gyroscope x, y, z).
#[derive(Debug, Clone, Copy, Default)]
struct Block {
    n: f64,
    sum: [f64; 6],
    sum_sq: [f64; 6],
    duration_s: f64,
    /// Whether every sample of the block was flagged rest by the detector.
    rest: bool,
    /// Whether every sample of the block was taken as motion by the filter.
    moving: bool,
}

/// The low-frequency spread of one window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    /// Variance of the low-passed specific force, summed over the axes, (m/s^2)^2.
    pub accel: f64,
    /// The same for the angular rate, (rad/s)^2.
    pub gyro: f64,
    /// Mean low-passed angular rate, rad/s, sensor frame.
    pub gyro_mean: Vector3<f64>,
}

/// What the navigator knows of a sample for [`StopTest::push`].
#[derive(Debug, Clone, Copy, Default)]
pub struct PushFlags {
    /// The detector flagged the sample rest.
    pub rest: bool,
    /// The platform stands before its first motion: a window of rest joins the reference.
    pub learn: bool,
    /// The filter took the sample as motion.
    pub moving: bool,
}

/// The standing windows' spreads, the newest [`REFERENCE_WINDOWS`], and their medians.
#[derive(Debug, Clone, Copy)]
struct Standing {
    /// Per window: accelerometer and gyroscope spreads, the gyroscope's mean (x, y, z).
    windows: [[f64; 5]; REFERENCE_WINDOWS],
    len: usize,
    next: usize,
    /// The per-column medians of `windows` (`None` before the first).
    median: Option<[f64; 5]>,
}

impl Default for Standing {
    fn default() -> Self {
        Self {
            windows: [[0.0; 5]; REFERENCE_WINDOWS],
            len: 0,
            next: 0,
            median: None,
        }
    }
}

impl Standing {
    /// Adds a window and updates the medians.
    fn push(&mut self, window: [f64; 5]) {
        self.windows[self.next] = window;
        self.next = (self.next + 1) % REFERENCE_WINDOWS;
        self.len = (self.len + 1).min(REFERENCE_WINDOWS);
        let mut column = [0.0; REFERENCE_WINDOWS];
        self.median = Some(std::array::from_fn(|c| {
            let values = &mut column[..self.len];
            for (v, w) in values.iter_mut().zip(&self.windows) {
                *v = w[c];
            }
            values.sort_unstable_by(f64::total_cmp);
            let n = values.len();
            (values[(n - 1) / 2] + values[n / 2]) / 2.0
        }));
    }
}

/// The low-frequency test (module documentation).
#[derive(Debug, Clone, Copy, Default)]
pub struct StopTest {
    coef: Coefficients,
    lp: [Biquad; 6],
    block: Block,
    ring: [Block; WINDOW_BLOCKS],
    filled: usize,
    next: usize,
    /// The standing reference's windows.
    standing: Standing,
    /// The last full window's spread.
    window: Option<Spread>,
    /// Windows wholly in motion, and how many of them were quiet.
    driving: [u32; 2],
    /// How long the windows have been quiet without a break, s.
    quiet_s: f64,
}

impl StopTest {
    /// Adds a sample (specific force `f`, m/s^2; rate `w`, rad/s; sensor frame) taken `dt_s`
    /// after the previous one, with the detector's rest flag `rest`; `learn` while the
    /// platform stands before its first motion (a full window of rest then joins the
    /// standing reference); `moving` when the filter takes the sample as motion.
    pub fn push(&mut self, f: &Vector3<f64>, w: &Vector3<f64>, dt_s: f64, flags: PushFlags) {
        let PushFlags {
            rest,
            learn,
            moving,
        } = flags;
        let x = [f.x, f.y, f.z, w.x, w.y, w.z];
        if !(dt_s > 0.0 && dt_s.is_finite()) {
            return;
        }
        if (dt_s - self.coef.dt_s).abs() > 0.05 * self.coef.dt_s.max(dt_s) {
            self.coef = Coefficients::new(dt_s);
            for (lp, x) in self.lp.iter_mut().zip(x) {
                lp.settle(&self.coef, x);
            }
        }
        let b = &mut self.block;
        if b.n == 0.0 {
            b.rest = true;
            b.moving = true;
        }
        for (c, (lp, x)) in self.lp.iter_mut().zip(x).enumerate() {
            let y = lp.step(&self.coef, x);
            b.sum[c] += y;
            b.sum_sq[c] += y * y;
        }
        b.n += 1.0;
        b.duration_s += dt_s;
        b.rest &= rest;
        b.moving &= moving;
        if b.duration_s >= BLOCK_S {
            self.close_block(learn);
        }
    }

    /// Ends the block: it joins the window, the window's spread is computed, and a window
    /// of rest joins the reference when learning.
    fn close_block(&mut self, learn: bool) {
        self.ring[self.next] = std::mem::take(&mut self.block);
        self.next = (self.next + 1) % WINDOW_BLOCKS;
        self.filled = (self.filled + 1).min(WINDOW_BLOCKS);
        if self.filled < WINDOW_BLOCKS {
            return;
        }
        let n: f64 = self.ring.iter().map(|b| b.n).sum();
        let var = |c: usize| {
            let s: f64 = self.ring.iter().map(|b| b.sum[c]).sum();
            let ss: f64 = self.ring.iter().map(|b| b.sum_sq[c]).sum();
            ((ss - s * s / n) / (n - 1.0)).max(0.0)
        };
        let mean = |c: usize| self.ring.iter().map(|b| b.sum[c]).sum::<f64>() / n;
        let spread = Spread {
            accel: (0..3).map(var).sum(),
            gyro: (3..6).map(var).sum(),
            gyro_mean: Vector3::new(mean(3), mean(4), mean(5)),
        };
        self.window = Some(spread);
        let block_s = self.ring[(self.next + WINDOW_BLOCKS - 1) % WINDOW_BLOCKS].duration_s;
        self.quiet_s = match self.quiet() {
            Some(true) => self.quiet_s + block_s,
            _ => 0.0,
        };
        let undecided = f64::from(self.driving[0]) * BLOCK_S < MIN_DRIVING_S;
        if undecided
            && self.ring.iter().all(|b| b.moving)
            && let Some(quiet) = self.quiet()
        {
            self.driving[0] += 1;
            self.driving[1] += u32::from(quiet);
        }
        if learn && self.ring.iter().all(|b| b.rest) {
            let m = spread.gyro_mean;
            self.standing
                .push([spread.accel, spread.gyro, m.x, m.y, m.z]);
        }
    }

    /// The standing reference's spreads (accelerometer, gyroscope) and mean rate, the medians
    /// over its windows; `None` before a full window of rest was learned.
    pub fn reference(&self) -> Option<(f64, f64, Vector3<f64>)> {
        let [a, g, x, y, z] = self.standing.median?;
        Some((a, g, Vector3::new(x, y, z)))
    }

    /// The last full window's spread.
    pub fn window(&self) -> Option<Spread> {
        self.window
    }

    /// The sample rate the low-pass runs at, Hz (`None` before two samples).
    pub fn rate_hz(&self) -> Option<f64> {
        (self.coef.dt_s > 0.0).then(|| 1.0 / self.coef.dt_s)
    }

    /// Whether the platform's driving has been told from its stops (module documentation):
    /// of the first [`MIN_DRIVING_S`] of windows in motion, at most [`QUIET_DRIVING_SHARE`]
    /// quiet (decided once: the windows later taken for stops are not driving's).
    pub fn driving_told(&self) -> bool {
        let [n, quiet] = self.driving.map(f64::from);
        n * BLOCK_S >= MIN_DRIVING_S && quiet <= QUIET_DRIVING_SHARE * n
    }

    /// How long the windows have been quiet without a break, s (counted in blocks: the first
    /// quiet window counts its newest block).
    pub fn quiet_for_s(&self) -> f64 {
        self.quiet_s
    }

    /// Whether the last window is quiet (module documentation); `None` before a reference
    /// and a window.
    pub fn quiet(&self) -> Option<bool> {
        let (ref_a, ref_g, ref_w) = self.reference()?;
        let w = self.window?;
        let sd_a = ref_a.sqrt().max(FLOOR_ACCEL_MPS2);
        let sd_g = ref_g.sqrt().max(FLOOR_GYRO_RPS);
        let turning = (w.gyro_mean - ref_w).norm() > TURN_RPS;
        Some(w.accel.sqrt() <= FACTOR * sd_a && w.gyro.sqrt() <= FACTOR * sd_g && !turning)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(test: &mut StopTest, seconds: f64, learn: bool, signal: impl Fn(f64) -> f64) {
        let dt = 0.01;
        let mut t = 0.0;
        while t < seconds {
            let f = Vector3::new(signal(t), 0.0, 9.81);
            let flags = PushFlags {
                rest: learn,
                learn,
                moving: !learn,
            };
            test.push(&f, &Vector3::zeros(), dt, flags);
            t += dt;
        }
    }

    /// A 1 Hz body mode of 0.05 m/s^2 (5 mg): a road's undulations through the suspension.
    fn body_mode(t: f64) -> f64 {
        0.05 * (2.0 * std::f64::consts::PI * t).sin()
    }

    #[test]
    fn an_engine_tone_is_quiet_and_a_body_mode_is_not() {
        let mut test = StopTest::default();
        // Standing: a 2 mg ripple at 30 Hz.
        run(&mut test, 3.0, true, |t| {
            0.02 * (60.0 * std::f64::consts::PI * t).sin()
        });
        assert!(test.reference().is_some());
        // A 0.5 m/s^2 engine tone at 23 Hz: far above the standing, but no low frequency.
        run(&mut test, 2.0, false, |t| {
            0.5 * (46.0 * std::f64::consts::PI * t).sin()
        });
        assert_eq!(test.quiet(), Some(true));
        run(&mut test, 2.0, false, body_mode);
        assert_eq!(test.quiet(), Some(false));
    }

    #[test]
    fn a_jolt_the_detector_took_for_rest_leaves_the_standing_reference() {
        let mut test = StopTest::default();
        // 3 s of a 0.3 m/s^2 body mode (someone getting in) flagged rest, then 27 s of
        // standing: the mean of the windows' variances would make the reference's standard
        // deviation 7 mg, and a cruise's 5 mg body mode quiet.
        run(&mut test, 3.0, true, |t| 6.0 * body_mode(t));
        run(&mut test, 27.0, true, |_| 0.0);
        let (accel, _, _) = test.reference().expect("learned");
        assert!(accel.sqrt() < 1e-3, "{}", accel.sqrt());
        run(&mut test, 2.0, false, body_mode);
        assert_eq!(test.quiet(), Some(false));
    }

    #[test]
    fn the_reference_is_the_newest_standing() {
        let mut test = StopTest::default();
        run(&mut test, 40.0, true, |t| 6.0 * body_mode(t));
        run(&mut test, 40.0, true, |_| 0.0);
        let (accel, _, _) = test.reference().expect("learned");
        assert!(accel.sqrt() < 1e-3, "{}", accel.sqrt());
    }

    #[test]
    fn driving_is_told_from_stops_only_when_it_is_not_quiet() {
        let mut rough = StopTest::default();
        run(&mut rough, 3.0, true, |_| 0.0);
        run(&mut rough, 20.0, false, body_mode);
        assert!(!rough.driving_told(), "20 s of driving is too little");
        run(&mut rough, 12.0, false, body_mode);
        assert!(rough.driving_told());
        // A smooth road: as quiet as standing.
        let mut smooth = StopTest::default();
        run(&mut smooth, 3.0, true, |_| 0.0);
        run(&mut smooth, 40.0, false, |_| 0.0);
        assert!(!smooth.driving_told());
        // Decided once: rough driving after that does not change it.
        run(&mut smooth, 40.0, false, body_mode);
        assert!(!smooth.driving_told());
    }

    #[test]
    fn quiet_is_counted_without_a_break() {
        let mut test = StopTest::default();
        run(&mut test, 3.0, true, |_| 0.0);
        run(&mut test, 3.0, false, body_mode);
        assert_eq!(test.quiet_for_s(), 0.0);
        // The body mode leaves the 1 s window within a second of stopping.
        run(&mut test, 4.0, false, |_| 0.0);
        let quiet = test.quiet_for_s();
        assert!((2.5..=4.0).contains(&quiet), "{quiet}");
        run(&mut test, 1.0, false, body_mode);
        assert_eq!(test.quiet_for_s(), 0.0);
    }

    #[test]
    fn a_steady_turn_is_not_quiet() {
        let mut test = StopTest::default();
        run(&mut test, 3.0, true, |_| 0.0);
        let w = Vector3::new(0.0, 0.0, 0.02);
        for _ in 0..200 {
            test.push(
                &Vector3::new(0.0, 0.0, 9.81),
                &w,
                0.01,
                PushFlags::default(),
            );
        }
        assert_eq!(test.quiet(), Some(false));
    }

    #[test]
    fn the_low_pass_passes_a_constant() {
        let c = Coefficients::new(1.0 / 40.0);
        let mut lp = Biquad::default();
        lp.settle(&c, 3.0);
        assert!((lp.step(&c, 3.0) - 3.0).abs() < 1e-12);
    }
}
