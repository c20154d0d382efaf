//! Innovation consistency: what the run's own innovations say of the filter's covariance
//! (covariance matching, innovation-based adaptive estimation: R. K. Mehra, "Approaches to
//! adaptive filtering", IEEE Trans. Automatic Control 17(5), 1972; A. H. Mohamed and K. P.
//! Schwarz, "Adaptive Kalman filtering for INS/GPS", Journal of Geodesy 73, 1999).
//!
//! Every update the filter makes has an innovation `nu` with predicted covariance `S`; the
//! normalized innovation squared `nu^T S^-1 nu` is chi-square with the update's degrees of
//! freedom (`dof`) when the covariance is consistent, so its mean is `dof`. Per update kind
//! (the zero-velocity update at rests, a speed hint, the IMU-only non-holonomic constraint)
//! an exponentially weighted sum of the NIS and of the dof is kept, with memory
//! [`ConsistencyConfig::memory_s`] seconds (weights `exp(-age / memory)`). Their ratio
//! `lambda_k` is the factor by which the innovations exceed their prediction. The window
//! counts as `n_eff = (sum w)^2 / sum w^2` innovations of the mean dof; under consistency the
//! weighted NIS sum scaled to `n_eff` is chi-square with `n_eff` times the mean dof degrees
//! of freedom. Only when that statistic lies beyond its `1 - significance` quantile is
//! `lambda_k` taken (else 1): the filter is overconfident by `lambda_k` with that
//! significance. The factor in force is the largest over the kinds; it holds until the next
//! update changes it. The test assumes white innovations, as a consistent filter's are;
//! innovations correlated by a model error count as more evidence than they hold, which
//! errs toward a larger factor, never a smaller one.
//!
//! How the factor is carried (module `eskf::reported` for why): by default in the published
//! 1-sigma only ([`Scaling::Report`]), multiplying the variance grown while it held;
//! [`Scaling::Process`] scales the process noise instead (measured against it in
//! docs/odometry.md); [`Scaling::Off`] ignores it.
//!
//! **False rests.** A zero-velocity window whose NIS, divided by the factor in force, lies
//! beyond the chi-square quantile of [`ConsistencyConfig::false_rest_significance`] (3 dof)
//! says the body was not at rest: it is not fed to the factor, and the rest is counted once
//! in `rests_inconsistent`. The update is still made (the estimate is what it would be
//! without this module); what it hides goes into the published 1-sigma. The two readings of
//! such a window, rest or motion as the IMU integrates it, differ by the velocity the update
//! removed; summed over the rest's inconsistent windows that is the velocity `u` (horizontal,
//! navigation frame, m/s) free integration would have had, and `d = sum u T_w` over their
//! spans `T_w` the displacement it would have added. The published variance of each
//! horizontal axis gets `d_i^2` (position) and `u_i^2` (velocity) for the rest (added as they
//! grow): the 1-sigma spans both readings. On a platform that cannot glide (a foot, a walker's
//! hand) the windows consistent with rest that follow add nothing: a stop detected late keeps
//! what the late windows removed, not a drift at that speed. On one that can
//! ([`ConsistencyConfig::false_rest_glides`]: a wheeled robot, a cart, an arm), the rest's
//! later windows are also what a cruise too smooth for the detector looks like once its
//! velocity has been removed: they carry the false rest's `u` on, `d += u T_w`, for the rest
//! of the rest (a robot at 0.3 m/s taken for rest over 2 s: 0.6 m, where the first window
//! alone gave 0.3 m/s times its span).
//!
//! Fixed-size state, no allocation: the stage's hot path runs it.

use statrs::distribution::{ChiSquared, ContinuousCDF};

use crate::eskf::Eskf;

/// How the innovation consistency enters the filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Scaling {
    /// Not at all (the filter's covariance as is).
    Off,
    /// In the published position and velocity 1-sigma only (estimates unchanged).
    Report,
    /// As a factor on the process noise (adaptive process noise: estimates change).
    Process,
}

