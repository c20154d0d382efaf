//! The repeated frames of the 4 kHz accelerometer mode.
//!
//! The FIFO is written at the sample rate (RM-MPU-9250A-00 register 25): for every 4 kHz
//! accelerometer sample to reach it the sample rate must be 8 kHz, and each accelerometer
//! sample is then written twice, in consecutive frames (PX4 src/drivers/imu/invensense/
//! mpu9250/MPU9250.cpp, `ProcessAccel`: "accel data is doubled in FIFO, but might be
//! shifted"; ArduPilot AP_InertialSensor_Invensense.cpp, `_accumulate_sensor_rate_sampling`).
//! After a FIFO reset the first frame may be either copy. [`Pairing`] finds the phase from
//! the data (the offset at which more neighbouring frames are equal), keeps the first copy of
//! each sample and checks that the second copy is identical: a mismatch means a corrupt or
//! misaligned frame (the sanity check ArduPilot applies to deep FIFO reads over I2C, and the
//! only one available without temperature in the frames).

/// Bytes of one accelerometer frame.
pub(crate) const FRAME: usize = 6;

/// The pairing state across reads.
#[derive(Debug, Clone, Default)]
pub(crate) struct Pairing {
    /// The first copy of the newest sample, when its second copy has not been seen yet.
    held: Option<[u8; FRAME]>,
    /// Whether the phase is known (false after a FIFO reset).
    in_phase: bool,
    /// The held frame may itself be a lone second copy (the phase was guessed from fewer than
    /// three frames): a different next frame is then a new sample, not a mismatch.
    tentative: bool,
}

impl Pairing {
    /// Forgets the phase (after a FIFO reset: the next frame may be either copy).
    pub(crate) fn reset(&mut self) {
        self.held = None;
        self.in_phase = false;
        self.tentative = false;
    }

    /// Goes through `frames` (whole 6-byte frames, oldest first) and calls `keep` with the
    /// index of each frame that is a new sample, and whether it is a lone second copy (its
    /// first copy was written one frame earlier, before a FIFO reset). Returns the index of
    /// the first frame that should have repeated its predecessor and does not; the frames from
    /// there on are not looked at.
    pub(crate) fn select(
        &mut self,
        frames: &[u8],
        mut keep: impl FnMut(usize, bool),
    ) -> Option<usize> {
        let n = frames.len() / FRAME;
        let frame = |i: usize| -> [u8; FRAME] {
            let mut f = [0; FRAME];
            f.copy_from_slice(&frames[i * FRAME..(i + 1) * FRAME]);
            f
        };
        let mut start = 0;
        if !self.in_phase && n > 0 && n < 3 {
            self.in_phase = true;
            self.tentative = true;
        } else if !self.in_phase && n > 0 {
            self.in_phase = true;
            let equal_at = |offset: usize| {
                (offset..n.saturating_sub(1))
                    .step_by(2)
                    .filter(|&i| frame(i) == frame(i + 1))
                    .count()
            };
            if equal_at(1) > equal_at(0) {
                // Frame 0 is the second copy of a sample whose first copy was reset away.
                keep(0, true);
                start = 1;
            }
        }
        for i in start..n {
            let f = frame(i);
            match self.held.take() {
                Some(first) if first == f => self.tentative = false,
                Some(_) if self.tentative => {
                    // The held frame was a lone second copy; this one starts a sample.
                    self.tentative = false;
                    keep(i, false);
                    self.held = Some(f);
                }
                Some(_) => {
                    self.reset();
                    return Some(i);
                }
                None => {
                    keep(i, false);
                    self.held = Some(f);
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frames(values: &[u8]) -> Vec<u8> {
        values.iter().flat_map(|&v| [v; FRAME]).collect()
    }

    fn kept(p: &mut Pairing, values: &[u8]) -> (Vec<usize>, Option<usize>) {
        let mut k = Vec::new();
        let bad = p.select(&frames(values), |i, _| k.push(i));
        (k, bad)
    }

    #[test]
    fn finds_the_phase_keeps_first_copies_and_carries_pairs_across_reads() {
        let mut p = Pairing::default();
        // Starts on a second copy: 1 | 2 2 | 3 3 | 4 (its copy comes in the next read).
        assert_eq!(kept(&mut p, &[1, 2, 2, 3, 3, 4]), (vec![0, 1, 3, 5], None));
        assert_eq!(kept(&mut p, &[4, 5, 5, 6]), (vec![1, 3], None));
        // Starts on a first copy.
        let mut p = Pairing::default();
        assert_eq!(kept(&mut p, &[1, 1, 2, 2, 3]), (vec![0, 2, 4], None));
    }

    #[test]
    fn a_second_copy_that_differs_is_reported() {
        let mut p = Pairing::default();
        assert_eq!(kept(&mut p, &[1, 1, 2, 9, 3, 3]), (vec![0, 2], Some(3)));
        // After the mismatch the phase is found again.
        assert_eq!(kept(&mut p, &[7, 8, 8, 9, 9]), (vec![0, 1, 3], None));
    }

    #[test]
    fn fewer_than_three_frames_after_a_reset_never_make_a_mismatch() {
        // A lone second copy, then the next sample's first copy, in a read of two.
        let mut p = Pairing::default();
        assert_eq!(kept(&mut p, &[1, 2]), (vec![0, 1], None));
        assert_eq!(kept(&mut p, &[2, 3, 3]), (vec![1], None));
        // A first copy and its repetition.
        let mut p = Pairing::default();
        assert_eq!(kept(&mut p, &[1]), (vec![0], None));
        assert_eq!(kept(&mut p, &[1, 2, 2]), (vec![1], None));
        // Once the phase is known, a differing second copy is a mismatch again.
        assert_eq!(kept(&mut p, &[3, 4]), (vec![0], Some(1)));
    }
}
