//! The selected effects written into a calibration file, so that a rerun of the odometry
//! (`mems-odometry offline --calib`) models them: the accelerometer's through its reading model
//! `a' = S a + b + c_b (T - T_ref)` (g, `calibrate::calibfile`), the gyro's (scale,
//! cross-axis, rotation) through its correction `omega = C w` (`[gyro] correction`).
//!
//! The diagnosis measures the effects in the calibrated output `a_c` (what the file's current
//! correction gives, in g after dividing by its gravity): `a_c = (I + diag(s)) a + beta +
//! c (T - T_ref)`. Put into `a' = S a_c + b`, that is `S' = S (I + diag(s))`, `b' = b + S beta`
//! and a temperature bias `S c`. For the gyro, `omega_true = (I + N) C w` gives
//! `C' = (I + N) C`, each selected gyro candidate's `N` in turn
//! (`Candidate::gyro_perturbation`). A file whose temperature terms also change the scale keeps them as
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
    let s = matrix(&file.scale);
    let mut bias = Vector3::from(file.bias_g);
    let mut scale = s;
    for &(candidate, p) in selected {
        match candidate {
            Candidate::AccelBias => bias += file.raw_bias_g(&p),
            Candidate::AccelScale => {
                scale = s * Matrix3::from_diagonal(&(Vector3::repeat(1.0) + p));
            }
            Candidate::AccelTempBias => {
                let per_c = file.raw_bias_g(&p);
                let reference = file.temperature.reference_c.unwrap_or(t_ref_c);
                // c (T - T_ref) = c (T - reference) + c (reference - T_ref).
                bias += per_c * (reference - t_ref_c);
                let old = Vector3::from(file.temperature.bias_g_per_c.unwrap_or([0.0; 3]));
                out.temperature.reference_c = Some(reference);
                out.temperature.bias_g_per_c = Some((old + per_c).into());
            }
            Candidate::GyroScale | Candidate::GyroCrossAxis | Candidate::GyroRotation => {
                let c = out
                    .gyro
                    .correction
                    .map_or(Matrix3::identity(), |c| matrix(&c));
                let n = Matrix3::identity() + candidate.gyro_perturbation(&p);
                out.gyro.correction = Some(rows(&(n * c)));
            }
            // No calibration term restores what a clip hid; the lag is removed from the
            // rerun's samples (`offline --accel-lag-s`), not by the file.
            Candidate::GyroSaturation | Candidate::AccelLag => {}
        }
    }
    out.bias_g = bias.into();
    out.scale = rows(&scale);
    out
}

#[cfg(test)]
mod tests {
    use approx::assert_relative_eq;

    use super::*;

    /// What the calibration stage makes of reading `a'` (g) with `file` (no temperature):
    /// `S^-1 (a' - b)`.
    fn corrected(file: &CalibrationFile, reading: Vector3<f64>) -> Vector3<f64> {
        let s = matrix(&file.scale);
        s.try_inverse().unwrap() * (reading - Vector3::from(file.bias_g))
    }

    #[test]
    fn bias_and_scale_found_in_the_output_are_undone() {
        let mut file = CalibrationFile::identity(9.8);
        file.scale = [[1.01, 0.002, 0.0], [0.0, 0.99, 0.0], [0.0, 0.0, 1.0]];
        file.bias_g = [0.01, 0.0, -0.02];
        let (s, beta) = (
            Vector3::new(0.02, -0.01, 0.005),
            Vector3::new(0.003, -0.004, 0.001),
        );
        let truth = Vector3::new(0.3, -0.5, 0.8);
        // A part whose calibrated output reads (I + diag(s)) a + beta.
        let output = truth.component_mul(&(Vector3::repeat(1.0) + s)) + beta;
        let reading = matrix(&file.scale) * output + Vector3::from(file.bias_g);
        let effects = [
            (Candidate::AccelBias, beta * 9.8),
            (Candidate::AccelScale, s),
        ];
        let fixed = apply(&file, &effects, f64::NAN);
        assert_relative_eq!(corrected(&fixed, reading), truth, epsilon = 1e-12);
    }

    #[test]
    fn gyro_scale_multiplies_the_correction() {
        let mut file = CalibrationFile::identity(9.8);
        file.gyro.correction = Some([[0.98, 0.01, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.02]]);
        let k = Vector3::new(0.05, -0.02, 0.0);
        let fixed = apply(&file, &[(Candidate::GyroScale, k)], f64::NAN);
        let c = matrix(&file.gyro.correction.unwrap());
        let expected = Matrix3::from_diagonal(&(Vector3::repeat(1.0) + k)) * c;
        assert_relative_eq!(
            matrix(&fixed.gyro.correction.unwrap()),
            expected,
            epsilon = 1e-12
        );
    }

    #[test]
    fn gyro_cross_axis_and_rotation_compose_with_the_scale() {
        let file = CalibrationFile::identity(9.8);
        let (k, m, phi) = (
            Vector3::new(0.02, 0.0, 0.0),
            Vector3::new(0.0, 0.0, 0.03),
            Vector3::new(0.0, 0.0, 0.01),
        );
        let fixed = apply(
            &file,
            &[
                (Candidate::GyroScale, k),
                (Candidate::GyroCrossAxis, m),
                (Candidate::GyroRotation, phi),
            ],
            f64::NAN,
        );
        let expected = (Matrix3::identity() + phi.cross_matrix())
            * Matrix3::new(1.0, 0.03, 0.0, 0.03, 1.0, 0.0, 0.0, 0.0, 1.0)
            * Matrix3::from_diagonal(&Vector3::new(1.02, 1.0, 1.0));
        assert_relative_eq!(
            matrix(&fixed.gyro.correction.unwrap()),
            expected,
            epsilon = 1e-12
        );
        // phi x w: a rate about x gains a part about y for a rotation about z.
        assert_relative_eq!(expected[(1, 0)], (0.03 + 0.01) * 1.02, epsilon = 1e-12);
    }

    #[test]
    fn a_temperature_bias_keeps_the_file_reference() {
        let mut file = CalibrationFile::identity(9.8);
        file.temperature.reference_c = Some(30.0);
        let c = Vector3::new(0.0098, 0.0, 0.0); // m/s^2/degC: 1 mg/degC
        let fixed = apply(&file, &[(Candidate::AccelTempBias, c)], 25.0);
        assert_eq!(fixed.temperature.reference_c, Some(30.0));
        assert_relative_eq!(
            fixed.temperature.bias_g_per_c.unwrap()[0],
            1e-3,
            epsilon = 1e-12
        );
        // c (T - 25) = c (T - 30) + 5 c: 5 mg into the bias.
        assert_relative_eq!(fixed.bias_g[0], 5e-3, epsilon = 1e-12);
    }
}
