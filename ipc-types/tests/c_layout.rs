//! Compiles a C program against `include/mems_ipc.h` with gcc and checks that every size,
//! alignment, field offset, flag value, service name and type name agrees with the Rust types.

use core::mem::{align_of, offset_of, size_of};
use ipc_types::{
    CorrectedImuSample, OdometryState, RawImuSample, RobotHint, Stamps, corrected_flags,
    hint_flags, odometry_flags, raw_flags, service,
};
use std::fmt::Write as _;
use std::process::Command;

/// One fact to compare: the C expression to print and the value Rust says it must have.
struct Fact {
    c_expr: String,
    rust: String,
}

/// Builds the facts for one struct: its size and alignment, and each field's offset.
macro_rules! layout_facts {
    ($facts:ident, $rust:ty, $c:literal, [$($field:ident),+ $(,)?]) => {
        $facts.push(Fact { c_expr: format!("sizeof({})", $c), rust: size_of::<$rust>().to_string() });
        $facts.push(Fact { c_expr: format!("_Alignof({})", $c), rust: align_of::<$rust>().to_string() });
        $(
            $facts.push(Fact {
                c_expr: format!("offsetof({}, {})", $c, stringify!($field)),
                rust: offset_of!($rust, $field).to_string(),
            });
        )+
    };
}

fn facts() -> Vec<Fact> {
    let mut f = Vec::new();
    layout_facts!(
        f,
        Stamps,
        "mems_stamps",
        [sample_ns, acquired_ns, calibrated_ns, odometry_ns]
    );
    layout_facts!(
        f,
        RawImuSample,
        "mems_raw_imu_sample",
        [
            stamps,
            seq,
            accel_g,
            gyro_dps,
            temp_c,
            accel_counts,
            gyro_counts,
            temp_counts,
            flags,
            lost_before,
            undelivered
        ]
    );
    layout_facts!(
        f,
        CorrectedImuSample,
        "mems_corrected_imu_sample",
        [
            stamps,
            seq,
            accel_mps2,
            gyro_rps,
            temp_c,
            zs_mean_mps2,
            zs_std_mps2,
            calib_id,
            flags,
            raw_flags,
            settles
        ]
    );
    layout_facts!(
        f,
        OdometryState,
        "mems_odometry_state",
        [
            stamps,
            seq,
            position_m,
            position_sigma_m,
            velocity_mps,
            velocity_sigma_mps,
            gravity_sensor_mps2,
            attitude_wxyz,
            distance_m,
            flags,
            reserved16,
            rest_count,
            hints_applied,
            hint_disagreements
        ]
    );
    layout_facts!(
        f,
        RobotHint,
        "mems_robot_hint",
        [
            stamps,
            seq,
            forward_speed_mps,
            forward_speed_sigma_mps,
            yaw_rate_rps,
            yaw_rate_sigma_rps,
            flags,
            reserved16,
            reserved
        ]
    );
    let flags: [(&str, u16); 32] = [
        ("MEMS_RAW_GAP_BEFORE", raw_flags::GAP_BEFORE),
        ("MEMS_RAW_FIFO_OVERFLOW", raw_flags::FIFO_OVERFLOW),
        ("MEMS_RAW_SATURATED", raw_flags::SATURATED),
        ("MEMS_RAW_REPAIRED", raw_flags::REPAIRED),
        ("MEMS_RAW_GYRO_VALID", raw_flags::GYRO_VALID),
        ("MEMS_RAW_TEMP_VALID", raw_flags::TEMP_VALID),
        ("MEMS_RAW_RESUMED", raw_flags::RESUMED),
        ("MEMS_RAW_SATURATED_AXES", raw_flags::SATURATED_AXES),
        ("MEMS_CORRECTED_ZERO_STATE", corrected_flags::ZERO_STATE),
        (
            "MEMS_CORRECTED_DETECTOR_READY",
            corrected_flags::DETECTOR_READY,
        ),
        ("MEMS_CORRECTED_BIAS_REFINED", corrected_flags::BIAS_REFINED),
        ("MEMS_CORRECTED_PROVISIONAL", corrected_flags::PROVISIONAL),
        ("MEMS_CORRECTED_NEW_SESSION", corrected_flags::NEW_SESSION),
        ("MEMS_CORRECTED_HOLE_BEFORE", corrected_flags::HOLE_BEFORE),
        ("MEMS_CORRECTED_CLIPPED", corrected_flags::CLIPPED),
        ("MEMS_CORRECTED_IMPLAUSIBLE", corrected_flags::IMPLAUSIBLE),
        ("MEMS_CORRECTED_GRAVITY_OFF", corrected_flags::GRAVITY_OFF),
        ("MEMS_ODOMETRY_ZERO_VELOCITY", odometry_flags::ZERO_VELOCITY),
        ("MEMS_ODOMETRY_ALIGNED", odometry_flags::ALIGNED),
        ("MEMS_ODOMETRY_REVISION", odometry_flags::REVISION),
        (
            "MEMS_ODOMETRY_HINT_STATIONARY",
            odometry_flags::HINT_STATIONARY,
        ),
        ("MEMS_ODOMETRY_HINT_SPEED", odometry_flags::HINT_SPEED),
        ("MEMS_ODOMETRY_HINT_STALE", odometry_flags::HINT_STALE),
        ("MEMS_ODOMETRY_HINT_DISAGREE", odometry_flags::HINT_DISAGREE),
        ("MEMS_ODOMETRY_NO_GYRO", odometry_flags::NO_GYRO),
        ("MEMS_ODOMETRY_GAP_BEFORE", odometry_flags::GAP_BEFORE),
        (
            "MEMS_ODOMETRY_UNTRUSTED_INPUT",
            odometry_flags::UNTRUSTED_INPUT,
        ),
        ("MEMS_HINT_STATIONARY", hint_flags::STATIONARY),
        ("MEMS_HINT_SOURCE_COMMANDED", hint_flags::SOURCE_COMMANDED),
        ("MEMS_HINT_SOURCE_ENCODERS", hint_flags::SOURCE_ENCODERS),
        ("MEMS_HINT_SPEED_VALID", hint_flags::SPEED_VALID),
        ("MEMS_HINT_YAW_RATE_VALID", hint_flags::YAW_RATE_VALID),
    ];
    for (name, value) in flags {
        f.push(Fact {
            c_expr: format!("(unsigned)({name})"),
            rust: value.to_string(),
        });
    }
    f
}

