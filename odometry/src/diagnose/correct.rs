//! The selected effects written into a calibration file, so that a rerun of the odometry
//! (`mems-odometry offline --calib`) models them: the accelerometer's through its reading model
//! `a' = S a + b + c_b (T - T_ref)` (g, `calibrate::calibfile`), the gyro's through its
//! correction `omega = C w` (`[gyro] correction`).
//!
//! The diagnosis measures the effects in the calibrated output `a_c` (what the file's current
//! correction gives, in g after dividing by its gravity): `a_c = (I + diag(s)) a + beta +
//! c (T - T_ref)`. Put into `a' = S a_c + b`, that is `S' = S (I + diag(s))`, `b' = b + S beta`
//! and a temperature bias `S c`. For the gyro, `omega_true = (I + diag(k)) C w` gives
//! `C' = (I + diag(k)) C`. A file whose temperature terms also change the scale keeps them as
//! they are (their product with the new scale's small change is neglected).

use calibrate::calibfile::CalibrationFile;
use nalgebra::{Matrix3, Vector3};

use super::rows::Candidate;

fn matrix(m: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| m[r][c])
}

fn rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// `file` with the effects `selected` (each candidate and its three parameters, in the units
/// of [`Candidate::unit`]) put into it; `t_ref_c` is the temperature candidate's reference.
pub fn apply(
    file: &CalibrationFile,
    selected: &[(Candidate, Vector3<f64>)],
    t_ref_c: f64,
) -> CalibrationFile {
    let mut out = file.clone();
    let g = file.gravity_mps2;
    let s = matrix(&file.scale);
    let mut bias = Vector3::from(file.bias_g);
    let mut scale = s;
    for &(candidate, p) in selected {
        match candidate {
            Candidate::AccelBias => bias += s * (p / g),
            Candidate::AccelScale => {
                scale = s * Matrix3::from_diagonal(&(Vector3::repeat(1.0) + p));
            }
            Candidate::AccelTempBias => {
                let per_c = s * (p / g);
                let reference = file.temperature.reference_c.unwrap_or(t_ref_c);
                // c (T - T_ref) = c (T - reference) + c (reference - T_ref).
                bias += per_c * (reference - t_ref_c);
                let old = Vector3::from(file.temperature.bias_g_per_c.unwrap_or([0.0; 3]));
                out.temperature.reference_c = Some(reference);
                out.temperature.bias_g_per_c = Some((old + per_c).into());
            }
            Candidate::GyroScale => {
                let c = file
                    .gyro
                    .correction
                    .map_or(Matrix3::identity(), |c| matrix(&c));
                let k = Matrix3::from_diagonal(&(Vector3::repeat(1.0) + p));
                out.gyro.correction = Some(rows(&(k * c)));
            }
        }
    }
    out.bias_g = bias.into();
    out.scale = rows(&scale);
    out
}
