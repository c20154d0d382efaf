use nalgebra::{DMatrix, Matrix3};

use crate::model::PARAM_NAMES;

/// Bounds on the parameters of a real part.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// Largest distance of a diagonal entry of `S` (or the gyroscope correction) from 1.
    pub scale_error: f64,
    /// Largest magnitude of an off-diagonal entry (cross-axis sensitivity, misalignment).
    pub cross_axis: f64,
    /// Largest condition number (largest over smallest singular value).
    pub condition: f64,
    /// Largest accelerometer bias per axis, g.
    pub accel_bias_g: f64,
    /// Largest gyroscope bias per axis, deg/s.
    pub gyro_bias_dps: f64,
}

/// The MPU-9250's tolerances (PS-MPU-9250A-01 rev 1.1, tables 3.1 and 3.2: sensitivity
/// +-3 %, cross-axis sensitivity +-2 %, zero-g offset +-60/+-80 mg, zero-rate offset
/// +-5 deg/s) widened several times for other parts, temperature and mounting: a file
/// beyond them holds a fit that failed or a damaged value.
pub const PLAUSIBLE: Bounds = Bounds {
    scale_error: 0.2,
    cross_axis: 0.1,
    condition: 1.5,
    accel_bias_g: 0.5,
    gyro_bias_dps: 50.0,
};

/// Relative tolerance of the covariance checks, as a fraction of its largest variance:
/// far above the rounding of a fit's `V diag(1/s^2) V^T` (1e-16) and of a TOML round trip
/// (exact), far below any real correlation.
const COVARIANCE_TOLERANCE: f64 = 1e-9;

/// Checks that the parameter covariance `c` (square, finite, rows in `PARAM_NAMES` order)
/// is symmetric and positive semi-definite, as every covariance is: a damaged or hand-made
/// one would give some combination of parameters a negative variance. The zero matrix of
/// an identity calibration passes.
pub fn covariance(c: &[Vec<f64>]) -> Result<(), String> {
    let n = c.len();
    let m = DMatrix::from_fn(n, n, |r, k| c[r][k]);
    let tol = COVARIANCE_TOLERANCE * m.diagonal().amax();
    for r in 0..n {
        for k in r + 1..n {
            if (m[(r, k)] - m[(k, r)]).abs() > tol {
                return Err(format!(
                    "covariance is not symmetric: covariance[{r}][{k}] = {:?} but \
                     covariance[{k}][{r}] = {:?}",
                    m[(r, k)],
                    m[(k, r)]
                ));
            }
        }
    }
    let eigen = m.symmetric_eigen();
    let (i, smallest) = eigen.eigenvalues.argmin();
    if smallest < -tol {
        let v = eigen.eigenvectors.column(i);
        let along: Vec<&str> = (0..n)
            .filter(|&k| v[k].abs() > 0.3)
            .map(|k| PARAM_NAMES.get(k).copied().unwrap_or("?"))
            .collect();
        return Err(format!(
            "covariance is not positive semi-definite: a combination of {} has the variance \
             {smallest:.3e} (no variance is negative)",
            along.join(" and ")
        ));
    }
    Ok(())
}

/// Whether `v` is a number of magnitude at most `limit` (false for NaN).
pub fn within(v: f64, limit: f64) -> bool {
    v.abs() <= limit
}

/// Checks that `m` (named `name`, row-major) is near the identity and well conditioned.
pub fn near_identity(name: &str, m: &[[f64; 3]; 3], b: &Bounds) -> Result<(), String> {
    for (r, row) in m.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            let (off, limit, what) = if r == c {
                (
                    (v - 1.0).abs(),
                    b.scale_error,
                    "a scale factor farther than",
                )
            } else {
                (v.abs(), b.cross_axis, "a cross-axis term larger than")
            };
            if !within(off, limit) {
                return Err(format!(
                    "{name}[{r}][{c}] = {v:?} is not plausible ({what} {limit} from the identity)"
                ));
            }
        }
    }
    let sv = Matrix3::from_fn(|r, c| m[r][c]).singular_values();
    let condition = sv.max() / sv.min();
    if !within(condition, b.condition) {
        return Err(format!(
            "{name} has condition number {condition:.3}, more than {}",
            b.condition
        ));
    }
    Ok(())
}
