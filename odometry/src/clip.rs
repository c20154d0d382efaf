//! Reconstruction of what a clipped gyroscope hid, once the next rest has measured it.
//!
//! A clipped axis read the end of its range while the truth was beyond it
//! (`crate::untrusted` widens the 1-sigma for that while the clip lasts). On a foot the gyro
//! clips in every swing about the same axis with the same sign, so the unseen rotation builds
//! up step by step; bridged as a random error it ends far off. Its shape inside the clip is not
//! known: a curve through the neighbours alone (below) errs on the corpus's walks by about as
//! much as the excess it reconstructs (docs/input-checks.md). The rest that ends the motion
//! measures what it missed: gravity gives the tilt, and the foot's velocity is zero. So the
//! motion from the first clipped sample to that rest's first [`REST_WINDOW_S`] (the *rest
//! window*) is redone at the window's last sample, or where the rest ends if sooner; the
//! rest's updates wait for it (`ClipRepair::waiting`, `ClipRepair::rest_ended`):
//!
//! 1. At the first sample with a gyroscope axis clipped the filter is copied as it was before
//!    it (fixed size: no allocation); every sample from there goes into a ring of [`CAPACITY`]
//!    samples. The states published meanwhile are the bridged ones (flagged
//!    `odometry_flags::UNTRUSTED_INPUT`): a real-time reader is not told more than is known.
//! 2. At the end of the rest window each clipped stretch of each gyroscope axis (a *run*) gets a prior
//!    reconstruction: a cubic Hermite curve through the unclipped neighbours on either side
//!    (at each side a least-squares line through up to [`NEIGHBOURS`] readings gives value and
//!    slope), never below the reading (the range's end, with the reading's sign) and never
//!    beyond what the profile's manoeuvre reaches (`OdometryConfig::manoeuvre`, 1-sigma
//!    figures: a curve through steep sides of a long clip overshoots). Its excess over the
//!    reading is then scaled by what the rests after the earlier clips of the same axis and
//!    sign found of the curve's excess (`Learned`: the posterior's sum over the curve's, the
//!    older runs' shares decaying by [`LEARN_DECAY`] per run, within a factor [`LEARN_BOUND`]
//!    of 1): a foot's swings repeat, and the curve errs alike on like swings (with the true
//!    rotation in place of the posterior, the scale takes the curve's rms error on the
//!    corpus's walks from 0.44-1.03 of the hidden rotation to 0.24-0.44). Units are the
//!    filter's (rad/s, rad), axes the sensor's, after the gyro correction; time from the
//!    samples' intervals.
//! 3. Each run `j` then takes one unknown `d_j`, the integral of what the prior missed (rad,
//!    about the run's sensor axis), spread over the run in the shape of the prior's excess
//!    (uniform where the prior found none), with the prior 1-sigma
//!    `|prior excess integral| + FLOOR_FRACTION |reading| T` (`T` the run's length). The rest
//!    window measures them: its mean specific force, rotated by the attitude the motion
//!    predicts at its end, must point up (1-sigma [`TILT_SIGMA_RAD`] each horizontal axis) and
//!    the velocity at its end must be zero (1-sigma [`VELOCITY_SIGMA_MPS`] each axis). The `d_j` are the regularised
//!    least-squares solution (up to [`GAUSS_NEWTON_STEPS`] Gauss-Newton steps, each halved
//!    until the cost falls, the Jacobian by finite differences of [`Eskf::coast`], the nominal
//!    state's prediction). The tilt residual is the horizontal part of the window's mean
//!    specific force, rotated into the navigation frame (z up) and normalised: zero when level.
//! 4. The filter is restored from the copy and the motion predicted again with the readings
//!    reconstructed, sample by sample (so the specific force of the clipped interval is rotated
//!    by the corrected attitude); each run's posterior 1-sigma of `d_j` widens the tilt about
//!    the horizontal part of its axis, fully correlated through the run (`Eskf::clipped_tilt`; the
//!    heading share is item 5's, beside the filter); accelerometer clips
//!    among the samples are bridged again (`crate::untrusted`). The rest's updates follow as
//!    usual.
//!
//! 5. The rest measures tilt and velocity, not heading. The velocity sees the heading only
//!    through the swing's horizontal accelerations, which the clip's unknown shape corrupts: on
//!    the corpus's walks clipped at +-250 deg/s, compared with the same walks unclipped, the
//!    reconstructed steps are as long as the true ones (within about 1 cm on average) and the
//!    end error is the heading the motions with a clipped yaw-ish axis turned wrongly
//!    (docs/input-checks.md). So the heading each motion's unknowns turn (finite differences
//!    of the same prediction: the rotation about the vertical, navigation frame, rad per
//!    unknown) is given the variance those unknowns keep when known from their prior and the
//!    rest's tilt alone, `h^T (I + J_t^T J_t)^-1 h` (whitened: `J_t` the tilt rows of the
//!    Jacobian, `h` the heading per unknown). That heading error turns the path after the rest
//!    about the rest's position: the reported position 1-sigma carries it
//!    (`ClipRepair::unseen_heading_variance`, the variance `s psi^2 |p - p_rest|^2` across the
//!    path, summed over the motions as independent), as a consider parameter: the filter
//!    does not estimate it (given to the filter's heading instead, the rests' zero-velocity
//!    updates took it for a heading they measure and the corpus's walks ended further off).
//!
//! Accelerometer clips are only bridged: reconstructed this way (a heel strike's spike,
//! measured by the rest's zero velocity) the corpus's walks clipped at +-2 g ended no closer.
//!
//! A motion longer than the ring, with more than [`MAX_RUNS`] runs, or during which the filter
//! took anything but predictions (a speed hint, the wheeled constraint, a gap, an implausible
//! sample) keeps the bridging.

