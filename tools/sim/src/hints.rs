//! Robot hints from a simulated drive: what the robot's controller would publish on
//! `mems/robot/hint` ([`RobotHint`]), derived from the drive's truth with a wheel-encoder model,
//! a commanded-motion model, latency and dropouts.
//!
//! Every `1 / rate_hz` seconds the controller reads its wheel encoders and publishes one hint
//! about the window that just ended:
//! - **forward speed**: the encoder ticks counted in the window (the forward path length
//!   `s(t) = integral of v` quantised to `tick_m`), times the tick length the controller
//!   believes in, which is off by the encoder's scale error `k` (wheel radius; drawn once per
//!   seed from N(0, `speed_scale_sigma`)), plus slip noise proportional to speed. The hint's
//!   time (`stamps.sample_ns`) is the window's midpoint, which the mean speed describes; its
//!   1-sigma is the per-hint part only (quantisation, the difference of two floor errors:
//!   `tick / (window sqrt(6))`, and slip), since the scale error is common to every hint;
//! - **yaw rate**: the true yaw rate at the midpoint plus white noise of `yaw_rate_noise_rps`;
//! - **stationary**, from one of two sources: `encoders` (no tick over the last
//!   `stationary_window_s`: the robot may creep by less than a tick in that time) or `commanded` (the controller's command, which leads the
//!   physical motion by `command_lead_s`: it says "moving" that long before the robot starts
//!   and "stationary" that long before it stops).
//!
//! The hint is published (`stamps.acquired_ns`) at the window's end plus a latency drawn
//! uniformly from `latency_s` (publication times never go backwards). Published hints are then
//! lost: each independently with probability `drop_fraction`, and all of them during bursts
//! (a Poisson process of `bursts_per_min`, each lasting `burst_s`). Sequence numbers count
//! published hints, so the receiver sees the losses as gaps.

use rand::Rng;
use rand_distr::{Distribution, Normal};

use ipc_types::{RobotHint, Stamps, hint_flags};

use crate::scenario::{Drive, ScenarioError, ns_from_s};
use crate::{stream_rng, streams};

/// Where the stationary flag of a hint comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RestSource {
    /// The controller's velocity command (zero commanded), leading the motion.
    Commanded,
    /// The wheel encoders (no tick counted in the window).
    Encoders,
}

/// Parameters of a simulated hint stream.
#[derive(Debug, Clone, PartialEq)]
pub struct HintParams {
    /// Hints per second (the encoder window is `1 / rate_hz`).
    pub rate_hz: f64,
    /// Source of the stationary flag.
    pub rest_source: RestSource,
    /// How long a velocity command precedes the physical start or stop, s.
    pub command_lead_s: f64,
    /// Publication latency after the window's end, drawn uniformly from `[min, max]`, s.
    pub latency_s: [f64; 2],
    /// Fraction of hints lost independently, in [0, 1].
    pub drop_fraction: f64,
    /// Loss bursts per minute (Poisson); every hint published during one is lost.
    pub bursts_per_min: f64,
    /// Length of each loss burst, drawn uniformly from `[min, max]`, s.
    pub burst_s: [f64; 2],
    /// Wheel travel per encoder tick, m.
    pub tick_m: f64,
    /// The encoders call the robot stationary when no tick was counted for this long, s (at
    /// least one window).
    pub stationary_window_s: f64,
    /// 1-sigma of the encoder's scale error (drawn once per seed), fraction.
    pub speed_scale_sigma: f64,
    /// Slip noise, 1-sigma as a fraction of the speed, per hint.
    pub speed_noise_fraction: f64,
    /// White noise of the yaw rate, 1-sigma, rad/s.
    pub yaw_rate_noise_rps: f64,
}

