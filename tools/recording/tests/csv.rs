//! The canonical CSV: exact round trips, derived fields, and errors naming file, line and field.

mod common;

use common::{any_truth, any_within, live_samples, sample_bits, tmp, truth_bits};
use ipc_types::{limits, raw_flags};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use recording::{ErrorKind, Format, Position};

#[test]
fn live_samples_with_truth_round_trip_exactly() {
    let samples = live_samples(500, 1);
    let truth = any_truth(&samples, 2);
    let path = tmp("roundtrip_live.csv");
    recording::csv::write_raw(&path, &samples, Some(&truth)).unwrap();

    let read = recording::csv::read_raw(&path).unwrap();
    assert_eq!(read.format, Format::CanonicalCsv);
    assert_eq!(read.samples, samples);
    for (a, b) in read.samples.iter().zip(&samples) {
        assert_eq!(sample_bits(a), sample_bits(b));
    }
    let read_truth = read.truth.expect("truth columns were written");
    assert_eq!(read_truth, truth);
    for (a, b) in read_truth.iter().zip(&truth) {
        assert_eq!(truth_bits(a), truth_bits(b));
    }
    // load_raw sniffs the same file to the same result.
    let sniffed = recording::load_raw(&path).unwrap();
    assert_eq!(sniffed.samples, samples);
}

/// Every value the readers accept (finite, within the sensor's range) reads back bit for bit.
#[test]
fn arbitrary_values_in_range_round_trip_bit_for_bit() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut samples = live_samples(300, 4);
    for s in &mut samples {
        s.accel_g = [0.0; 3].map(|_| any_within(&mut rng, limits::ACCEL_LIMIT_G));
        s.gyro_dps = [0.0; 3].map(|_| any_within(&mut rng, limits::GYRO_LIMIT_DPS));
        s.temp_c = any_within(&mut rng, limits::TEMP_MAX_C);
    }
    samples[0].accel_g = [-0.0, f64::MIN_POSITIVE / 3.0, limits::ACCEL_LIMIT_G];
    let path = tmp("roundtrip_any.csv");
    recording::csv::write_raw(&path, &samples, None).unwrap();
    let read = recording::csv::read_raw(&path).unwrap();
    assert!(read.truth.is_none());
    assert_eq!(read.samples.len(), samples.len());
    for (a, b) in read.samples.iter().zip(&samples) {
        assert_eq!(sample_bits(a), sample_bits(b));
        assert_eq!(a.stamps, b.stamps);
        assert_eq!(a.flags, b.flags);
    }
}

#[test]
fn minimal_file_derives_seq_counts_and_flags() {
    let path = tmp("minimal.csv");
    std::fs::write(
        &path,
        "# a comment before the header\n\
         t_s,ax_g,ay_g,az_g\n\
         0.5,0.25,-0.5,1\n\
         # a comment between rows\n\
         \n\
         1.000000001,2.5,0.0000305,-1\n",
    )
    .unwrap();
    let rec = recording::load_raw(&path).unwrap();
    assert_eq!(rec.samples.len(), 2);
    let (a, b) = (&rec.samples[0], &rec.samples[1]);
    assert_eq!((a.seq, b.seq), (0, 1));
    assert_eq!(a.stamps.sample_ns, 500_000_000);
    assert_eq!(b.stamps.sample_ns, 1_000_000_001);
    // 16384 counts/g: 0.25 g = 4096, -0.5 g = -8192, 1 g = 16384.
    assert_eq!(a.accel_counts, [4096, -8192, 16384]);
    assert_eq!(a.flags, 0);
    // 2.5 g is beyond +-2 g: the derived count saturates, but the file's range is not known
    // to be +-2 g, so nothing is flagged (the caller marks clipping from the range it knows);
    // 0.0000305 g * 16384 = 0.4997 rounds to 0.
    assert_eq!(b.accel_counts, [i16::MAX, 0, -16384]);
    assert_eq!(b.flags, 0);
    assert_eq!(b.accel_g, [2.5, 0.0000305, -1.0]);
    assert!(rec.truth.is_none());
}