use ipc_types::raw_flags;
use nalgebra::{SMatrix, SVector, UnitQuaternion, Vector3};

use crate::config::OdometryConfig;
use crate::eskf::{Eskf, Imu, Nominal};
use crate::untrusted::{Untrusted, Verdict};

/// Longest motion (samples, from the first clipped one to the rest) that is reconstructed.
pub const CAPACITY: usize = 1024;
/// Readings each side's line takes.
pub const NEIGHBOURS: usize = 3;
/// Most runs (clipped stretches of one axis) in one motion that are reconstructed.
pub const MAX_RUNS: usize = 8;
/// Prior 1-sigma of a run's excess beyond the reconstruction, as a fraction of the reading
/// times the run's length (added to the reconstructed excess).
pub const FLOOR_FRACTION: f64 = 0.25;
/// The rest's first stretch whose mean specific force measures the tilt, s: the motion is
/// redone at its last sample (or where the rest ends, if sooner). The first rest sample alone
/// is the foot still settling from the heel strike: on the corpus's walks with their true rates
/// (`tools/real-data/clip_oracle.py`) its specific force lies 3.5-5 deg rms per horizontal axis
/// from the attitude those rates predict (12 deg on gdin-35), the mean of the first 0.1 s
/// (20 samples at 200 Hz) 0.9-2.4 deg.
pub const REST_WINDOW_S: f64 = 0.1;
/// 1-sigma of the tilt the rest window's mean specific force gives, rad, each horizontal axis
/// (2 deg: the scatter above).
pub const TILT_SIGMA_RAD: f64 = 0.035;
/// 1-sigma of the velocity at the rest window's last sample, m/s, each axis (0.1 m/s: the
/// same walks with their true rates end the window 0.05-0.12 m/s rms per axis from zero).
pub const VELOCITY_SIGMA_MPS: f64 = 0.1;

const SEQ: usize = NEIGHBOURS + CAPACITY;
/// The weight a learned run keeps per later run of its axis and sign (`Learned`).
pub const LEARN_DECAY: f64 = 0.8;
/// The learned scale stays within this factor of 1 (`Learned`).
pub const LEARN_BOUND: f64 = 4.0;
/// Most Gauss-Newton steps of the solve.
pub const GAUSS_NEWTON_STEPS: usize = 4;
/// Measurements: tilt (2), velocity (3).
const MEAS: usize = 5;
const NO_RUN: u8 = u8::MAX;
/// The `raw_flags::SATURATED_AXES` bits of the gyroscope's axes.
const GYRO_AXES: u16 =
    raw_flags::saturated_axis(3) | raw_flags::saturated_axis(4) | raw_flags::saturated_axis(5);
const ZERO: Imu = Imu {
    f: Vector3::new(0.0, 0.0, 0.0),
    w: Vector3::new(0.0, 0.0, 0.0),
};

/// One sample: the reading the filter took, its reconstruction, its interval, which axes
/// clipped, and per axis its run and the run's shape there (1/s).
#[derive(Debug, Clone, Copy)]
struct Entry {
    /// As read.
    m: Imu,
    /// Reconstructed (the reading on the axes that did not clip).
    fixed: Imu,
    dt: f64,
    /// `raw_flags::SATURATED_AXES` bits.
    clipped: u16,
    run: [u8; 6],
    shape: [f64; 6],
}

impl Default for Entry {
    fn default() -> Self {
        Self {
            m: ZERO,
            fixed: ZERO,
            dt: 0.0,
            clipped: 0,
            run: [NO_RUN; 6],
            shape: [0.0; 6],
        }
    }
}

impl Entry {
    fn new(m: &Imu, dt: f64, clipped: u16) -> Self {
        Self {
            m: *m,
            fixed: *m,
            dt,
            clipped,
            ..Self::default()
        }
    }

    /// Axis `i` of `m`: accelerometer x, y, z (m/s^2), gyroscope x, y, z (rad/s).
    fn axis(m: &Imu, i: usize) -> f64 {
        if i < 3 { m.f[i] } else { m.w[i - 3] }
    }

    fn axis_mut(m: &mut Imu, i: usize) -> &mut f64 {
        if i < 3 { &mut m.f[i] } else { &mut m.w[i - 3] }
    }

    fn clipped_on(&self, i: usize) -> bool {
        self.clipped & raw_flags::saturated_axis(i) != 0
    }

    /// The reconstruction with the runs' unknowns `d` added.
    fn with(&self, d: &[f64; MAX_RUNS]) -> Imu {
        let mut m = self.fixed;
        for (axis, run) in self.run.iter().enumerate() {
            if let Some(d) = d.get(usize::from(*run)) {
                *Entry::axis_mut(&mut m, axis) += d * self.shape[axis];
            }
        }
        m
    }
}

/// Counts of what `ClipRepair` did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ClipStats {
    /// Motions with clipped samples reconstructed at their rest.
    pub reconstructed: u64,
    /// Motions with clipped samples left bridged.
    pub bridged: u64,
}

/// A run's prior and posterior 1-sigma (rad or m/s), and what [`Learned`] takes from it.
#[derive(Debug, Clone, Copy, Default)]
struct Run {
    prior_sigma: f64,
    sigma: f64,
    /// Its gyroscope axis (0-2) and whether it clipped at the positive end.
    axis: usize,
    positive: bool,
    /// The curve's excess rotation before and after [`Learned`]'s scale, rad.
    curve: f64,
    scaled: f64,
}

