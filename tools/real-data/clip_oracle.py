#!/usr/bin/env python3
"""What the clip handling costs when the readings are right: each foot walk of the corpus kept
as recorded (the true rates) but with every sample whose gyroscope axis exceeds +-DPS deg/s
flagged as clipped on that axis (a `flags` column: `raw_flags::GYRO_VALID`, `SATURATED` and the
axis's `SATURATED_AXES` bit, ipc-types/src/wire.rs). The odometry then treats the samples a
part with that range would have clipped as clipped, while holding their truth, so any loss
against the unflagged run is the clip handling's own, not the missing rotation's.

Each walk is run as bench.py runs it (the identity calibration, `mems-odometry offline
--json`), four ways: unflagged (the plain recording), flagged and reconstructed at the rest
(odometry/src/clip.rs; its prior curve is kept at or beyond the reading, which here is the
truth), flagged and bridged only (`--bridge-clipped`: the true readings integrated, the 1-sigma
widened about each clipped axis for what the clip would have hidden) and flagged and integrated
as measured (`--trust-clipped`: must equal the unflagged run, the check that the flags change
nothing else). Printed: horizontal end error / 1-sigma (m, bench.py's `evaluate`) and whether
the 68 % radius covers the error.

Usage: clip_oracle.py [--gyro-dps DPS] [--bin PATH] [--data DIR] [--only ID ...]
"""

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench  # noqa: E402

HERE = Path(__file__).resolve().parent
GYRO = ("gx_dps", "gy_dps", "gz_dps")
# ipc-types/src/wire.rs, raw_flags.
GYRO_VALID, TEMP_VALID, SATURATED = 1 << 4, 1 << 5, 1 << 2


def saturated_axis(i):
    """raw_flags::saturated_axis: 0-2 accelerometer x, y, z; 3-5 gyroscope x, y, z."""
    return 1 << (7 + i)


def flag_csv(src, dst, limit):
    """Writes `src` to `dst` with a `flags` column marking the gyroscope axes beyond `limit`
    deg/s as clipped, values unchanged; returns the rows flagged."""
    ig, base, flagged = [], GYRO_VALID, 0

    def header(cells, line):
        nonlocal base
        if "flags" in cells:
            raise SystemExit(f"{src}:{line}: already has a flags column")
        ig.extend(cells.index(c) for c in GYRO)
        base |= TEMP_VALID if "temp_c" in cells else 0
        return cells + ["flags"]

    def row(cells):
        nonlocal flagged
        flags = base
        for axis, i in enumerate(ig):
            if abs(float(cells[i])) > limit:
                flags |= SATURATED | saturated_axis(3 + axis)
        flagged += flags != base
        return cells + [str(flags)]

    bench.rewrite_csv(src, dst, header, row)
    return flagged


def cell(row):
    if "error" in row:
        return "failed | -"
    r = row["result"]
    return f"{r['error_m'][1]:.2f} / {r['sigma_h_m']:.2f} | {r['covered']}"


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--gyro-dps", type=float, default=250.0)
    p.add_argument("--bin", default=str(HERE.parent.parent / "target" / "release" / "mems-odometry"))
    p.add_argument("--data", default=os.environ.get("MEMS_REAL_DATA", "/work/real-data"))
    p.add_argument("--only", action="append", default=[])
    args = p.parse_args()
    recs = bench.corpus_recordings(args.only, "foot")
    data = Path(args.data)
    print(f"Foot walks with their true rates, flagged clipped beyond +-{args.gyro_dps:g} deg/s (gyro); "
          "horizontal end error / 1-sigma, m")
    print()
    print("| walk | rows flagged | unflagged | covered | reconstructed at the rest | covered "
          "| bridged only | covered | integrated as measured | covered |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    with bench.plain_and_changed(args.bin, data) as (plain, flagged, flagged_dir):
        for rec in recs:
            name = bench.copy_sidecar(data, flagged_dir, rec)
            if not name.endswith(".csv"):
                raise SystemExit(f"{rec['id']}: {name} is not a CSV recording")
            rows = flag_csv(data / name, flagged_dir / name, args.gyro_dps)
            extra = list(rec.get("extra_args", []))
            cells = [cell(plain.row(rec, extra))] + [
                cell(flagged.row(rec, extra + mode)) for mode in ([], ["--bridge-clipped"], ["--trust-clipped"])
            ]
            print(f"| {rec['id']} | {rows} | {' | '.join(cells)} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