/// Strings the header must spell exactly as Rust does: (C macro, Rust value).
fn strings() -> Vec<(&'static str, String)> {
    use iceoryx2::prelude::ZeroCopySend;
    let name = |n: &str| n.to_string();
    // SAFETY (every call): the derived `type_name` only returns the static string given
    // by `#[type_name]`; it is unsafe because implementations must keep it stable.
    vec![
        ("MEMS_SERVICE_RAW", service::RAW.to_string()),
        ("MEMS_SERVICE_CORRECTED", service::CORRECTED.to_string()),
        ("MEMS_SERVICE_ODOMETRY", service::ODOMETRY.to_string()),
        ("MEMS_SERVICE_HINT", service::HINT.to_string()),
        (
            "MEMS_TYPE_NAME_RAW",
            name(unsafe { RawImuSample::type_name() }),
        ),
        (
            "MEMS_TYPE_NAME_CORRECTED",
            name(unsafe { CorrectedImuSample::type_name() }),
        ),
        (
            "MEMS_TYPE_NAME_ODOMETRY",
            name(unsafe { OdometryState::type_name() }),
        ),
        (
            "MEMS_TYPE_NAME_HINT",
            name(unsafe { RobotHint::type_name() }),
        ),
    ]
}

#[test]
fn c_header_matches_rust_layout() {
    let facts = facts();
    let strings = strings();
    let mut program = String::from(
        "#include <stddef.h>\n#include <stdio.h>\n#include \"mems_ipc.h\"\nint main(void) {\n",
    );
    for fact in &facts {
        writeln!(
            program,
            "    printf(\"%zu\\n\", (size_t)({}));",
            fact.c_expr
        )
        .unwrap();
    }
    for (macro_name, _) in &strings {
        writeln!(program, "    printf(\"%s\\n\", {macro_name});").unwrap();
    }
    program.push_str("    return 0;\n}\n");

    let dir = std::env::temp_dir().join(format!("mems-c-layout-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let source = dir.join("layout.c");
    let binary = dir.join("layout");
    std::fs::write(&source, &program).unwrap();
    let include = concat!(env!("CARGO_MANIFEST_DIR"), "/include");
    let status = Command::new("gcc")
        .args([
            "-std=c11", "-Wall", "-Wextra", "-Werror", "-I", include, "-o",
        ])
        .arg(&binary)
        .arg(&source)
        .status()
        .expect("gcc must be installed to check the C header");
    assert!(status.success(), "gcc failed to compile the layout program");
    let output = Command::new(&binary).output().unwrap();
    assert!(output.status.success());
    let stdout = String::from_utf8(output.stdout).unwrap();
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), facts.len() + strings.len());
    for (fact, c_value) in facts.iter().zip(&lines) {
        assert_eq!(
            *c_value, fact.rust,
            "C says {} = {c_value}, Rust says {}",
            fact.c_expr, fact.rust
        );
    }
    for ((macro_name, rust), c_value) in strings.iter().zip(&lines[facts.len()..]) {
        assert_eq!(c_value, rust, "C macro {macro_name} differs from Rust");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