/// How much of the curve's excess the rests found, per gyroscope axis and sign: a foot's
/// swings repeat, so the steps before tell how far the curve through a clip's sides errs
/// (module documentation, item 2). Sums over the reconstructed runs, each older run's share
/// decaying by [`LEARN_DECAY`].
#[derive(Debug, Clone, Copy, Default)]
struct Learned {
    /// Per axis and sign (negative, positive): the curves' excess and the posterior's, rad.
    sums: [[(f64, f64); 2]; 3],
}

impl Learned {
    /// The scale of the curve's excess about `axis` with sign `positive`: the posterior's
    /// sum over the curve's, within [`LEARN_BOUND`] and its inverse; 1 before any run.
    fn scale(&self, axis: usize, positive: bool) -> f64 {
        let (curve, post) = self.sums[axis][usize::from(positive)];
        if curve > 0.0 {
            (post / curve).clamp(1.0 / LEARN_BOUND, LEARN_BOUND)
        } else {
            1.0
        }
    }

    /// Takes a run with its posterior excess `post` (rad, at least zero).
    fn add(&mut self, run: &Run, post: f64) {
        let (curve, sum) = &mut self.sums[run.axis][usize::from(run.positive)];
        *curve = LEARN_DECAY * *curve + run.curve;
        *sum = LEARN_DECAY * *sum + post.max(0.0);
    }
}

/// The motion in progress and what it needs to be redone (see the module documentation).
#[derive(Clone)]
pub(crate) struct ClipRepair {
    /// The filter before the first clipped sample; `None` when no clip is pending.
    start: Option<Eskf>,
    /// The last unclipped samples before it, then the samples since.
    seq: [Entry; SEQ],
    /// Entries of `seq` in use.
    len: usize,
    /// The first entry of `seq` that is a sample (the ones before are filler).
    first: usize,
    /// The filter took something other than a prediction since, or the ring is full.
    spoiled: bool,
    /// The newest [`NEIGHBOURS`] unclipped samples, oldest first.
    before: [Entry; NEIGHBOURS],
    before_len: usize,
    runs: [Run; MAX_RUNS],
    n_runs: usize,
    learned: Learned,
    stats: ClipStats,
    /// The heading the reconstructed motions may have got wrong (module documentation, item 5).
    unseen: UnseenHeading,
    /// The heading variance the last solve left, rad^2.
    heading_var: f64,
    /// Rest samples recorded at the end of the motion (the rest window, [`REST_WINDOW_S`]).
    rest_n: usize,
    rest_s: f64,
}

impl Default for ClipRepair {
    fn default() -> Self {
        Self {
            start: None,
            seq: [Entry::default(); SEQ],
            len: 0,
            first: 0,
            spoiled: false,
            before: [Entry::default(); NEIGHBOURS],
            before_len: 0,
            runs: [Run::default(); MAX_RUNS],
            n_runs: 0,
            learned: Learned::default(),
            stats: ClipStats::default(),
            unseen: UnseenHeading::default(),
            heading_var: 0.0,
            rest_n: 0,
            rest_s: 0.0,
        }
    }
}

impl ClipRepair {
    /// Makes this a copy of `other` without allocating (only the entries in use are copied).
    pub fn copy_from(&mut self, other: &Self) {
        self.start.clone_from(&other.start);
        self.seq[..other.len].copy_from_slice(&other.seq[..other.len]);
        self.len = other.len;
        self.first = other.first;
        self.spoiled = other.spoiled;
        self.before = other.before;
        self.before_len = other.before_len;
        self.runs = other.runs;
        self.learned = other.learned;
        self.n_runs = other.n_runs;
        self.stats = other.stats;
        self.unseen = other.unseen;
        self.heading_var = other.heading_var;
        self.rest_n = other.rest_n;
        self.rest_s = other.rest_s;
    }

    /// The variance (m^2, navigation frame x, y) that the heading errors of the reconstructed
    /// motions so far add to the position `p` (module documentation, item 5).
    pub fn unseen_heading_variance(&self, p: &Vector3<f64>) -> [f64; 2] {
        self.unseen.position_variance(p)
    }

    /// What it did so far.
    pub fn stats(&self) -> ClipStats {
        self.stats
    }

    fn active(&self) -> bool {
        self.start.is_some()
    }

    /// Whether a motion waits for its rest window to be redone: the rest's updates wait too
    /// (the motion is redone by predictions alone), until [`Self::after_predict`] has redone it
    /// or [`Self::rest_ended`] is called.
    pub fn waiting(&self) -> bool {
        self.active() && self.rest_n > 0
    }

    /// Called before the prediction of a sample whose clipped axes are `clipped`: the first
    /// sample of a motion with a gyroscope axis clipped copies `kf` as it stands.
    pub fn before_predict(&mut self, kf: &Eskf, clipped: u16) {
        if clipped & GYRO_AXES == 0 || self.active() {
            return;
        }
        self.start.clone_from(&Some(kf.clone()));
        self.first = NEIGHBOURS - self.before_len;
        self.seq[..self.first].fill(Entry::default());
        self.seq[self.first..NEIGHBOURS].copy_from_slice(&self.before[..self.before_len]);
        self.len = NEIGHBOURS;
        self.spoiled = false;
        (self.rest_n, self.rest_s) = (0, 0.0);
    }