#[test]
fn gyro_and_temperature_columns_set_validity_flags() {
    let path = tmp("gyro_temp.csv");
    std::fs::write(
        &path,
        "t_s,ax_g,ay_g,az_g,gx_dps,gy_dps,gz_dps,temp_c\n0,0,0,1,1,-2,250,36\n",
    )
    .unwrap();
    let s = recording::load_raw(&path).unwrap().samples[0];
    assert_eq!(s.flags, raw_flags::GYRO_VALID | raw_flags::TEMP_VALID);
    // 131 counts per deg/s.
    assert_eq!(s.gyro_counts, [131, -262, 32750]);
    // (36 - 21) degC * 333.87 counts/degC = 5008.05.
    assert_eq!(s.temp_counts, 5008);
    assert_eq!(s.temp_c, 36.0);
}

#[test]
fn seconds_convert_exactly_with_rounding_beyond_nanoseconds() {
    let path = tmp("times.csv");
    std::fs::write(
        &path,
        "t_s,ax_g,ay_g,az_g\n\
         0.0000000014,0,0,0\n\
         0.0000000025,0,0,0\n\
         1e-8,0,0,0\n\
         .5,0,0,0\n",
    )
    .unwrap();
    let times = |path| -> Vec<u64> {
        let rec = recording::load_raw(path).unwrap();
        rec.samples.iter().map(|s| s.stamps.sample_ns).collect()
    };
    assert_eq!(times(&path), [1, 3, 10, 500_000_000]);
    // The end of the u64 range, a second file (a step from 0.5 s would be a 584-year gap).
    std::fs::write(
        &path,
        "t_s,ax_g,ay_g,az_g\n18446744073.7,0,0,0\n18446744073.709551615,0,0,0\n",
    )
    .unwrap();
    assert_eq!(times(&path), [u64::MAX - 9_551_615, u64::MAX]);
}

/// Writes `body` to a file and returns the error `load_raw` gives for it.
fn load_error(name: &str, body: &str) -> (std::path::PathBuf, recording::Error) {
    let path = tmp(name);
    std::fs::write(&path, body).unwrap();
    let err = recording::load_raw(&path).expect_err("the file is malformed");
    (path, err)
}

#[test]
fn bad_number_is_reported_with_file_line_and_field() {
    let (path, err) = load_error(
        "bad_number.csv",
        "t_s,ax_g,ay_g,az_g\n# comment\n0.1,0,0,1\n0.2,0,1.2.3,1\n",
    );
    assert_eq!(
        err.to_string(),
        format!(
            "{}:4: field \"ay_g\": cannot parse \"1.2.3\" as a number",
            path.display()
        )
    );
    assert_eq!(err.position, Some(Position::Line(4)));
}

#[test]
fn non_finite_values_are_rejected() {
    for (i, text) in ["NaN", "inf", "-infinity"].iter().enumerate() {
        let (_, err) = load_error(
            &format!("non_finite_{i}.csv"),
            &format!("t_s,ax_g,ay_g,az_g,temp_c\n0,0,0,1,20\n1,0,0,1,{text}\n"),
        );
        assert_eq!(err.position, Some(Position::Line(3)));
        assert_eq!(err.field.as_deref(), Some("temp_c"));
        assert!(matches!(err.kind, ErrorKind::NotFinite { .. }), "{err}");
    }
    let (_, err) = load_error("nan_time.csv", "t_s,ax_g,ay_g,az_g\nnan,0,0,1\n");
    assert_eq!(err.field.as_deref(), Some("t_s"));
    assert!(matches!(err.kind, ErrorKind::NotFinite { .. }), "{err}");
}

#[test]
fn missing_and_extra_fields_are_rejected() {
    let (path, err) = load_error("missing_field.csv", "t_s,ax_g,ay_g,az_g\n0,0,0,1\n1,0,0\n");
    assert_eq!(
        err.to_string(),
        format!(
            "{}:3: field \"az_g\": missing (the line has 3 fields, the header 4)",
            path.display()
        )
    );
    let (_, err) = load_error("extra_field.csv", "t_s,ax_g,ay_g,az_g\n0,0,0,1,7\n");
    assert_eq!(err.position, Some(Position::Line(2)));
    assert!(
        matches!(err.kind, ErrorKind::ExtraField { ref text, .. } if text == "7"),
        "{err}"
    );
}

