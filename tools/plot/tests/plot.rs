//! `mems-plot` on recordings with known content: the PNGs exist, have the documented size, and
//! show the series, bands and shading the data calls for (checked by pixel colour); the track
//! draws the path, its ellipses, the truth and the revised path, clipped to its plot area.

use std::path::{Path, PathBuf};
use std::process::Command;

use image::RgbImage;
use ipc_types::{
    CorrectedImuSample, OdometryState, RawImuSample, Stamps, corrected_flags, odometry_flags,
    raw_flags,
};
use mems_plot::track::{TRACK_COLOUR, TRUTH_COLOUR};
use mems_plot::{AXIS_COLOURS, REST_COLOUR, REVISED_COLOUR, SIZE};
use plotters::style::RGBColor;
use recording::Truth;
use recording::mcap::Writer;

const G: f64 = 9.80665;
const RATE_HZ: u64 = 200;

fn dir(test: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("plot-{test}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Whether the sample at `t` s is at rest: 0-3 s and 9-12 s; between, the sensor moves along x.
fn at_rest(t: f64) -> bool {
    !(3.0..9.0).contains(&t)
}

/// Along-track acceleration, m/s^2: one sine period over the motion (speed up, slow down).
fn accel_x(t: f64) -> f64 {
    if at_rest(t) {
        0.0
    } else {
        (2.0 * std::f64::consts::PI * (t - 3.0) / 6.0).sin()
    }
}

/// A 12 s drive at 200 Hz on every channel; `revisions` adds revised states of the motion.
fn write_drive(path: &Path, with_stages: bool, revisions: bool) {
    let mut w = Writer::create(path).unwrap();
    let raw_ch = w.add_channel::<RawImuSample>().unwrap();
    let cor_ch = w.add_channel::<CorrectedImuSample>().unwrap();
    let odo_ch = w.add_channel::<OdometryState>().unwrap();
    let (mut v, mut x) = (0.0, 0.0);
    let dt = 1.0 / RATE_HZ as f64;
    let mut states = Vec::new();
    for i in 0..12 * RATE_HZ {
        let t = i as f64 * dt;
        let stamps = Stamps {
            sample_ns: 7_000_000_000 + i * 1_000_000_000 / RATE_HZ,
            ..Stamps::default()
        };
        // A little deterministic vibration while moving.
        let wobble = if at_rest(t) {
            0.0
        } else {
            0.2 * (40.0 * t).sin()
        };
        let accel_g = [accel_x(t) / G + wobble / G, 0.01, 1.0 + 0.5 * wobble / G];
        let raw = RawImuSample {
            stamps,
            seq: i,
            accel_g,
            accel_counts: accel_g.map(|a| (a * 16384.0) as i16),
            flags: raw_flags::TEMP_VALID,
            temp_c: 25.0,
            ..RawImuSample::default()
        };
        w.write(raw_ch, &raw, stamps.sample_ns).unwrap();
        if !with_stages {
            continue;
        }
        let rest = at_rest(t);
        let corrected = CorrectedImuSample {
            stamps,
            seq: i,
            accel_mps2: accel_g.map(|a| a * G),
            zs_mean_mps2: [0.0, 0.0, G],
            zs_std_mps2: if rest { [0.003; 3] } else { [0.15, 0.02, 0.08] },
            flags: corrected_flags::DETECTOR_READY
                | if rest { corrected_flags::ZERO_STATE } else { 0 },
            ..CorrectedImuSample::default()
        };
        w.write(cor_ch, &corrected, stamps.sample_ns).unwrap();
        v += accel_x(t) * dt;
        x += v * dt;
        let sigma = if rest {
            0.002
        } else {
            0.002 + 0.05 * (t - 3.0)
        };
        let state = OdometryState {
            stamps,
            seq: i,
            position_m: [x, 0.1 * x, 0.0],
            position_sigma_m: [sigma, sigma, 0.5 * sigma],
            velocity_mps: [v, 0.1 * v, 0.0],
            attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
            flags: odometry_flags::ALIGNED
                | if rest {
                    odometry_flags::ZERO_VELOCITY
                } else {
                    0
                },
            ..OdometryState::default()
        };
        w.write(odo_ch, &state, stamps.sample_ns).unwrap();
        states.push(state);
        if revisions && (t - 9.5).abs() < dt / 2.0 {
            // Half a second after the motion ended: its states revised at 20 Hz, 5 % shorter.
            for s in states
                .iter()
                .filter(|s| s.seq % 10 == 0 && s.seq >= 3 * RATE_HZ && s.seq < 9 * RATE_HZ)
            {
                let mut r = *s;
                r.position_m = s.position_m.map(|p| 0.95 * p);
                r.flags |= odometry_flags::REVISION;
                w.write(odo_ch, &r, stamps.sample_ns).unwrap();
            }
        }
    }
    w.finish().unwrap();
}

fn mems_plot(file: &Path, out: &Path) -> (bool, String, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_mems-plot"))
        .arg(file)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    (
        output.status.success(),
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

fn load(path: &Path) -> RgbImage {
    let image = image::open(path).unwrap().to_rgb8();
    assert_eq!(image.dimensions(), SIZE, "{}", path.display());
    image
}

/// `colour` drawn with opacity `alpha` over white, as plotters blends it.
fn over_white(colour: RGBColor, alpha: f64) -> RGBColor {
    let blend = |c: u8| (f64::from(c) * alpha + 255.0 * (1.0 - alpha)).round() as u8;
    RGBColor(blend(colour.0), blend(colour.1), blend(colour.2))
}

/// Pixels within 3 per channel of `colour` in rows `rows` of the image.
fn count(image: &RgbImage, colour: RGBColor, rows: std::ops::Range<u32>) -> usize {
    let near = |a: u8, b: u8| a.abs_diff(b) <= 3;
    rows.flat_map(|y| (0..image.width()).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let p = image.get_pixel(x, y).0;
            near(p[0], colour.0) && near(p[1], colour.1) && near(p[2], colour.2)
        })
        .count()
}

#[test]
fn a_full_recording_gives_three_figures_with_their_series() {
    let dir = dir("full");
    let file = dir.join("drive.mcap");
    write_drive(&file, true, true);
    let (ok, stdout, stderr) = mems_plot(&file, &dir);
    assert!(ok, "{stderr}");
    for name in ["acceleration", "zero-state", "position", "track"] {
        let png = dir.join(format!("drive-{name}.png"));
        assert!(
            stdout.contains(&format!("wrote {}", png.display())),
            "{stdout}"
        );
    }
    let h = SIZE.1;

    // Raw on the top half, corrected on the bottom half: all three axes in each.
    let accel = load(&dir.join("drive-acceleration.png"));
    for colour in AXIS_COLOURS {
        assert!(
            count(&accel, colour, 0..h / 2) > 100,
            "{colour:?} in the raw panel"
        );
        assert!(
            count(&accel, colour, h / 2..h) > 100,
            "{colour:?} in the corrected panel"
        );
    }

    // Rest shading in every panel (|a|, window std, speed).
    let zs = load(&dir.join("drive-zero-state.png"));
    let shade = over_white(REST_COLOUR, 0.25);
    for third in 0..3 {
        let rows = third * h / 3..(third + 1) * h / 3;
        assert!(
            count(&zs, shade, rows) > 5_000,
            "rest shading in panel {third}"
        );
    }

    // Each axis with its 1-sigma band, and the revised states.
    let pos = load(&dir.join("drive-position.png"));
    for (axis, colour) in AXIS_COLOURS.iter().enumerate() {
        let rows = axis as u32 * h / 3..(axis as u32 + 1) * h / 3;
        assert!(count(&pos, *colour, rows.clone()) > 100, "axis {axis} line");
        assert!(
            count(&pos, over_white(*colour, 0.2), rows.clone()) > 2_000,
            "axis {axis} band"
        );
        assert!(
            count(&pos, REVISED_COLOUR, rows) > 50,
            "axis {axis} revisions"
        );
    }
}

#[test]
fn without_revisions_no_revised_line_is_drawn() {
    let dir = dir("norevision");
    let file = dir.join("live.mcap");
    write_drive(&file, true, false);
    let (ok, _, stderr) = mems_plot(&file, &dir);
    assert!(ok, "{stderr}");
    let pos = load(&dir.join("live-position.png"));
    assert_eq!(count(&pos, REVISED_COLOUR, 0..SIZE.1), 0);
}

#[test]
fn a_raw_only_recording_gives_the_acceleration_and_says_why_not_the_rest() {
    let dir = dir("raw");
    let file = dir.join("raw.mcap");
    write_drive(&file, false, false);
    let (ok, stdout, stderr) = mems_plot(&file, &dir);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("skipped zero-state: no corrected samples"),
        "{stdout}"
    );
    assert!(
        stdout.contains("skipped position: no odometry states"),
        "{stdout}"
    );
    let accel = load(&dir.join("raw-acceleration.png"));
    for colour in AXIS_COLOURS {
        assert!(count(&accel, colour, 0..SIZE.1) > 100, "{colour:?}");
    }
    assert!(!dir.join("raw-position.png").exists());
    assert!(
        stdout.contains("skipped track: no aligned odometry state"),
        "{stdout}"
    );
}

#[test]
fn a_file_that_is_not_mcap_is_an_error_naming_it() {
    let dir = dir("bad");
    let file = dir.join("notes.mcap");
    std::fs::write(&file, "t_s,ax_g,ay_g,az_g\n").unwrap();
    let (ok, _, stderr) = mems_plot(&file, &dir);
    assert!(!ok);
    assert!(stderr.contains(&file.display().to_string()), "{stderr}");
    assert!(stderr.contains("MCAP magic"), "{stderr}");
}

/// A 20 s curve at 50 Hz, aligned from the start, its truth 10 % longer, and revisions of
/// every fifth state swinging six times as far sideways (out of the axes, which cover the live
/// path and the truth, and back).
fn write_track(path: &Path) {
    let mut w = Writer::create(path).unwrap();
    let odo_ch = w.add_channel::<OdometryState>().unwrap();
    let truth_ch = w.add_channel::<Truth>().unwrap();
    for i in 0..1000_u64 {
        let t = i as f64 * 0.02;
        let sample_ns = 5_000_000_000 + i * 20_000_000;
        let (x, y) = (t, 3.0 * (0.3 * t).sin());
        let truth = Truth {
            t_ns: sample_ns,
            position_m: [1.1 * x, 1.1 * y, 0.0],
            attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
            ..Truth::default()
        };
        w.write(truth_ch, &truth, sample_ns).unwrap();
        let state = OdometryState {
            stamps: Stamps {
                sample_ns,
                ..Stamps::default()
            },
            seq: i,
            position_m: [x, y, 0.0],
            position_sigma_m: [0.05 + 0.05 * t, 0.05 + 0.03 * t, 0.1],
            attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
            flags: odometry_flags::ALIGNED,
            ..OdometryState::default()
        };
        w.write(odo_ch, &state, sample_ns).unwrap();
        if i % 5 == 0 {
            let revised = OdometryState {
                position_m: [x, 6.0 * y, 0.0],
                flags: odometry_flags::ALIGNED | odometry_flags::REVISION,
                ..state
            };
            w.write(odo_ch, &revised, sample_ns).unwrap();
        }
    }
    w.finish().unwrap();
}

#[test]
fn the_track_shows_path_ellipses_truth_and_revisions_inside_its_plot_area() {
    let dir = dir("track");
    let file = dir.join("curve.mcap");
    write_track(&file);
    let (ok, stdout, stderr) = mems_plot(&file, &dir);
    assert!(ok, "{stderr}");
    let png = dir.join("curve-track.png");
    assert!(
        stdout.contains(&format!("wrote {}", png.display())),
        "{stdout}"
    );
    let track = load(&png);
    let h = SIZE.1;
    assert!(count(&track, TRACK_COLOUR, 0..h) > 500, "the live path");
    assert!(count(&track, TRUTH_COLOUR, 0..h) > 500, "the truth");
    assert!(
        count(&track, over_white(TRACK_COLOUR, 0.5), 0..h) > 500,
        "the 1-sigma ellipses"
    );
    assert!(count(&track, REVISED_COLOUR, 0..h) > 20, "the revised path");
    // Outside the plot area (the title above it, the axis labels left of and below it) no
    // line is drawn: the revised path leaves the axes and is cut at their edges.
    let margins = |colour| {
        count(&track, colour, 0..45)
            + count(&track, colour, h - 50..h)
            + (0..h)
                .flat_map(|y| (0..90).map(move |x| (x, y)))
                .filter(|&(x, y)| {
                    *track.get_pixel(x, y) == image::Rgb([colour.0, colour.1, colour.2])
                })
                .count()
    };
    assert_eq!(
        margins(REVISED_COLOUR),
        0,
        "revisions outside the plot area"
    );
    assert_eq!(margins(TRACK_COLOUR), 0, "ellipses outside the plot area");
}
