//! Every flag bit of the wire format, as the C header and the Python mirror name it (without
//! the C `MEMS_` prefix), shared by the two layout tests. [`all`] checks itself against the
//! `*_flags` modules of `src/wire.rs`, so a flag added there and not here fails both tests.

use ipc_types::{corrected_flags, hint_flags, odometry_flags, raw_flags};

macro_rules! flags {
    ($($prefix:literal $module:ident [$($name:ident),+]),+) => {
        vec![$($((concat!($prefix, "_", stringify!($name)), $module::$name)),+),+]
    };
}

/// (name, value) of every flag: `RAW_GAP_BEFORE`, ...; panics naming any flag of
/// `src/wire.rs` the list lacks.
pub fn all() -> Vec<(&'static str, u16)> {
    let all = listed();
    let missing = undeclared(&all);
    assert!(
        missing.is_empty(),
        "flags of src/wire.rs not in tests/flag_list: {missing:?}"
    );
    all
}

fn listed() -> Vec<(&'static str, u16)> {
    flags!(
        "RAW" raw_flags [GAP_BEFORE, FIFO_OVERFLOW, SATURATED, REPAIRED, GYRO_VALID, TEMP_VALID,
            RESUMED, SATURATED_AXES],
        "CORRECTED" corrected_flags [ZERO_STATE, DETECTOR_READY, BIAS_REFINED, PROVISIONAL,
            NEW_SESSION, HOLE_BEFORE, CLIPPED, IMPLAUSIBLE, GRAVITY_OFF],
        "ODOMETRY" odometry_flags [ZERO_VELOCITY, ALIGNED, REVISION, HINT_STATIONARY, HINT_SPEED,
            HINT_STALE, HINT_DISAGREE, NO_GYRO, GAP_BEFORE, UNTRUSTED_INPUT, REST_VIBRATING,
            NONHOLONOMIC_REJECTED, REST_MOVING, VIBRATING_STOP],
        "HINT" hint_flags [STATIONARY, SOURCE_COMMANDED, SOURCE_ENCODERS, SPEED_VALID,
            YAW_RATE_VALID]
    )
}

/// The flags `src/wire.rs` declares (`pub const NAME` inside `pub mod X_flags`) that
/// `listed` does not hold.
fn undeclared(listed: &[(&str, u16)]) -> Vec<String> {
    let wire = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/src/wire.rs"))
        .expect("src/wire.rs");
    let listed: Vec<&str> = listed.iter().map(|(n, _)| *n).collect();
    let (mut prefix, mut missing) = (None, Vec::new());
    for line in wire.lines().map(str::trim) {
        if let Some(m) = line.strip_prefix("pub mod ") {
            prefix = m.strip_suffix("_flags {").map(str::to_uppercase);
        } else if line == "}" {
            prefix = None;
        } else if let (Some(p), Some(c)) = (&prefix, line.strip_prefix("pub const ")) {
            // Constants only (`NAME: u16`), not `pub const fn`.
            let Some((name, _)) = c.split_once(':').filter(|_| !c.starts_with("fn ")) else {
                continue;
            };
            let name = format!("{p}_{name}");
            if !listed.contains(&name.as_str()) {
                missing.push(name);
            }
        }
    }
    missing
}
