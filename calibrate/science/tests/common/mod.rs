//! What the calibration tests on simulated parts share.

use calibrate::model::{AccelModel, ModelKind};
use mems_sim::model::TriadModel;
use nalgebra::{Matrix3, Vector3};

/// The true model `a' = S a + b` of a simulated accelerometer triad: `S` has `1 + scale` on its
/// diagonal and the misalignment off it, `b` is the bias (g).
pub fn true_model(t: &TriadModel) -> AccelModel {
    let s = Matrix3::from_fn(|r, c| {
        if r == c {
            1.0 + t.scale[r]
        } else {
            t.misalignment[r][c]
        }
    });
    AccelModel::new(ModelKind::Full, s, Vector3::from(t.bias)).unwrap()
}