/// Configuration of the innovation consistency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConsistencyConfig {
    /// How the factor enters.
    pub scaling: Scaling,
    /// Memory of the weighted NIS means, s.
    pub memory_s: f64,
    /// Significance of the chi-square test that takes a factor above 1.
    pub significance: f64,
    /// Significance of one zero-velocity window's chi-square test that calls a rest false.
    pub false_rest_significance: f64,
    /// Whether the platform can glide through a rest the detector cannot tell from a smooth
    /// cruise (wheels), so that a false rest's velocity is carried through the rest's later
    /// windows; not for a foot or a walker's hand, which cannot.
    pub false_rest_glides: bool,
}

impl Default for ConsistencyConfig {
    /// Report-only, 30 s of memory (several rests of a walk or a robot's stop-and-go, short
    /// against a recording), 1 % and 0.1 %, no glide (the profiles turn it on,
    /// `Profile::odometry`).
    fn default() -> Self {
        Self {
            scaling: Scaling::Report,
            memory_s: 30.0,
            significance: 0.01,
            false_rest_significance: 1e-3,
            false_rest_glides: false,
        }
    }
}

/// The update kinds whose innovations are tracked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Zero-velocity update at a rest (3 dof).
    ZeroVelocity = 0,
    /// Speed hint: forward speed, lateral and vertical body velocity (3 dof).
    Speed = 1,
    /// IMU-only non-holonomic constraint (2 dof: lateral and vertical).
    Nonholonomic = 2,
}

const KINDS: usize = 3;

/// Exponentially weighted sums of one kind's innovations.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Weighted {
    /// Time of the newest, ns.
    t_ns: u64,
    /// Sum of the weights and of their squares.
    w: f64,
    w2: f64,
    /// Weighted sums of the NIS and of the dof.
    nis: f64,
    dof: f64,
    /// Innovations taken.
    count: u64,
    /// The factor the sums support (1 unless significant).
    lambda: f64,
}

impl Weighted {
    fn push(&mut self, t_ns: u64, nis: f64, dof: f64, cfg: &ConsistencyConfig) {
        let age_s = t_ns.saturating_sub(self.t_ns) as f64 * 1e-9;
        let decay = if self.count == 0 {
            0.0
        } else {
            (-age_s / cfg.memory_s).exp()
        };
        self.t_ns = t_ns;
        self.w = self.w * decay + 1.0;
        self.w2 = self.w2 * decay * decay + 1.0;
        self.nis = self.nis * decay + nis;
        self.dof = self.dof * decay + dof;
        self.count += 1;
        let ratio = self.nis / self.dof;
        let n_eff = self.w * self.w / self.w2;
        let k = n_eff * self.dof / self.w;
        let significant = ChiSquared::new(k)
            .map(|chi2| chi2.sf(ratio * k) < cfg.significance)
            .unwrap_or(false);
        self.lambda = if significant { ratio.max(1.0) } else { 1.0 };
    }
}

/// What the innovations said so far (the stage's summary, the offline JSON).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ConsistencyReport {
    /// Factor in force on the published variance (or process noise), >= 1.
    pub lambda: f64,
    /// Largest factor in force at any time.
    pub lambda_max: f64,
    /// Per kind (zero-velocity, speed hint, non-holonomic): innovations taken and the
    /// weighted NIS over dof now.
    pub zero_velocity: KindReport,
    /// See `zero_velocity`.
    pub speed: KindReport,
    /// See `zero_velocity`.
    pub nonholonomic: KindReport,
    /// Rests with a zero-velocity window beyond the false-rest test.
    pub rests_inconsistent: u64,
    /// Zero-velocity windows beyond it.
    pub windows_inconsistent: u64,
}