    /// The filter took an update (or a gap's widening) during this sample: the motion cannot
    /// be redone by predictions alone.
    pub fn spoil(&mut self) {
        if self.active() {
            self.spoiled = true;
        }
    }

    /// Called after the prediction (and the bridging's widening) of a sample with reading `m`,
    /// interval `dt` s and clipped axes `clipped`, `rest` when the filter takes it for rest:
    /// records it and, at the end of the rest window after clipped samples, redoes the motion
    /// on `kf`. Returns whether it did.
    pub fn after_predict(
        &mut self,
        kf: &mut Eskf,
        m: &Imu,
        dt: f64,
        clipped: u16,
        rest: bool,
        cfg: &OdometryConfig,
    ) -> bool {
        let e = Entry::new(m, dt, clipped);
        if clipped == 0 {
            if self.before_len == NEIGHBOURS {
                self.before.rotate_left(1);
                self.before_len -= 1;
            }
            self.before[self.before_len] = e;
            self.before_len += 1;
        }
        if !self.active() {
            return false;
        }
        if self.len == SEQ {
            self.spoiled = true;
        } else {
            self.seq[self.len] = e;
            self.len += 1;
        }
        if rest {
            self.rest_n += 1;
            self.rest_s += dt;
        }
        let window_open = rest && self.rest_s + 0.5 * dt < REST_WINDOW_S && self.len < SEQ;
        if (!rest || window_open) && !self.spoiled {
            return false;
        }
        self.redo(kf, cfg)
    }

    /// The rest that follows a motion ended before its window was full: the motion is redone
    /// on `kf` with the rest samples recorded. Call before the rest's updates are made and
    /// before the next sample's prediction. Returns whether it did.
    pub fn rest_ended(&mut self, kf: &mut Eskf, cfg: &OdometryConfig) -> bool {
        self.waiting() && self.redo(kf, cfg)
    }

    /// Redoes the motion recorded on `kf` (module documentation, items 2-4), or gives it up
    /// when spoiled or beyond [`MAX_RUNS`]. Returns whether it did.
    fn redo(&mut self, kf: &mut Eskf, cfg: &OdometryConfig) -> bool {
        // A spoiled motion is given up at once: the next clip may start afresh.
        let start = self.start.take().expect("a clip is pending");
        if self.spoiled || !self.reconstruct(cfg.manoeuvre.rate) {
            self.stats.bridged += 1;
            return false;
        }
        self.solve(&start);
        *kf = start;
        self.repredict(kf, cfg);
        self.stats.reconstructed += 1;
        true
    }

    /// Gives every clipped stretch of every axis its prior reconstruction, run and shape;
    /// `false` when there are more than [`MAX_RUNS`] runs.
    fn reconstruct(&mut self, reach: f64) -> bool {
        let mut t = [0.0; SEQ];
        for i in 1..self.len {
            t[i] = t[i - 1] + self.seq[i].dt;
        }
        self.n_runs = 0;
        for axis in 3..6 {
            let mut i = NEIGHBOURS;
            while i < self.len {
                if !self.seq[i].clipped_on(axis) {
                    i += 1;
                    continue;
                }
                let a = i;
                while i < self.len && self.seq[i].clipped_on(axis) {
                    i += 1;
                }
                if self.n_runs == MAX_RUNS {
                    return false;
                }
                self.prior(axis, a, i, &t, reach);
                self.n_runs += 1;
            }
        }
        true
    }

    /// The prior reconstruction of axis `axis` over the clipped entries `a..b` (times `t`, s,
    /// at most `reach` in magnitude; left as read when a side has fewer than two unclipped
    /// readings), recorded as run `n_runs` with its shape and prior 1-sigma.
    fn prior(&mut self, axis: usize, a: usize, b: usize, t: &[f64; SEQ], reach: f64) {
        let left = self.side(axis, (self.first..a).rev(), t);
        let right = self.side(axis, b..self.len, t);
        if let (Some((t0, y0, s0)), Some((t1, y1, s1))) = (left, right)
            && t1 > t0
        {
            let span = t1 - t0;
            for (e, t) in self.seq[a..b].iter_mut().zip(&t[a..b]) {
                let read = Entry::axis(&e.m, axis);
                let h = hermite((t - t0) / span, y0, s0 * span, y1, s1 * span);
                // Never below the range's end, never beyond the envelope: the reading's sign.
                let v = (h * read.signum()).clamp(read.abs(), reach.max(read.abs()));
                *Entry::axis_mut(&mut e.fixed, axis) = v * read.signum();
            }
        }
        let excess_of = |seq: &[Entry]| {
            seq.iter()
                .map(|e| (Entry::axis(&e.fixed, axis) - Entry::axis(&e.m, axis)).abs() * e.dt)
                .sum::<f64>()
        };
        let curve = excess_of(&self.seq[a..b]);
        // The curve's excess as the rests after the same foot's earlier clips found it.
        let positive = Entry::axis(&self.seq[a].m, axis) > 0.0;
        let scale = self.learned.scale(axis - 3, positive);
        for e in &mut self.seq[a..b] {
            let read = Entry::axis(&e.m, axis);
            let fixed = Entry::axis_mut(&mut e.fixed, axis);
            let v = (read.abs() + (*fixed - read).abs() * scale).min(reach.max(read.abs()));
            *fixed = v * read.signum();
        }
        let excess = excess_of(&self.seq[a..b]);
        let (mut floor, mut span) = (0.0, 0.0);
        for e in &self.seq[a..b] {
            floor += FLOOR_FRACTION * Entry::axis(&e.m, axis).abs() * e.dt;
            span += e.dt;
        }
        let run = self.n_runs;
        for e in &mut self.seq[a..b] {
            let read = Entry::axis(&e.m, axis);
            let own = (Entry::axis(&e.fixed, axis) - read).abs();
            let shape = if excess > 0.0 {
                own / excess
            } else {
                1.0 / span.max(1e-9)
            };
            e.run[axis] = run as u8;
            e.shape[axis] = shape * read.signum();
        }
        self.runs[run] = Run {
            prior_sigma: excess + floor,
            sigma: excess + floor,
            axis: axis - 3,
            positive,
            curve,
            scaled: excess,
        };
    }

