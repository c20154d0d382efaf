//! The Python ctypes mirror (`python/mems_ipc.py`) has the Rust layout: python3 prints every
//! struct's size, alignment and field offsets and its type name, and each must equal Rust's.

mod flag_list;
mod python_run;

use core::mem::{align_of, offset_of, size_of};
use iceoryx2::prelude::ZeroCopySend;
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint, Stamps};
use python_run::run_python;

/// `name size align type_name field:offset ...` for one type, as the Python script prints it.
macro_rules! rust_line {
    ($t:ty, $py:literal, [$($field:ident),+]) => {{
        // SAFETY: the derived `type_name` returns the static `#[type_name]` string.
        let type_name = unsafe { <$t>::type_name() };
        let mut line = format!("{} {} {} {}", $py, size_of::<$t>(), align_of::<$t>(), type_name);
        $( line.push_str(&format!(" {}:{}", stringify!($field), offset_of!($t, $field))); )+
        line
    }};
}

#[test]
fn python_ctypes_match_rust_layout() {
    let expected = [
        rust_line!(
            Stamps,
            "Stamps",
            [sample_ns, acquired_ns, calibrated_ns, odometry_ns]
        ),
        rust_line!(
            RawImuSample,
            "RawImuSample",
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
        ),
        rust_line!(
            CorrectedImuSample,
            "CorrectedImuSample",
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
        ),
        rust_line!(
            OdometryState,
            "OdometryState",
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
        ),
        rust_line!(
            RobotHint,
            "RobotHint",
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
        ),
    ];
    let script = r#"
import ctypes, sys
sys.path.insert(0, sys.argv[1])
import mems_ipc
for t in mems_ipc.ALL_TYPES:
    fields = " ".join(f"{n}:{getattr(t, n).offset}" for n, _ in t._fields_)
    print(t.__name__, ctypes.sizeof(t), ctypes.alignment(t), t.type_name(), fields)
"#;
    let stdout = run_python(script, &[]);
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines, expected);
}

#[test]
fn python_flags_match_rust() {
    // Every RAW_/CORRECTED_/ODOMETRY_/HINT_ constant the module defines, so that one Rust
    // lacks is caught too.
    let script = r#"
import sys
sys.path.insert(0, sys.argv[1])
import mems_ipc
for name in sorted(dir(mems_ipc)):
    if name.split("_")[0] in ("RAW", "CORRECTED", "ODOMETRY", "HINT") and isinstance(getattr(mems_ipc, name), int):
        print(name, getattr(mems_ipc, name))
"#;
    let stdout = run_python(script, &[]);
    let mut expected: Vec<String> = flag_list::all()
        .iter()
        .map(|(name, value)| format!("{name} {value}"))
        .collect();
    expected.sort();
    assert_eq!(stdout.lines().collect::<Vec<_>>(), expected);
}