impl std::fmt::Display for ConsistencyReport {
    /// One line: the factor, each kind's NIS per dof over its count, the false rests.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let k = |r: &KindReport| format!("{:.2} over {}", r.nis_per_dof, r.count);
        write!(
            f,
            "innovations (NIS per degree of freedom, 1 when the 1-sigma is honest): \
             zero-velocity {}, speed hints {}, non-holonomic {}; 1-sigma factor on the variance \
             now {:.2} (largest {:.2}); rests inconsistent with rest {} ({} windows), their \
             possible motion in the 1-sigma",
            k(&self.zero_velocity),
            k(&self.speed),
            k(&self.nonholonomic),
            self.lambda,
            self.lambda_max,
            self.rests_inconsistent,
            self.windows_inconsistent
        )
    }
}

/// One kind's figures.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct KindReport {
    /// Innovations taken.
    pub count: u64,
    /// Weighted NIS over weighted dof (1 when consistent), 0 before any.
    pub nis_per_dof: f64,
    /// The factor the test supports (1 unless significant).
    pub lambda: f64,
}

/// The current rest's false-rest evidence (horizontal, navigation frame).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct FalseRest {
    /// Whether the rest has been counted.
    counted: bool,
    /// Sum of the velocities its inconsistent windows removed, m/s.
    u: [f64; 2],
    /// Displacement free integration would have added over them, m.
    d: [f64; 2],
    /// Position and velocity variance added for it so far, m^2 and (m/s)^2 per axis.
    added_p: [f64; 2],
    added_v: [f64; 2],
}

/// Variance to add to the published 1-sigma, m^2 (position) and (m/s)^2 (velocity) per
/// horizontal axis.
pub type Widening = ([f64; 2], [f64; 2]);

impl FalseRest {
    /// Takes a window of `span_s` seconds that removed `removed` (m/s) into the motion the
    /// rest may hide; returns the variance to add.
    fn carry(&mut self, span_s: f64, removed: [f64; 2]) -> Widening {
        for ((u, d), removed) in self.u.iter_mut().zip(self.d.iter_mut()).zip(removed) {
            *u += removed;
            *d += *u * span_s;
        }
        let p = raise(&mut self.added_p, self.d.map(|d| d * d));
        let v = raise(&mut self.added_v, self.u.map(|u| u * u));
        (p, v)
    }
}

/// The increase from `added` to `target` (none when it shrinks), and `added` raised to it.
fn raise(added: &mut [f64; 2], target: [f64; 2]) -> [f64; 2] {
    std::array::from_fn(|i| {
        let add = (target[i] - added[i]).max(0.0);
        added[i] += add;
        add
    })
}

/// The tracker (fixed size, `Copy`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Consistency {
    cfg: ConsistencyConfig,
    kinds: [Weighted; KINDS],
    lambda_max: f64,
    /// Chi-square quantile (3 dof) of the false-rest test.
    false_rest_nis: f64,
    rest: FalseRest,
    rests_inconsistent: u64,
    windows_inconsistent: u64,
}

impl Consistency {
    /// A tracker with `cfg`.
    pub fn new(cfg: ConsistencyConfig) -> Self {
        let false_rest_nis = ChiSquared::new(3.0)
            .expect("3 dof")
            .inverse_cdf(1.0 - cfg.false_rest_significance);
        Self {
            cfg,
            kinds: [Weighted::default(); KINDS],
            lambda_max: 1.0,
            false_rest_nis,
            rest: FalseRest::default(),
            rests_inconsistent: 0,
            windows_inconsistent: 0,
        }
    }

    /// How the factor enters.
    pub fn scaling(&self) -> Scaling {
        self.cfg.scaling
    }

    /// The factor in force (>= 1): the largest the kinds support.
    pub fn lambda(&self) -> f64 {
        self.kinds.iter().fold(1.0, |m, k| m.max(k.lambda))
    }

    /// Takes one update's NIS with its degrees of freedom at `t_ns`; returns the factor now
    /// in force.
    pub fn push(&mut self, kind: Kind, t_ns: u64, nis: f64, dof: f64) -> f64 {
        if nis.is_finite() {
            self.kinds[kind as usize].push(t_ns, nis, dof, &self.cfg);
        }
        let lambda = self.lambda();
        self.lambda_max = self.lambda_max.max(lambda);
        lambda
    }

