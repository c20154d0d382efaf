#!/usr/bin/env python3
"""How far the clip reconstruction's prior is from the truth: each gyroscope axis of a recording
capped at +-DPS deg/s, every clipped stretch (a run) reconstructed as odometry/src/clip.rs's
prior does it (`ClipRepair::prior`, written again here: a cubic Hermite curve through the
unclipped neighbours, each side's value and slope from a least-squares line through up to 3
readings, never below the range's end and never beyond 10 rad/s, the pedestrian profile's
manoeuvre rate), and the run's hidden rotation (the integral of |truth| - range over the run,
deg) compared with the reconstructed one. The unclipped recording is the truth of every clipped
sample. Printed per recording: runs, median hidden rotation, the reconstructed/true ratio's
10th/50th/90th percentiles, the signed sums over the recording (true, reconstructed), the
rms of the runs' error over the rms of their hidden rotation, and that ratio once each run's
reconstructed excess is scaled as clip.rs's `Learned` scales it, with the true hidden rotation
of the earlier runs in place of what the rests found of them (per axis and sign, in time order:
the sum of their hidden rotations over the sum of their reconstructed ones, each older run's
share decaying by 0.8 per run, the scale within 4x of 1; 1 before the first): what that scale
can give at best.

Usage: clip_prior.py [--gyro-dps DPS] [--data DIR] [FILE.csv ...]
(default: the corpus's foot walks; a mems-sim CSV with `--gyro-range 2000` works too)
"""

import argparse
import json
import math
import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
NEIGHBOURS = 3
REACH_DPS = math.degrees(10.0)
# clip.rs's LEARN_DECAY and LEARN_BOUND.
LEARN_DECAY, LEARN_BOUND = 0.8, 4.0


def read(path):
    """(interval s, gyro rows deg/s) of a canonical CSV; the interval from its rate (a
    sidecar's `rate_hz`) or its median time step."""
    rows, header = [], None
    with open(path) as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            cells = line.rstrip("\n").split(",")
            if header is None:
                header = cells
                idx = [header.index(c) for c in ("gx_dps", "gy_dps", "gz_dps")]
                it = header.index("t_s")
                continue
            rows.append((float(cells[it]), [float(cells[i]) for i in idx]))
    side = Path(path).with_suffix(".json")
    if side.is_file() and "rate_hz" in json.loads(side.read_text()):
        dt = 1.0 / json.loads(side.read_text())["rate_hz"]
    else:
        steps = sorted(b[0] - a[0] for a, b in zip(rows, rows[1:]))
        dt = steps[len(steps) // 2]
    return dt, [g for _, g in rows]


def line(pts, t_at):
    n = len(pts)
    mt = sum(t for t, _ in pts) / n
    my = sum(y for _, y in pts) / n
    stt = sum((t - mt) ** 2 for t, _ in pts)
    slope = sum((t - mt) * (y - my) for t, y in pts) / stt
    return my + slope * (t_at - mt), slope


def hermite(s, y0, m0, y1, m1):
    return (2 * s**3 - 3 * s**2 + 1) * y0 + (s**3 - 2 * s**2 + s) * m0 + (-2 * s**3 + 3 * s**2) * y1 + (s**3 - s**2) * m1


def runs(values, limit):
    """(first, end) of each stretch at or beyond the range."""
    i, n = 0, len(values)
    while i < n:
        if abs(values[i]) >= limit:
            a = i
            while i < n and abs(values[i]) >= limit:
                i += 1
            yield a, i
        else:
            i += 1


def prior(clipped, a, b, dt, limit):
    """The reconstruction of clipped[a:b] (deg/s), or None without two neighbours a side."""
    left = [(j * dt, clipped[j]) for j in range(a - 1, max(a - 1 - NEIGHBOURS, -1), -1)]
    right = [(j * dt, clipped[j]) for j in range(b, min(b + NEIGHBOURS, len(clipped)))]
    left = [p for p in left if abs(p[1]) < limit]
    right = [p for p in right if abs(p[1]) < limit]
    if len(left) < 2 or len(right) < 2:
        return None
    (t0, y0, s0), (t1, y1, s1) = [(pts[0][0], *line(pts, pts[0][0])) for pts in (left, right)]
    span = t1 - t0
    out = []
    for j in range(a, b):
        sign = math.copysign(1.0, clipped[j])
        h = hermite((j * dt - t0) / span, y0, s0 * span, y1, s1 * span)
        out.append(sign * min(max(h * sign, limit), max(REACH_DPS, limit)))
    return out


def measure(path, limit):
    """(hidden, reconstructed, reconstructed as scaled by the learning) rotation of each run,
    deg, in time order."""
    dt, gyro = read(path)
    runs_found = []
    for axis in range(3):
        truth = [g[axis] for g in gyro]
        clipped = [max(-limit, min(limit, v)) for v in truth]
        for a, b in runs(truth, limit):
            rec = prior(clipped, a, b, dt, limit)
            if rec is None:
                continue
            hidden = sum(t - c for t, c in zip(truth[a:b], clipped[a:b])) * dt
            guess = sum(r - c for r, c in zip(rec, clipped[a:b])) * dt
            runs_found.append((a, axis, clipped[a] > 0, hidden, guess))
    runs_found.sort()
    sums, out = {}, []
    for _, axis, positive, hidden, guess in runs_found:
        curve, truth_sum = sums.get((axis, positive), (0.0, 0.0))
        scale = min(max(truth_sum / curve, 1.0 / LEARN_BOUND), LEARN_BOUND) if curve > 0 else 1.0
        out.append((hidden, guess, guess * scale))
        sums[(axis, positive)] = (LEARN_DECAY * curve + abs(guess), LEARN_DECAY * truth_sum + abs(hidden))
    return out


def percentile(values, q):
    v = sorted(values)
    return v[min(len(v) - 1, int(q * len(v)))]


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--gyro-dps", type=float, default=250.0)
    p.add_argument("--data", default=os.environ.get("MEMS_REAL_DATA", "/work/real-data"))
    p.add_argument("files", nargs="*")
    args = p.parse_args()
    files = args.files
    if not files:
        corpus = json.loads((HERE / "corpus.json").read_text())
        files = [str(Path(args.data) / f"{r['id']}.csv") for r in corpus["recordings"] if r.get("platform") == "foot"]
    print(f"Clip prior against the truth, gyroscope capped at +-{args.gyro_dps:g} deg/s; rotations in deg")
    print()
    print("| recording | runs | median hidden | reconstructed / true, p10 / p50 / p90 | sum true | sum reconstructed "
          "| rms error / rms hidden | the same, scale learned from the truth |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for f in files:
        pairs = measure(f, args.gyro_dps)
        if not pairs:
            print(f"| {Path(f).stem} | 0 | - | - | - | - | - | - |")
            continue
        ratios = [g / h for h, g, _ in pairs if abs(h) > 1e-9]
        rms = lambda xs: math.sqrt(sum(x * x for x in xs) / len(xs))
        print(f"| {Path(f).stem} | {len(pairs)} | {percentile([abs(h) for h, _, _ in pairs], 0.5):.1f} | "
              f"{percentile(ratios, 0.1):.2f} / {percentile(ratios, 0.5):.2f} / {percentile(ratios, 0.9):.2f} | "
              f"{sum(h for h, _, _ in pairs):+.0f} | {sum(g for _, g, _ in pairs):+.0f} | "
              f"{rms([g - h for h, g, _ in pairs]) / rms([h for h, _, _ in pairs]):.2f} | "
              f"{rms([s - h for h, _, s in pairs]) / rms([h for h, _, _ in pairs]):.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
