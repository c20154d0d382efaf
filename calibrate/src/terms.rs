//! The reading terms a calibration file can add to `a' = S a + b`, and the correction that
//! undoes them: what `mems-calibrate diagnose --out` writes and the live stage applies.
//!
//! Units and conventions as in [`crate::model`] (readings and specific force in g, sensor frame).
//! With `dT = T_die - T_ref` (degC) and `t` the time since power-on (s, from the first sample of
//! a stream), the full reading model is
//!
//! ```text
//! a' = (S + diag(c_s) dT) a + b + c_b dT + r min(t, t_max) + w exp(-t / tau) + k o a o a
//! ```
//!
//! (`o` the element-wise product): `c_b` temperature bias (g/degC), `c_s` temperature change
//! of the scale diagonal (1/degC), `r` a linear bias drift (g/s) held constant after the
//! longest time the fit saw (`t_max`) rather than extrapolated, `w` a warm-up transient (g)
//! with time constant `tau` (s), `k` the quadratic scale nonlinearity (g/g^2). Absent terms are
//! zero.
//!
//! The correction solves that for `a`: with `y = a' - b - c_b dT - r min(t, t_max) - w
//! exp(-t / tau)` and `S_T = S + diag(c_s) dT`, `a = S_T^-1 (y - k o a o a)` by fixed-point
//! iteration from `a = S_T^-1 y`. The map contracts by about `2 |k| |a|` per step (|k| is a few
//! 1e-3 for an MPU-9250), so [`NONLINEARITY_ITERATIONS`] steps leave an error far below the
//! quantization step.

use nalgebra::{Matrix3, Vector3};

use crate::model::AccelModel;

/// Fixed-point steps of the nonlinearity inversion: each multiplies the error by about
/// `2 |k| |a|` (at most 0.04 for a 1% nonlinearity at 2 g), so 8 steps take the first step's
/// error of at most `|k| |a|^2` (4e-2 g) below 1e-12 g.
pub const NONLINEARITY_ITERATIONS: usize = 8;

/// Why the terms of a calibration file are inconsistent.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct TermsError(pub(crate) String);

/// The optional terms of a calibration file, ready to apply (see the module documentation).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ReadingTerms {
    /// Reference temperature `T_ref`, degC (present when any temperature term is).
    pub reference_c: Option<f64>,
    /// `c_b`, g/degC.
    pub temp_bias_g_per_c: Option<Vector3<f64>>,
    /// `c_s`, 1/degC.
    pub temp_scale_per_c: Option<Vector3<f64>>,
    /// `r` (g/s) and `t_max` (s).
    pub drift: Option<(Vector3<f64>, f64)>,
    /// `w` (g) and `tau` (s).
    pub warm_up: Option<(Vector3<f64>, f64)>,
    /// `k`, g/g^2.
    pub quadratic_g_per_g2: Option<Vector3<f64>>,
}

impl ReadingTerms {
    /// Whether the correction needs the die temperature.
    pub fn needs_temperature(&self) -> bool {
        self.reference_c.is_some()
    }

    /// The bias terms at temperature offset `d_temp` (degC; ignored without temperature terms)
    /// and time since power-on `t_s`, g: `c_b dT + r min(t, t_max) + w exp(-t / tau)`.
    pub fn bias_g(&self, d_temp: f64, t_s: f64) -> Vector3<f64> {
        let mut b = Vector3::zeros();
        if let Some(c) = self.temp_bias_g_per_c {
            b += c * d_temp;
        }
        if let Some((r, t_max)) = self.drift {
            b += r * t_s.clamp(0.0, t_max);
        }
        if let Some((w, tau)) = self.warm_up {
            b += w * (-t_s.max(0.0) / tau).exp();
        }
        b
    }

    /// The true specific force (g) for reading `raw_g` (g) under `model` at die temperature
    /// `temp_c` (degC; `None` is accepted only when no temperature term is present) and time
    /// since power-on `t_s` (s). See the module documentation.
    ///
    /// # Panics
    /// If temperature terms are present and `temp_c` is `None` (callers check first), or if
    /// the temperature-dependent scale matrix is singular (a temperature absurdly far from the
    /// reference).
    pub fn correct(
        &self,
        model: &AccelModel,
        raw_g: &Vector3<f64>,
        temp_c: Option<f64>,
        t_s: f64,
    ) -> Vector3<f64> {
        let d_temp = match self.reference_c {
            Some(t_ref) => temp_c.expect("temperature terms need the die temperature") - t_ref,
            None => 0.0,
        };
        let y = raw_g - model.bias_g() - self.bias_g(d_temp, t_s);
        let s_inv: Matrix3<f64> = match self.temp_scale_per_c {
            Some(c) => (model.scale() + Matrix3::from_diagonal(&(c * d_temp)))
                .try_inverse()
                .expect("S + diag(c_s) dT is invertible near the reference temperature"),
            None => *model.scale_inv(),
        };
        let mut a = s_inv * y;
        if let Some(k) = self.quadratic_g_per_g2 {
            for _ in 0..NONLINEARITY_ITERATIONS {
                a = s_inv * (y - k.component_mul(&a).component_mul(&a));
            }
        }
        a
    }