    /// A new rest starts (the false-rest evidence of the last one is closed).
    pub fn rest_started(&mut self) {
        self.rest = FalseRest::default();
    }

    /// Takes a zero-velocity window of `span_s` seconds at `t_ns` whose update had NIS `nis`
    /// and removed the horizontal velocity `removed` (m/s, navigation frame). Returns the
    /// variance to add to the published 1-sigma for a false rest (zeros for a consistent
    /// window) and the factor in force.
    pub fn zero_velocity(
        &mut self,
        t_ns: u64,
        nis: f64,
        span_s: f64,
        removed: [f64; 2],
    ) -> (Widening, f64) {
        if nis <= self.lambda() * self.false_rest_nis {
            let lambda = self.push(Kind::ZeroVelocity, t_ns, nis, 3.0);
            let glides = self.cfg.false_rest_glides && self.rest.counted;
            let widen = if glides {
                self.rest.carry(span_s, removed)
            } else {
                ([0.0; 2], [0.0; 2])
            };
            return (widen, lambda);
        }
        self.windows_inconsistent += 1;
        if !self.rest.counted {
            self.rest.counted = true;
            self.rests_inconsistent += 1;
        }
        (self.rest.carry(span_s, removed), self.lambda())
    }

    /// Takes the NIS of an update `kf` made (`None`: it made none) and sets the factor in
    /// force on it (unless [`Scaling::Off`]).
    pub fn update(&mut self, kf: &mut Eskf, kind: Kind, t_ns: u64, nis: Option<f64>, dof: f64) {
        if let Some(nis) = nis {
            let lambda = self.push(kind, t_ns, nis, dof);
            self.apply(kf, lambda, ([0.0; 2], [0.0; 2]));
        }
    }

    /// Takes the zero-velocity update `kf` made over a rest window (see
    /// [`Self::zero_velocity`]; `nis` `None`: it made none) and widens its published 1-sigma
    /// for a false rest (unless [`Scaling::Off`]).
    pub fn rest_window(
        &mut self,
        kf: &mut Eskf,
        t_ns: u64,
        nis: Option<f64>,
        span_s: f64,
        removed: [f64; 2],
    ) {
        if let Some(nis) = nis {
            let (widen, lambda) = self.zero_velocity(t_ns, nis, span_s, removed);
            self.apply(kf, lambda, widen);
        }
    }

    fn apply(&self, kf: &mut Eskf, lambda: f64, widen: Widening) {
        if self.cfg.scaling == Scaling::Off {
            return;
        }
        kf.set_consistency(lambda, self.cfg.scaling == Scaling::Process);
        kf.widen_reported(widen.0, widen.1);
    }

