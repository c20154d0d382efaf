//! The text report of `mems-odometry diagnose` (the `--json` report's figures, one line each).

use std::fmt::Write;
use std::path::Path;

use odometry::diagnose::saturation::Saturation;
use odometry::diagnose::{Diagnosis, Score};
use serde_json::Value;

fn num(v: &Value, unit: &str) -> String {
    v.as_f64().map_or("-".into(), |x| format!("{x:.4} {unit}"))
}

/// One candidate's line: its score, parameters and how they compare with the model.
fn candidate(c: &Score) -> String {
    let name = c.candidate.name();
    if let Some(why) = &c.untestable {
        return format!("{name:<16} not testable: {why}");
    }
    // The lag uses one of the three slots.
    let used = c.candidate.params();
    let p = |v: &[f64; 3], prec: usize| {
        v[..used]
            .iter()
            .map(|x| format!("{x:.prec$e}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    format!(
        "{name:<16} score {:>10.1}  params [{}] +- [{}] {}  {} model's 1-sigma{}",
        c.gain,
        p(&c.params, 3),
        p(&c.sigma, 1),
        c.candidate.unit(),
        if c.beyond_model {
            "beyond the"
        } else {
            "within the"
        },
        if c.plausible {
            ""
        } else {
            ", implausible for a real part"
        }
    )
}

/// The saturation candidate's line: its score, the hidden rate (deg/s) and the clipped
/// motions' tilt before and after.
fn saturation(sat: &Saturation) -> String {
    let name = "gyro_saturation";
    if let Some(why) = &sat.untestable {
        return format!("{name:<16} not testable: {why}");
    }
    let hidden: Vec<String> = (0..3)
        .filter(|&i| sat.clipped_axes[i])
        .map(|i| {
            format!(
                "{} {:.1} +- {:.1}",
                ["x", "y", "z"][i],
                sat.hidden_rps[i].to_degrees(),
                sat.sigma_rps[i].to_degrees()
            )
        })
        .collect();
    format!(
        "{name:<16} score {:>10.1}  hidden rate {} deg/s beyond the range; {} clipped \
         motions' tilt rms {:.3} mrad before, {:.3} after (noise {:.3}, p {:.2e}): {}",
        sat.gain,
        hidden.join(", "),
        sat.motions,
        sat.rms_before * 1e3,
        sat.rms_after * 1e3,
        sat.rms_noise * 1e3,
        sat.p_after,
        if sat.found {
            "found (remedy: a wider gyro range)"
        } else {
            "not found"
        }
    )
}

/// The report for `input`: the diagnosis `d` and the figures of `report` (the JSON form).
pub fn text(input: &Path, d: &Diagnosis, report: &Value) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{}: {} rests, {} motions between them ({} with the gyro clipped, tested apart for saturation), {} clipped samples",
        input.display(),
        d.rests,
        d.motions,
        d.motions_gyro_clipped,
        d.clipped_samples
    );
    let _ = writeln!(
        s,
        "  magnitude rows {:>4}: rms {:.5} m/s^2 before, {:.5} after the fit; noise predicts {:.5}",
        d.magnitude.rows, d.magnitude.rms_before, d.magnitude.rms_after, d.magnitude.rms_noise
    );
    let _ = writeln!(
        s,
        "  tilt rows      {:>4}: rms {:.3} mrad before, {:.3} after the fit; noise predicts {:.3}",
        d.tilt.rows,
        d.tilt.rms_before * 1e3,
        d.tilt.rms_after * 1e3,
        d.tilt.rms_noise * 1e3
    );
    let _ = writeln!(
        s,
        "  velocity rows  {:>4}: rms {:.4} m/s before, {:.4} after the fit; noise and the model's 1-sigma predict {:.4}",
        d.velocity.rows, d.velocity.rms_before, d.velocity.rms_after, d.velocity.rms_noise
    );
    for c in &d.scores {
        let _ = writeln!(s, "    {}", candidate(c));
    }
    let _ = writeln!(s, "    {}", saturation(&d.saturation));
    let _ = writeln!(s, "    {}", lever_text(&report["lever_arm"]));
    let names: Vec<&str> = d.selected.iter().map(|(c, _)| c.name()).collect();
    let _ = writeln!(
        s,
        "  selected: {}",
        if names.is_empty() {
            "none".into()
        } else {
            names.join(", ")
        }
    );
    let _ = writeln!(
        s,
        "  remaining: chi2 {:.1} for {} dof (noise and the model's 1-sigma), p {:.2e}; {}",
        d.chi2,
        d.dof,
        d.p,
        if d.unexplained {
            "unexplained: the residuals exceed noise and model and no candidate explains them"
        } else {
            "explained"
        }
    );
    if report["confirmed"] == false {
        let _ = writeln!(
            s,
            "  the rerun does not confirm the selection (its rest innovation rms is larger): \
             unexplained"
        );
    }
    let before = &report["before"];
    let after = &report["after"]["figures"];
    for (label, key, unit) in [
        ("rest innovation rms", "rest_innovation_rms_mps", "m/s"),
        ("end error", "end_error_m", "m"),
        ("truth end error", "truth_error_m", "m"),
    ] {
        if before[key].is_null() && after[key].is_null() {
            continue;
        }
        let _ = writeln!(
            s,
            "  {label:<20} before {:>12}  after {:>12}",
            num(&before[key], unit),
            num(&after[key], unit)
        );
    }
    s
}

/// The lever-arm candidate's line of the text report, from its JSON
/// (`crate::diagnose::lever::test`'s result).
fn lever_text(lever: &Value) -> String {
    let c = &lever["candidate"];
    let name = "lever_arm";
    if let Some(why) = c["untestable"].as_str() {
        return format!("{name:<16} not testable: {why}");
    }
    let f = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
    let mut line = format!(
        "{name:<16} score {:>10.1}  forward offset IMU to axle {:.3} +- {:.3} m: {}",
        f(&c["gain"]),
        f(&c["r_x_m"]),
        f(&c["sigma_m"]),
        if c["found"] == true {
            "found"
        } else {
            "not found"
        }
    );
    if c["found"] == true {
        let fig = |k: &str| {
            let g = |side: &str| {
                lever[side][k]
                    .as_f64()
                    .map_or("-".into(), |x| format!("{x:.3}"))
            };
            format!("{k} {} -> {}", g("before"), g("after"))
        };
        line += &format!(
            "; rerun with it: constraint NIS sum {:.1} -> {:.1} ({}), {}, {}",
            f(&c["points"][0]["chi2"]),
            f(&lever["nis_sum_after"]),
            if lever["confirmed"] == true {
                "confirmed"
            } else {
                "not confirmed"
            },
            fig("end_error_m"),
            fig("truth_error_m")
        );
    }
    line
}