#[test]
fn time_must_strictly_increase() {
    let (path, err) = load_error(
        "backwards.csv",
        "t_s,ax_g,ay_g,az_g\n1,0,0,1\n2,0,0,1\n1.5,0,0,1\n",
    );
    assert_eq!(
        err.to_string(),
        format!(
            "{}:4: field \"t_s\": time goes backwards: 1.500000000 s after 2.000000000 s",
            path.display()
        )
    );
    let (_, err) = load_error("duplicate.csv", "t_s,ax_g,ay_g,az_g\n1,0,0,1\n1.0,0,0,1\n");
    assert_eq!(err.position, Some(Position::Line(3)));
    assert!(
        matches!(
            err.kind,
            ErrorKind::DuplicateTime {
                t_ns: 1_000_000_000
            }
        ),
        "{err}"
    );
    let (_, err) = load_error("negative.csv", "t_s,ax_g,ay_g,az_g\n-1,0,0,1\n");
    assert_eq!(err.field.as_deref(), Some("t_s"));
}

#[test]
fn header_errors_name_the_column() {
    let (path, err) = load_error(
        "unknown_column.csv",
        "t_s,ax_g,ay_g,az_g,pressure\n0,0,0,1,3\n",
    );
    assert_eq!(err.position, Some(Position::Line(1)));
    assert_eq!(err.field.as_deref(), Some("pressure"));
    assert!(err.to_string().starts_with(&format!(
        "{}:1: field \"pressure\": unknown column",
        path.display()
    )));

    let (_, err) = load_error("missing_column.csv", "t_s,ax_g,az_g\n0,0,1\n");
    assert_eq!(err.field.as_deref(), Some("ay_g"));
    assert!(matches!(err.kind, ErrorKind::MissingColumn { .. }), "{err}");

    let (_, err) = load_error("partial_gyro.csv", "t_s,ax_g,ay_g,az_g,gx_dps\n0,0,0,1,3\n");
    assert_eq!(err.field.as_deref(), Some("gy_dps"));

    let (_, err) = load_error(
        "partial_truth.csv",
        "t_s,ax_g,ay_g,az_g,truth_px_m\n0,0,0,1,3\n",
    );
    assert_eq!(err.field.as_deref(), Some("truth_py_m"));

    let (_, err) = load_error(
        "duplicate_column.csv",
        "t_s,ax_g,ay_g,az_g,ax_g\n0,0,0,1,3\n",
    );
    assert!(matches!(err.kind, ErrorKind::DuplicateColumn), "{err}");
}

#[test]
fn flags_must_match_the_columns() {
    let (_, err) = load_error("flags_gyro.csv", "t_s,ax_g,ay_g,az_g,flags\n0,0,0,1,16\n");
    assert_eq!(err.field.as_deref(), Some("flags"));
    let (_, err) = load_error(
        "flags_range.csv",
        "t_s,ax_g,ay_g,az_g,flags\n0,0,0,1,70000\n",
    );
    assert!(matches!(err.kind, ErrorKind::Parse { .. }), "{err}");
    let (_, err) = load_error("unrecognised.csv", "a,b,c\n1,2,3\n4,5,6\n");
    assert!(matches!(err.kind, ErrorKind::UnknownFormat(_)), "{err}");
}

#[test]
fn writer_refuses_what_it_could_not_read_back() {
    let mut samples = live_samples(3, 5);
    let truth = any_truth(&samples, 6);
    let path = tmp("refused.csv");
    let err = recording::csv::write_raw(&path, &samples, Some(&truth[..2])).unwrap_err();
    assert!(
        err.to_string().contains("2 truth records for 3 samples"),
        "{err}"
    );
    samples[1].accel_g[2] = f64::NAN;
    let err = recording::csv::write_raw(&path, &samples, None).unwrap_err();
    assert_eq!(err.position, Some(Position::Line(3)));
    samples[1].accel_g[2] = 1.0;
    samples[2].stamps.sample_ns = samples[1].stamps.sample_ns;
    let err = recording::csv::write_raw(&path, &samples, None).unwrap_err();
    assert_eq!(err.field.as_deref(), Some("t_s"));
}

