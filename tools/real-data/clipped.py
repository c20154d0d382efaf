#!/usr/bin/env python3
"""The corpus's foot walks clipped as a cheap part's range would clip them, run as bench.py runs
them: a table of the end error and 1-sigma unclipped, clipped (the default: clipped samples
flagged, counted, reconstructed and widened) and clipped with `--trust-clipped` (integrated as
measured, the behaviour before the check), with the samples found clipped.

A clipped copy of each walk's CSV caps every gyroscope column at +-DPS deg/s (`--gyro-dps`)
or every accelerometer column at +-G g (`--accel-g`), as a part with that range outputs its
end of range for anything beyond. Nothing tells the odometry the range: it infers it from the
readings stuck at the file's extreme (ipc_types::stream::range). Errors and coverage are
bench.py's (`evaluate`: horizontal end error, covered when within the 68 % radius).

Usage: clipped.py (--gyro-dps DPS | --accel-g G) [--bin PATH] [--data DIR] [--only ID ...] [--json]
"""

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench  # noqa: E402

COLUMNS = {"gyro": ("gx_dps", "gy_dps", "gz_dps"), "accel": ("ax_g", "ay_g", "az_g")}


def clip_csv(src, dst, columns, limit):
    """Writes `src` to `dst` with `columns` capped at +-limit; returns the rows capped."""
    capped = 0
    with open(src) as fin, open(dst, "w") as fout:
        header = None
        for line in fin:
            if line.startswith("#") or not line.strip():
                fout.write(line)
                continue
            cells = line.rstrip("\n").split(",")
            if header is None:
                header = cells
                idx = [header.index(c) for c in columns]
                fout.write(line)
                continue
            hit = False
            for i in idx:
                v = float(cells[i])
                if abs(v) > limit:
                    cells[i] = repr(limit if v > 0 else -limit)
                    hit = True
            capped += hit
            fout.write(",".join(cells) + "\n")
    return capped


def figures(row):
    """(horizontal error upper end, m; 1-sigma, m; covered; clipped samples) of a run."""
    if "error" in row:
        return None
    r, out = row["result"], row["odometry"]
    return r["error_m"][1], r["sigma_h_m"], r["covered"], out.get("clipped_samples")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--gyro-dps", type=float, help="clip the gyroscope at +-DPS deg/s")
    which.add_argument("--accel-g", type=float, help="clip the accelerometer at +-G g")
    p.add_argument("--bin", default=str(bench.REPO / "target" / "release" / "mems-odometry"))
    p.add_argument("--data", default=os.environ.get("MEMS_REAL_DATA", "/work/real-data"))
    p.add_argument("--only", action="append", metavar="ID")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    sensor, limit = ("gyro", args.gyro_dps) if args.gyro_dps else ("accel", args.accel_g)
    corpus = json.loads((bench.HERE / "corpus.json").read_text())
    walks = [r for r in corpus["recordings"] if r.get("platform") == "foot"
             and (not args.only or r["id"] in args.only)]
    data = Path(args.data)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        calib = tmp / "identity.toml"
        calib.write_text(bench.identity_calibration())
        clipped_dir = tmp / "clipped"
        clipped_dir.mkdir()
        plain = bench.Runner(Path(args.bin), calib, data, 900.0, quiet=True)
        clipped = bench.Runner(Path(args.bin), calib, clipped_dir, 900.0, quiet=True)
        for rec in walks:
            side = json.loads((data / f"{rec['id']}.json").read_text())
            csv = side["csv"]
            (clipped_dir / f"{rec['id']}.json").write_text(json.dumps(side))
            capped = clip_csv(data / csv, clipped_dir / csv, COLUMNS[sensor], limit)
            extra = list(rec.get("extra_args", []))
            rows.append({
                "id": rec["id"],
                "rows_capped": capped,
                "unclipped": figures(plain.row(rec, extra)),
                "clipped": figures(clipped.row(rec, extra)),
                "trusted": figures(clipped.row(rec, extra + ["--trust-clipped"])),
            })
            print(f"{rec['id']}: done", file=sys.stderr)
    if args.json:
        json.dump(rows, sys.stdout, indent=1)
        print()
        return 0
    unit = "deg/s" if sensor == "gyro" else "g"
    print(f"Foot walks clipped at +-{limit:g} {unit} ({sensor}); horizontal end error / 1-sigma, m")
    print()
    print("| walk | rows clipped | unclipped | clipped, flagged and bridged | covered | clipped, integrated as measured | within 2x of unclipped |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    fmt = lambda f: "failed" if f is None else f"{f[0]:.2f} / {f[1]:.2f}"
    good = covered = 0
    for r in rows:
        u, c, t = r["unclipped"], r["clipped"], r["trusted"]
        within = u is not None and c is not None and c[0] <= 2 * max(u[0], 0.0)
        good += within
        covered += c is not None and c[2] == "yes"
        print(f"| {r['id']} | {r['rows_capped']} ({c[3] if c else '?'} flagged) | {fmt(u)} | {fmt(c)} | "
              f"{c[2] if c else '-'} | {fmt(t)} | {'yes' if within else 'no'} |")
    print()
    print(f"{good} of {len(rows)} within 2x of their unclipped error; {covered} of {len(rows)} covered by the 1-sigma")
    return 0


if __name__ == "__main__":
    sys.exit(main())