    /// The line through up to [`NEIGHBOURS`] unclipped readings of `axis` at the entries
    /// `js` (nearest the stretch first, up to the first clipped one): (time of the nearest,
    /// value there, slope per s).
    fn side(
        &self,
        axis: usize,
        js: impl Iterator<Item = usize>,
        t: &[f64; SEQ],
    ) -> Option<(f64, f64, f64)> {
        let mut pts = [(0.0, 0.0); NEIGHBOURS];
        let mut n = 0;
        for j in js.take(NEIGHBOURS) {
            let e = &self.seq[j];
            if e.clipped_on(axis) {
                break;
            }
            pts[n] = (t[j], Entry::axis(&e.m, axis));
            n += 1;
        }
        let (t_near, _) = pts[0];
        let (value, slope) = line(&pts[..n], t_near)?;
        Some((t_near, value, slope))
    }

    /// The whitened residuals at the rest of the motion from `start` with the runs' unknowns
    /// `d`: tilt (the rest window's mean specific force, rotated, must point up) and velocity;
    /// and the attitude there.
    fn residuals(
        &self,
        start: &Eskf,
        d: &[f64; MAX_RUNS],
    ) -> (SVector<f64, MEAS>, UnitQuaternion<f64>) {
        let entries = &self.seq[NEIGHBOURS..self.len];
        let x: Nominal = start.coast(entries.iter().map(|e| (e.with(d), e.dt)));
        // The foot is still over the window: its mean specific force, rotated by the attitude
        // at the window's end.
        let window = &entries[entries.len() - self.rest_n.max(1)..];
        let f = window.iter().fold(Vector3::zeros(), |sum, e| sum + e.m.f) / window.len() as f64;
        let up = (x.q * (f - x.b_a)).normalize();
        let r = SVector::from([
            up.x / TILT_SIGMA_RAD,
            up.y / TILT_SIGMA_RAD,
            x.v.x / VELOCITY_SIGMA_MPS,
            x.v.y / VELOCITY_SIGMA_MPS,
            x.v.z / VELOCITY_SIGMA_MPS,
        ]);
        (r, x.q)
    }

    /// Solves for the runs' unknowns (module documentation, item 3), adds them to the
    /// reconstruction and keeps their posterior 1-sigma and the heading variance the rest's tilt
    /// leaves (item 5).
    fn solve(&mut self, start: &Eskf) {
        let n = self.n_runs;
        let sigma: [f64; MAX_RUNS] =
            std::array::from_fn(|j| if j < n { self.runs[j].prior_sigma } else { 0.0 });
        // Whitened unknowns z_j = d_j / prior sigma_j; the prior adds z to the residuals.
        let mut z = SVector::<f64, MAX_RUNS>::zeros();
        let mut cov = SMatrix::<f64, MAX_RUNS, MAX_RUNS>::identity();
        let d_of = |z: &SVector<f64, MAX_RUNS>| -> [f64; MAX_RUNS] {
            std::array::from_fn(|j| z[j] * sigma[j])
        };
        let cost = |r: &SVector<f64, MEAS>, z: &SVector<f64, MAX_RUNS>| {
            r.norm_squared() + z.norm_squared()
        };
        let (mut r0, mut q0) = self.residuals(start, &d_of(&z));
        self.heading_var = 0.0;
        for _ in 0..GAUSS_NEWTON_STEPS {
            let mut jac = SMatrix::<f64, MEAS, MAX_RUNS>::zeros();
            // Heading per unit of z_j: the rotation about the vertical (navigation frame).
            let mut heading = SVector::<f64, MAX_RUNS>::zeros();
            for j in 0..n {
                let mut zj = z;
                zj[j] += 1e-3;
                let (rj, qj) = self.residuals(start, &d_of(&zj));
                jac.set_column(j, &((rj - r0) / 1e-3));
                heading[j] = (qj * q0.inverse()).scaled_axis().z / 1e-3;
            }
            self.heading_var = tilt_only_variance(&jac, &heading);
            let a = jac.transpose() * jac + SMatrix::<f64, MAX_RUNS, MAX_RUNS>::identity();
            let Some(a_inv) = a.try_inverse() else {
                return;
            };
            cov = a_inv;
            let step = -(a_inv * (jac.transpose() * r0 + z));
            // Halved until the cost falls (the attitude makes the residuals far from linear).
            let mut scale = 1.0;
            let before = cost(&r0, &z);
            let accepted = loop {
                let zn = z + step * scale;
                let (rn, qn) = self.residuals(start, &d_of(&zn));
                if cost(&rn, &zn) < before {
                    break Some((zn, rn, qn));
                }
                scale /= 2.0;
                if scale < 1.0 / 16.0 {
                    break None;
                }
            };
            let Some((zn, rn, qn)) = accepted else {
                break;
            };
            (z, r0, q0) = (zn, rn, qn);
        }
        let d = d_of(&z);
        for e in &mut self.seq[NEIGHBOURS..self.len] {
            e.fixed = e.with(&d);
        }
        for (j, run) in self.runs[..n].iter_mut().enumerate() {
            run.sigma = sigma[j] * cov[(j, j)].max(0.0).sqrt();
            if run.curve > 0.0 {
                self.learned.add(run, run.scaled + d[j]);
            }
        }
    }

