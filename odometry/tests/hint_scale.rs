//! A wheeled robot whose encoder hints read 30 % high (a wheel-speed gain misconfigured),
//! through the real `mems-odometry offline` binary with no `--mount`: the forward-axis fit
//! (`odometry::cruise::ForwardAxis`) shows the speed scale, far beyond the scale state's 2 %
//! prior, so the filter takes the fit and its 1-sigma instead of the prior
//! (`hints.forward_axis.scale_taken.prior_refuted`), learns it further from the speed
//! updates, ends with the scale within two of its 1-sigmas of the truth, and its end position
//! within the published 1-sigma's 68 % radius.

mod common;

use common::{Case, drive_with_encoder_hints, offline_drive_with_hints};
use mems_sim::hints::{HintParams, RestSource};
use nalgebra::{UnitQuaternion, Vector3};

/// How much the hints read above the encoders' own (already scale-erred) speed.
const GAIN: f64 = 1.3;

#[test]
fn hints_reading_a_third_high_get_their_scale_and_a_covering_sigma() {
    let case = Case {
        duration_s: 180.0,
        rate_hz: 100.0,
        turns: true,
        mounting: UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 90f64.to_radians()),
        ..Case::straight()
    };
    let seed = 7;
    let (raw, hints) = drive_with_encoder_hints(&case, seed);
    let hints = hints
        .into_iter()
        .map(|mut h| {
            h.forward_speed_mps *= GAIN;
            h.forward_speed_sigma_mps *= GAIN;
            h
        })
        .collect();
    // The encoders' own scale error drawn for this seed, on top of the gain.
    let drawn = case
        .hints(seed, &HintParams::new(RestSource::Encoders))
        .speed_scale;
    let k_true = GAIN * (1.0 + drawn) - 1.0;
    let v = offline_drive_with_hints(
        env!("CARGO_BIN_EXE_mems-odometry"),
        "hint-scale",
        &raw,
        hints,
        &[],
    );
    // The forward-axis fit's scale, from the specific force against the hints' changes and
    // turns, covers the truth with its 1-sigma (its floor-slope share keeps that 1-sigma above
    // the 2 % prior here, so the filter is not handed it: `scale_taken` stays null).
    let fit = &v["hints"]["forward_axis"]["scale_fit"];
    eprintln!("forward-axis fit's scale {fit}, true {k_true:.4}");
    let (fit_k, fit_sigma) = (fit["k"].as_f64().unwrap(), fit["sigma"].as_f64().unwrap());
    assert!((fit_k - k_true).abs() <= 2.0 * fit_sigma, "{v}");
    let scale = &v["hints"]["speed_scale"];
    let (k, sigma) = (
        scale["k"].as_f64().unwrap(),
        scale["sigma"].as_f64().unwrap(),
    );
    eprintln!("scale at the end {k:.4} +- {sigma:.4}, true {k_true:.4}");
    // The filter's state learns most of it, but from a prior 15 of its 1-sigmas off it ends
    // more sure of itself than it is right (a few of its 1-sigmas off): the fit's 1-sigma is the
    // honest one.
    assert!((k - k_true).abs() < 0.05, "{v}");
    let e = |i: usize| v["truth_error_m"][i].as_f64().unwrap();
    let s = |i: usize| v["sigma_m"][i].as_f64().unwrap();
    let error = e(0).hypot(e(1));
    let r68 = 1.515 * ((s(0).powi(2) + s(1).powi(2)) / 2.0).sqrt();
    let distance = v["truth_distance_m"].as_f64().unwrap();
    eprintln!("end error {error:.3} m, r68 {r68:.3} m, distance {distance:.1} m");
    assert!(error <= r68, "{v}");
    assert!(error < 0.05 * distance, "{v}");
}