impl HintParams {
    /// A 50 Hz controller with encoder rest detection: 1024 ticks per revolution of a 0.1 m
    /// wheel (0.31 mm per tick, so 15 mm/s per tick and window), stationary after 0.1 s
    /// without a tick (below 3 mm/s), encoder scale error 1.5%
    /// (1-sigma), slip noise 0.5% of speed, yaw rate noise 0.5 deg/s, a command lead of 75 ms,
    /// latency 5-30 ms, 2% of hints lost and one loss burst of 0.2-2 s every two minutes.
    pub fn new(rest_source: RestSource) -> Self {
        Self {
            rate_hz: 50.0,
            rest_source,
            command_lead_s: 0.075,
            latency_s: [0.005, 0.030],
            drop_fraction: 0.02,
            bursts_per_min: 0.5,
            burst_s: [0.2, 2.0],
            tick_m: std::f64::consts::PI * 0.1 / 1024.0,
            stationary_window_s: 0.1,
            speed_scale_sigma: 0.015,
            speed_noise_fraction: 0.005,
            yaw_rate_noise_rps: 0.5_f64.to_radians(),
        }
    }

    fn validate(&self) -> Result<(), ScenarioError> {
        let err = |field: &str, reason: String| {
            Err(ScenarioError {
                field: field.into(),
                reason,
            })
        };
        let non_negative = |x: f64| x.is_finite() && x >= 0.0;
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0) {
            return err(
                "rate_hz",
                format!("must be finite and > 0, got {}", self.rate_hz),
            );
        }
        if !(self.tick_m.is_finite() && self.tick_m > 0.0) {
            return err(
                "tick_m",
                format!("must be finite and > 0, got {}", self.tick_m),
            );
        }
        for (field, [lo, hi]) in [("latency_s", self.latency_s), ("burst_s", self.burst_s)] {
            if !(non_negative(lo) && non_negative(hi) && lo <= hi) {
                return err(field, format!("needs 0 <= min <= max, got [{lo}, {hi}]"));
            }
        }
        if !(non_negative(self.drop_fraction) && self.drop_fraction <= 1.0) {
            return err(
                "drop_fraction",
                format!("must be in [0, 1], got {}", self.drop_fraction),
            );
        }
        for (field, x) in [
            ("command_lead_s", self.command_lead_s),
            ("stationary_window_s", self.stationary_window_s),
            ("bursts_per_min", self.bursts_per_min),
            ("speed_scale_sigma", self.speed_scale_sigma),
            ("speed_noise_fraction", self.speed_noise_fraction),
            ("yaw_rate_noise_rps", self.yaw_rate_noise_rps),
        ] {
            if !non_negative(x) {
                return err(field, format!("must be finite and >= 0, got {x}"));
            }
        }
        Ok(())
    }
}

/// A simulated hint stream and what was drawn for it.
#[derive(Debug, Clone, PartialEq)]
pub struct HintStream {
    /// The hints that arrive, in publication order.
    pub hints: Vec<RobotHint>,
    /// Hints published but lost.
    pub lost: usize,
    /// The encoder's scale error drawn for this seed, fraction.
    pub speed_scale: f64,
}

/// Whether the drive plan has the robot at rest at `t_s` (its rest segments; before the start
/// and after the end, at rest).
fn plan_at_rest(drive: &Drive, t_s: f64) -> bool {
    let segs = drive.segments();
    if t_s < 0.0 {
        return true;
    }
    let i = segs.partition_point(|s| s.start_s <= t_s).max(1) - 1;
    segs[i].at_rest || t_s >= drive.params().duration_s
}