    /// The reading (g) the model predicts for true specific force `a_g` (g): the forward model
    /// that [`Self::correct`] inverts.
    pub fn measure(
        &self,
        model: &AccelModel,
        a_g: &Vector3<f64>,
        temp_c: Option<f64>,
        t_s: f64,
    ) -> Vector3<f64> {
        let d_temp = match self.reference_c {
            Some(t_ref) => temp_c.expect("temperature terms need the die temperature") - t_ref,
            None => 0.0,
        };
        let mut s = *model.scale();
        if let Some(c) = self.temp_scale_per_c {
            s += Matrix3::from_diagonal(&(c * d_temp));
        }
        let mut y = s * a_g + model.bias_g() + self.bias_g(d_temp, t_s);
        if let Some(k) = self.quadratic_g_per_g2 {
            y += k.component_mul(a_g).component_mul(a_g);
        }
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ModelKind;

    fn model() -> AccelModel {
        let s = Matrix3::new(
            1.01, 0.008, 0.009, -0.006, 0.995, 0.011, -0.010, -0.004, 1.022,
        );
        AccelModel::new(ModelKind::Full, s, Vector3::new(0.04, -0.035, 0.055)).unwrap()
    }

    fn all_terms() -> ReadingTerms {
        ReadingTerms {
            reference_c: Some(25.0),
            temp_bias_g_per_c: Some(Vector3::new(8e-4, -6e-4, 1.2e-3)),
            temp_scale_per_c: Some(Vector3::new(2.6e-4, -2e-4, 2.6e-4)),
            drift: Some((Vector3::new(1e-5, -2e-5, 3e-5), 60.0)),
            warm_up: Some((Vector3::new(0.01, -0.005, 0.02), 20.0)),
            quadratic_g_per_g2: Some(Vector3::new(0.01, -0.01, 0.005)),
        }
    }

    #[test]
    fn correction_inverts_the_forward_model_with_every_term() {
        let (m, terms) = (model(), all_terms());
        for (a, temp, t) in [
            (Vector3::new(0.3, -0.5, 0.81), 31.0, 5.0),
            (Vector3::new(-1.0, 0.0, 0.0), 18.5, 120.0),
            (Vector3::new(0.0, 0.0, 1.0), 25.0, 0.0),
        ] {
            let reading = terms.measure(&m, &a, Some(temp), t);
            let back = terms.correct(&m, &reading, Some(temp), t);
            assert!((back - a).norm() < 1e-12, "{back} vs {a}");
        }
    }

    #[test]
    fn each_term_has_its_stated_effect_on_the_reading() {
        let m = AccelModel::identity(ModelKind::Full);
        let a = Vector3::new(0.0, 0.6, 0.8);
        let base = ReadingTerms::default();
        let plain = base.measure(&m, &a, None, 0.0);
        assert_eq!(plain, a);
        // Temperature bias: c_b dT.
        let t = ReadingTerms {
            reference_c: Some(20.0),
            temp_bias_g_per_c: Some(Vector3::new(1e-3, 0.0, 0.0)),
            ..base
        };
        assert!(
            (t.measure(&m, &a, Some(30.0), 0.0) - a - Vector3::new(0.01, 0.0, 0.0)).norm() < 1e-15
        );
        // Temperature scale: c_s dT a (the diagonal of S changes).
        let t = ReadingTerms {
            reference_c: Some(20.0),
            temp_scale_per_c: Some(Vector3::new(0.0, 1e-3, 1e-3)),
            ..base
        };
        let got = t.measure(&m, &a, Some(30.0), 0.0) - a;
        assert!((got - Vector3::new(0.0, 0.006, 0.008)).norm() < 1e-15);
        // Drift, held after t_max.
        let t = ReadingTerms {
            drift: Some((Vector3::new(0.0, 0.0, 1e-4), 50.0)),
            ..base
        };
        assert!((t.measure(&m, &a, None, 10.0).z - a.z - 1e-3).abs() < 1e-15);
        assert!((t.measure(&m, &a, None, 500.0).z - a.z - 5e-3).abs() < 1e-15);
        // Warm-up: w at power-on, w / e after one time constant.
        let t = ReadingTerms {
            warm_up: Some((Vector3::new(0.02, 0.0, 0.0), 10.0)),
            ..base
        };
        assert!((t.measure(&m, &a, None, 0.0).x - 0.02).abs() < 1e-15);
        assert!((t.measure(&m, &a, None, 10.0).x - 0.02 / std::f64::consts::E).abs() < 1e-15);
        // Nonlinearity: k a_i^2.
        let t = ReadingTerms {
            quadratic_g_per_g2: Some(Vector3::new(0.0, 0.01, 0.01)),
            ..base
        };
        let got = t.measure(&m, &a, None, 0.0) - a;
        assert!((got - Vector3::new(0.0, 0.0036, 0.0064)).norm() < 1e-15);
    }
}