    /// What the innovations said so far.
    pub fn report(&self) -> ConsistencyReport {
        let kind = |k: Kind| {
            let w = &self.kinds[k as usize];
            KindReport {
                count: w.count,
                nis_per_dof: if w.dof > 0.0 { w.nis / w.dof } else { 0.0 },
                lambda: w.lambda.max(1.0),
            }
        };
        ConsistencyReport {
            lambda: self.lambda(),
            lambda_max: self.lambda_max,
            zero_velocity: kind(Kind::ZeroVelocity),
            speed: kind(Kind::Speed),
            nonholonomic: kind(Kind::Nonholonomic),
            rests_inconsistent: self.rests_inconsistent,
            windows_inconsistent: self.windows_inconsistent,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{ChiSquared as Chi2, Distribution};

    /// Feeds `n` NIS values of `dof`, `scale` times chi-square, 100 per second.
    fn feed(scale: f64, dof: f64, n: u64) -> Consistency {
        let mut c = Consistency::new(ConsistencyConfig::default());
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let chi2 = Chi2::new(dof).unwrap();
        for i in 0..n {
            c.push(
                Kind::Speed,
                i * 10_000_000,
                scale * chi2.sample(&mut rng),
                dof,
            );
        }
        c
    }

    #[test]
    fn consistent_innovations_keep_the_factor_at_one() {
        let c = feed(1.0, 3.0, 20_000);
        let r = c.report();
        assert!((r.speed.nis_per_dof - 1.0).abs() < 0.1, "{r:?}");
        // At 1 % significance a consistent filter is flagged about 1 % of the time.
        assert!(r.lambda < 1.15, "{r:?}");
    }

    #[test]
    fn ten_times_the_noise_gives_a_factor_of_a_hundred() {
        let r = feed(100.0, 2.0, 20_000).report();
        assert!((r.lambda / 100.0 - 1.0).abs() < 0.1, "{r:?}");
    }

    /// A walk at 1.4 m/s along x taken for rest: the first window removes the walk's
    /// velocity, the next ones what each window's acceleration added (here none); the
    /// widening is the displacement free integration would have made.
    #[test]
    fn a_false_rest_is_counted_once_and_widens_with_its_span() {
        let mut c = Consistency::new(ConsistencyConfig::default());
        c.rest_started();
        let ((p1, v1), _) = c.zero_velocity(0, 1e4, 0.01, [1.4, 0.0]);
        assert!((v1[0] - 1.4f64.powi(2)).abs() < 1e-12 && v1[1] == 0.0);
        let mut p = p1[0];
        for k in 1..100 {
            let ((pk, _), _) = c.zero_velocity(k * 10_000_000, 1e4, 0.01, [0.0, 0.0]);
            p += pk[0];
        }
        assert_eq!(c.report().rests_inconsistent, 1);
        assert_eq!(c.report().windows_inconsistent, 100);
        // One second of walking: 1.4 m.
        assert!((p - 1.4f64.powi(2)).abs() < 1e-9, "{p}");
        // A consistent window adds nothing and feeds the factor.
        let (w, _) = c.zero_velocity(2_000_000_000, 2.0, 0.01, [1e-3, 0.0]);
        assert_eq!(w, ([0.0; 2], [0.0; 2]));
        assert_eq!(c.report().zero_velocity.count, 1);
        c.rest_started();
        c.zero_velocity(3_000_000_000, 1e4, 0.01, [1.0, 0.0]);
        assert_eq!(c.report().rests_inconsistent, 2);
    }

    /// A robot cruising at 0.3 m/s taken for a 2 s rest: one inconsistent window removes its
    /// velocity, the 199 after it see none. A platform that glides carries the 0.3 m/s
    /// through them (0.6 m); a foot's rest does not (0.003 m, the first window's span).
    #[test]
    fn a_false_rest_of_a_gliding_platform_carries_its_velocity_through_the_rest() {
        let position_sigma = |glides: bool| {
            let cfg = ConsistencyConfig {
                false_rest_glides: glides,
                ..ConsistencyConfig::default()
            };
            let mut c = Consistency::new(cfg);
            c.rest_started();
            let mut p = 0.0;
            for k in 0..200 {
                let (nis, removed) = if k == 0 { (1e4, 0.3) } else { (1.0, 0.0) };
                let ((pk, _), _) = c.zero_velocity(k * 10_000_000, nis, 0.01, [removed, 0.0]);
                p += pk[0];
            }
            assert_eq!(c.report().windows_inconsistent, 1);
            // The consistent windows still feed the factor.
            assert_eq!(c.report().zero_velocity.count, 199);
            p.sqrt()
        };
        assert!((position_sigma(true) - 0.6).abs() < 1e-9);
        assert!((position_sigma(false) - 0.003).abs() < 1e-9);
        // A consistent rest adds nothing either way.
        let mut c = Consistency::new(ConsistencyConfig {
            false_rest_glides: true,
            ..ConsistencyConfig::default()
        });
        c.rest_started();
        let (w, _) = c.zero_velocity(0, 1.0, 0.01, [0.01, 0.0]);
        assert_eq!(w, ([0.0; 2], [0.0; 2]));
    }
}