    /// Predicts the motion again on `kf` (restored to its start) with the reconstructed
    /// readings, widening for what they may still miss (module documentation, items 4 and 5);
    /// an accelerometer clip among them is bridged again (`crate::untrusted`).
    fn repredict(&mut self, kf: &mut Eskf, cfg: &OdometryConfig) {
        let mut sum = [0.0f64; MAX_RUNS];
        let mut accel = Untrusted::default();
        for e in &self.seq[NEIGHBOURS..self.len] {
            kf.predict(e.fixed, e.dt);
            let verdict = Verdict {
                implausible: false,
                clipped: e.clipped & !GYRO_AXES,
            };
            accel.widen(kf, &e.m, e.dt, verdict, cfg);
            let mut var = [0.0; 6];
            for (axis, var) in var.iter_mut().enumerate() {
                let j = usize::from(e.run[axis]);
                let Some(run) = self.runs[..self.n_runs].get(j) else {
                    continue;
                };
                let share = e.shape[axis].abs() * e.dt;
                let before = sum[j];
                sum[j] += run.sigma * share;
                *var = sum[j].powi(2) - before.powi(2);
            }
            // The tilt share only: the heading that share would turn is carried beside the
            // filter (`UnseenHeading`, module documentation, item 5); in the filter, the rest's
            // zero-velocity updates take it for a heading they measure: the corpus's walks with
            // their true rates, flagged clipped and widened about the whole axis, ended 0.3-30 m
            // off where unflagged they end 0.04-4.4 m off (`tools/real-data/clip_oracle.py`).
            if var.iter().any(|v| *v > 0.0) {
                kf.clipped_tilt(&var);
            }
        }
        self.unseen.add(self.heading_var, &kf.x.p);
    }
}

/// The variance (rad^2) of the heading `heading^T z` (`heading` per whitened unknown) with
/// the unknowns `z` known from their prior (identity) and the rest's tilt alone (the first two
/// rows of the whitened Jacobian `jac`): `heading^T (I + J_t^T J_t)^-1 heading`; the prior's
/// `heading^T heading` where that is singular.
fn tilt_only_variance(jac: &SMatrix<f64, MEAS, MAX_RUNS>, heading: &SVector<f64, MAX_RUNS>) -> f64 {
    let tilt = jac.fixed_rows::<2>(0);
    let info = tilt.transpose() * tilt + SMatrix::<f64, MAX_RUNS, MAX_RUNS>::identity();
    info.try_inverse().map_or(heading.norm_squared(), |c| {
        (heading.transpose() * c * heading)[0]
    })
}

/// Heading errors left by reconstructed motions, independent from motion to motion, each
/// turning the path after it about the position where it was made: motion `k` with heading
/// variance `s_k` (rad^2) at horizontal position `p_k` moves a later position `p` by
/// `d psi_k z x (p - p_k)`. Kept as the sums `sum s_k`, `sum s_k p_k` and `sum s_k p_k^2` (per
/// axis), so the variance at any `p` is a few products (no allocation).
#[derive(Debug, Clone, Copy, Default)]
struct UnseenHeading {
    s0: f64,
    s1: [f64; 2],
    s2: [f64; 2],
}

impl UnseenHeading {
    /// Adds a motion's heading variance `var` (rad^2), made at position `p` (m).
    fn add(&mut self, var: f64, p: &Vector3<f64>) {
        self.s0 += var;
        for i in 0..2 {
            self.s1[i] += var * p[i];
            self.s2[i] += var * p[i] * p[i];
        }
    }

    /// The variance (m^2) it adds to the x and y of position `p`: `sum s_k (p_y - p_k,y)^2` to
    /// x, `sum s_k (p_x - p_k,x)^2` to y.
    fn position_variance(&self, p: &Vector3<f64>) -> [f64; 2] {
        let along =
            |i: usize| (self.s0 * p[i] * p[i] - 2.0 * p[i] * self.s1[i] + self.s2[i]).max(0.0);
        [along(1), along(0)]
    }
}

/// The least-squares line through `pts` (time s, value): its value at `t_at` and its slope;
/// `None` for fewer than two points or all at one time.
fn line(pts: &[(f64, f64)], t_at: f64) -> Option<(f64, f64)> {
    if pts.len() < 2 {
        return None;
    }
    let n = pts.len() as f64;
    let (mt, my) = pts
        .iter()
        .fold((0.0, 0.0), |(a, b), (t, y)| (a + t / n, b + y / n));
    let (sty, stt) = pts.iter().fold((0.0, 0.0), |(a, b), (t, y)| {
        (a + (t - mt) * (y - my), b + (t - mt) * (t - mt))
    });
    if stt <= 0.0 {
        return None;
    }
    let slope = sty / stt;
    Some((my + slope * (t_at - mt), slope))
}

