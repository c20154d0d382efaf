#!/usr/bin/env python3
"""Lag between a recording's speed hints and its IMU's forward acceleration, by
cross-correlation.

Reads ID.mcap from the converted data (JSON messages on mems/imu/raw and mems/robot/hint) and
the IMU's forward axis in the sensor frame (given per recording below, from the sidecar's
source_format notes). Both signals are put on a common 50 Hz grid (linear interpolation): the
hint speed's rate of change (central differences, m/s^2) and the specific force along the
forward axis (m/s^2); each is smoothed by a 0.2 s moving mean and has its 5 s moving mean
removed (slow tilt and bias). The lag is where the normalized cross-correlation
corr(a_fwd(t), ds/dt(t + lag)) peaks over -1..+1 s: a positive lag means the hints describe
the motion that late (the hint's sample time is late by that much).

Usage: hint_lag.py [--data DIR] ID ...
"""
import argparse
import json
import os
import sys

import numpy as np
from mcap.reader import make_reader

FORWARD = {
    "f1tenth": np.array([0.0, -1.0, 0.0]),  # the VESC's -y points forward
    "husky": np.array([0.0, 0.0, -1.0]),  # +y up, -z forward
    "comma2k19": np.array([1.0, 0.0, 0.0]),  # [forward, right, down]
}
G = 9.80665
RATE = 50.0


def read(path):
    imu, hint = [], []
    with open(path, "rb") as f:
        for _, ch, msg in make_reader(f).iter_messages():
            d = json.loads(msg.data)
            t = d["stamps"]["sample_ns"] * 1e-9
            if ch.topic == "mems/imu/raw":
                imu.append((t, *d["accel_g"]))
            elif ch.topic == "mems/robot/hint" and d["flags"] & 8:  # SPEED_VALID (ipc_types::hint_flags)
                hint.append((t, d["forward_speed_mps"]))
    return np.array(imu), np.array(hint)


def smooth(x, seconds):
    n = max(1, int(round(seconds * RATE)))
    return np.convolve(x, np.ones(n) / n, mode="same")


def lag(rec_id, data):
    fwd = next(v for k, v in FORWARD.items() if rec_id.startswith(k))
    imu, hint = read(os.path.join(data, rec_id + ".mcap"))
    t0, t1 = max(imu[0, 0], hint[0, 0]), min(imu[-1, 0], hint[-1, 0])
    t = np.arange(t0, t1, 1.0 / RATE)
    a = np.interp(t, imu[:, 0], imu[:, 1:] @ fwd) * G
    s = np.interp(t, hint[:, 0], hint[:, 1])
    ds = np.gradient(s, t)
    a, ds = (smooth(x, 0.2) - smooth(x, 5.0) for x in (a, ds))
    lags = np.arange(-int(RATE), int(RATE) + 1)
    n = len(t)
    corr = []
    for k in lags:
        x, y = (a[: n - k], ds[k:]) if k >= 0 else (a[-k:], ds[: n + k])
        corr.append(np.corrcoef(x, y)[0, 1])
    corr = np.array(corr)
    best = int(np.argmax(corr))
    return lags[best] / RATE, corr[best], corr[int(RATE)]


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", default=os.environ.get("MEMS_REAL_DATA", "/work/real-data"))
    p.add_argument("ids", nargs="+")
    args = p.parse_args()
    for rec_id in args.ids:
        best, peak, at_zero = lag(rec_id, args.data)
        print(f"{rec_id}: lag {best:+.2f} s (correlation {peak:.2f}; at 0 s {at_zero:.2f})")


if __name__ == "__main__":
    sys.exit(main())
