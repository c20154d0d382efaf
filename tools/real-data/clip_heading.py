#!/usr/bin/env python3
"""Where a clipped walk's end error comes from: each foot walk of the corpus run as converted and
with every gyroscope column capped at +-DPS deg/s (perturb.py's clipping, the reconstruction at
the rests on), and the two runs' rests (`mems-odometry offline --json`'s `rests`, matched by
time) compared step by step: a step is the horizontal move from one rest to the next, kept where
the unclipped step is at least 0.3 m. Each rest's position is the `track`'s (every 0.1 s) first
at least SETTLE_S after the rest's first sample, in both runs at the same time: a rest's own
`position_m` is its first sample's, and after a clipped motion that is the bridged state the
reconstruction replaces at the end of the rest window (odometry/src/clip.rs, `REST_WINDOW_S`,
0.1 s), so steps measured there are the bridging's (the xio walks' came out 36-37 cm short),
not what the run keeps. Printed per walk: steps matched, the clipped steps' length
error (mean and mean absolute, cm), the heading error of the clipped path (the direction of the
clipped step less the unclipped one's, deg: median over the first and the last quarter of the
steps) and the end error / 1-sigma of the clipped run (m, bench.py's).

The unclipped run is the truth of the clipped one here: what the clips cost, not what either
gets wrong.

Usage: clip_heading.py [--gyro-dps DPS] [--bin PATH] [--data DIR] [--only ID ...]
"""

import argparse
import math
import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench  # noqa: E402
import perturb  # noqa: E402

MIN_STEP_M = 0.3
# After a rest's first sample, s: past clip.rs's rest window (0.1 s), where a clipped motion is
# redone.
SETTLE_S = 0.15


def settled(track, t):
    """The horizontal position of `track` (rows t s, x, y, z m) at its first row at least
    SETTLE_S after `t`, None past its end."""
    for row in track:
        if row[0] >= t + SETTLE_S:
            return row[1:3]
    return None


def steps(clean, clipped):
    """(heading error deg, length error m) of each matched step of the runs `clean` and
    `clipped` (`mems-odometry offline --json` outputs)."""
    by_t = {round(r["t_s"], 2): r for r in clean["rests"]}
    out, prev = [], None
    for r in clipped["rests"]:
        c = by_t.get(round(r["t_s"], 2))
        if c is None:
            continue
        here = (settled(clipped["track"], r["t_s"]), settled(clean["track"], r["t_s"]))
        if None in here:
            break
        if prev is not None:
            sk = [a - b for a, b in zip(here[0], prev[0])]
            sc = [a - b for a, b in zip(here[1], prev[1])]
            if math.hypot(*sc) >= MIN_STEP_M:
                turn = math.degrees(math.atan2(sk[1], sk[0]) - math.atan2(sc[1], sc[0]))
                out.append(((turn + 180) % 360 - 180, math.hypot(*sk) - math.hypot(*sc)))
        prev = here
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--gyro-dps", type=float, default=250.0)
    p.add_argument("--bin", default=str(bench.REPO / "target" / "release" / "mems-odometry"))
    p.add_argument("--data", default=os.environ.get("MEMS_REAL_DATA", "/work/real-data"))
    p.add_argument("--only", nargs="*")
    args = p.parse_args()
    clip = perturb.Perturbation(argparse.Namespace(accel_scale=None, accel_bias_g=None, accel_g=None,
                                                   gyro_dps=args.gyro_dps))
    recs = bench.corpus_recordings(args.only, "foot")
    print(f"Foot walks with the gyroscope clipped at +-{args.gyro_dps:g} deg/s against the same walks unclipped, step by step")
    print()
    print("| walk | steps | length error, mean / mean abs, cm | heading error, first / last quarter, deg | end error / 1-sigma, m |")
    print("| --- | --- | --- | --- | --- |")
    with bench.plain_and_changed(args.bin, args.data) as (plain, clipped, clipped_dir):
        for rec in recs:
            name = bench.copy_sidecar(args.data, clipped_dir, rec)
            write = perturb.perturb_mcap if name.endswith(".mcap") else perturb.perturb_csv
            write(Path(args.data) / name, clipped_dir / name, clip)
            extra = list(rec.get("extra_args", []))
            a, b = plain.row(rec, extra), clipped.row(rec, extra)
            if "error" in a or "error" in b:
                print(f"| {rec['id']} | failed: {a.get('error') or b.get('error')} | | | |")
                continue
            st = steps(a["odometry"], b["odometry"])
            q = max(1, len(st) // 4)
            head = [h for h, _ in st]
            lengths = [dl for _, dl in st]
            r = b["result"]
            print(f"| {rec['id']} | {len(st)} | {100 * statistics.mean(lengths):+.1f} / "
                  f"{100 * statistics.mean(abs(x) for x in lengths):.1f} | "
                  f"{statistics.median(head[:q]):+.1f} / {statistics.median(head[-q:]):+.1f} | "
                  f"{r['error_m'][1]:.2f} / {r['sigma_h_m']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