/// The cubic Hermite curve at `tau` in 0..1 from value `y0` with slope `m0` (per unit of
/// `tau`) to value `y1` with slope `m1`.
fn hermite(tau: f64, y0: f64, m0: f64, y1: f64, m1: f64) -> f64 {
    let (t2, t3) = (tau * tau, tau * tau * tau);
    (2.0 * t3 - 3.0 * t2 + 1.0) * y0
        + (t3 - 2.0 * t2 + tau) * m0
        + (-2.0 * t3 + 3.0 * t2) * y1
        + (t3 - t2) * m1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eskf::{NoiseModel, TH, align};
    use crate::profile::Profile;
    use nalgebra::UnitQuaternion;

    const G: f64 = 9.80665;

    #[test]
    fn hermite_through_a_parabola_is_the_parabola() {
        // y = 1 + 4 s (1 - s) on 0..1: value 1 at both ends, slopes +4 and -4.
        for s in [0.0, 0.25, 0.5, 0.9] {
            assert!((hermite(s, 1.0, 4.0, 1.0, -4.0) - (1.0 + 4.0 * s * (1.0 - s))).abs() < 1e-12);
        }
        let (value, slope) = line(&[(0.0, 1.0), (1.0, 3.0), (2.0, 5.0)], 2.0).unwrap();
        assert!((value - 5.0).abs() < 1e-12 && (slope - 2.0).abs() < 1e-12);
        assert!(line(&[(0.0, 1.0)], 0.0).is_none());
    }

    /// Sine of `kf`'s tilt: the horizontal length of its sensor z axis in the navigation frame.
    fn tilt(kf: &Eskf) -> f64 {
        (kf.x.q * Vector3::z()).xy().norm()
    }

    /// A sensor held level in place is turned about its axis `axis` (0 x, 2 z) by a rate pulse
    /// that peaks at 8 rad/s, clipped at 250 deg/s (4.36 rad/s), then turned back slowly
    /// (unclipped) and left at rest; the rest window's last sample ends the motion. Returns the
    /// repair, the filter repaired, the filter that integrated the readings as measured and
    /// the true angle at the end (rad, a few mrad from 0: the pulse's trapezoid sums).
    fn clipped_pulse(axis: usize) -> (ClipRepair, Eskf, Eskf, f64) {
        clipped_pulse_resting(axis, REST_WINDOW_S)
    }

    /// [`clipped_pulse`] with a rest of `rest_s` seconds: shorter than the rest window, the
    /// motion is redone where the rest ends ([`ClipRepair::rest_ended`]).
    fn clipped_pulse_resting(axis: usize, rest_s: f64) -> (ClipRepair, Eskf, Eskf, f64) {
        let cfg = Profile::Pedestrian.odometry(OdometryConfig::mpu9250(G));
        let noise = NoiseModel {
            accel_noise_density: 1e-3,
            gyro_noise_density: 1e-4,
            accel_bias_random_walk: 1e-5,
            gyro_bias_random_walk: 1e-6,
            vibration_accel_density_per_mps: 0.0,
            vibration_gyro_density_per_mps: 0.0,
        };
        let up = Vector3::new(0.0, 0.0, G);
        let (x, cov) = align(
            up,
            Vector3::zeros(),
            G,
            Vector3::repeat(0.01),
            Vector3::repeat(1e-4),
        );
        let level = Imu {
            f: up,
            w: Vector3::zeros(),
        };
        let (dt, limit) = (0.005, 250f64.to_radians());
        let (peak, pulse_s, back) = (8.0, 0.3, 2.0);
        let turned = 2.0 * peak * pulse_s / std::f64::consts::PI;
        let back_s = turned / back;
        let rate = |t: f64| {
            if t < pulse_s {
                peak * (std::f64::consts::PI * t / pulse_s).sin()
            } else if t < pulse_s + back_s {
                -back
            } else {
                0.0
            }
        };
        let about = Vector3::ith(axis, 1.0);
        let mut angle = 0.0;
        let mut repaired = Eskf::new(x, cov, G, noise, level);
        let mut measured = repaired.clone();
        let mut clip = ClipRepair::default();
        for _ in 0..10 {
            clip.after_predict(&mut repaired, &level, dt, 0, false, &cfg);
        }
        let steps = ((pulse_s + back_s) / dt).ceil() as usize + 2;
        let window = (rest_s / dt).round() as usize;
        for k in 1..steps + window {
            let t = k as f64 * dt;
            let w_true = rate(t);
            angle += 0.5 * (rate(t - dt) + w_true) * dt;
            let f = UnitQuaternion::from_scaled_axis(about * angle).inverse() * up;
            let clipped = if w_true.abs() > limit {
                raw_flags::saturated_axis(3 + axis)
            } else {
                0
            };
            let m = Imu {
                f,
                w: about * w_true.clamp(-limit, limit),
            };
            let rest = k >= steps;
            assert!(!clip.waiting() || rest, "waiting in motion at {k}");
            clip.before_predict(&repaired, clipped);
            repaired.predict(m, dt);
            measured.predict(m, dt);
            clip.after_predict(&mut repaired, &m, dt, clipped, rest, &cfg);
        }
        assert_eq!(clip.waiting(), rest_s + 0.5 * dt < REST_WINDOW_S);
        clip.rest_ended(&mut repaired, &cfg);
        assert!(!clip.waiting());
        assert!(angle.abs() < 0.005, "{angle}");
        assert_eq!(clip.stats().reconstructed, 1);
        (clip, repaired, measured, angle)
    }

    /// Pitched about x (horizontal when level): the clipped reading hides about 0.44 rad of
    /// the pulse; after the rest sample the repaired filter is level (as the truth), the one
    /// that integrated the readings as measured is not. The tilt measured the rotation, so the
    /// heading keeps almost none of its prior.
    #[test]
    fn the_rest_after_a_clipped_pulse_gives_back_what_it_hid() {
        let (clip, repaired, measured, pitch) = clipped_pulse(0);
        assert!(tilt(&measured) > 0.3, "as measured: {}", tilt(&measured));
        assert!(
            (tilt(&repaired) - pitch.abs()).abs() < 0.02,
            "repaired: {} against {pitch}",
            tilt(&repaired)
        );
        let prior = clip.runs[0].prior_sigma;
        assert!(
            clip.unseen.s0 < 0.01 * prior * prior,
            "heading variance {} against the prior's {}",
            clip.unseen.s0,
            prior * prior
        );
    }

    /// A rest of 3 samples, shorter than the window: the motion waits through it and is
    /// redone where it ends, from those samples' mean specific force, as level as the truth.
    #[test]
    fn a_rest_shorter_than_the_window_redoes_the_motion_where_it_ends() {
        let (_, repaired, measured, pitch) = clipped_pulse_resting(0, 0.015);
        assert!(tilt(&measured) > 0.3, "as measured: {}", tilt(&measured));
        assert!(
            (tilt(&repaired) - pitch.abs()).abs() < 0.03,
            "repaired: {} against {pitch}",
            tilt(&repaired)
        );
    }

    /// The widening after a reconstruction (`Eskf::clipped_tilt`) goes to the tilt only: about a sensor axis that is
    /// vertical nothing is added, about a horizontal one all of it, about one at 45 deg half
    /// (the attitude covariance's trace, rad^2).
    #[test]
    fn the_widening_takes_the_tilt_share_of_the_axis_only() {
        let (_, kf, _, _) = clipped_pulse(0);
        let trace = |kf: &Eskf| kf.cov.fixed_view::<3, 3>(TH, TH).trace();
        let widened = |q: UnitQuaternion<f64>, axis: usize| {
            let mut k = kf.clone();
            k.x.q = q;
            k.propagate();
            let before = trace(&k);
            let mut var = [0.0; 6];
            var[3 + axis] = 0.01;
            k.clipped_tilt(&var);
            trace(&k) - before
        };
        let level = UnitQuaternion::identity();
        assert!(widened(level, 2).abs() < 1e-15, "{}", widened(level, 2));
        assert!((widened(level, 0) - 0.01).abs() < 1e-12);
        let tipped = UnitQuaternion::from_scaled_axis(Vector3::x() * std::f64::consts::FRAC_PI_4);
        assert!(
            (widened(tipped, 2) - 0.005).abs() < 1e-12,
            "{}",
            widened(tipped, 2)
        );
    }

    /// The learned scale: 1 before any run; the posterior's excess over the curve's, older
    /// runs decaying; bounded.
    #[test]
    fn the_learned_scale_is_what_the_rests_found_of_the_curve() {
        let mut l = Learned::default();
        assert_eq!(l.scale(1, true), 1.0);
        let run = |curve| Run {
            axis: 1,
            positive: true,
            curve,
            ..Run::default()
        };
        l.add(&run(0.2), 0.1);
        assert!((l.scale(1, true) - 0.5).abs() < 1e-12);
        assert_eq!(l.scale(1, false), 1.0);
        assert_eq!(l.scale(0, true), 1.0);
        // (0.8 * 0.1 + 0.3) / (0.8 * 0.2 + 0.1)
        l.add(&run(0.1), 0.3);
        assert!((l.scale(1, true) - 0.38 / 0.26).abs() < 1e-12);
        l.add(&run(0.1), 10.0);
        assert_eq!(l.scale(1, true), LEARN_BOUND);
        // A posterior below the reading counts as no excess: the scale's lower bound.
        let mut l = Learned::default();
        l.add(&run(0.2), -0.1);
        assert_eq!(l.scale(1, true), 1.0 / LEARN_BOUND);
    }

    /// Turned about z (vertical when level): the rest's tilt and zero velocity cannot see the
    /// unknown, so the heading keeps its prior, and the position 1-sigma grows with the
    /// distance from the rest where it was made, across the path.
    #[test]
    fn a_clipped_turn_about_the_vertical_keeps_its_prior_in_the_heading() {
        let (clip, repaired, measured, _) = clipped_pulse(2);
        let yaw = |kf: &Eskf| (kf.x.q * Vector3::x()).y.atan2((kf.x.q * Vector3::x()).x);
        // The prior puts back some of what the clip hid (the curve through its sides).
        assert!(yaw(&measured) < -0.3, "as measured: {}", yaw(&measured));
        assert!(
            yaw(&repaired) > yaw(&measured),
            "repaired: {}",
            yaw(&repaired)
        );
        let prior = clip.runs[0].prior_sigma;
        let var = clip.unseen.s0;
        assert!(
            (var / (prior * prior) - 1.0).abs() < 0.1,
            "heading variance {var} against the prior's {}",
            prior * prior
        );
        let at = |x: f64, y: f64| clip.unseen_heading_variance(&Vector3::new(x, y, 0.0));
        let here = repaired.x.p;
        let [sx, sy] = at(here.x + 10.0, here.y);
        assert!(
            sx < 1e-9 && (sy / (100.0 * var) - 1.0).abs() < 1e-6,
            "{sx} {sy}"
        );
        let [sx, _] = at(here.x, here.y - 5.0);
        assert!((sx / (25.0 * var) - 1.0).abs() < 1e-6, "{sx}");
    }
}
