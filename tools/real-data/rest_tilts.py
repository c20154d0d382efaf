#!/usr/bin/env python3
"""Tilt change between successive rests of the corpus's non-foot recordings: the figure the
uncalibrated part's bias random walk is sized by (odometry/src/config.rs,
`REST_TILT_CHANGE_DEG`; docs/real-data.md, "An uncalibrated part").

A stillness test of its own, not the odometry's detector: the samples are cut into windows of
WINDOW_S; a window is still when the norm of its per-axis standard deviations is below
ACCEL_STD_G (accelerometer, g) and GYRO_STD_DPS (gyroscope, deg/s); successive still windows
make one rest, kept when at least MIN_REST_S long. The rest's attitude is the direction of its
mean specific force (sensor frame); the tilt change is the angle between successive rests'
directions, degrees. Foot walks are left out: their stances are no rests of a refinement
(SHOE refines nothing).

Usage: rest_tilts.py [--data DIR] [--accel-std-g G] [--gyro-std-dps DPS]
"""

import argparse
import json
import math
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import containers  # noqa: E402

WINDOW_S = 0.5
MIN_REST_S = 1.0
COLUMNS = ("t_s", "ax_g", "ay_g", "az_g", "gx_dps", "gy_dps", "gz_dps")


def samples(data, rid):
    """(n, 7) array: time s, accelerometer g, gyroscope deg/s of converted recording `rid`."""
    side = json.loads((data / f"{rid}.json").read_text())
    name = side.get("input", side["csv"])
    path = data / name
    if name.endswith(".mcap"):
        rows = []
        for op, body in containers.read_mcap_records(path.read_bytes()):
            if op == containers.MCAP_OP["message"]:
                msg = json.loads(body[22:])
                if "accel_g" in msg:
                    rows.append([msg["stamps"]["sample_ns"] * 1e-9, *msg["accel_g"], *msg["gyro_dps"]])
        return np.array(rows)
    with open(path) as f:
        lines = [line for line in f if line.strip() and not line.startswith("#")]
    header = lines[0].strip().split(",")
    missing = [c for c in COLUMNS if c not in header]
    if missing:
        raise SystemExit(f"{path}:1: no column {', '.join(missing)}")
    idx = [header.index(c) for c in COLUMNS]
    return np.array([[float(line.split(",")[i]) for i in idx] for line in lines[1:]])


def rest_directions(a, accel_std_g, gyro_std_dps):
    """Unit mean specific force of each rest of the samples `a` (see the module doc)."""
    n = max(int(round(WINDOW_S / np.median(np.diff(a[:, 0])))), 5)
    need = int(math.ceil(MIN_REST_S / WINDOW_S))
    rests, run = [], []
    for k in range(0, len(a) - n + 1, n):
        w = a[k:k + n]
        if np.linalg.norm(w[:, 1:4].std(0)) < accel_std_g and np.linalg.norm(w[:, 4:7].std(0)) < gyro_std_dps:
            run.append(w[:, 1:4].mean(0))
            continue
        if len(run) >= need:
            rests.append(np.mean(run, 0))
        run = []
    if len(run) >= need:
        rests.append(np.mean(run, 0))
    return [r / np.linalg.norm(r) for r in rests]


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", default=os.environ.get("MEMS_REAL_DATA", "/work/real-data"))
    p.add_argument("--accel-std-g", type=float, default=0.03)
    p.add_argument("--gyro-std-dps", type=float, default=2.0)
    args = p.parse_args()
    corpus = json.loads((Path(__file__).resolve().parent / "corpus.json").read_text())
    every = []
    print("| recording | rests | tilt change between successive rests, deg (each) |")
    print("| --- | --- | --- |")
    for rec in corpus["recordings"]:
        if rec["platform"] == "foot":
            continue
        dirs = rest_directions(samples(Path(args.data), rec["id"]), args.accel_std_g, args.gyro_std_dps)
        tilts = [math.degrees(math.acos(min(1.0, float(u @ v)))) for u, v in zip(dirs, dirs[1:])]
        every += tilts
        print(f"| {rec['id']} | {len(dirs)} | {', '.join(f'{t:.2f}' for t in tilts) or '-'} |")
    print()
    if every:
        t = np.array(every)
        print(f"{len(t)} successive-rest pairs: median {np.median(t):.2f} deg, rms "
              f"{math.sqrt(np.mean(t ** 2)):.2f} deg, largest {t.max():.2f} deg (windows of {WINDOW_S} s "
              f"still below {args.accel_std_g} g and {args.gyro_std_dps} deg/s, rests of at least {MIN_REST_S} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
