#!/usr/bin/env python3
"""The error of fitted gyro corrections against a simulated part's own gyro model.

    mems-sim print-model --preset datasheet > model.toml
    mems-calibrate gyrocal --input session.mcap --calib calib.toml --json > fit.json
    python3 calibrate/science/scripts/gyrocal_error.py model.toml fit.json [fit2.json ...]

For each fit: the largest entry error of `correction` against the inverse of the model's
`I + diag(gyro.scale) + gyro.misalignment` (what a perfect calibration gives when the
accelerometer's fit leaves no residual misalignment), absolute and in the fit's own 1-sigma
(`correction_sigma`). Plain Python 3.11 (tomllib), no numpy.
"""
import json
import sys
import tomllib


def inverse3(a):
    """The inverse of a 3 x 3 matrix (list of rows) by its adjugate."""
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = a
    det = a0 * (b1 * c2 - b2 * c1) - a1 * (b0 * c2 - b2 * c0) + a2 * (b0 * c1 - b1 * c0)
    adj = [
        [b1 * c2 - b2 * c1, a2 * c1 - a1 * c2, a1 * b2 - a2 * b1],
        [b2 * c0 - b0 * c2, a0 * c2 - a2 * c0, a2 * b0 - a0 * b2],
        [b0 * c1 - b1 * c0, a1 * c0 - a0 * c1, a0 * b1 - a1 * b0],
    ]
    return [[adj[i][k] / det for k in range(3)] for i in range(3)]


def main(model_path, fits):
    gyro = tomllib.load(open(model_path, "rb"))["gyro"]
    s, m = gyro["scale"], gyro["misalignment"]
    reference = inverse3([[(1.0 + s[i] if i == k else 0.0) + m[i][k] for k in range(3)] for i in range(3)])
    for path in fits:
        fit = json.load(open(path))
        c, sigma = fit["correction"], fit["correction_sigma"]
        cells = [(i, k) for i in range(3) for k in range(3)]
        error = max(abs(c[i][k] - reference[i][k]) for i, k in cells)
        z = max(abs(c[i][k] - reference[i][k]) / sigma[i][k] for i, k in cells)
        print(f"{path}: {fit.get('poses')} poses, largest entry error {error:.1e} ({z:.1f} sigma)")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2:])
