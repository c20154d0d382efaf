//! Compiles a C program against `include/mems_ipc.h` with gcc and checks that every size,
//! alignment, field offset, flag value, service name and type name agrees with the Rust types.

mod flag_list;

use core::mem::{align_of, offset_of, size_of};
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint, Stamps, service};
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
            settles,
            refined_accel_mps2,
            refined_gyro_rps
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
    for (name, value) in flag_list::all() {
        f.push(Fact {
            c_expr: format!("(unsigned)(MEMS_{name})"),
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