#[test]
fn a_real_log_s_repeated_rows_and_times_are_repaired_and_counted() {
    let path = tmp("real_log.csv");
    // Rows 2 and 5 repeat their predecessors' values (a logger polling faster than the
    // sensor), row 4 repeats a time with new values (host timestamps quantised), row 6 steps
    // back in time by 2 ms (jitter).
    std::fs::write(
        &path,
        "t_s,ax_g,ay_g,az_g,gx_dps,gy_dps,gz_dps\n\
         0.000,0,0,1,0.1,0,0\n\
         0.010,0,0,1,0.1,0,0\n\
         0.010,0,0.01,1,0.1,0,0\n\
         0.010,0,0.02,1,0.1,0,0\n\
         0.020,0,0.02,1,0.1,0,0\n\
         0.018,0,0.03,1,0.1,0,0\n\
         0.040,0,0.04,1,0.1,0,0\n",
    )
    .unwrap();
    // Read strictly, the repeated time is refused naming its line.
    let err = recording::load_raw(&path).unwrap_err();
    assert!(matches!(err.kind, ErrorKind::DuplicateTime { .. }), "{err}");
    assert!(matches!(err.position, Some(Position::Line(4))), "{err}");

    let rec = recording::load_raw_with(&path, recording::LogPolicy::Repair).unwrap();
    assert_eq!(rec.repairs.repeats_dropped, 2);
    assert_eq!(rec.repairs.times_rebuilt, 2);
    // Kept rows' times 0, 10, 10, 18, 40 ms: between distinct times the steps per row are 10,
    // 4 (8 ms over two rows) and 22 ms, whose median, 10 ms, is the nominal period the
    // non-increasing times are rebuilt from.
    let times: Vec<u64> = rec.samples.iter().map(|s| s.stamps.sample_ns).collect();
    let p = rec.repairs.period_ns;
    assert_eq!(
        times,
        [
            0,
            10_000_000,
            10_000_000 + p,
            10_000_000 + 2 * p,
            40_000_000
        ]
    );
    assert_eq!(p, 10_000_000);
    let ay: Vec<f64> = rec.samples.iter().map(|s| s.accel_g[1]).collect();
    assert_eq!(ay, [0.0, 0.01, 0.02, 0.03, 0.04]);
    assert_eq!(
        rec.samples.iter().map(|s| s.seq).collect::<Vec<_>>(),
        [0, 1, 2, 3, 4]
    );

    // A host clock quantised to twice the sample period: two rows per stamp, the period is the
    // step per row (1 ms), not the step (2 ms).
    let quantised: String = (0..6)
        .map(|k| format!("{}.{:03},0,{},1\n", 0, 2 * (k / 2), k))
        .collect();
    std::fs::write(&path, format!("t_s,ax_g,ay_g,az_g\n{quantised}")).unwrap();
    let rec = recording::load_raw_with(&path, recording::LogPolicy::Repair).unwrap();
    let times: Vec<u64> = rec.samples.iter().map(|s| s.stamps.sample_ns).collect();
    assert_eq!(rec.repairs.period_ns, 1_000_000);
    assert_eq!(times, (0..6).map(|k| k * 1_000_000).collect::<Vec<u64>>());

    // A step back of more than a second is not jitter: refused even when repairing.
    std::fs::write(&path, "t_s,ax_g,ay_g,az_g\n5.0,0,0,1\n3.5,0,0.1,1\n").unwrap();
    let err = recording::load_raw_with(&path, recording::LogPolicy::Repair).unwrap_err();
    assert!(matches!(err.kind, ErrorKind::TimeBackwards { .. }), "{err}");
}
