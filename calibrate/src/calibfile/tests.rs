//! The calibration file's format, round trips and checks.

use super::*;
use nalgebra::{Matrix3, Vector3};

/// The identity file round-trips through TOML and its model leaves a reading unchanged.
#[test]
fn identity_file_leaves_readings_unchanged() {
    let file = CalibrationFile::identity(9.797);
    assert_eq!(file.gravity_mps2, 9.797);
    assert!(file.sigma.iter().all(|&s| s == 0.0));
    let path = std::env::temp_dir().join(format!("identity-{}.toml", std::process::id()));
    file.save(&path).unwrap();
    let back = CalibrationFile::load(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    let reading = Vector3::new(0.01, -0.98, 0.2);
    assert_eq!(back.accel_model().unwrap().correct(&reading), reading);
}

fn example() -> CalibrationFile {
    let s = Matrix3::new(
        1.0, 0.008, 0.009, -0.006, 1.0004, 0.0106, -0.0102, -0.0044, 1.022,
    );
    let m = AccelModel::new(ModelKind::Full, s, Vector3::new(0.0916, 0.0473, -0.2502)).unwrap();
    let mut cov = ParamCovariance::identity() * 1e-8;
    cov[(0, 3)] = 2e-9;
    cov[(3, 0)] = 2e-9;
    let source = SourceSection {
        file: "six.csv".into(),
        kind: "six_position_means".into(),
        poses: 6,
        repaired_samples: 0,
    };
    let residuals = ResidualSection {
        rms_g: [1e-3, 2e-3, 3e-3],
        max_abs_g: 4e-3,
        dof: [2, 2, 2],
        chi2: [1e-6, 2e-6, 3e-6],
        per_pose_g: vec![[1e-3, -1e-3, 0.0]; 6],
    };
    CalibrationFile::new(
        &m,
        &cov,
        FitMethod::Labelled,
        Weighting::Unweighted,
        CovarianceMode::ResidualScaled,
        9.797,
        source,
        residuals,
    )
}

#[test]
fn round_trips_through_toml() {
    let f = example();
    let back: CalibrationFile = toml::from_str(&f.to_toml()).unwrap();
    assert_eq!(back, f);
    assert_eq!(back.accel_model().unwrap(), f.accel_model().unwrap());
    assert_eq!(back.covariance_matrix()[(0, 3)], 2e-9);
}

#[test]
fn fitted_terms_round_trip_and_incomplete_ones_are_refused() {
    let dir = std::env::temp_dir().join(format!("calibfile-terms-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("terms.toml");
    let mut f = example();
    f.temperature.reference_c = Some(27.5);
    f.temperature.scale_per_c = Some([2e-4, -1e-4, 3e-4]);
    f.time.drift_g_per_s = Some([1e-6, -2e-6, 3e-6]);
    f.time.drift_max_s = Some(60.0);
    f.time.warm_up_g = Some([1e-3, 0.0, -2e-3]);
    f.time.warm_up_time_constant_s = Some(12.0);
    f.nonlinearity.quadratic_g_per_g2 = Some([0.002, -0.001, 0.003]);
    f.save(&path).unwrap();
    assert_eq!(CalibrationFile::load(&path).unwrap(), f);
    type Spoil = fn(&mut CalibrationFile);
    let cases: [(&str, Spoil); 4] = [
        ("drift_max_s", |f| f.time.drift_max_s = None),
        ("warm_up_time_constant_s", |f| {
            f.time.warm_up_time_constant_s = Some(0.0)
        }),
        ("reference_c", |f| f.temperature.reference_c = None),
        ("nonlinearity.quadratic_g_per_g2", |f| {
            f.nonlinearity.quadratic_g_per_g2 = Some([f64::NAN, 0.0, 0.0])
        }),
    ];
    for (name, spoil) in cases {
        let mut g = f.clone();
        spoil(&mut g);
        g.save(&path).unwrap();
        let err = CalibrationFile::load(&path).unwrap_err().to_string();
        assert!(err.contains("terms.toml") && err.contains(name), "{err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_gyro_correction_round_trips_and_is_checked_on_load() {
    let dir = std::env::temp_dir().join(format!("calibfile-gyro-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("gyro.toml");
    let mut f = example();
    f.gyro.bias_dps = Some([0.5, -0.2, 0.1]);
    f.gyro.correction = Some([
        [0.99, -0.005, 0.005],
        [0.005, 1.01, -0.005],
        [-0.005, 0.005, 0.99],
    ]);
    f.gyro.correction_sigma = Some([[1e-4, 2e-4, 3e-4]; 3]);
    f.save(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let table: toml::Table = toml::from_str(&text).unwrap();
    assert_eq!(
        table["gyro"]["correction"][1][1].as_float(),
        Some(1.01),
        "row-major under [gyro]: {text}"
    );
    assert_eq!(CalibrationFile::load(&path).unwrap(), f);

    // A [gyro] table written before the correction existed (bias only) loads without one.
    let mut older = table.clone();
    let gyro = older["gyro"].as_table_mut().unwrap();
    gyro.remove("correction");
    gyro.remove("correction_sigma");
    std::fs::write(&path, toml::to_string(&older).unwrap()).unwrap();
    let back = CalibrationFile::load(&path).unwrap();
    assert_eq!(back.gyro.bias_dps, f.gyro.bias_dps);
    assert_eq!(
        (back.gyro.correction, back.gyro.correction_sigma),
        (None, None)
    );

    type Spoil = fn(&mut CalibrationFile);
    let cases: [(&str, Spoil); 3] = [
        ("gyro.correction must be finite", |f| {
            f.gyro.correction.as_mut().unwrap()[2][0] = f64::INFINITY
        }),
        ("gyro.correction_sigma must be finite and >= 0", |f| {
            f.gyro.correction_sigma.as_mut().unwrap()[0][1] = f64::NAN
        }),
        ("gyro.correction_sigma must be finite and >= 0", |f| {
            f.gyro.correction_sigma.as_mut().unwrap()[1][2] = -1e-4
        }),
    ];
    for (message, spoil) in cases {
        let mut g = f.clone();
        spoil(&mut g);
        g.save(&path).unwrap();
        let err = CalibrationFile::load(&path).unwrap_err().to_string();
        assert!(err.contains("gyro.toml") && err.contains(message), "{err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn older_files_without_optional_sections_load_and_unknown_keys_are_refused() {
    let mut value: toml::Table = toml::from_str(&example().to_toml()).unwrap();
    value.remove("noise");
    value.remove("temperature");
    value.remove("temperature_range_c");
    value.remove("gyro");
    value.remove("time");
    value.remove("nonlinearity");
    let text = toml::to_string(&value).unwrap();
    let back: CalibrationFile = toml::from_str(&text).unwrap();
    assert_eq!(back.noise, None);
    assert_eq!(back.temperature_range_c, None);
    assert_eq!(back.gyro, GyroSection::default());
    assert_eq!(back.time, TimeTerms::default());
    assert_eq!(back.nonlinearity, NonlinearityTerms::default());

    // A key no table has, at the top, in a table, and deep in [noise]: refused naming the
    // file, the line, the table and the key.
    let dir = std::env::temp_dir().join(format!("calibfile-keys-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("keys.toml");
    let mut with_noise = example();
    with_noise.noise = Some(crate::noise_params::tests::sample());
    let good = with_noise.to_toml();
    let cases = [
        (
            good.replacen("gravity_mps2 =", "gravity = 9.8\ngravity_mps2 =", 1),
            "keys.toml: line 6: unknown field `gravity`",
        ),
        (
            good.replacen("[source]\n", "[source]\nfiles = 2\n", 1),
            "of [source]: unknown field `files`",
        ),
        (
            good.replacen(
                "[noise.accel.y.white_noise_density]\n",
                "[noise.accel.y.white_noise_density]\nvalu = 1.0\n",
                1,
            ),
            "of [noise]: in [noise.accel.y]: unknown field `valu`",
        ),
    ];
    for (text, expected) in cases {
        std::fs::write(&path, text).unwrap();
        let err = CalibrationFile::load(&path).unwrap_err().to_string();
        assert!(err.contains(expected), "{err}");
    }
    std::fs::write(&path, good).unwrap();
    assert_eq!(CalibrationFile::load(&path).unwrap(), with_noise);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn gravity_and_covariance_are_checked_on_load() {
    let dir = std::env::temp_dir().join(format!("calibfile-cov-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("cov.toml");
    type Spoil = fn(&mut CalibrationFile);
    let cases: [(&str, Spoil); 5] = [
        ("gravity_mps2 = 1000000.0 m/s^2 is not the gravity", |f| {
            f.gravity_mps2 = 1e6
        }),
        ("gravity_mps2 = 9.7 m/s^2", |f| f.gravity_mps2 = 9.7),
        ("gravity_mps2 = 1.0 m/s^2", |f| f.gravity_mps2 = 1.0),
        ("covariance[1][5] = 1e-9 but covariance[5][1] = 0.0", |f| {
            f.covariance[1][5] = 1e-9
        }),
        // Each variance positive, the correlation of b_x and b_y beyond 1.
        (
            "a combination of b_x and b_y has the variance -1.010e-8",
            |f| {
                f.covariance[0][1] = 2e-8;
                f.covariance[1][0] = 2e-8;
            },
        ),
    ];
    for (expected, spoil) in cases {
        let mut f = example();
        spoil(&mut f);
        f.save(&path).unwrap();
        let err = CalibrationFile::load(&path).unwrap_err().to_string();
        assert!(
            err.contains("cov.toml: ") && err.contains(expected),
            "{err}"
        );
    }
    // The sites at the ends of the range, and a fitted covariance with its rounding, load.
    for g in [9.7639, 9.8337] {
        let mut f = example();
        f.gravity_mps2 = g;
        f.covariance[0][3] *= 1.0 + 1e-15;
        f.save(&path).unwrap();
        CalibrationFile::load(&path).unwrap();
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn load_names_the_file_and_the_problem() {
    let dir = std::env::temp_dir().join(format!("calibfile-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("bad.toml");
    let mut f = example();
    f.covariance.pop();
    std::fs::write(&path, f.to_toml()).unwrap();
    let err = CalibrationFile::load(&path).unwrap_err().to_string();
    assert!(
        err.contains("bad.toml") && err.contains("covariance"),
        "{err}"
    );
    std::fs::write(&path, "model = \"full\"\n").unwrap();
    let err = CalibrationFile::load(&path).unwrap_err().to_string();
    assert!(
        err.contains("bad.toml") && err.contains("missing field"),
        "{err}"
    );
    let mut f = example();
    f.temperature.bias_g_per_c = Some([1e-4, 0.0, 0.0]);
    std::fs::write(&path, f.to_toml()).unwrap();
    let err = CalibrationFile::load(&path).unwrap_err().to_string();
    assert!(
        err.contains("bad.toml") && err.contains("reference_c"),
        "{err}"
    );
    let mut f = example();
    f.gyro.bias_dps = Some([0.1, f64::NAN, 0.0]);
    std::fs::write(&path, f.to_toml()).unwrap();
    let err = CalibrationFile::load(&path).unwrap_err().to_string();
    assert!(
        err.contains("bad.toml") && err.contains("gyro.bias_dps"),
        "{err}"
    );
    // Implausible values: each is refused naming the file and the field.
    type Spoil = fn(&mut CalibrationFile);
    let cases: [(&str, Spoil); 7] = [
        ("scale[0][0]", |f| f.scale[0][0] = 1e300),
        ("scale[0][0]", |f| f.scale[0][0] = -1.0),
        ("scale[1][2]", |f| f.scale[1][2] = 0.5),
        ("bias_g[2]", |f| f.bias_g[2] = 3.0),
        ("gyro.correction[0][0]", |f| {
            f.gyro.correction = Some([[0.0; 3]; 3])
        }),
        ("gyro.bias_dps[1]", |f| {
            f.gyro.bias_dps = Some([0.0, 400.0, 0.0])
        }),
        ("covariance[4][4]", |f| f.covariance[4][4] = -1e-6),
    ];
    for (field, spoil) in cases {
        let mut f = example();
        spoil(&mut f);
        std::fs::write(&path, f.to_toml()).unwrap();
        let err = CalibrationFile::load(&path).unwrap_err().to_string();
        assert!(
            err.contains("bad.toml") && err.contains(field),
            "{field}: {err}"
        );
    }
    // Entries each within bounds that together make a badly conditioned matrix.
    let mut f = example();
    f.gyro.correction = Some([[0.8, 0.1, 0.1], [0.1, 0.8, -0.1], [0.1, 0.1, 1.2]]);
    let b = plausibility::PLAUSIBLE;
    let m = f.gyro.correction.unwrap();
    let err = plausibility::near_identity("m", &m, &b).unwrap_err();
    assert!(err.contains("condition number"), "{err}");
    let good = dir.join("good.toml");
    example().save(&good).unwrap();
    assert_eq!(CalibrationFile::load(&good).unwrap(), example());
    std::fs::remove_dir_all(&dir).unwrap();
}
