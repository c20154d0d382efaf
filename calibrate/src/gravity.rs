//! The local gravity a calibration or noise file may state.

/// The local gravity a file may state, m/s^2: every place on the Earth's surface. Normal
/// gravity at sea level runs from 9.7803 (equator) to 9.8322 (poles) (WGS 84, Somigliana's
/// formula) and falls by 3.1e-6 m/s^2 per metre of height; the lowest surface value, on the
/// summit of Huascaran (6768 m, 9 deg S), is 9.7639 and the highest, on the Arctic Ocean, 9.8337.
/// A value outside is a typo or a damaged file (1e6, 9.81e3 in mm/s^2, 1.0 in g).
pub const GRAVITY_RANGE_MPS2: (f64, f64) = (9.76, 9.84);

/// Checks that `value` (a local gravity, m/s^2) is within [`GRAVITY_RANGE_MPS2`]; the error
/// says what is wrong with the value, for the caller to name where it came from.
pub fn check_gravity(value: f64) -> Result<(), String> {
    let (lo, hi) = GRAVITY_RANGE_MPS2;
    if value >= lo && value <= hi {
        return Ok(());
    }
    Err(format!(
        "{value:?} m/s^2 is not the gravity of any place on Earth ({lo} to {hi} m/s^2)"
    ))
}
