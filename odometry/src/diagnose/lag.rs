//! The accelerometer lag removed from a stream of raw samples, as the diagnosis's rerun applies
//! it (`mems-odometry offline --accel-lag-s`): each sample's specific force is replaced by the
//! accelerometer's reading at the sample's time plus the lag (linear between the two samples
//! around it), so that it lines up with the gyro's rate of the same sample. The lag is in s,
//! positive when the accelerometer lags (the sample stamped `t` holds the specific force at
//! `t - lag`, `mems_sim::mounting`); a positive lag holds each sample back until the sample
//! after its time plus the lag has arrived. Only `accel_g` changes (the counts, flags and the
//! rest stay the sample's own: the calibration stage reads `accel_g`). Before the first
//! sample and after the last the nearest reading holds.

use std::collections::VecDeque;

use ipc_types::RawImuSample;

/// The largest lag the diagnosis accepts as a real part's, s: ten times the spread of the
/// MPU-9250's filter delays at its common settings (register map RM-MPU-9250A-00, 4.6 and
/// 4.8: 0.97-33.5 ms for the gyro, 1.88-32.5 ms for the accelerometer, 66.96 ms only at
/// A_DLPF_CFG 6), and the order of the offsets between separately stamped phone sensors.
pub const MAX_LAG_S: f64 = 0.1;

/// The lag's removal from a stream (module documentation).
#[derive(Debug)]
pub struct LagShift {
    lag_ns: i64,
    /// The samples read and still needed, oldest first.
    buffer: VecDeque<RawImuSample>,
    /// Index in `buffer` of the next sample to release.
    next: usize,
}

impl LagShift {
    /// A shift by `lag_s` seconds (finite, within [`MAX_LAG_S`]; else an error naming it).
    pub fn new(lag_s: f64) -> Result<Self, String> {
        if !(lag_s.is_finite() && lag_s.abs() <= MAX_LAG_S) {
            return Err(format!(
                "accelerometer lag {lag_s} s: must be finite and within {MAX_LAG_S} s"
            ));
        }
        Ok(Self {
            lag_ns: (lag_s * 1e9).round() as i64,
            buffer: VecDeque::new(),
            next: 0,
        })
    }

    /// Takes the next sample read; hands the samples now ready to `ready`, in order (no
    /// allocation once the buffer has grown to the lag's span).
    pub fn push(&mut self, raw: RawImuSample, mut ready: impl FnMut(RawImuSample)) {
        self.buffer.push_back(raw);
        let newest = raw.stamps.sample_ns as i64;
        while self.next < self.buffer.len() {
            let t = self.buffer[self.next].stamps.sample_ns as i64;
            if newest < t + self.lag_ns {
                break;
            }
            ready(self.release());
        }
    }

    /// Hands the samples still held to `ready`, at the end of the stream.
    pub fn finish(&mut self, mut ready: impl FnMut(RawImuSample)) {
        while self.next < self.buffer.len() {
            ready(self.release());
        }
    }

    /// Releases the sample at `next` with its accelerometer reading moved by the lag, and
    /// drops the samples no later one needs.
    fn release(&mut self) -> RawImuSample {
        let mut s = self.buffer[self.next];
        let at = s.stamps.sample_ns as i64 + self.lag_ns;
        s.accel_g = self.reading_at(at);
        self.next += 1;
        // Later samples read at later times: what precedes the bracket of `at` goes.
        while self.next > 0
            && self.buffer.len() > 1
            && (self.buffer[1].stamps.sample_ns as i64) <= at
        {
            self.buffer.pop_front();
            self.next -= 1;
        }
        s
    }

    /// The accelerometer's reading at `at_ns`, linear between the samples around it.
    fn reading_at(&self, at_ns: i64) -> [f64; 3] {
        let t = |i: usize| self.buffer[i].stamps.sample_ns as i64;
        let last = self.buffer.len() - 1;
        if at_ns <= t(0) {
            return self.buffer[0].accel_g;
        }
        if at_ns >= t(last) {
            return self.buffer[last].accel_g;
        }
        let j = (0..last).find(|&j| t(j + 1) >= at_ns).unwrap_or(last - 1);
        let (a, b) = (&self.buffer[j], &self.buffer[j + 1]);
        let w = (at_ns - t(j)) as f64 / (t(j + 1) - t(j)).max(1) as f64;
        std::array::from_fn(|i| a.accel_g[i] + w * (b.accel_g[i] - a.accel_g[i]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples every 5 ms whose accelerometer x reads a ramp of 1 g/s, with its own time in
    /// the gyro's x (to check each keeps its own).
    fn ramp(n: u64) -> Vec<RawImuSample> {
        (0..n)
            .map(|k| {
                let mut s = RawImuSample {
                    seq: k,
                    accel_g: [k as f64 * 0.005, 0.0, 1.0],
                    gyro_dps: [k as f64, 0.0, 0.0],
                    ..RawImuSample::default()
                };
                s.stamps.sample_ns = 1_000_000_000 + k * 5_000_000;
                s
            })
            .collect()
    }

    fn shifted(lag_s: f64, input: &[RawImuSample]) -> Vec<RawImuSample> {
        let mut shift = LagShift::new(lag_s).unwrap();
        let mut out = Vec::new();
        for s in input {
            shift.push(*s, |r| out.push(r));
        }
        shift.finish(|r| out.push(r));
        out
    }

    #[test]
    fn each_sample_reads_the_force_at_its_time_plus_the_lag() {
        let input = ramp(100);
        for lag in [0.0, 0.012, -0.0075] {
            let out = shifted(lag, &input);
            assert_eq!(out.len(), input.len(), "lag {lag}");
            for (k, s) in out.iter().enumerate() {
                assert_eq!(s.seq, k as u64);
                assert_eq!(s.gyro_dps[0], k as f64);
                let t = k as f64 * 0.005 + lag;
                // Within the run the ramp is read exactly; beyond it the end holds.
                let want = t.clamp(0.0, 99.0 * 0.005);
                assert!(
                    (s.accel_g[0] - want).abs() < 1e-9,
                    "lag {lag} sample {k}: {}",
                    s.accel_g[0]
                );
            }
        }
    }

    #[test]
    fn a_positive_lag_holds_samples_back_only_as_long_as_it_needs() {
        let mut shift = LagShift::new(0.012).unwrap();
        let input = ramp(10);
        let ready: Vec<usize> = input
            .iter()
            .map(|s| {
                let mut n = 0;
                shift.push(*s, |_| n += 1);
                n
            })
            .collect();
        // 12 ms is 2.4 samples: the first is released with the fourth sample.
        assert_eq!(ready, [0, 0, 0, 1, 1, 1, 1, 1, 1, 1]);
        let mut held = 0;
        shift.finish(|_| held += 1);
        assert_eq!(held, 3);
    }

    #[test]
    fn lags_beyond_a_real_part_are_refused() {
        for lag in [f64::NAN, 0.2, -0.11] {
            assert!(LagShift::new(lag).is_err(), "{lag}");
        }
    }
}
