#!/usr/bin/env python3
"""Vibration and its low-frequency part, second by second, of the corpus's car recordings: the
figures behind odometry::stops (a stop with the engine running against driving) and the
simulator's engine and road (tools/sim/src/vibration.rs).

For each converted CSV recording named (default the two wid-car drives; from the data directory,
default $MEMS_REAL_DATA or /work/real-data), the samples are cut into windows of 1 s. Per window:
- `all mg`: the standard deviation of the three accelerometer axes together (sqrt of the sum of
  the per-axis variances), as the zero-state detector's scatter sees it;
- `<2 Hz mg` and `<2 Hz dps`: the same of the accelerometer and gyroscope after the second-order
  Butterworth low-pass at 2 Hz that odometry::stops runs (bilinear transform, started at the
  first sample's value);
- `peak Hz`: the frequency of the largest accelerometer spectral line (a plain DFT of the
  window, its mean removed).
Printed per window, then the 10-90 % range of each column over the time spans given with
`--span NAME:START:END` (seconds from the recording's start).

Usage: low_frequency.py [--data DIR] [ID ...] [--span NAME:START:END ...]
"""

import argparse
import cmath
import math
import os
from pathlib import Path

G_MPS2 = 9.80665
CUTOFF_HZ = 2.0


def read_csv(path):
    """(t_s, accel m/s^2 triples, gyro rad/s triples) of a converted CSV (g and deg/s)."""
    t, a, w = [], [], []
    with open(path) as f:
        for line in f:
            if line.startswith("#") or line.startswith("t_s"):
                continue
            c = [float(x) for x in line.split(",")[:7]]
            t.append(c[0])
            a.append([x * G_MPS2 for x in c[1:4]])
            w.append([math.radians(x) for x in c[4:7]])
    return t, a, w


def low_pass(xs, dt):
    """Each channel of the rows `xs` through the Butterworth low-pass at CUTOFF_HZ."""
    fc = min(CUTOFF_HZ, 0.4 / dt)
    k = math.tan(math.pi * fc * dt)
    q = math.sqrt(0.5)
    norm = 1.0 / (1.0 + k / q + k * k)
    b0 = k * k * norm
    b = (b0, 2 * b0, b0)
    a = (2 * (k * k - 1) * norm, (1 - k / q + k * k) * norm)
    out = []
    state = [[(b[1] - a[0]) * x + (b[2] - a[1]) * x, (b[2] - a[1]) * x] for x in xs[0]]
    for row in xs:
        y_row = []
        for s, x in zip(state, row):
            y = b[0] * x + s[0]
            s[0] = b[1] * x - a[0] * y + s[1]
            s[1] = b[2] * x - a[1] * y
            y_row.append(y)
        out.append(y_row)
    return out


def spread(rows):
    """sqrt of the sum of the per-channel variances of `rows`."""
    n = len(rows)
    total = 0.0
    for c in range(len(rows[0])):
        m = sum(r[c] for r in rows) / n
        total += sum((r[c] - m) ** 2 for r in rows) / (n - 1)
    return math.sqrt(total)


def peak_hz(rows, rate):
    """Frequency of the largest line of the rows' spectrum (power summed over channels)."""
    n = len(rows)
    means = [sum(r[c] for r in rows) / n for c in range(3)]
    best, best_f = -1.0, 0.0
    for k in range(1, n // 2 + 1):
        p = 0.0
        for c in range(3):
            z = sum((rows[i][c] - means[c]) * cmath.exp(-2j * math.pi * k * i / n) for i in range(n))
            p += abs(z) ** 2
        if p > best:
            best, best_f = p, k * rate / n
    return best_f


def windows(path):
    """Per 1 s window: (start s, all mg, <2 Hz mg, <2 Hz dps, peak Hz)."""
    t, a, w = read_csv(path)
    dt = (t[-1] - t[0]) / (len(t) - 1)
    rate = 1.0 / dt
    la, lw = low_pass(a, dt), low_pass(w, dt)
    n = int(round(rate))
    out = []
    for i in range(0, len(t) - n, n):
        out.append((
            t[i] - t[0],
            spread(a[i:i + n]) / G_MPS2 * 1e3,
            spread(la[i:i + n]) / G_MPS2 * 1e3,
            math.degrees(spread(lw[i:i + n])),
            peak_hz(a[i:i + n], rate),
        ))
    return out


def quantiles(xs):
    xs = sorted(xs)
    return xs[int(0.1 * (len(xs) - 1))], xs[int(0.9 * (len(xs) - 1))]


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("ids", nargs="*", default=["wid-car-06", "wid-car-10"])
    p.add_argument("--data", default=os.environ.get("MEMS_REAL_DATA", "/work/real-data"))
    p.add_argument("--span", action="append", default=[], metavar="NAME:START:END")
    args = p.parse_args()
    for rid in args.ids:
        rows = windows(Path(args.data) / f"{rid}.csv")
        print(f"{rid}\n  t s   all mg  <2 Hz mg  <2 Hz dps  peak Hz")
        for r in rows:
            print(f"  {r[0]:5.0f} {r[1]:7.1f} {r[2]:8.1f} {r[3]:9.3f} {r[4]:8.1f}")
        for span in args.span:
            name, start, end = span.split(":")
            sel = [r for r in rows if float(start) <= r[0] and r[0] + 1 <= float(end)]
            if not sel:
                continue
            cols = [quantiles([r[i] for r in sel]) for i in (1, 2, 3)]
            print(f"  {name} {start}-{end} s ({len(sel)} windows), 10-90 %: all {cols[0][0]:.1f}-"
                  f"{cols[0][1]:.1f} mg, <2 Hz {cols[1][0]:.1f}-{cols[1][1]:.1f} mg and "
                  f"{cols[2][0]:.3f}-{cols[2][1]:.3f} deg/s")


if __name__ == "__main__":
    main()