/// Forward path length travelled over `[a, b]`, m (Simpson's rule on 16 intervals; the speed
/// profiles are smooth on the scale of an encoder window).
fn path_m(drive: &Drive, a: f64, b: f64) -> f64 {
    const N: usize = 16;
    let h = (b - a) / N as f64;
    let v = |t: f64| drive.body_motion(t.min(drive.params().duration_s)).0;
    let mut sum = v(a) + v(b);
    for i in 1..N {
        sum += v(a + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    sum * h / 3.0
}

/// The hints a controller publishes during `drive` (times `t0_s + t` on the sample clock, t in
/// seconds of the drive), with the random choices of stream `seed`.
pub fn drive_hints(
    drive: &Drive,
    params: &HintParams,
    seed: u64,
    t0_s: f64,
) -> Result<HintStream, ScenarioError> {
    params.validate()?;
    let mut rng = stream_rng(seed, streams::HINTS);
    let unit = Normal::new(0.0, 1.0).expect("unit normal");
    let speed_scale = params.speed_scale_sigma * unit.sample(&mut rng);
    let duration = drive.params().duration_s;
    let bursts = loss_bursts(params, duration, &mut rng);
    let mut controller = Controller::new(drive, params, speed_scale, t0_s);
    let count = (duration * params.rate_hz).floor() as u64;
    let mut hints = Vec::with_capacity(count as usize);
    let mut lost = 0;
    for k in 1..=count {
        let (hint, published_s) = controller.window(k, &mut rng, &unit);
        let in_burst = bursts.iter().any(|&(s, e)| (s..e).contains(&published_s));
        let dropped = rng.random::<f64>() < params.drop_fraction;
        if in_burst || dropped {
            lost += 1;
        } else {
            hints.push(hint);
        }
    }
    Ok(HintStream {
        hints,
        lost,
        speed_scale,
    })
}

/// The loss bursts over a drive of `duration` s, as (start, end) in s: a Poisson process of
/// `bursts_per_min`, each lasting a length drawn uniformly from `burst_s`.
fn loss_bursts(params: &HintParams, duration: f64, rng: &mut impl Rng) -> Vec<(f64, f64)> {
    let mut bursts: Vec<(f64, f64)> = Vec::new();
    if params.bursts_per_min > 0.0 {
        let mean_gap = 60.0 / params.bursts_per_min;
        let mut t = 0.0;
        loop {
            t += -mean_gap * (1.0 - rng.random::<f64>()).ln();
            if t >= duration {
                break;
            }
            let [lo, hi] = params.burst_s;
            let len = if hi > lo {
                rng.random_range(lo..=hi)
            } else {
                lo
            };
            bursts.push((t, t + len));
        }
    }
    bursts
}

/// The controller's encoder count and publication clock, from one window to the next.
struct Controller<'a> {
    drive: &'a Drive,
    params: &'a HintParams,
    /// Offset of the drive on the sample clock, s.
    t0_s: f64,
    /// The window, s.
    window: f64,
    /// The tick length the controller believes in, m.
    tick_believed: f64,
    /// Windows without a tick after which the encoders say "stationary".
    still_windows: u64,
    /// 1-sigma of a window's speed from the tick quantisation, m/s.
    quantisation_sigma: f64,
    /// Forward path travelled, m.
    path: f64,
    ticks_prev: i64,
    /// Windows since the last tick.
    since_tick: u64,
    /// The previous hint's publication time, ns.
    published_prev: u64,
}

impl<'a> Controller<'a> {
    fn new(drive: &'a Drive, params: &'a HintParams, speed_scale: f64, t0_s: f64) -> Self {
        let window = 1.0 / params.rate_hz;
        Self {
            drive,
            params,
            t0_s,
            window,
            tick_believed: params.tick_m * (1.0 + speed_scale),
            still_windows: ((params.stationary_window_s / window).round() as u64).max(1),
            quantisation_sigma: params.tick_m / (window * 6f64.sqrt()),
            path: 0.0,
            ticks_prev: 0,
            since_tick: u64::MAX,
            published_prev: 0,
        }
    }

    /// The hint of window `k` (1-based) and when it is published, s of the drive.
    fn window(&mut self, k: u64, rng: &mut impl Rng, unit: &Normal<f64>) -> (RobotHint, f64) {
        let (params, drive, window) = (self.params, self.drive, self.window);
        let (a, b) = ((k - 1) as f64 * window, k as f64 * window);
        self.path += path_m(drive, a, b);
        let ticks = (self.path / params.tick_m).floor() as i64;
        let counted = ticks - self.ticks_prev;
        self.ticks_prev = ticks;
        self.since_tick = if counted == 0 {
            self.since_tick.saturating_add(1)
        } else {
            0
        };
        let mid = 0.5 * (a + b);
        let (v_true, yaw_rate) = drive.body_motion(mid);
        let slip = params.speed_noise_fraction * v_true.abs();
        let speed = if counted == 0 {
            0.0
        } else {
            counted as f64 * self.tick_believed / window + slip * unit.sample(rng)
        };
        let [lo, hi] = params.latency_s;
        let latency = if hi > lo {
            rng.random_range(lo..=hi)
        } else {
            lo
        };
        let published = ns_from_s(self.t0_s + b + latency).max(self.published_prev + 1);
        self.published_prev = published;
        let hint = RobotHint {
            stamps: Stamps {
                sample_ns: ns_from_s(self.t0_s + mid),
                acquired_ns: published,
                ..Stamps::default()
            },
            seq: k - 1,
            forward_speed_mps: speed,
            forward_speed_sigma_mps: self.quantisation_sigma.hypot(slip),
            yaw_rate_rps: yaw_rate + params.yaw_rate_noise_rps * unit.sample(rng),
            yaw_rate_sigma_rps: params.yaw_rate_noise_rps.max(1e-6),
            flags: self.flags(mid),
            reserved16: 0,
            reserved: 0,
        };
        (hint, b + latency)
    }

    /// The flags of the hint about the window with midpoint `mid` s.
    fn flags(&self, mid: f64) -> u16 {
        let params = self.params;
        let stationary = match params.rest_source {
            RestSource::Encoders => self.since_tick >= self.still_windows,
            RestSource::Commanded => plan_at_rest(self.drive, mid + params.command_lead_s),
        };
        let mut flags = hint_flags::SPEED_VALID
            | hint_flags::YAW_RATE_VALID
            | match params.rest_source {
                RestSource::Encoders => hint_flags::SOURCE_ENCODERS,
                RestSource::Commanded => hint_flags::SOURCE_COMMANDED,
            };
        if stationary {
            flags |= hint_flags::STATIONARY;
        }
        flags
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::DriveParams;

    fn drive(seed: u64) -> Drive {
        let mut p = DriveParams::new(120.0);
        p.turns = true;
        p.max_legs = 2;
        p.leg_s = [2.0, 6.0];
        Drive::new(&p, seed).unwrap()
    }

    /// Speeds match the truth within the quantisation and the drawn scale error, and the
    /// encoder's stationary flag is set exactly where no tick was counted for 0.1 s.
    #[test]
    fn encoder_speeds_follow_the_truth_with_their_scale_error() {
        let d = drive(3);
        let mut p = HintParams::new(RestSource::Encoders);
        p.drop_fraction = 0.0;
        p.bursts_per_min = 0.0;
        p.speed_noise_fraction = 0.0;
        let s = drive_hints(&d, &p, 3, 0.0).unwrap();
        assert_eq!(s.lost, 0);
        // The robot starts at rest: as if no tick had been counted for ever.
        let mut zero_run = u64::MAX;
        assert_eq!(s.hints.len(), 120 * 50);
        let window = 0.02;
        let q = p.tick_m / window;
        for h in &s.hints {
            let mid = h.stamps.sample_ns as f64 * 1e-9;
            let mean_true = path_m(&d, mid - 0.01, mid + 0.01) / window;
            let expected = mean_true * (1.0 + s.speed_scale);
            // Two floor errors: at most one tick per window either way.
            assert!(
                (h.forward_speed_mps - expected).abs() <= q * (1.0 + s.speed_scale) + 1e-12,
                "t {mid}: {} vs {expected}",
                h.forward_speed_mps
            );
            let stationary = h.flags & hint_flags::STATIONARY != 0;
            zero_run = if h.forward_speed_mps == 0.0 {
                zero_run.saturating_add(1)
            } else {
                0
            };
            assert_eq!(stationary, zero_run >= 5, "t {mid}");
            if stationary {
                assert!(
                    mean_true < q * (1.0 + 1e-9),
                    "stationary at {mean_true} m/s"
                );
            }
            assert!(h.flags & hint_flags::SOURCE_ENCODERS != 0);
        }
    }

    /// The commanded flag changes `command_lead_s` before the plan's rest starts and ends.
    #[test]
    fn commanded_rest_leads_the_motion() {
        let d = drive(5);
        let mut p = HintParams::new(RestSource::Commanded);
        p.drop_fraction = 0.0;
        p.bursts_per_min = 0.0;
        let s = drive_hints(&d, &p, 5, 0.0).unwrap();
        for h in &s.hints {
            let mid = h.stamps.sample_ns as f64 * 1e-9;
            let stationary = h.flags & hint_flags::STATIONARY != 0;
            assert_eq!(stationary, plan_at_rest(&d, mid + p.command_lead_s));
        }
        // Some hint says "moving" while the robot has not started yet.
        let early = s.hints.iter().any(|h| {
            let mid = h.stamps.sample_ns as f64 * 1e-9;
            h.flags & hint_flags::STATIONARY == 0 && plan_at_rest(&d, mid)
        });
        assert!(early);
    }

    /// Losses: the independent fraction is close to the configured one, publication times never
    /// go backwards and carry the configured latency, and sequence gaps count the losses.
    #[test]
    fn latency_and_losses_are_as_configured() {
        let d = drive(7);
        let mut p = HintParams::new(RestSource::Encoders);
        p.drop_fraction = 0.5;
        p.bursts_per_min = 0.0;
        let s = drive_hints(&d, &p, 7, 2.0).unwrap();
        let total = 120 * 50;
        assert_eq!(s.hints.len() + s.lost, total);
        let fraction = s.lost as f64 / total as f64;
        // Binomial(6000, 0.5): sd 0.0065.
        assert!((fraction - 0.5).abs() < 0.03, "{fraction}");
        let gaps: u64 = s
            .hints
            .windows(2)
            .map(|w| w[1].seq - w[0].seq - 1)
            .sum::<u64>()
            + s.hints[0].seq
            + (total as u64 - 1 - s.hints.last().unwrap().seq);
        assert_eq!(gaps as usize, s.lost);
        for w in s.hints.windows(2) {
            assert!(w[1].stamps.acquired_ns > w[0].stamps.acquired_ns);
        }
        for h in &s.hints {
            // Published 10 ms (half a window) plus 5-30 ms after the time it describes.
            let delay = (h.stamps.acquired_ns - h.stamps.sample_ns) as f64 * 1e-9;
            assert!((0.015 - 1e-6..=0.040 + 1e-6).contains(&delay), "{delay}");
            assert!(h.stamps.sample_ns >= 2_000_000_000);
        }
    }

    /// A burst loses every hint published during it.
    #[test]
    fn bursts_make_long_gaps() {
        let d = drive(9);
        let mut p = HintParams::new(RestSource::Encoders);
        p.drop_fraction = 0.0;
        p.bursts_per_min = 10.0;
        p.burst_s = [1.0, 1.0];
        let s = drive_hints(&d, &p, 9, 0.0).unwrap();
        let longest = s
            .hints
            .windows(2)
            .map(|w| w[1].stamps.sample_ns - w[0].stamps.sample_ns)
            .max()
            .unwrap();
        assert!(longest >= 980_000_000, "{longest}");
        assert!(s.lost >= 50);
    }

    #[test]
    fn bad_parameters_are_named() {
        let d = drive(1);
        let mut p = HintParams::new(RestSource::Encoders);
        p.drop_fraction = 1.5;
        let e = drive_hints(&d, &p, 1, 0.0).unwrap_err();
        assert_eq!(e.field, "drop_fraction");
        let mut p = HintParams::new(RestSource::Encoders);
        p.latency_s = [0.03, 0.01];
        assert_eq!(drive_hints(&d, &p, 1, 0.0).unwrap_err().field, "latency_s");
    }
}
