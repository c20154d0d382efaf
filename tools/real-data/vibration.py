#!/usr/bin/env python3
"""Vibration of the corpus's wheeled robots standing, creeping and driving, by their own wheel
speeds: the figures behind the simulator's vibration floor (tools/sim/src/vibration.rs).

For every converted recording with speed hints (the MCAPs convert.py writes, from the data
directory, default $MEMS_REAL_DATA or /work/real-data), the IMU samples are cut into windows of
1 s; each window's vibration is the standard deviation of the three accelerometer axes together
(sqrt of the sum of the per-axis variances, mg) and of the three gyroscope axes (deg/s). It
includes the window's own motion (a turn, a change of speed), so it is an upper bound on
vibration while driving. A window is *standing* when every hint in it says 0 m/s, *slow* when
they all say 0.03-0.3 m/s and *driving* when they all say more than 0.3 m/s. Printed per
recording and class: windows, median and 10-90 % range.
"""

import argparse
import bisect
import json
import math
import os
import statistics
import struct
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from containers import read_mcap_records  # noqa: E402

RECORDINGS = ["husky-parking-lot", "f1tenth-ds1", "f1tenth-ds3", "f1tenth-ds4", "f1tenth-ds5"]
CLASSES = [("standing", 0.0, 0.0), ("slow 0.03-0.3 m/s", 0.03, 0.3), ("driving > 0.3 m/s", 0.3, math.inf)]


def read(path):
    """(samples [t s, ax, ay, az g, gx, gy, gz deg/s], hints [(t s, |speed| m/s)]) of an MCAP
    written by convert.py (JSON messages on the raw and hint topics)."""
    with open(path, "rb") as f:
        records = read_mcap_records(f.read())
    topics, samples, hints = {}, [], []
    for op, body in records:
        if op == 0x04:  # Channel: id, schema id, topic
            (cid,) = struct.unpack_from("<H", body)
            (n,) = struct.unpack_from("<I", body, 4)
            topics[cid] = body[8 : 8 + n].decode()
        elif op == 0x05:  # Message: channel id, sequence, log time, publish time, data
            (cid,) = struct.unpack_from("<H", body)
            m = json.loads(body[22:])
            t = m["stamps"]["sample_ns"] * 1e-9
            if topics[cid] == "mems/imu/raw":
                samples.append([t] + m["accel_g"] + m["gyro_dps"])
            else:
                hints.append((t, abs(m["forward_speed_mps"])))
    return samples, hints


def windows(samples, hints, length_s=1.0):
    """(class name or None, accel sd mg, gyro sd deg/s) of each window of `length_s`."""
    times = [h[0] for h in hints]
    out, start = [], 0
    while start < len(samples):
        t0 = samples[start][0]
        end = start
        while end < len(samples) and samples[end][0] - t0 < length_s:
            end += 1
        w = samples[start:end]
        start = end
        if len(w) < 5:
            continue
        speeds = [s for _, s in hints[bisect.bisect_left(times, t0) : bisect.bisect_left(times, w[-1][0] + 1e-9)]]
        if not speeds:
            continue
        accel = 1000 * math.sqrt(sum(statistics.pvariance([x[k] for x in w]) for k in (1, 2, 3)))
        gyro = math.sqrt(sum(statistics.pvariance([x[k] for x in w]) for k in (4, 5, 6)))
        name = next((n for n, lo, hi in CLASSES if all(lo <= s <= hi if hi == lo else lo < s <= hi for s in speeds)), None)
        out.append((name, accel, gyro))
    return out


def summary(values):
    """`median (p10-p90)` of `values`."""
    v = sorted(values)
    q = lambda p: v[int(p * (len(v) - 1))]  # noqa: E731
    return f"{q(0.5):.1f} ({q(0.1):.1f}-{q(0.9):.1f})"


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", default=os.environ.get("MEMS_REAL_DATA", "/work/real-data"), help="converted data")
    args = p.parse_args()
    print("| recording | class | windows of 1 s | accel sd, 3 axes, mg: median (10-90 %) | gyro sd, 3 axes, deg/s |")
    print("|---|---|---|---|---|")
    for rec in RECORDINGS:
        path = os.path.join(args.data, rec + ".mcap")
        if not os.path.exists(path):
            sys.exit(f"{path}: no such recording (tools/real-data/convert.py writes it)")
        ws = windows(*read(path))
        for name, _, _ in CLASSES:
            these = [w for w in ws if w[0] == name]
            if these:
                print(f"| {rec} | {name} | {len(these)} | {summary([w[1] for w in these])} | {summary([w[2] for w in these])} |")


if __name__ == "__main__":
    main()
